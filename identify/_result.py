"""`FitResult`: estimates, uncertainty, verdicts, and the report and JSON views of a fit."""

from __future__ import annotations

import dataclasses
import math
import os
from typing import Any

import jax.numpy as jnp
import numpy as np

import jaxunilat as ju

from ._problem import PARAMETERS, from_z, units


@dataclasses.dataclass
class FitResult:
    """The outcome of `identify.fit`.

    **Fields:**

    - `parameters`: `{name: {"value", "stderr", "ci95"}}` for kappa (N/m), k_r (N·s/m),
      drag (s/m), x0 (m), v0 (m/s) and offset (s), in SI units; a parameter that was
      not fitted has stderr 0 (and the file's or the initial value).
    - `derived`: the same for `restitution` (e, Kelvin–Voigt, [K90 Eq. 3.1]) and
      `contact_time` (t_c = π/ω_d, s).
    - `identifiable`: `{kappa, k_r, restitution, contact_time}` → bool: a finite 95%
      CI whose half-width is at most `rel_halfwidth` of the value, and a fit that
      passes the χ² test of `goodness` (all False when it fails).
    - `goodness`: `{"reduced_chi2", "dof", "p_value", "consistent"}`, the χ² test of
      the fit against the file's noise σ (p_value and consistent are None when σ was
      estimated from the residuals).
    - `correlation`: the correlation matrix of the fitted entries of z (logs for
      κ, k_r, drag), in the order `free`.
    - `converged`, `message`, `iterations` (LM), `gradient_steps` (optax stage).
    - `chi2`: Σ((prediction − data)/σ)²; `sigma`: the noise σ used for the
      uncertainty (from the file, or estimated from the residuals: `sigma_source`).
      Under the restitution-scatter model of impact onsets (`sigma_source` =
      "restitution scatter") the fitted rows are log ratios of successive flights,
      `chi2` is theirs and `sigma` is the relative bounce-to-bounce variation of e.
    - `residuals`: prediction − data, in the data's units.
    - `starts`: the cost and convergence of every start; `initial`: the closed-form
      start; `profile`: the profile likelihood of κ (when asked for).
    - `law`, `laws`, `law_choice`: the contact law, and with `law="auto"` each law's
      χ², AIC, BIC and estimates on the rows both used (`criteria`).
    - `datasets`: one dict per file (rows, used, held out, `outliers`, `missed` bounces,
      residual `rms`, its own x0/v0/offset, its `restitution_alone`); `datasets_data`
      the files themselves; `used`: the fitted rows (outliers and held-out rows not).
    - `noise`: the stated σ against the residual scatter, in words (`noise["text"]`).
    - `holdout`: `{"fraction", "rows", "rms", "max", "within_noise", …}` in data units.
    - `robust`: the robust pass's loss, threshold and scale (None with keep_outliers).
    - `simulations`: compiled evaluations (each 2q + 1 event-mode runs, q the free
      parameters other than the offset, whose Jacobian column needs no run); `wall_s`.
    """

    data: Any
    problem: Any
    z: np.ndarray
    free: list[str]
    parameters: dict
    derived: dict
    identifiable: dict
    correlation: np.ndarray
    cost: float
    residuals: np.ndarray
    chi2: float
    sigma: float
    sigma_source: str
    goodness: dict
    converged: bool
    message: str
    iterations: int
    gradient_steps: int
    method: str
    starts: list
    initial: dict
    profile: dict | None
    rel_halfwidth: float
    simulations: int
    wall_s: float
    law: str = "kelvin-voigt"
    datasets: list = dataclasses.field(default_factory=list)
    used: np.ndarray | None = None
    noise: dict | None = None
    holdout: dict | None = None
    robust: dict | None = None
    n_parameters: int = 2
    joint_z: np.ndarray | None = None
    laws: dict | None = None
    law_choice: str = "given"
    row_sigma: np.ndarray | None = None
    sigma_known: bool = False
    datasets_data: list = dataclasses.field(default_factory=list)
    notes: list = dataclasses.field(default_factory=list)

    def criteria(self, used: np.ndarray | None = None) -> dict:
        """χ², AIC and BIC of the fit over the `used` rows (default: its fitted rows).

        With the files' noise σ: χ² = Σ(r/σ)², AIC = χ² + 2p, BIC = χ² + p ln n; without
        it, χ² is replaced by n ln(RSS/n) (the Gaussian likelihood at the estimated σ).
        Two laws are compared on the same rows (`fit(law="auto")` passes the rows both
        used).
        """
        used = self.used if used is None else used
        sigma = self.row_sigma if self.row_sigma is not None else np.ones_like(self.residuals)
        r = (self.residuals / sigma)[used]
        n, p = int(r.size), int(self.n_parameters)
        chi2 = float(np.sum(r**2))
        fit_term = chi2 if self.sigma_known else n * math.log(max(chi2 / max(n, 1), 1e-300))
        return {
            "chi2": chi2,
            "n": n,
            "p": p,
            "aic": fit_term + 2 * p,
            "bic": fit_term + p * math.log(max(n, 1)),
            "parameters": {k: self.parameters[k]["value"] for k in ("kappa", "k_r")},
            "restitution": self.derived["restitution"]["value"],
            "contact_time": self.derived["contact_time"]["value"],
            "converged": bool(self.converged),
        }

    @property
    def kappa(self) -> float:
        """κ, N/m."""
        return self.parameters["kappa"]["value"]

    @property
    def k_r(self) -> float:
        """k_r, N·s/m."""
        return self.parameters["k_r"]["value"]

    def values(self) -> dict[str, float]:
        """All six parameter values, SI units."""
        return from_z(self.z)

    def kappa_k_r_correlation(self) -> float:
        """corr(log κ, log k_r) of the estimates (NaN unless both were fitted)."""
        if "kappa" in self.free and "k_r" in self.free:
            return float(self.correlation[self.free.index("kappa"), self.free.index("k_r")])
        return math.nan

    def ball(self) -> ju.Ball:
        """The fitted `jaxunilat.Ball` (exact Heaviside) for this data set's scene."""
        return self.problem.ball(jnp.asarray(self.z))

    def inconsistency_warning(self) -> str:
        """What a failed χ² test against the stated noise means here, and what to try."""
        g = self.goodness
        hints = ["check the file's scene, x0, v0, drag and noise"]
        if self.data.observe in ("impacts", "trace") and "offset" not in self.free:
            what = "acoustic impact times" if self.data.observe == "impacts" else "video frames"
            hints.insert(0, f"{what} rarely know the release time: add --fit offset")
        elif "x0" not in self.free or "v0" not in self.free:
            hints.append("or fit the start with --fit x0,v0")
        return (
            f"WARNING: the model does not fit the data within the stated noise: reduced chi-square "
            f"{g['reduced_chi2']:.4g} (p = {g['p_value']:.2g}).\nThe intervals above use the residual "
            "scatter instead; that is honest only if the excess is scatter (bounce-to-bounce variation) "
            "and not a wrong model.\nTo check: " + "; ".join(hints) + "."
        )

    def to_json_dict(self) -> dict:
        """The JSON document of `jaxunilat identify --json` (schema in the README)."""
        k = self.kappa_k_r_correlation()

        def clean(entry):
            out = {}
            for key, value in entry.items():
                if key == "ci95":
                    out[key] = [_finite_or_none(v) for v in value]
                else:
                    out[key] = _finite_or_none(value)
            return out

        return {
            "parameters": {n: clean(self.parameters[n]) for n in ("kappa", "k_r")},
            "derived": {n: clean(self.derived[n]) for n in ("restitution", "contact_time")},
            "identifiable": {n: bool(v) for n, v in self.identifiable.items()},
            "correlation": [[1.0, _finite_or_none(k)], [_finite_or_none(k), 1.0]],
            "converged": bool(self.converged),
            "nuisance": {
                n: clean(self.parameters[n]) for n in PARAMETERS[2:] if n in self.free or n != "offset"
            },
            "fitted": list(self.free),
            "correlation_all": {
                "names": list(self.free),
                "matrix": [[_finite_or_none(v) for v in row] for row in np.asarray(self.correlation)],
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
                k: _finite_or_none(v) if isinstance(v, float) else v for k, v in self.goodness.items()
            },
            "message": self.message,
            "method": self.method,
            "iterations": self.iterations,
            "rel_halfwidth": self.rel_halfwidth,
            "wall_s": self.wall_s,
            "law": self.law,
            "law_choice": self.law_choice,
            "units": {n: units(self.law)[n] for n in ("kappa", "k_r")},
            "laws": None if self.laws is None else _clean_json(self.laws),
            "noise": None if self.noise is None else _clean_json(self.noise),
            "robust": None if self.robust is None else _clean_json(self.robust),
            "outliers": [
                {
                    "data": d["data"],
                    "rows": [o["row"] for o in d["outliers"]],
                    "details": _clean_json(d["outliers"]),
                }
                for d in self.datasets
            ],
            "datasets": [_clean_json(d) for d in self.datasets],
            "holdout": None if self.holdout is None else _clean_json(self.holdout),
            "notes": list(self.notes),
            "profile_kappa": None
            if self.profile is None
            else {
                "kappa": [float(v) for v in self.profile["kappa"]],
                "delta_chi2": [_finite_or_none(v) for v in self.profile["delta_chi2"]],
                "ci95": [_finite_or_none(v) for v in self.profile["ci95"]],
                "failed": [float(v) for v in self.profile.get("failed", [])],
            },
        }

    def report(self) -> str:
        """A plain-text report in the style of lmfit's `fit_report`."""
        sections = (
            self._report_data,
            self._report_statistics,
            self._report_variables,
            self._report_identifiability,
            self._report_rows,
            self._report_laws,
            self._report_holdout,
            self._report_notes,
        )
        return "\n".join(line for section in sections for line in section())

    def _report_data(self) -> list[str]:
        d = self.data
        lines = ["[[Data]]"]
        files = [e["data"] or "(in memory)" for e in self.datasets] or [d.path or "(in memory)"]
        lines.append(f"    file               = {files[0]}")
        lines += [f"                         {f}" for f in files[1:]]
        lines.append(f"    scene, observe     = {d.scene}, {d.observe}")
        lines.append(f"    data points        = {len(self.residuals)}" + self._used_text())
        lines.append(f"    mass               = {d.mass:g} kg")
        return lines

    def _used_text(self) -> str:
        if self.used is None or self.used.all():
            return ""
        return f" ({int(self.used.sum())} fitted)"

    def _report_statistics(self) -> list[str]:
        lines = ["[[Fit Statistics]]"]
        lines.append(f"    law                = {self.law} ({self.law_choice})")
        lines.append(f"    method             = {self.method} (event mode, exact contact)")
        lines.append(
            f"    start              = e = {self.initial['restitution']:.4f} from {self.initial['source']}"
        )
        lines.append(
            f"                         t_c = {self.initial['contact_time'] * 1e3:.3g} ms (prior 0.5-2 ms)"
        )
        lines.append(
            f"    starts             = {len(self.starts)}, best chi-square of each: " + _costs(self.starts)
        )
        lines.append(f"    LM iterations      = {self.iterations}")
        lines.append(
            f"    function evals     = {self.simulations} (each one compiled batch of event-mode runs)"
        )
        lines.append(f"    chi-square         = {self.chi2:.6g}")
        lines.append(f"    reduced chi-square = {self.goodness['reduced_chi2']:.6g}")
        unit = "s" if self.data.observe == "impacts" else "m"
        if self.sigma_source == "restitution scatter":
            lines.append(f"    noise sigma        = {self.sigma:.3%} of e per bounce (restitution scatter)")
        else:
            lines.append(f"    noise sigma        = {self.sigma:.4g} {unit} ({self.sigma_source})")
        if self.noise is not None:
            lines.append(f"    noise              = {self.noise['text']}")
        g = self.goodness
        if g["p_value"] is None:
            lines.append("    fit vs noise       = not tested (sigma estimated from the residuals)")
        else:
            verdict = "consistent" if g["consistent"] else "INCONSISTENT"
            lines.append(
                f"    fit vs noise       = {verdict} (P(chi2_{g['dof']} >= chi-square) = {g['p_value']:.3g})"
            )
        lines.append(f"    converged          = {self.converged} ({self.message})")
        lines.append(
            f"    wall time          = {self.wall_s:.2f} s (including JIT compilation, or loading it from the cache)"
        )
        return lines

    def _report_variables(self) -> list[str]:
        d, unit = self.data, units(self.law)
        lines = [
            "[[Variables]]" + ("" if self.converged else " (NOT CONVERGED: the values are not estimates)")
        ]
        for name in PARAMETERS:
            entry = self.parameters[name]
            if name not in self.free:
                if name in ("kappa", "k_r") or (name == "drag" and d.drag > 0) or name in ("x0", "v0"):
                    lines.append(f"    {name:<7}= {entry['value']:<12.6g} (fixed)  {unit[name]}")
                continue
            lines.append("    " + _format_entry(name, entry, unit[name], self.converged))
        where = "" if self.law == "kelvin-voigt" else " at the data's typical impact speed"
        lines.append(f"[[Derived]] ({self.law}{where})")
        lines.append("    " + _format_entry("e", self.derived["restitution"], "", self.converged))
        lines.append("    " + _format_entry("t_c", self.derived["contact_time"], "s", self.converged))
        return lines

    def _report_identifiability(self) -> list[str]:
        lines = [
            f"[[Identifiability]] (95% CI finite and half-width <= {self.rel_halfwidth:.0%} of the value)"
        ]
        if self.goodness["consistent"] is False:
            lines.extend("    " + line for line in self.inconsistency_warning().splitlines())
        for name, label in (
            ("kappa", "kappa"),
            ("k_r", "k_r"),
            ("restitution", "e"),
            ("contact_time", "t_c"),
        ):
            entry = self.parameters.get(name) or self.derived.get(name)
            lines.append(
                f"    {label:<7}: {'yes' if self.identifiable[name] else 'NO':<4}" + _halfwidth(entry)
            )
        lines.append("[[Correlations]] (of the fitted entries; logs for kappa, k_r, drag)")
        names, corr = self.free, np.asarray(self.correlation)
        for i in range(len(names)):
            for j in range(i + 1, len(names)):
                lines.append(f"    C({names[i]}, {names[j]}) = {corr[i, j]:+.6f}")
        if self.profile is not None:
            lo, hi = self.profile["ci95"]
            lines.append("[[Profile likelihood]]")
            lines.append(
                f"    kappa 95% CI (delta chi2 <= 3.84): [{lo:.6g}, {hi:.6g}] {units(self.law)['kappa']}"
            )
            if self.profile.get("failed"):
                lines.append(
                    f"    grid points whose re-fit failed (not excluded): {len(self.profile['failed'])}"
                )
        return lines

    def _report_rows(self) -> list[str]:
        """Per file: rows used, outliers, missed bounces, residual scatter, own e."""
        if not self.datasets:
            return []
        unit = "ms" if self.data.observe == "impacts" else "mm"
        lines = ["[[Files]]" if len(self.datasets) > 1 else "[[Rows]]"]
        header = f"    {'file':<28} {'rows':>5} {'used':>5} {'outliers':>8} {'rms (' + unit + ')':>9}"
        lines.append(header + ("   e alone (t_c prior)" if len(self.datasets) > 1 else ""))
        for e in self.datasets:
            name = os.path.basename(e["data"]) if e["data"] else "(in memory)"
            rms = f"{e['rms'] * 1e3:9.3g}" if e["rms"] is not None else f"{'-':>9}"
            row = f"    {name[:28]:<28} {e['rows']:>5} {e['used']:>5} {len(e['outliers']):>8} {rms}"
            alone = e.get("restitution_alone")
            if alone is not None:
                row += f"   {alone['value']:.4f} +/- {alone['stderr']:.2g}"
            lines.append(row)
        for e in self.datasets:
            name = os.path.basename(e["data"]) if e["data"] else "(in memory)"
            for o in e["outliers"]:
                at = f" at t = {o['t']:.6g} s" if o.get("t") is not None else ""
                lines.append(
                    f"    outlier: {name} row {o['row']}{at}, residual {o['residual']:.3g} ({o['reason']})"
                )
            for m in e["missed"]:
                lines.append(
                    f"    missed bounce: {name} between rows {m['after_row']} and {m['before_row']} "
                    f"(interval {m['interval']:.4g} s after {m['previous']:.4g} s)"
                )
        return lines

    def _report_laws(self) -> list[str]:
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
        return ["[[Notes]]", *(f"    {note}" for note in self.notes)] if self.notes else []

    def _report_holdout(self) -> list[str]:
        h = self.holdout
        if h is None:
            return []
        lines = [f"[[Hold-out]] (the last {h['fraction']:.0%} of each file's rows, predicted)"]
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


def _finite_or_none(value):
    value = float(value)
    return value if math.isfinite(value) else None


def _clean_json(value):
    """Plain JSON types: floats finite or None, numpy scalars and arrays unpacked."""
    if isinstance(value, dict):
        return {str(k): _clean_json(v) for k, v in value.items()}
    if isinstance(value, (list, tuple, np.ndarray)):
        return [_clean_json(v) for v in value]
    if isinstance(value, (bool, np.bool_)):
        return bool(value)
    if isinstance(value, (int, np.integer)):
        return int(value)
    if isinstance(value, (float, np.floating)):
        return _finite_or_none(value)
    return value


def _costs(starts) -> str:
    return ", ".join(f"{2 * s['cost']:.4g}" + ("" if s["converged"] else "*") for s in starts)


def _format_entry(name: str, entry: dict, unit: str, converged: bool = True) -> str:
    value, stderr = entry["value"], entry["stderr"]
    if not converged:
        return f"{name:<7}= {value:<12.6g} (no interval: the fit did not converge) {unit}"
    lo, hi = entry["ci95"]
    rel = f"({_percent(stderr / abs(value))})" if math.isfinite(stderr) and value else "(inf)"
    return f"{name:<7}= {value:<12.6g} +/- {stderr:<10.4g} {rel:<9} 95% CI [{lo:.6g}, {hi:.6g}] {unit}"


def _halfwidth(entry) -> str:
    lo, hi = entry["ci95"]
    if not (math.isfinite(lo) and math.isfinite(hi)):
        return "  (95% CI unbounded)"
    return f"  (95% half-width {_percent((hi - lo) / 2 / abs(entry['value']))})"


def _percent(fraction: float) -> str:
    """A relative width as a percentage, or '> 1000%' for an unbounded one."""
    return f"{fraction:.2%}" if fraction <= 10.0 else "> 1000%"
