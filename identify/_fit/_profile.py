"""The profile likelihood of κ, what it says about the fit's own minimum, and whether it
closes: a κ (hence t_c) that the profile leaves open on a side is not identifiable,
whatever the Gauss–Newton interval says (that interval is a local, linear statement)."""

from __future__ import annotations

import dataclasses
import math

import numpy as np

from ._outcome import FitOutcome, Profile
from ._stages import Point, lm, row_weights
from ._uncertainty import Z95


def _row_variance(result, setup) -> float:
    """The variance that turns the profile's costs into Δχ²: the fitted scatter of e
    itself under the restitution-scatter model (its rows are unweighted log ratios),
    else the noise used relative to the file's σ."""
    if result.sigma_source == "restitution scatter":
        return result.sigma**2
    return (result.sigma / float(setup.sigmas[0])) ** 2


def profile_kappa(setup, best, rows, result: FitOutcome, opts, points: int = 13) -> Profile:
    """χ²(κ) with the other free parameters re-optimized: the profile likelihood of κ.

    Returns the grid, Δχ² = 2(cost − cost_min)/s², the 95% interval where Δχ² ≤ 3.84
    (the χ²₁ quantile, found by linear interpolation on the grid), and the grid points
    whose re-optimization failed (`failed`: never taken as excluded; an interval edge
    next to one is reported as unknown, NaN), as a `Profile`.
    """
    ev = setup.evaluator
    i_kappa = int(setup.layout.index[0, 0])
    sd = result.params["kappa"].stderr / max(result.kappa, 1e-300)
    sd = sd if math.isfinite(sd) else 5.0
    half = min(3.0 * max(sd, 1e-4), 5.0)
    grid = best.z[i_kappa] + np.linspace(-half, half, points)
    others = [j for j in setup.free if j != i_kappa]
    costs = np.full(points, np.inf)
    failed = np.zeros(points, bool)
    centre = points // 2
    weights = row_weights(setup, rows)
    for order in (range(centre, points), range(centre, -1, -1)):
        z = best.z.copy()
        for k in order:
            z[i_kappa] = grid[k]
            if others:
                out = lm(setup, z, weights, opts, free=others)
                z, cost = out.z, out.cost
                failed[k] = not (out.converged and math.isfinite(cost))
            else:
                r, _, ok = ev(z)
                cost = 0.5 * float(np.sum((weights * r) ** 2)) if ok else math.inf
                failed[k] = not ok
            costs[k] = cost
    s2 = _row_variance(result, setup)
    delta = 2.0 * (costs - min(best.cost, float(np.min(costs)))) / s2
    threshold = Z95**2
    inside = np.flatnonzero((delta <= threshold) & ~failed)
    lo_k, hi_k = (inside[0], inside[-1]) if inside.size else (centre, centre)

    def cross(k_in, k_out):
        if k_out < 0 or k_out >= points:
            return -math.inf if k_out < 0 else math.inf
        if failed[k_out]:
            return math.nan
        d0, d1 = delta[k_in], delta[k_out]
        frac = (threshold - d0) / (d1 - d0) if d1 != d0 else 0.5
        return float(grid[k_in] + frac * (grid[k_out] - grid[k_in]))

    ci = [cross(lo_k, lo_k - 1), cross(hi_k, hi_k + 1)]
    return Profile(
        kappa=np.exp(grid),
        delta_chi2=delta,
        costs=costs,
        failed=tuple(float(math.exp(g)) for g, bad in zip(grid, failed, strict=True) if bad),
        ci95=(
            (0.0 if ci[0] == -math.inf else math.exp(ci[0])) if not math.isnan(ci[0]) else math.nan,
            math.exp(ci[1]) if not math.isnan(ci[1]) else math.nan,
        ),
        value=result.kappa,
        unit=result.params["kappa"].unit,
    )


#: A profile point this many χ² units below the fit's own χ² means the fit is not at its
#: minimum (the LM's stall test counts 0.1 reduced χ² over ten steps as flat).
PROFILE_SLACK = 0.1


def check_profile_minimum(result: FitOutcome, best: Point, setup) -> FitOutcome:
    """`result` with how far its profile reached below the fit (`Profile.below_fit`); a
    profile that finds a lower χ² than the fit means the fit is not at its minimum: then
    not converged, nothing identifiable, and the message says so."""
    prof = result.profile
    s2 = _row_variance(result, setup)
    costs = prof.costs
    if costs is None:
        return result
    finite = costs[np.isfinite(costs)]
    if finite.size == 0:
        return result
    lower = 2.0 * (best.cost - float(np.min(finite))) / s2
    result = dataclasses.replace(result, profile=dataclasses.replace(prof, below_fit=float(max(lower, 0.0))))
    if lower <= PROFILE_SLACK:
        return result
    k = float(prof.kappa[int(np.argmin(np.where(np.isfinite(costs), costs, np.inf)))])
    return result.nothing_identifiable(
        converged=False,
        message=f"the profile of kappa found a chi-square {lower:.3g} below the fit's at kappa = {k:.6g}: "
        "the fit stopped short of its minimum",
    )


def profile_closes(profile: Profile) -> str | None:
    """None when the profile's 95% interval of κ is bounded on both sides; otherwise
    why not, in words (a side left open, or a re-fit that failed next to the edge)."""
    lo, hi = (float(v) for v in profile.ci95)
    if math.isnan(lo) or math.isnan(hi):
        return "the profile likelihood of kappa could not be re-fitted next to an end of its interval"
    open_sides = [side for side, end in (("below", lo), ("above", hi)) if end <= 0.0 or math.isinf(end)]
    if open_sides:
        grid = np.asarray(profile.kappa)
        reach = {"below": f"down to {grid[0]:.3g}", "above": f"up to {grid[-1]:.3g}"}
        return (
            "the profile likelihood of kappa stays within 95% "
            + " and ".join(f"{reach[s]}" for s in open_sides)
            + " (delta chi2 < 3.84): the data do not bound it "
            + " or ".join(open_sides)
        )
    return None
