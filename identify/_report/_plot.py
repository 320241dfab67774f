"""The data against the fit: residuals per file with the excluded rows marked, and for
impact onsets the plot people look at first, restitution against impact speed.

Figures stay readable from one file to dozens: no legend sits over the data (the legend
of the markers goes below the axes, the key of the files to their right: a legend of
file names up to `MANY_FILES` files, beyond that a colour bar of the release height),
held-out rows are open circles and outliers red crosses, and residuals beyond the axis
of the kept rows are drawn at its edge instead of squashing it.

Only drawing happens here: the restitution panel draws a `RestitutionCurves` that the fit
layer computed (`identify._fit._curves`; `identify.plot` passes it).
"""

from __future__ import annotations

import os
from typing import TYPE_CHECKING

import numpy as np

if TYPE_CHECKING:
    from .._fit._curves import RestitutionCurves

#: Up to this many files the figure names every file in a legend; beyond, a colour bar.
MANY_FILES = 10
#: Outlier marker colour (matplotlib's "C3", red).
OUTLIER = "C3"


def _label(d, f: int) -> str:
    return os.path.basename(d.path) if d.path else f"data {f + 1}"


def _files(result):
    """(dataset, residuals in data units, used mask, outlier rows) per file."""
    datasets = result.datasets_data or [result.data]
    residuals = np.asarray(result.residuals)
    used = result.used if result.used is not None else np.ones(len(residuals), bool)
    out, start = [], 0
    for f, d in enumerate(datasets):
        n = d.num_rows
        entry = result.datasets[f] if result.datasets else None
        outliers = np.asarray([o.row for o in entry.outliers] if entry is not None else [], dtype=int)
        out.append((d, residuals[start : start + n], used[start : start + n], outliers))
        start += n
    return out


class _Key:
    """Each file's colour and the figure's key to them: a legend of names, or a colour bar
    of the release height x0 (mm; of the file number when every file has the same x0)."""

    def __init__(self, result):
        files = result.file_table() if result.datasets else None
        datasets = result.datasets_data or [result.data]
        self.names = [_label(d, f) for f, d in enumerate(datasets)]
        self.n = len(datasets)
        if files is not None:
            heights = np.asarray([f["x0"]["value"] for f in files], dtype=float) * 1e3
        else:
            heights = np.asarray([float(d.x0) for d in datasets]) * 1e3
        self.by_height = bool(np.ptp(heights) > 0)
        self.values = heights if self.by_height else np.arange(1, self.n + 1, dtype=float)
        self.scale = self.n > MANY_FILES
        if self.scale:
            from matplotlib import colormaps
            from matplotlib.colors import Normalize

            lo, hi = float(np.min(self.values)), float(np.max(self.values))
            self.norm = Normalize(lo, hi if hi > lo else lo + 1.0)
            self.cmap = colormaps["viridis"]
            self.colours = [self.cmap(self.norm(v)) for v in self.values]
        else:
            self.colours = [f"C{f % 10}" for f in range(self.n)]

    def draw(self, fig, axes) -> None:
        """The files' key to the right of `axes` (nothing for a single file)."""
        if self.n < 2:
            return
        if self.scale:
            from matplotlib.cm import ScalarMappable

            mappable = ScalarMappable(norm=self.norm, cmap=self.cmap)
            label = "release height x0 [mm]" if self.by_height else "file number"
            bar = fig.colorbar(mappable, ax=axes, location="right", shrink=0.9, pad=0.01, aspect=30)
            bar.set_label(f"file: {label} ({self.n} files)")
            return
        from matplotlib.lines import Line2D

        handles = [
            Line2D([], [], ls="none", marker="o", ms=5, color=c, label=name)
            for c, name in zip(self.colours, self.names, strict=True)
        ]
        fig.legend(handles=handles, loc="outside right upper", fontsize=8, title="file", title_fontsize=8)


def _style_legend(
    fig, *, laws=(), held_out: bool, outliers: bool, trace: bool = False, row_label: str = "fitted row"
) -> None:
    """The markers' (and the law curves') legend, one row below the axes."""
    from matplotlib.lines import Line2D

    handles = [Line2D([], [], color=c, ls=ls, lw=1.5, label=name) for name, c, ls in laws]
    handles.append(
        Line2D([], [], ls="none", marker="." if trace else "o", ms=5, color="0.35", label=row_label)
    )
    if held_out:
        handles.append(
            Line2D(
                [],
                [],
                ls="none",
                marker="o",
                ms=6,
                mfc="none",
                mew=1.2,
                color="0.35",
                label="held-out row (predicted, not fitted)",
            )  # fmt: skip
        )
    if outliers:
        handles.append(
            Line2D([], [], ls="none", marker="x", ms=7, mew=2, color=OUTLIER, label="outlier (excluded)")
        )
        handles.append(
            Line2D([], [], ls="none", marker="^", ms=6, color=OUTLIER, label="outlier beyond the axis")
        )
    fig.legend(handles=handles, loc="outside lower center", ncol=len(handles), fontsize=8, frameon=False)


def plot_restitution_of_fit(result, view: RestitutionCurves, *, ax=None):
    """Per-bounce restitution against impact speed: the data (drag-corrected flights of
    the kept onsets, each file in its colour) and each fitted law's curve (black), as the
    fit layer computed them (`view`).

    On a new figure (`ax` None) the files' key and the legend sit outside the axes as in
    `plot_fit`; on a given `ax`, one legend (the laws, and the files up to `MANY_FILES`)
    goes just right of it. **Returns:** the figure.
    """
    from matplotlib.figure import Figure
    from matplotlib.lines import Line2D

    key = _Key(result)
    points, curves = view.points, view.curves
    if ax is None:
        fig = Figure(
            figsize=(7.5, max(4.6, 1.8 + 0.26 * key.n * (key.n <= MANY_FILES))), layout="constrained"
        )
        ax = fig.add_subplot()
        laws = _restitution_panel(ax, result, key, points, curves)
        key.draw(fig, [ax])
        _style_legend(fig, laws=laws, held_out=False, outliers=False, row_label="bounce (kept onsets)")
        return fig
    laws = _restitution_panel(ax, result, key, points, curves)
    handles = [Line2D([], [], color=c, ls=ls, lw=1.5, label=name) for name, c, ls in laws]
    if 1 < key.n <= MANY_FILES:
        handles += [
            Line2D([], [], ls="none", marker="o", ms=5, color=c, label=name)
            for c, name in zip(key.colours, key.names, strict=True)
        ]
    ax.legend(handles=handles, loc="upper left", bbox_to_anchor=(1.01, 1.0), fontsize=8, borderaxespad=0.0)
    return ax.figure


def _restitution_panel(ax, result, key: _Key, points, curves) -> list:
    """e against impact speed, each file's bounces in its colour, the laws as black lines.

    A file whose own flights show e changing with the impact speed (`result.trends`) gets
    each side's mean e as a dotted step in its colour and the split speed as a dotted
    vertical line; where the fit kept only the bounces above it (e falling at low speed),
    the bounces below are open markers. **Returns:** the curves' (name, colour, linestyle)
    for the legend."""
    trends = {t.get("file", 0): t for t in getattr(result, "trends", None) or []}
    for f, _, p in points:
        v, e = np.asarray(p.impact_speed, float), np.asarray(p.restitution, float)
        trend = trends.get(f)
        slow = (
            v < trend["speed"] if trend is not None and trend["direction"] == "falls at low speed" else v < 0
        )
        style = dict(ms=4, color=key.colours[f], alpha=0.85 if key.n > 1 else 1.0, ls="none")
        ax.plot(v[~slow], e[~slow], "o", **style)
        if slow.any():
            ax.plot(v[slow], e[slow], "o", mfc="none", **style)
    for f, trend in trends.items():
        colour = key.colours[min(f, len(key.colours) - 1)]
        speeds = np.concatenate([np.asarray(p.impact_speed, float) for g, _, p in points if g == f] or [[]])
        if speeds.size == 0:
            continue
        cut = trend["speed"]
        ax.plot([speeds.min(), cut, cut, speeds.max()],
                [trend["e_below"], trend["e_below"], trend["e_above"], trend["e_above"]],
                color=colour, ls=":", lw=1.2)  # fmt: skip
        ax.axvline(cut, color=colour, ls=":", lw=0.8)
        kept = " (fitted above)" if trend["direction"] == "falls at low speed" else ""
        ax.annotate(f"e {trend['direction']}{kept}", (cut, trend["e_below"]), xytext=(4, -10),
                    textcoords="offset points", fontsize=7, color=colour)  # fmt: skip
    every = [np.asarray(p.impact_speed, float) for *_, p in points]
    every = np.concatenate(every) if every else np.array([1.0])
    if trends and every.size and every.min() > 0 and every.max() > 5 * every.min():
        ax.set_xscale("log")  # the slow bounces, where e changes, would crowd at the axis
    laws = []
    for j, (name, (speeds, e)) in enumerate(curves.items()):
        ls = "-" if j == 0 else "--"
        order = np.argsort(speeds)
        ax.plot(np.asarray(speeds)[order], np.asarray(e)[order], color="k", ls=ls, lw=1.5)
        laws.append((str(name), "k", ls))
    ax.set_xlabel("impact speed v [m/s]")
    ax.set_ylabel("restitution e = v_out / v_in [-]")
    ax.set_title(
        f"restitution per bounce ({sum(len(p.restitution) for *_, p in points)} bounces)", fontsize=9
    )
    ax.grid(True, alpha=0.3)
    return laws


def plot_fit(result, view: RestitutionCurves | None = None, *, title: str | None = None):
    """The figure of `jaxunilat.identify.plot.plot_fit` (its docstring says what it shows).
    `view`: the restitution panel's points and curves (impact onsets only;
    `identify._fit._curves.restitution_curves`)."""
    from matplotlib.figure import Figure

    data = result.data
    key = _Key(result)
    files = _files(result)
    held = any(np.any(_held_out(res, used, out)) for _, res, used, out in files)
    excluded = any(out.size for *_, out in files)
    named = key.n if 1 < key.n <= MANY_FILES else 0
    height = max(5.2, 2.0 + 0.26 * named)
    if data.observe == "impacts":
        fig = Figure(figsize=(13.0, height), layout="constrained")
        left, right = fig.subplots(1, 2, width_ratios=(1, 1.2))
        laws = _restitution_panel(left, result, key, view.points, view.curves)
        _residual_panel(
            right, result, key, scale=1e3, unit="ms", xlabel="onset time t [s] (each file's clock)"
        )
        key.draw(fig, [left, right])
        _style_legend(
            fig, laws=laws, held_out=held, outliers=excluded, row_label="bounce (left), fitted onset (right)"
        )
        fig.suptitle(title or _title(result), fontsize=10)
        return fig
    fig = Figure(figsize=(11.0, max(6.5, height + 1.3)), layout="constrained")
    top, bottom = fig.subplots(2, 1, sharex=True, height_ratios=(3, 2))
    d, res, used, outliers = files[0]
    held_rows = _held_out(res, used, outliers)
    c = key.colours[0]
    which = f" ({_label(d, 0)}, file 1 of {key.n})" if key.n > 1 else ""
    if data.observe == "trace":
        x = np.asarray(d.t)
        y = np.asarray(d.x)
        top.plot(x, y, ".", ms=2, color="0.55")
        top.plot(x, y + res, lw=1.0, color="k")
        top.set_ylabel("x [m]")
        top.set_title("position: data (grey dots) and fit (black line)" + which, fontsize=9)
        _residual_panel(bottom, result, key, scale=1e3, unit="mm", xlabel="t [s]")
        laws = [("fit", "k", "-")]
    else:
        x = np.arange(len(res))
        y = np.asarray(d.h)
        top.plot(x, y, "o", color="0.55", ms=5)
        top.plot(x, y + res, "_", color="k", ms=14, mew=2)
        top.set_ylabel("apex height h [m]")
        top.set_title("rebound apex heights: data (grey) and fit (black bars)" + which, fontsize=9)
        _residual_panel(bottom, result, key, scale=1e3, unit="mm", xlabel="rebound number")
        laws = [("fit", "k", "-")]
    if held_rows.any():
        small = data.observe == "trace"
        top.plot(x[held_rows], y[held_rows], "o", ms=3 if small else 7, mfc="none", mew=0.8 if small else 1.2,
                 color=c)  # fmt: skip
    if outliers.size:
        top.plot(x[outliers], y[outliers], "x", color=OUTLIER, ms=8, mew=2)
    top.grid(True, alpha=0.3)
    key.draw(fig, [top, bottom])
    _style_legend(fig, laws=laws, held_out=held, outliers=excluded, trace=data.observe == "trace")
    fig.suptitle(title or _title(result), fontsize=10)
    return fig


def _held_out(res, used, outliers) -> np.ndarray:
    """Rows neither fitted nor outliers: the held-out rows."""
    held = ~np.asarray(used, bool)
    held[outliers] = False
    return held & np.isfinite(res)


def _residual_panel(ax, result, key: _Key, *, scale: float, unit: str, xlabel: str) -> None:
    """Every file's residuals (prediction − data, × `scale` into `unit`) against time
    (apex: against the rebound): fitted rows dots, held-out rows open circles, outliers
    red crosses, or red triangles at the edge when beyond the range of the other rows."""
    kept_values, outs = [], []
    for f, (d, res, used, outliers) in enumerate(_files(result)):
        x = np.asarray(d.t) if d.observe in ("trace", "impacts") else np.arange(len(res))
        r = np.asarray(res) * scale
        c = key.colours[f]
        trace = d.observe == "trace"
        ax.plot(x[used], r[used], "." if trace else "o", ms=2 if trace else 3.5, color=c)
        held = _held_out(res, used, outliers)
        if held.any():
            ax.plot(x[held], r[held], "o", ms=3 if trace else 6, mfc="none", mew=0.8 if trace else 1.2,
                    color=c)  # fmt: skip
        kept_values.append(r[used | held])
        outs += [(float(x[i]), float(r[i])) for i in outliers]
    kept = np.concatenate(kept_values) if kept_values else np.zeros(0)
    kept = kept[np.isfinite(kept)]
    ax.axhline(0.0, color="0.6", lw=0.8)
    beyond = 0
    if kept.size:
        lo, hi = float(np.min(kept)), float(np.max(kept))
        pad = 0.15 * max(hi - lo, 1e-12)
        lo, hi = min(lo - pad, -pad), max(hi + pad, pad)
        edge_lo, edge_hi = lo + 0.4 * pad, hi - 0.4 * pad
        for x, r in outs:
            if r > hi:
                ax.plot(x, edge_hi, "^", color=OUTLIER, ms=7, clip_on=False)
                beyond += 1
            elif r < lo:
                ax.plot(x, edge_lo, "v", color=OUTLIER, ms=7, clip_on=False)
                beyond += 1
            else:
                ax.plot(x, r, "x", color=OUTLIER, ms=8, mew=2)
        ax.set_ylim(lo, hi)
    else:
        for x, r in outs:
            ax.plot(x, r, "x", color=OUTLIER, ms=8, mew=2)
    ax.set_ylabel(f"fit - data [{unit}]")
    ax.set_xlabel(xlabel)
    ax.grid(True, alpha=0.3)
    text = f"residuals, {key.n} files" if key.n > 1 else "residuals"
    if outs:
        text += f"; {len(outs)} outlier{'s' * (len(outs) > 1)} excluded"
        if beyond:
            worst = max(abs(r) for _, r in outs)
            text += f" ({beyond} off the axis, up to {worst:.3g} {unit})"
    ax.set_title(text, fontsize=9)


def _title(result) -> str:
    """The figure's title: the data, the law, e, and κ and k_r only where the data carry
    them (`result.identifiable`); a κ the data do not bound is named as such, not printed."""
    kappa, k_r = result.params["kappa"], result.params["k_r"]
    e = result.derived["restitution"]
    u = result.units
    files = result.datasets_data or [result.data]
    name = _label(files[0], 0) if len(files) == 1 else f"{len(files)} files"
    known = result.identifiable or {}
    shown = [f"e = {e.value:.4f}"]
    for key, entry in (("kappa", kappa), ("k_r", k_r)):
        if known.get(key):
            shown.append(f"{key} = {entry.value:.4g} {u[key]}")
    missing = [key for key in ("kappa", "k_r") if not known.get(key)]
    if missing:
        shown.append(f"{' and '.join(missing)} not identifiable from these data")
    return f"{name}: {result.law}, " + ", ".join(shown)
