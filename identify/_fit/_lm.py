"""The Levenberg–Marquardt of the fit: host-side, on z = (log κ, log k_r, …), with
Marquardt scaling, bounds by projection and frozen entries (design notes:
`identify/README.md`, "The LM's stall test").

It only needs an evaluator `z → (r, J, ok)` with a `free` list (the Jacobian's columns);
it returns an `LMPoint`.
"""

from __future__ import annotations

import dataclasses
import math

import numpy as np

#: Levenberg–Marquardt damping divisor after an accepted step. Along the κ–k_r ridge
#: (correlation ~0.99999) a slowly released damping crawls: with 3, each start of the
#: impacts fit took 12 accepted steps, each step ~3x the last; with 10 it takes 6.
LAMBDA_DOWN = 10.0
#: The stall test: over this many accepted steps, a χ² decrease below this many
#: reduced χ² is convergence.
STALL_STEPS, STALL_CHI2 = 10, 0.1


@dataclasses.dataclass(frozen=True)
class LMPoint:
    """Where a Levenberg–Marquardt run stopped.

    **Fields:** `z`, the joint point; `r` and `jac`, the residuals and Jacobian there
    (columns: the evaluator's `free` entries); `cost` = ½Σ(w·r)² (inf when the start
    failed); `iterations`, the iterations run; `converged` and `why`, the stop's verdict
    and its reason in words.
    """

    z: np.ndarray
    r: np.ndarray
    jac: np.ndarray
    cost: float
    iterations: int
    converged: bool
    why: str


def _newton_decrement(a, g, d):
    """½ gᵀA⁻¹g, the decrease of ½χ² at the Gauss–Newton step (A = JᵀJ, scaled by d)."""
    s = 1.0 / np.sqrt(d)
    try:
        step = s * np.linalg.lstsq(s[:, None] * a * s[None, :], s * g, rcond=1e-14)[0]
    except np.linalg.LinAlgError:
        return math.inf
    return 0.5 * float(g @ step)


def _reduced(cost: float, weights: np.ndarray, n_free: int) -> float:
    """The reduced χ² at `cost` (the unit of the χ² tolerances)."""
    return 2.0 * cost / max(int(np.count_nonzero(weights)) - n_free, 1)


def levenberg_marquardt(
    evaluator, z, free, weights, lo, hi, *, max_iterations, dchi2=1e-6, xtol=1e-10
) -> LMPoint:
    """Minimize ½Σ(w·r)² over z[free] within [lo, hi].

    Converged when an accepted step lowers χ² = Σ(w·r)² by less than `dchi2` (in units
    of the reduced χ², so the step is far below one standard error), or moves z by
    less than `xtol`, or the scaled gradient vanishes, or before any trial run when
    even the Gauss–Newton step's predicted decrease of χ² (twice the Newton decrement
    ½gᵀ(JᵀJ)⁻¹g) is below that tolerance: at the optimum, trial steps only measure noise,
    and each costs a run of every row. Also converged when `STALL_STEPS` accepted steps
    together lowered χ² by less than `STALL_CHI2` reduced χ²: a creep along a flat
    valley (a contact time the data hardly see) that moves the estimate by well under
    one standard error.
    """
    r, jac, ok = evaluator(z)
    if not ok:
        return LMPoint(z, r, jac, math.inf, 0, False, "the simulation failed at the start point")
    cost = 0.5 * float(np.sum((weights * r) ** 2))
    lam = 1e-3
    history = [cost]
    columns = [evaluator.free.index(i) for i in free]

    def point(it, converged, why):
        return LMPoint(z, r, jac, cost, it, converged, why)

    for it in range(1, max_iterations + 1):
        jw = weights[:, None] * jac[:, columns]
        g = jw.T @ (weights * r)
        a = jw.T @ jw
        d = np.maximum(np.diag(a), 1e-12 * max(float(np.max(np.diag(a))), 1e-300))
        if float(np.max(np.abs(g) / np.sqrt(d))) <= 1e-10 * max(math.sqrt(2 * cost), 1e-300):
            return point(it - 1, True, "gradient below tolerance")
        # The most any step can gain on the local quadratic model (the Gauss–Newton
        # decrement ½ gᵀA⁻¹g): below the χ² tolerance, no trial step is worth a run.
        if _newton_decrement(a, g, d) <= 0.5 * dchi2 * _reduced(cost, weights, len(free)):
            return point(it - 1, True, "predicted change below tolerance")
        while True:
            try:
                step = np.linalg.solve(a + lam * np.diag(d), -g)
            except np.linalg.LinAlgError:
                step = np.zeros_like(g)
            z_new = z.copy()
            z_new[free] = np.clip(z[free] + step, lo[free], hi[free])
            r_new, jac_new, ok_new = evaluator(z_new)
            cost_new = 0.5 * float(np.sum((weights * r_new) ** 2)) if ok_new else math.inf
            if cost_new <= cost:
                moved = np.max(np.abs(z_new[free] - z[free]))
                decrease = cost - cost_new
                z, r, jac, cost = z_new, r_new, jac_new, cost_new
                lam = max(lam / LAMBDA_DOWN, 1e-12)
                reduced = _reduced(cost, weights, len(free))
                if (
                    moved <= xtol * (1.0 + float(np.max(np.abs(z[free]))))
                    or 2.0 * decrease <= dchi2 * reduced
                ):
                    return point(it, True, "relative change below tolerance")
                history.append(cost)
                if (
                    len(history) > STALL_STEPS
                    and 2.0 * (history[-1 - STALL_STEPS] - cost) <= STALL_CHI2 * reduced
                ):
                    return point(it, True, f"chi-square stalled over {STALL_STEPS} steps")
                break
            lam *= 4.0
            if lam > 1e12:
                return point(it, False, "no decrease found (damping at its limit)")
    return point(max_iterations, False, f"max_iterations = {max_iterations} reached")
