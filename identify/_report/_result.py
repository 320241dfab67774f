"""`FitResult`: a finished fit (`identify._fit._outcome.FitOutcome`) with its report and
JSON views. Nothing here fits or computes an estimate: every number comes from the fit
layer; this module only formats text and JSON."""

from __future__ import annotations

import dataclasses
import math
import os
from collections.abc import Mapping
from decimal import ROUND_HALF_UP, Decimal

import numpy as np

from jaxunilat._internal import finite_or_none

from .._fit._estimate import ABSURD, Bound, Estimate
from .._fit._outcome import VERDICTS, FileFit, FitOutcome
from .._fit._problem import PARAMETERS, TRACE_ONLY
from .._fit._uncertainty import P_INCONSISTENT

#: Each file's own entries (the joint layout's local ones), their SI unit, and how the
#: [[Files]] table shows them (scale from SI, unit).
_LOCAL = (
    ("x0", "m", 1e3, "mm"),
    ("v0", "m/s", 1.0, "m/s"),
    ("offset", "s", 1e3, "ms"),
    ("scale", "", 1.0, ""),
    ("level", "m", 1e3, "mm"),
)
_LOCAL_NAMES = tuple(name for name, *_ in _LOCAL)

#: The report lists the correlations of at least this size (the JSON has them all).
SHOWN_CORRELATION = 0.1


@dataclasses.dataclass(frozen=True, eq=False)
class FitResult(FitOutcome):
    """The outcome of `identify.fit`: frozen, built once (fields: `FitOutcome`).

    Each quantity is an `Estimate` (value, stderr, ci95, unit, fixed, identifiable,
    bound): `result.params["kappa"].value` (N/m), `result.derived["restitution"].ci95`;
    `result.identifiable` maps κ, k_r, e and t_c to their verdicts. `report()` is the
    text for people, `to_json_dict()` the JSON of `jaxunilat identify --json`,
    `file_table()` each file's own values. A variant is a new result
    (`dataclasses.replace`); assigning to a field raises
    `dataclasses.FrozenInstanceError`.
    """

    def inconsistency_warning(self) -> str:
        """What a failed χ² test against the stated noise means here, and what to try."""
        g = self.goodness
        hints = ["check the file's scene, x0, v0, drag and noise"]
        if self.data.observe in ("impacts", "trace") and "offset" not in self.free:
            if self.data.observe == "impacts":
                hint = "acoustic impact times rarely know the release time: fit the offset (leave out --freeze offset)"
            else:
                hint = "video frames rarely know the release time: add --fit offset"
            hints.insert(0, hint)
        elif "x0" not in self.free or "v0" not in self.free:
            hints.append("or fit the start with --fit x0,v0")
        return (
            f"WARNING: the model does not fit the data within the stated noise: reduced chi-square "
            f"{g['reduced_chi2']:.4g} (p = {g['p_value']:.2g} < {P_INCONSISTENT:g}).\nThe intervals above use the residual "
            "scatter instead; that is honest only if the excess is scatter (bounce-to-bounce variation) "
            "and not a wrong model.\nTo check: " + "; ".join(hints) + "."
        )

    def to_json_dict(self) -> dict:
        """The JSON document of `jaxunilat identify --json` (schema in the README)."""
        k = self.kappa_k_r_correlation()
        return {
            "parameters": {n: self.params[n].to_json() for n in ("kappa", "k_r")},
            "derived": {n: self.derived[n].to_json() for n in ("restitution", "contact_time")},
            "identifiable": {n: bool(v) for n, v in self.identifiable.items()},
            "withheld": dict(self.withheld),
            "correlation": [[1.0, finite_or_none(k)], [finite_or_none(k), 1.0]],
            "converged": bool(self.converged),
            "nuisance": {
                n: self.params[n].to_json()
                for n in PARAMETERS[2:]
                if n in self.free or (n != "offset" and (n not in TRACE_ONLY or self.data.observe == "trace"))
            },
            "fitted": list(self.free),
            "correlation_all": {
                "names": list(self.free),
                "matrix": [[finite_or_none(v) for v in row] for row in np.asarray(self.correlation)],
            },
            "mass": float(self.data.mass),
            "scene": self.data.scene,
            "observe": self.data.observe,
            "data": self.data.path,
            "n_data": int(len(self.residuals) if self.used is None else self.used.sum()),
            "chi2": self.chi2,
            "sigma": self.sigma,
            "sigma_source": self.sigma_source,
            "goodness_of_fit": {
                k: finite_or_none(v) if isinstance(v, float) else v for k, v in self.goodness.items()
            },
            "message": self.message,
            "method": self.method,
            "iterations": self.iterations,
            "rel_halfwidth": self.rel_halfwidth,
            "wall_s": self.wall_s,
            "law": self.law,
            "law_choice": self.law_choice,
            "units": {n: self.units[n] for n in ("kappa", "k_r")},
            "laws": None if self.laws is None else _clean_json(self.laws),
            "noise": None if self.noise is None else _clean_json(self.noise),
            "robust": None if self.robust is None else _clean_json(self.robust),
            "outliers": [
                {
                    "data": d.data,
                    "rows": [o.row for o in d.outliers],
                    "details": _clean_json([dataclasses.asdict(o) for o in d.outliers]),
                }
                for d in self.datasets
            ],
            "datasets": [_clean_json(d.to_json()) for d in self.datasets],
            "holdout": None if self.holdout is None else _clean_json(self.holdout),
            "notes": list(self.notes),
            "restitution_trend": _clean_json(self.trends),
            "restart": None if self.restart is None else _clean_json(dataclasses.asdict(self.restart)),
            "files": _clean_json(self.file_table()),
            "bounds": {n: _clean_json(b.to_json()) for n, b in self.bounds().items()},
            "profile_kappa": None
            if self.profile is None
            else {
                "kappa": [float(v) for v in self.profile.kappa],
                "delta_chi2": [finite_or_none(v) for v in self.profile.delta_chi2],
                "ci95": [finite_or_none(v) for v in self.profile.ci95],
                "failed": [float(v) for v in self.profile.failed],
                "bound": _clean_json(self.profile.bound.to_json()),
            },
        }

    def bounds(self) -> dict[str, Bound]:
        """What the data bound of κ, k_r, e and t_c (`Estimate.bound`): kind "none" where
        the 95% interval is unbounded or absurd (not finite, beyond 1e±30, or spanning more
        than `SPAN_DECADES` decades)."""
        return {name: self.estimate(name).bound for name in VERDICTS}

    def file_table(self) -> list[dict]:
        """One dict per file, in file order: the per-file (nuisance) values of the fit.

        Keys: `name` (the file's base name), `data` (its path or None), `observe`, `rows`,
        `used` (fitted rows), `held_out`, `outliers` and `missed` (counts); `x0` (m),
        `v0` (m/s), `offset` (s), `scale` (dimensionless) and `level` (m; both (1, 0) for
        all but traces), each `{"value", "stderr", "unit", "status"}` with status
        "fitted" (stderr from the joint covariance) or "fixed" (stderr None);
        `e_alone`: the file's own restitution `{"value", "stderr", "ci95"}` (κ, k_r fitted
        to this file alone; for a one-file fit, the fit's e); `rms`: the residual rms of
        the used rows `{"value", "unit"}` in SI units (s for onsets, m otherwise) and
        `rms_shown` the same in the report's unit (ms or mm).
        """
        datasets = self.datasets_data or (self.data,)
        entries = self.datasets or (None,) * len(datasets)
        per_file = self.file_values()
        used = self.used if self.used is not None else np.ones(len(self.residuals), bool)
        out, start = [], 0
        for f, (d, e) in enumerate(zip(datasets, entries, strict=True)):
            n = int(d.num_rows)
            if e is None:  # a result built by hand: derive the counts from the mask
                res, mask = np.asarray(self.residuals[start : start + n]), used[start : start + n]
                rms = float(np.sqrt(np.mean(res[mask] ** 2))) if mask.any() else None
                e = FileFit(data=d.path, observe=d.observe, rows=n, used=int(mask.sum()), held_out=0, rms=rms)
            start += n
            scale, shown = residual_unit(e.observe)
            alone = e.restitution_alone
            if alone is None and len(datasets) == 1:
                alone = self.derived["restitution"]
            out.append(
                {
                    "name": _file_name(e.data, f),
                    "data": e.data,
                    "observe": e.observe,
                    "rows": int(e.rows),
                    "used": int(e.used),
                    "held_out": int(e.held_out),
                    "outliers": len(e.outliers),
                    "missed": len(e.missed),
                    **self._file_values(f, d, e, per_file[f]),
                    "e_alone": None
                    if alone is None
                    else {"value": alone.value, "stderr": alone.stderr, "ci95": list(alone.ci95)},
                    "rms": {"value": e.rms, "unit": "s" if e.observe == "impacts" else "m"},
                    "rms_shown": {"value": None if e.rms is None else e.rms * scale, "unit": shown},
                }
            )
        return out

    def _file_values(self, f: int, d, e: FileFit, held: dict[str, float]) -> dict[str, dict]:
        """File f's x0, v0, offset, scale and level for `file_table`: its own fitted entry,
        a trace calibration fitted without a per-file interval, or the value held."""
        values = {}
        for name, unit, *_ in _LOCAL:
            own: Estimate | None = e.params.get(name)
            value, stderr = (own.value, own.stderr) if own is not None else (held[name], None)
            fitted = own is not None
            if own is None and name in TRACE_ONLY and name in self.free and e.observe == "trace":
                if name not in (getattr(d, "measured", ()) or ()):
                    # File 0's entry is the headline view; a per-file summary that lists
                    # only x0, v0 and offset leaves the other files' s.e. out.
                    fitted = True
                    if f == 0:
                        value, stderr = self.params[name].value, self.params[name].stderr
            values[name] = {
                "value": value,
                "stderr": stderr,
                "unit": unit,
                "status": "fitted" if fitted else "fixed",
            }
        return values

    def report(self) -> str:
        """A plain-text report for people, most wanted first: the data, the results (e,
        t_c, κ, k_r with their identifiability), the nuisance parameters, the statistics,
        the per-file table and notes; how the fit ran comes last, under [[Diagnostics]]."""
        sections = (
            self._report_data,
            self._report_results,
            self._report_nuisance,
            self._report_statistics,
            self._report_correlations,
            self._report_profile,
            self._report_rows,
            self._report_laws,
            self._report_holdout,
            self._report_notes,
            self._report_diagnostics,
        )
        return "\n".join(line for section in sections for line in section())

    def _report_data(self) -> list[str]:
        """[[Data]]: the files, what they observe, their rows, the mass and gravity."""
        d = self.data
        lines = ["[[Data]]"]
        files = [e.data or "(in memory)" for e in self.datasets] or [d.path or "(in memory)"]
        lines.append(f"    file               = {files[0]}")
        lines += [f"                         {f}" for f in files[1:]]
        lines.append(f"    scene, observe     = {d.scene}, {d.observe}")
        lines.append(f"    data points        = {len(self.residuals)}" + self._used_text())
        lines.append(f"    mass               = {d.mass:g} kg")
        gravity = list(dict.fromkeys(float(f.gravity) for f in self.datasets_data or [d]))
        each = " (per file)" if len(gravity) > 1 else ""
        lines.append(f"    gravity g          = {', '.join(f'{g:g}' for g in gravity)} m/s^2{each}")
        return lines

    def _used_text(self) -> str:
        """` (N fitted)` where outliers or held-out rows were left out of the fit."""
        if self.used is None or self.used.all():
            return ""
        return f" ({int(self.used.sum())} fitted)"

    def _report_results(self) -> list[str]:
        """[[Results]]: e, t_c, κ and k_r, each with its identifiability verdict beside it."""
        u = self.units
        where = (
            "; e and t_c at the data's typical impact speed"
            if self.law_model.restitution_depends_on_speed
            else ""
        )
        lines = [
            f"[[Results]] ({self.law}{where}; identifiable: 95% CI finite and half-width <= "
            f"{self.rel_halfwidth:.0%} of the value)"
            + ("" if self.converged else " (NOT CONVERGED: the values are not estimates)")
        ]
        rows = []
        for name, label, scale, unit in (
            ("restitution", "e", 1.0, ""),
            ("contact_time", "t_c", 1e3, "ms"),
            ("kappa", "kappa", 1.0, u["kappa"]),
            ("k_r", "k_r", 1.0, u["k_r"]),
        ):
            entry = self.estimate(name)
            if name in ("kappa", "k_r") and name not in self.free:
                columns, says = [f"{label:<7}= {entry.value:.6g} (fixed) {unit}"], "held, not fitted"
            else:
                b = entry.bound
                columns = _entry_columns(label, entry, unit, self.converged, b, scale)
                says = _halfwidth(entry) if b.kind == "interval" else ""
            says = self.withheld.get(name, says if self.converged else "the fit did not converge")
            verdict = "yes" if self.identifiable[name] else "NO"
            rows.append([*columns, f" identifiable: {verdict}" + (f" ({says})" if says else "")])
        lines += _aligned(rows)
        if self.goodness["consistent"] is False:
            lines.extend("    " + line for line in self.inconsistency_warning().splitlines())
        return lines

    def _report_nuisance(self) -> list[str]:
        """[[Nuisance parameters]]: drag, the release state, clock offset and a trace's
        calibration, fitted or held (a several-file fit points to [[Files]])."""
        d, unit = self.data, self.units
        several = len(self.datasets_data or [d]) > 1
        lines = [
            "[[Nuisance parameters]]"
            + ("" if self.converged else " (NOT CONVERGED: the values are not estimates)")
            + (" (shared by every file)" if several else "")
        ]
        per_file, rows = [], []
        for name in PARAMETERS[2:]:
            entry = self.params[name]
            if several and name in _LOCAL_NAMES:
                if name not in TRACE_ONLY or any(f.observe == "trace" for f in self.datasets_data):
                    per_file.append(name)
                continue
            if name not in self.free:
                held = name in ("x0", "v0") or (name in TRACE_ONLY and d.observe == "trace")
                if held or (name == "drag" and d.drag > 0):
                    shown = f" {unit[name]}" if unit[name] else ""
                    rows.append([f"{name:<7}= {entry.value:.6g} (fixed){shown}"])
                continue
            rows.append(_entry_columns(name, entry, unit[name], self.converged, entry.bound))
        lines += _aligned(rows)
        if several:
            lines.append(self._per_file_line(per_file))
        return lines

    def _report_statistics(self) -> list[str]:
        """[[Fit Statistics]]: the law, χ² over the fitted rows, the noise and its test."""
        lines = ["[[Fit Statistics]]"]
        lines.append(f"    law                = {self.law} ({self.law_choice})")
        n_used = int(len(self.residuals) if self.used is None else self.used.sum())
        rows = (
            "log ratios of successive flights"
            if self.sigma_source == "restitution scatter"
            else "fitted data rows"
        )
        lines.append(f"    chi-square         = {self.chi2:.6g} (over the {n_used} {rows})")
        reduced = self.goodness["reduced_chi2"]
        lines.append(
            f"    reduced chi-square = {reduced:.4g}"
            if abs(reduced) < 1e4
            else f"    reduced chi-square = {reduced:.0f}"
        )
        unit = "s" if self.data.observe == "impacts" else "m"
        if self.sigma_source == "restitution scatter":
            lines.append(f"    noise sigma        = {self.sigma:.2%} of e per bounce (restitution scatter)")
        else:
            lines.append(f"    noise sigma        = {self.sigma:.4g} {unit} ({self.sigma_source})")
        if self.noise is not None:
            lines.append(f"    noise              = {self.noise['text']}")
        lines.append(f"    fit vs noise       = {self._noise_test()}")
        lines.append(f"    converged          = {self.converged} ({self.message})")
        return lines

    def _noise_test(self) -> str:
        """The χ² test of the fit against the stated noise, with the threshold it used."""
        g = self.goodness
        if g["p_value"] is None:
            return "not tested (sigma estimated from the residuals)"
        dof, p = g["dof"], g["p_value"]
        if self.noise is not None and self.noise.get("verdict") == "overstated":
            return (
                f"OVERSTATED noise: chi-square far below its expectation "
                f"(P(chi2_{dof} <= chi-square) = {1.0 - p:.2g}, below the threshold {P_INCONSISTENT:g})"
            )
        if g["consistent"]:
            return f"consistent (P(chi2_{dof} >= chi-square) = {p:.2g}, at or above the threshold {P_INCONSISTENT:g})"
        return f"INCONSISTENT (P(chi2_{dof} >= chi-square) = {p:.2g}, below the threshold {P_INCONSISTENT:g})"

    def _per_file_line(self, names: list[str]) -> str:
        """Where a several-file fit's x0, v0 and offset are: the [[Files]] table, or one
        value held for every file."""
        table = self.file_table()
        fitted = [n for n in names if any(f[n]["status"] == "fitted" for f in table)]
        held = [n for n in names if n not in fitted]
        parts = []
        if fitted:
            parts.append(f"{', '.join(fitted)} fitted per file: values in [[Files]] below")
        for n in held:
            values = {f[n]["value"] for f in table}
            unit = table[0][n]["unit"]
            if len(values) == 1:
                parts.append(f"{n} = {values.pop():g} {unit} (fixed, every file)")
            else:
                parts.append(f"{n} fixed per file (in [[Files]])")
        return "    per file: " + "; ".join(parts)

    def _report_correlations(self) -> list[str]:
        """[[Correlations]] of the fitted entries, those with |C| >= `SHOWN_CORRELATION`."""
        lines = [
            f"[[Correlations]] (|C| >= {SHOWN_CORRELATION:g}; of the fitted entries, logs for kappa, k_r, drag)"
        ]
        names, corr = self.free, np.asarray(self.correlation)
        for i in range(len(names)):
            for j in range(i + 1, len(names)):
                c = float(corr[i, j])
                if not math.isfinite(c):
                    lines.append(f"    C({names[i]}, {names[j]}) = undefined (a variance is 0 or infinite)")
                elif abs(c) >= SHOWN_CORRELATION:
                    lines.append(f"    C({names[i]}, {names[j]}) = {c:+.2f}")
        if len(lines) == 1:
            lines.append(f"    none (every |C| < {SHOWN_CORRELATION:g})")
        return lines

    def _report_profile(self) -> list[str]:
        """[[Profile likelihood]] of κ, where it was computed."""
        if self.profile is None:
            return []
        lo, hi = self.profile.ci95
        u = self.units["kappa"]
        lines = ["[[Profile likelihood]]"]
        if self.profile.bound.kind == "interval":
            place = rounded(self.kappa, self.params["kappa"].stderr)[1]
            lines.append(f"    kappa 95% CI (delta chi2 <= 3.84): [{_at(lo, place)}, {_at(hi, place)}] {u}")
        else:
            lines.append(
                f"    kappa 95% CI (delta chi2 <= 3.84): lower end {_profile_end(lo, u, 'lower')}, "
                f"upper end {_profile_end(hi, u, 'upper')}"
            )
        below = self.profile.below_fit
        if below is not None and below > 0:
            lines.append(
                f"    the profile reached a chi-square {below:.3g} below the fit's own"
                + (": the fit is not at its minimum" if not self.converged else " (within the tolerance)")
            )
        if self.profile.failed:
            lines.append(f"    grid points whose re-fit failed (not excluded): {len(self.profile.failed)}")
        return lines

    def _report_diagnostics(self) -> list[str]:
        """[[Diagnostics]]: how the fit ran (start, starts, iterations, evaluations, time)."""
        steps = f", {self.gradient_steps} optax steps" if self.gradient_steps else ""
        unconverged = " (* not converged)" if any(not s.converged for s in self.starts) else ""
        return [
            "[[Diagnostics]] (how the fit ran)",
            f"    method    = {self.method} (event mode, exact contact): {self.iterations} LM iterations{steps}, "
            f"{self.simulations} function evals (each one compiled batch of event-mode runs)",
            f"    start     = e = {self.initial.restitution:.4f} from {self.initial.source}, "
            f"t_c = {self.initial.contact_time * 1e3:.3g} ms (prior 0.5-2 ms)",
            f"    starts    = {len(self.starts)}, chi-square of each on the first window: {_costs(self.starts)}"
            f"{unconverged} (rows in the first 35% of each file's span, plus the t_c prior row where used; "
            "not comparable with the final chi-square)",
            f"    wall time = {self.wall_s:.2f} s (including JIT compilation, or loading it from the cache)",
        ]

    def _report_rows(self) -> list[str]:
        """Per file: rows used, held out, outliers, residual rms, its x0/v0/offset and own e."""
        if not self.datasets:
            return []
        table = self.file_table()
        several = len(table) > 1
        scale, unit = residual_unit(self.data.observe)
        lines = ["[[Files]] (each file's own values; kappa, k_r, drag shared)" if several else "[[Rows]]"]
        # A column for every per-file value that is fitted or differs between files.
        columns = []
        if several:
            for name, _, s, u in _LOCAL:
                if (
                    any(f[name]["status"] == "fitted" for f in table)
                    or len({f[name]["value"] for f in table}) > 1
                ):
                    columns.append((name, s, u))
        width = max([len(f["name"]) for f in table] + [4]) if several else 28
        width = min(width, 32)
        header = f"    {'file':<{width}} {'rows':>5} {'used':>5} {'held':>5} {'outliers':>8} {'rms (' + unit + ')':>9}"
        header += "".join(f"  {name + (' (' + u + ')' if u else ''):<20}" for name, _, u in columns)
        lines.append(header + ("  e alone (t_c prior)" if several else ""))
        for f in table:
            rms = f["rms_shown"]["value"]
            rms = f"{rms:9.3g}" if rms is not None else f"{'-':>9}"
            name = f["name"] if len(f["name"]) <= width else f["name"][: width - 3] + "..."
            row = f"    {name:<{width}} {f['rows']:>5} {f['used']:>5} {f['held_out']:>5} {f['outliers']:>8} {rms}"
            for col, s, _ in columns:
                shown = _pm(f[col]["value"], f[col]["stderr"], s)
                if f[col]["status"] == "fitted" and f[col]["stderr"] is None:
                    shown = f"{f[col]['value'] * s:.6g} (fitted)"
                row += f"  {shown:<20}"
            alone = f["e_alone"]
            if several and alone is not None:
                row += f"  {_pm(alone['value'], alone['stderr'], 1.0)}"
            lines.append(row.rstrip())
        for f, e in zip(table, self.datasets, strict=True):
            s, u = residual_unit(f["observe"])
            for o in e.outliers:
                at = f" at t = {o.t:.6g} s" if o.t is not None else ""
                lines.append(
                    f"    outlier: {f['name']} row {o.row}{at}, residual {o.residual * s:+.3g} {u} ({o.reason})"
                )
            for m in e.missed:
                lines.append(
                    f"    missed bounce: {f['name']} between rows {m.after_row} and {m.before_row} "
                    f"(interval {m.interval * 1e3:.4g} ms after one of {m.previous * 1e3:.4g} ms)"
                )
        return lines

    def _report_laws(self) -> list[str]:
        """[[Contact laws]]: each law's chi-square, AIC, BIC and e (with `law="auto"`)."""
        if not self.laws or len(self.laws) < 2:
            return []
        lines = ["[[Contact laws]] (same rows; lower is better)"]
        lines.append(f"    {'law':<14} {'chi-square':>12} {'AIC':>12} {'BIC':>12} {'e':>8}")
        for name, c in self.laws.items():
            mark = "  <- chosen" if name == self.law else ""
            lines.append(
                f"    {name:<14} {c['chi2']:>12.6g} {c['aic']:>12.6g} {c['bic']:>12.6g} {c['restitution']:>8.4f}{mark}"
            )
        return lines

    def _report_notes(self) -> list[str]:
        """[[Notes]]: what the fit and the data's checks want the reader to know."""
        return ["[[Notes]]", *(f"    {note}" for note in self.notes)] if self.notes else []

    def _report_holdout(self) -> list[str]:
        """[[Hold-out]]: the held-out rows' prediction errors against the noise."""
        h = self.holdout
        if h is None:
            return []
        lines = [f"[[Hold-out]] (the last {h['fraction']:.0%} of each file's rows, predicted)"]
        if h.get("reason"):
            return lines + [f"    {h['reason']}"]
        if h["rms"] is None:
            return lines + ["    no held-out row left to predict"]
        scale = 1e3
        unit = "ms" if h["unit"] == "s" else "mm"
        verdict = "within the noise" if h["within_noise"] else "NOT within the noise"
        lines.append(
            f"    rows {h['rows']}, rms {h['rms'] * scale:.3g} {unit}, max {h['max'] * scale:.3g} {unit}: {verdict}"
            f" (p = {h['p_value']:.3g})"
        )
        return lines


def _profile_end(value: float, unit: str, side: str) -> str:
    """One end of the profile interval: a value, "unbounded" or "unknown"."""
    if math.isnan(value):
        return "unknown (the re-fit next to it failed)"
    if not math.isfinite(value) or value <= 0 or abs(value) >= ABSURD:
        return f"unbounded (delta chi2 stays below 3.84 to the {'lowest' if side == 'lower' else 'highest'} kappa tried)"
    return f"{value:.6g} {unit}"


def _clean_json(value):
    """Plain JSON types: floats finite or None, numpy scalars and arrays unpacked."""
    if isinstance(value, Mapping):
        return {str(k): _clean_json(v) for k, v in value.items()}
    if isinstance(value, (list, tuple, np.ndarray)):
        return [_clean_json(v) for v in value]
    if isinstance(value, (bool, np.bool_)):
        return bool(value)
    if isinstance(value, (int, np.integer)):
        return int(value)
    if isinstance(value, (float, np.floating)):
        return finite_or_none(value)
    return value


def _costs(starts) -> str:
    """Each start's chi-square on the first window (* where it did not converge)."""
    return ", ".join(f"{2 * s.cost:.4g}" + ("" if s.converged else "*") for s in starts)


def _entry_columns(
    name: str, entry: Estimate, unit: str, converged: bool = True, b: Bound | None = None, scale: float = 1.0
) -> list[str]:
    """The columns of one parameter line: `name = value +/- stderr unit`, `(relative)` and
    `95% CI [lo, hi] unit`, every number rounded to the stderr's two significant digits
    (`rounded`), all × `scale`; `b` (`Estimate.bound`) replaces an unbounded or absurd
    interval by what the data bound. One column where the fit did not converge."""
    value, stderr = entry.value * scale, entry.stderr * scale
    shown = f" {unit}" if unit else ""
    if not converged:
        return [f"{name:<7}= {value:.6g}{shown} (no interval: the fit did not converge)"]
    text, place = rounded(value, stderr)
    rel = f"({_percent(stderr / abs(value))})" if math.isfinite(stderr) and value else "(inf)"
    head = f"{name:<7}= {text}{shown}"
    if b is not None and b.kind != "interval":
        return [head, rel + ";", b.text]
    lo, hi = (end * scale for end in entry.ci95)
    return [head, rel, f"95% CI [{_at(lo, place)}, {_at(hi, place)}]{shown}"]


def _aligned(rows: list[list[str]], gap: str = "  ") -> list[str]:
    """Rows of columns as indented lines, each column but a row's last padded to the
    widest entry of that column."""
    widths: dict[int, int] = {}
    for row in rows:
        for i, cell in enumerate(row[:-1]):
            widths[i] = max(widths.get(i, 0), len(cell))
    return [
        "    " + gap.join([f"{c:<{widths[i]}}" for i, c in enumerate(row[:-1])] + row[-1:]) for row in rows
    ]


def _halfwidth(entry: Estimate) -> str:
    """The 95% half-width of an estimate relative to its value, in words."""
    lo, hi = entry.ci95
    if not (math.isfinite(lo) and math.isfinite(hi)):
        return "95% CI unbounded"
    return f"95% half-width {_percent((hi - lo) / 2 / abs(entry.value))}"


def _percent(fraction: float) -> str:
    """A relative width as a percentage to two significant digits (`0.0079%`, `1.6%`,
    `97%`), or '> 1000%' for an unbounded one."""
    if not math.isfinite(fraction) or fraction > 10.0:
        return "> 1000%"
    return f"{_two(fraction * 100)}%" if fraction > 0 else "0%"


#: Fixed notation for numbers below this magnitude rounded to at most this many decimals;
#: scientific notation beyond.
MAX_FIXED, MAX_DECIMALS = 1e7, 8
#: The most significant digits a rounded value shows (a relative uncertainty below 1e-12
#: is shown as 12 digits of the value).
MAX_DIGITS = 12


def _round_at(x: float, place: int) -> Decimal:
    """x rounded half away from zero to a multiple of 10**place (of its shortest decimal
    form, so 2.675 rounds to 2.68 as written, not as stored in binary)."""
    out = Decimal(repr(float(x))).quantize(Decimal(1).scaleb(place), rounding=ROUND_HALF_UP)
    return abs(out) if out == 0 else out


def _second_digit(x: float) -> int:
    """The decimal place (power of ten) of x's second significant digit once x is rounded
    to two (99.7 rounds to 100, whose second digit is the tens)."""
    place = math.floor(math.log10(abs(x))) - 1
    if abs(_round_at(x, place)) >= Decimal(100).scaleb(place):
        place += 1
    return place


def _fixed_at(x: float, place: int) -> str | None:
    """x rounded to 10**place in fixed notation; None where that would run long."""
    if -place > MAX_DECIMALS or abs(x) >= MAX_FIXED:
        return None
    return f"{_round_at(x, place):f}"


def _sci_at(x: float, place: int) -> str:
    """x rounded to 10**place in scientific notation (at most `MAX_DIGITS` digits)."""
    if x == 0:
        return "0"
    digits = min(max(math.floor(math.log10(abs(x))) - place, 0), MAX_DIGITS - 1)
    return f"{x:.{digits}e}"


def _at(x: float, place: int | None) -> str:
    """x rounded to 10**place (fixed notation where short, else scientific); 6
    significant digits where `place` is None; `inf`/`nan` as such."""
    if place is None or not math.isfinite(x):
        return f"{x:.6g}"
    return _fixed_at(x, place) or _sci_at(x, place)


def _two(x: float) -> str:
    """x to two significant digits (fixed notation where short, else scientific)."""
    if x == 0 or not math.isfinite(x):
        return f"{x:g}"
    return _at(x, _second_digit(x))


def rounded(value: float, stderr: float | None) -> tuple[str, int | None]:
    """`value +/- stderr` for people, and the decimal place the value was rounded at.

    The stderr is rounded to two significant digits and the value to the same decimal
    place (27097.8 ± 434.4 → `27100 +/- 430`; 0.935008 ± 7.426e-06 → `0.9350080 +/-
    0.0000074`); numbers of 1e7 or more, or rounded past `MAX_DECIMALS` decimals, share one
    exponent (`(1.000 +/- 0.020)e+08`). A stderr of None is a held value: 6 significant
    digits and `(fixed)`; a stderr of 0 shows the value alone, an infinite one `+/- inf`.
    Where the stderr is so much larger than the value that rounding would print 0 for a
    value that is not, each keeps two significant digits of its own (`450000 +/- 5.0e+07`).
    The place is None where the value was shown to 6 (or `MAX_DIGITS`) significant digits.
    """
    if stderr is None:
        return f"{value:.6g} (fixed)", None
    if not (math.isfinite(value) and math.isfinite(stderr)):
        return f"{value:.6g} +/- {stderr:.2g}", None
    if stderr <= 0:
        return f"{value:.6g}", None
    place = _second_digit(stderr)
    if value != 0 and abs(value) < 5.0 * 10.0 ** (place - 1):
        return f"{_two(value)} +/- {_two(stderr)}", place
    v, s = _fixed_at(value, place), _fixed_at(stderr, place)
    if v is not None and s is not None:
        return f"{v} +/- {s}", place
    lead = math.floor(math.log10(max(abs(value), stderr)))
    if lead - place >= MAX_DIGITS:
        return f"{value:.{MAX_DIGITS}g} +/- {stderr:.2g}", None
    unit = 10.0**lead
    return (
        f"({_round_at(value / unit, place - lead):f} +/- {_round_at(stderr / unit, place - lead):f})e{lead:+03d}",
        place,
    )


def residual_unit(observe: str) -> tuple[float, str]:
    """(scale from SI, unit) in which a residual of this data kind is printed: ms for
    impact onset times, mm for positions (trace) and apex heights."""
    return (1e3, "ms") if observe == "impacts" else (1e3, "mm")


def _pm(value: float, stderr: float | None, scale: float) -> str:
    """value +/- stderr, both × scale, rounded to two significant digits of the stderr
    (`rounded`)."""
    return rounded(value * scale, None if stderr is None else stderr * scale)[0]


def _file_name(path: str | None, f: int) -> str:
    """A file's base name, or "data <f + 1>" for data held in memory."""
    return os.path.basename(path) if path else f"data {f + 1}"
