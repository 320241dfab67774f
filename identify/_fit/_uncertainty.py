"""Gauss–Newton uncertainty: covariance, standard errors, 95% intervals, identifiability.

With residuals r = (prediction − data)/σ and their Jacobian J with respect to the fitted
vector z at the optimum, the Gauss–Newton covariance is

    Cov(z) = s² (JᵀJ)⁻¹,

where s² = 1 when σ is the known measurement noise (the file's `noise`), or
s² = Σr²/(N − p) estimated from the residuals otherwise. Directions of JᵀJ with
eigenvalue below `1e-13·λ_max` are treated as unidentified: every parameter that loads
on one gets an infinite variance (as mujoco.sysid reports infinite CIs along null
directions).

κ, k_r and t_c are positive and fitted as logs, so their 95% intervals are
exp(log value ± 1.96·sd(log)): asymmetric, and never negative. The restitution's
interval is value ± 1.96·sd, clipped to [0, 1].

A quantity is *identifiable* when its 95% interval is finite and its half-width is
below `rel_halfwidth` (25% by default) of its value. The correlation is reported
beside the verdict but never decides it: a 1 kHz drop trace identifies κ and k_r to
about 1% although their estimates correlate at 0.9999.

All of this assumes the model fits the data. With a known σ that is testable: χ² of
a consistent fit follows the χ² distribution with N − p degrees of freedom
(`goodness_of_fit`). A fit that fails the test (p < `P_INCONSISTENT`: a wrong scene,
a wrong x0, an unknown release time not fitted) has standard errors and intervals that
describe nothing, so no quantity is declared identifiable.
"""

from __future__ import annotations

import math

import numpy as np

from ._kelvin_voigt import restitution_and_contact_time
from ._problem import LOG_PARAMETERS, PARAMETERS

Z95 = 1.959963984540054
#: A fit whose χ² has a chance below this under the stated noise is inconsistent.
P_INCONSISTENT = 1e-3


def goodness_of_fit(chi2: float, n: int, p: int, *, sigma_known: bool) -> dict:
    """χ² test of the fit against the stated noise.

    **Returns:** `{"reduced_chi2", "dof", "p_value", "consistent"}`: χ²/(N − p), the
    degrees of freedom N − p, P(χ²_dof ≥ χ²) (`chi2_tail`), and whether p_value ≥
    `P_INCONSISTENT`. With σ estimated from the residuals the reduced χ² is 1 by
    construction and nothing is tested: p_value and consistent are None.
    """
    dof = max(int(n) - int(p), 1)
    reduced = float(chi2) / dof
    if not sigma_known:
        return {"reduced_chi2": reduced, "dof": dof, "p_value": None, "consistent": None}
    if not math.isfinite(chi2):
        return {"reduced_chi2": reduced, "dof": dof, "p_value": 0.0, "consistent": False}
    p_value = chi2_tail(float(chi2), dof)
    return {"reduced_chi2": reduced, "dof": dof, "p_value": p_value, "consistent": p_value >= P_INCONSISTENT}


def chi2_tail(chi2: float, dof: float) -> float:
    """P(χ²_dof ≥ chi2), the χ² distribution's upper tail (dimensionless; chi2 ≥ 0, dof > 0):
    `scipy.special.chdtrc`, the regularized upper incomplete gamma Q(dof/2, chi2/2) (Cephes,
    relative accuracy ~1e-14 where the tail is above 1e-300). Imported on use: importing
    identify loads no scipy."""
    from scipy.special import chdtrc

    return float(chdtrc(dof, max(chi2, 0.0)))


def covariance(jac: np.ndarray, r: np.ndarray, *, sigma_known: bool) -> tuple[np.ndarray, float]:
    """Cov of the free entries of z, and s² (1 when σ is known).

    **Arguments:**

    - `jac`: ∂r/∂z_free, shape (N, p).
    - `r`: the normalized residuals at the optimum, shape (N,).
    - `sigma_known`: whether r was divided by the known noise σ.
    """
    n, p = jac.shape
    s2 = 1.0 if sigma_known else float(np.sum(r**2) / max(n - p, 1))
    a = jac.T @ jac
    lam, vec = np.linalg.eigh(a)
    lam_max = float(np.max(lam)) if p else 0.0
    null = lam <= 1e-13 * max(lam_max, 1e-300)
    inv = np.where(null, 0.0, 1.0 / np.where(null, 1.0, lam))
    cov = (vec * inv) @ vec.T * s2
    if np.any(null):
        loads = np.any(np.abs(vec[:, null]) > 1e-8, axis=1)
        cov[loads, :] = np.inf
        cov[:, loads] = np.inf
    return cov, s2


def _entry(value: float, sd: float, *, log: bool, clip: tuple[float, float] | None = None) -> dict:
    """value, stderr and ci95 of one quantity; sd is of log(value) when `log`."""
    if not math.isfinite(sd) or (log and Z95 * sd > 700.0):
        return {"value": value, "stderr": math.inf, "ci95": [-math.inf, math.inf]}
    if log:
        lo, hi = value * math.exp(-Z95 * sd), value * math.exp(Z95 * sd)
        stderr = value * sd
    else:
        lo, hi = value - Z95 * sd, value + Z95 * sd
        stderr = sd
    if clip is not None:
        lo, hi = max(lo, clip[0]), min(hi, clip[1])
    return {"value": value, "stderr": stderr, "ci95": [lo, hi]}


def summarize(
    z: np.ndarray,
    cov: np.ndarray,
    free: list[int],
    mass: float,
    *,
    rel_halfwidth: float = 0.25,
    derived=restitution_and_contact_time,
):
    """Estimates with stderr and CIs, derived e and t_c, correlation and verdicts.

    `derived(log κ, log k_r, mass)` gives (e, t_c, ∂e/∂(log κ, log k_r), ∂log t_c/∂(…))
    for the contact law (default: the Kelvin–Voigt closed forms).

    **Returns:** `(parameters, derived, identifiable, correlation, names)`: dicts of
    `{"value", "stderr", "ci95"}` entries in physical units (a parameter that was not
    fitted has stderr 0 and a point interval), the verdict per quantity, and the
    correlation matrix of the free entries with their names.
    """
    full = np.zeros((len(PARAMETERS), len(PARAMETERS)))
    full[np.ix_(free, free)] = cov
    parameters = {}
    for i, name in enumerate(PARAMETERS):
        log = name in LOG_PARAMETERS
        value = math.exp(z[i]) if log else float(z[i])
        sd = math.sqrt(full[i, i]) if full[i, i] >= 0 else math.nan
        parameters[name] = _entry(value, sd, log=log)
    e, t_c, ge, gt = derived(float(z[0]), float(z[1]), mass)
    sub = full[:2, :2]
    with np.errstate(invalid="ignore"):
        var_e = float(ge @ sub @ ge) if np.all(np.isfinite(sub)) else math.inf
        var_t = float(gt @ sub @ gt) if np.all(np.isfinite(sub)) else math.inf
    quantities = {
        "restitution": _entry(e, math.sqrt(max(var_e, 0.0)), log=False, clip=(0.0, 1.0)),
        "contact_time": _entry(t_c, math.sqrt(max(var_t, 0.0)), log=True),
    }

    def verdict(entry) -> bool:
        lo, hi = entry["ci95"]
        if not (math.isfinite(lo) and math.isfinite(hi)):
            return False
        return (hi - lo) / 2 <= rel_halfwidth * abs(entry["value"])

    identifiable = {
        "kappa": 0 in free and verdict(parameters["kappa"]),
        "k_r": 1 in free and verdict(parameters["k_r"]),
        "restitution": (0 in free or 1 in free) and verdict(quantities["restitution"]),
        "contact_time": (0 in free or 1 in free) and verdict(quantities["contact_time"]),
    }
    with np.errstate(invalid="ignore", divide="ignore"):
        sd = np.sqrt(np.diag(cov))
        corr = cov / np.outer(sd, sd)
    corr = np.where(np.isfinite(corr), corr, np.nan)
    names = [PARAMETERS[i] for i in free]
    return parameters, quantities, identifiable, corr, names
