"""`FitResult`: estimates, uncertainty, verdicts, and the report and JSON views of a fit."""

from __future__ import annotations

import dataclasses
import math
from typing import Any

import jax.numpy as jnp
import numpy as np

import jaxunilat as ju

from ._problem import PARAMETERS, UNITS, from_z


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
    - `residuals`: prediction − data, in the data's units.
    - `starts`: the cost and convergence of every start; `initial`: the closed-form
      start; `profile`: the profile likelihood of κ (when asked for).
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
        """Why the verdicts are all NO when the fit fails its χ² test, and what to try."""
        g = self.goodness
        hints = ["check the file's scene, x0, v0, drag and noise"]
        if self.data.observe == "impacts" and "offset" not in self.free:
            hints.insert(0, "acoustic impact times rarely know the release time: add --fit offset")
        elif "x0" not in self.free or "v0" not in self.free:
            hints.append("or fit the start with --fit x0,v0")
        return (
            f"WARNING: the model does not fit the data: reduced chi-square {g['reduced_chi2']:.4g} "
            f"with the file's noise\n(p = {g['p_value']:.2g}), so the intervals above describe nothing "
            f"and no quantity is declared identifiable.\nTo fix: " + "; ".join(hints) + "."
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
            "n_data": int(len(self.residuals)),
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
            "profile_kappa": None
            if self.profile is None
            else {
                "kappa": [float(v) for v in self.profile["kappa"]],
                "delta_chi2": [_finite_or_none(v) for v in self.profile["delta_chi2"]],
                "ci95": [_finite_or_none(v) for v in self.profile["ci95"]],
            },
        }

    def report(self) -> str:
        """A plain-text report in the style of lmfit's `fit_report`."""
        d = self.data
        lines = ["[[Data]]"]
        lines.append(f"    file               = {d.path or '(in memory)'}")
        lines.append(f"    scene, observe     = {d.scene}, {d.observe}")
        lines.append(f"    data points        = {len(self.residuals)}")
        lines.append(f"    mass               = {d.mass:g} kg")
        lines.append("[[Fit Statistics]]")
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
        lines.append(f"    function evals     = {self.simulations} (each 2q+1 event-mode runs)")
        lines.append(f"    chi-square         = {self.chi2:.6g}")
        n, p = len(self.residuals), len(self.free)
        lines.append(f"    reduced chi-square = {self.chi2 / max(n - p, 1):.6g}")
        unit = "s" if d.observe == "impacts" else "m"
        lines.append(f"    noise sigma        = {self.sigma:.4g} {unit} ({self.sigma_source})")
        g = self.goodness
        if g["p_value"] is None:
            lines.append("    fit vs noise       = not tested (sigma estimated from the residuals)")
        else:
            verdict = "consistent" if g["consistent"] else "INCONSISTENT"
            lines.append(
                f"    fit vs noise       = {verdict} (P(chi2_{g['dof']} >= chi-square) = {g['p_value']:.3g})"
            )
        lines.append(f"    converged          = {self.converged} ({self.message})")
        lines.append(f"    wall time          = {self.wall_s:.2f} s (including JIT compilation)")
        lines.append("[[Variables]]")
        for name in PARAMETERS:
            entry = self.parameters[name]
            if name not in self.free:
                if name in ("kappa", "k_r") or (name == "drag" and d.drag > 0) or name in ("x0", "v0"):
                    lines.append(f"    {name:<7}= {entry['value']:<12.6g} (fixed)  {UNITS[name]}")
                continue
            lines.append("    " + _format_entry(name, entry, UNITS[name]))
        lines.append("[[Derived]] (Kelvin-Voigt)")
        lines.append("    " + _format_entry("e", self.derived["restitution"], ""))
        tc = {k: v for k, v in self.derived["contact_time"].items()}
        lines.append("    " + _format_entry("t_c", tc, "s"))
        lines.append(
            f"[[Identifiability]] (95% CI finite and half-width <= {self.rel_halfwidth:.0%} of the value)"
        )
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
        names = self.free
        corr = np.asarray(self.correlation)
        for i in range(len(names)):
            for j in range(i + 1, len(names)):
                lines.append(f"    C({names[i]}, {names[j]}) = {corr[i, j]:+.6f}")
        if self.profile is not None:
            lo, hi = self.profile["ci95"]
            lines.append("[[Profile likelihood]]")
            lines.append(f"    kappa 95% CI (delta chi2 <= 3.84): [{lo:.6g}, {hi:.6g}] N/m")
        return "\n".join(lines)


def _finite_or_none(value):
    value = float(value)
    return value if math.isfinite(value) else None


def _costs(starts) -> str:
    return ", ".join(f"{2 * s['cost']:.4g}" + ("" if s["converged"] else "*") for s in starts)


def _format_entry(name: str, entry: dict, unit: str) -> str:
    value, stderr = entry["value"], entry["stderr"]
    lo, hi = entry["ci95"]
    rel = f"({stderr / abs(value):.2%})" if math.isfinite(stderr) and value else "(inf)"
    return f"{name:<7}= {value:<12.6g} +/- {stderr:<10.4g} {rel:<9} 95% CI [{lo:.6g}, {hi:.6g}] {unit}"


def _halfwidth(entry) -> str:
    lo, hi = entry["ci95"]
    if not (math.isfinite(lo) and math.isfinite(hi)):
        return "  (95% CI unbounded)"
    return f"  (95% half-width {(hi - lo) / 2 / abs(entry['value']):.2%})"
