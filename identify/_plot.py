"""The data against the fit: residuals per file with the excluded rows marked, and for
impact onsets the plot people look at first, restitution against impact speed."""

from __future__ import annotations

import os

import numpy as np


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
        entry = result.datasets[f] if result.datasets else {"outliers": []}
        outliers = np.asarray([o["row"] for o in entry["outliers"]], dtype=int)
        out.append((d, residuals[start : start + n], used[start : start + n], outliers))
        start += n
    return out


def law_curves(result, speeds) -> dict:
    """e(v) of the fitted law (and, after `law="auto"`, of the other law) at `speeds` (m/s)."""
    from ._restitution import law_restitution

    d = result.data
    laws = (
        result.laws
        if result.laws
        else {result.law: {"parameters": {"kappa": result.kappa, "k_r": result.k_r}}}
    )
    curves = {}
    for name, entry in laws.items():
        p = entry["parameters"]
        e = law_restitution(name, p["kappa"], p["k_r"], d.mass, speeds, gravity=d.gravity)
        curves[f"{name} (fit)" if name == result.law else name] = (np.asarray(speeds), np.asarray(e))
    return curves


def plot_restitution_of_fit(result, *, ax=None):
    """Per-bounce restitution against impact speed: the data (drag-corrected flights of
    the kept onsets) and each fitted law's curve. **Returns:** the figure."""
    from ._plot_restitution import plot_restitution
    from ._summary import bounce_points

    points = dict(bounce_points(result))
    speeds = (
        np.concatenate([np.asarray(p.impact_speed) for p in points.values()]) if points else np.array([1.0])
    )
    speeds = speeds[np.isfinite(speeds)]
    lo, hi = (float(np.min(speeds)), float(np.max(speeds))) if speeds.size else (0.3, 3.0)
    grid = np.linspace(max(0.8 * lo, 0.05), 1.1 * hi, 24)
    return plot_restitution(points or None, law_curves(result, grid), ax=ax, title="restitution per bounce")


def plot_fit(result, *, title: str | None = None):
    """A figure of the data against the fitted model and the residuals.

    - impact onsets: restitution against impact speed (left: each bounce from the data's
      drag-corrected flight times, each fitted law as a curve) and the onset residuals
      of every file (right), excluded rows marked with a red cross;
    - trace: x(t) data and the fitted run of the first file (top), the residuals of
      every file (bottom);
    - apex: observed rebound heights against the fitted ones (top), residuals (bottom).

    **Returns:** a `matplotlib.figure.Figure` (save it with `jaxunilat.save_figure`).
    """
    from matplotlib.figure import Figure

    data = result.data
    if data.observe == "impacts":
        fig = Figure(figsize=(12.0, 5.0), layout="constrained")
        left, right = fig.subplots(1, 2, width_ratios=(1, 1.2))
        plot_restitution_of_fit(result, ax=left)
        _residual_panel(right, result, scale=1e3, unit="ms", xlabel="onset time t [s]")
        fig.suptitle(title or _title(result), fontsize=10)
        return fig
    fig = Figure(figsize=(9.0, 6.0), layout="constrained")
    top, bottom = fig.subplots(2, 1, sharex=True, height_ratios=(3, 1))
    d, res, _, outliers = _files(result)[0]
    if data.observe == "trace":
        t = np.asarray(d.t)
        top.plot(t, d.x, ".", ms=2, color="0.5", label="data")
        top.plot(t, np.asarray(d.x) + res, lw=1.0, color="C0", label="fit")
        top.set_ylabel("x [m]")
        _residual_panel(bottom, result, scale=1e3, unit="mm", xlabel="t [s]")
    else:
        k = np.arange(len(res))
        top.plot(k, d.h, "o", color="0.5", label="data")
        top.plot(k, np.asarray(d.h) + res, "x", color="C0", label="fit")
        top.set_ylabel("apex height h [m]")
        _residual_panel(bottom, result, scale=1e3, unit="mm", xlabel="rebound")
    if outliers.size:
        x = np.asarray(d.t) if data.observe == "trace" else np.arange(len(res))
        y = d.x if data.observe == "trace" else d.h
        top.plot(x[outliers], np.asarray(y)[outliers], "x", color="C3", ms=8, label="excluded")
    top.legend(loc="upper right")
    top.set_title(title or _title(result), fontsize=10)
    top.grid(True, alpha=0.3)
    return fig


def _residual_panel(ax, result, *, scale: float, unit: str, xlabel: str) -> None:
    """Every file's residuals against time (apex: against the rebound), outliers as red crosses."""
    for f, (d, res, used, outliers) in enumerate(_files(result)):
        x = np.asarray(d.t) if d.observe in ("trace", "impacts") else np.arange(len(res))
        style = dict(ms=2) if d.observe == "trace" else dict(ms=4)
        ax.plot(x[used], res[used] * scale, "o" if d.observe != "trace" else ".", color=f"C{f % 10}",
                label=_label(d, f), **style)  # fmt: skip
        if outliers.size:
            ax.plot(x[outliers], res[outliers] * scale, "x", color="C3", ms=9, mew=2)
    ax.axhline(0.0, color="0.6", lw=0.8)
    ax.set_ylabel(f"fit - data [{unit}]")
    ax.set_xlabel(xlabel)
    ax.grid(True, alpha=0.3)
    if len(result.datasets_data or [1]) > 1:
        ax.legend(fontsize=7, ncol=2)
    excluded = sum(len(e["outliers"]) for e in result.datasets)
    if excluded:
        ax.set_title(f"residuals ({excluded} excluded rows marked x)", fontsize=9)


def _title(result) -> str:
    from ._problem import units

    kappa, k_r = result.parameters["kappa"], result.parameters["k_r"]
    e = result.derived["restitution"]
    u = units(result.law)
    files = result.datasets_data or [result.data]
    name = _label(files[0], 0) + (f" and {len(files) - 1} more" if len(files) > 1 else "")
    return (
        f"{name}: {result.law}, kappa = {kappa['value']:.4g} {u['kappa']}, k_r = {k_r['value']:.4g} {u['k_r']}, "
        f"e = {e['value']:.4f}"
    )
