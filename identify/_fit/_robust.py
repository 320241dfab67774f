"""Outliers, missed bounces, honest noise and held-out rows: what real recordings need.

**Robust pass.** A spurious onset (an echo, a rattle, a handled phone), a missed quiet
bounce or a mistracked video frame must not wreck a fit. The fit first minimises a
Cauchy loss Σ ρ(r/(c·s)) by iteratively reweighted Levenberg–Marquardt: each round
recomputes the weights w = 1/√(1 + (r/(c·s))²) (c = 2.385, the Cauchy loss's 95%
efficiency constant; s, the robust residual scale 1.4826·median|r|, in units of the
stated σ and never below 1 when the file states σ). Rows with |r| > `threshold`·s
(default 4) are then excluded, and the fit is redone by plain least squares on the
rest. `keep_outliers=True` skips both.

**Missed bounces.** A ball's flights only get shorter; an observed interval longer
than 1.25× the one before means a bounce between them went unheard. Impact onsets are
matched to the nearest predicted onset, so such a gap costs nothing; it is reported.

**Honest noise.** With a stated σ, the χ² test says whether the residuals agree. When
they scatter more (p < 1e-3) the stated σ is replaced by the residual scatter for the
intervals, and the report says so in words: for impacts, bounce-to-bounce variation
of the restitution (spin, the contact point, the seam: 0.2–0.5% for a real ball) adds
a scatter of the *intervals* of about δe/e times the interval. A scatter beyond what a
ball can do (a variation of e over 2%; for traces and apex heights, over 5× the stated
σ) is a wrong model (a clock offset not fitted, a wrong scene), and then no quantity
is declared identifiable. A σ overstated by a large factor (p > 1 − 1e-3, reduced
χ² ≪ 1) is flagged too.
"""

from __future__ import annotations

import dataclasses
import functools
import math

import numpy as np

from .._data._trace_flights import bounce_spread
from ._uncertainty import P_INCONSISTENT, goodness_of_fit

#: The Cauchy loss's scale constant (95% asymptotic efficiency on Gaussian noise).
CAUCHY_C = 2.385
#: Default outlier threshold, in robust residual scales.
THRESHOLD = 4.0
#: An interval this much longer than the previous one means a missed bounce.
MISSED_RATIO = 1.25
#: Beyond this bounce-to-bounce variation of e, excess onset scatter is a misfit of the
#: model, not scatter of the ball. Measured on 57 real hand-dropped throws (a rubber ball,
#: a tennis ball, a golf ball; phone and lab recordings): 0.3–7.4%, the highest on short
#: throws of 5-8 onsets; a fit in a wrong basin showed 879%.
MAX_E_VARIATION = 0.10
#: Likewise for traces and apex heights: residual scatter beyond this multiple of the
#: stated σ is a misfit.
MAX_SCATTER_RATIO = 5.0
#: With no stated noise, the residual scatter of a position trace or of apex heights
#: beyond this (m) is a misfit: video tracking scatters by a pixel or two (~1-3 mm),
#: a ruler or a high-speed frame reads apex heights to a few mm.
MAX_UNSTATED_SCATTER = 0.01
#: ... or beyond this fraction of the data's own height scale (a drop's release height,
#: the rackets' gap): 2% of a 0.5 m drop is 10 mm, already several pixels of any video.
MAX_RELATIVE_SCATTER = 0.02


def robust_scale(r: np.ndarray, used: np.ndarray, *, floor: float) -> float:
    """1.4826·median|r| over the used rows (a σ estimate that ignores outliers), ≥ floor."""
    rr = np.abs(r[used])
    if rr.size == 0:
        return max(floor, 1e-300)
    return max(1.4826 * float(np.median(rr)), floor, 1e-300)


def cauchy_weights(r: np.ndarray, scale: float) -> np.ndarray:
    """IRLS weights √ρ'(r²) of the Cauchy loss with scale c·s (applied to residuals)."""
    return 1.0 / np.sqrt(1.0 + (r / (CAUCHY_C * scale)) ** 2)


def fitted_count(n: int, holdout: float) -> int:
    """How many of a file's n rows a fit keeps when the last `holdout` fraction is held out."""
    return n - int(math.floor(holdout * n + 1e-9))


@dataclasses.dataclass
class Rows:
    """Which data rows a stage uses, per file, as boolean masks over the concatenated rows.

    **Fields:** `offsets`, the first row of each file; `holdout`, rows kept out of the fit
    (the last fraction of each file); `outlier`, rows excluded by the robust pass;
    `slow`, the onsets of bounces below the speed range where the file's e is constant
    (`identify._fit._trend`), left out before the fit and predicted.
    """

    offsets: np.ndarray
    holdout: np.ndarray
    outlier: np.ndarray
    slow: np.ndarray | None = None

    def __post_init__(self):
        if self.slow is None:
            self.slow = np.zeros_like(self.holdout)

    @classmethod
    def make(cls, n_rows: list[int], holdout: float) -> Rows:
        offsets = np.concatenate([[0], np.cumsum(n_rows)])
        held = np.zeros(int(offsets[-1]), bool)
        for f, n in enumerate(n_rows):
            keep = fitted_count(n, holdout)
            held[offsets[f] + keep : offsets[f + 1]] = True
        return cls(offsets=offsets, holdout=held, outlier=np.zeros_like(held))

    @property
    def fitted(self) -> np.ndarray:
        return ~self.holdout & ~self.outlier & ~self.slow

    def of_file(self, f: int) -> slice:
        return slice(int(self.offsets[f]), int(self.offsets[f + 1]))


def flag_outliers(r: np.ndarray, rows: Rows, scale: float, threshold: float) -> np.ndarray:
    """Rows of the fitted part with |r| > threshold·scale (r in σ units)."""
    return ~rows.holdout & (np.abs(r) > threshold * scale)


def missed_bounces(times: np.ndarray, keep: np.ndarray) -> list[dict]:
    """Gaps in a file's onset times (s) where a bounce went unheard.

    Only kept rows count; returns `{"after_row", "before_row", "interval", "previous"}`
    for each interval more than `MISSED_RATIO` times the one before.
    """
    idx = np.flatnonzero(keep)
    out = []
    for a, b, c in zip(idx[:-2], idx[1:-1], idx[2:], strict=True):
        previous, interval = times[b] - times[a], times[c] - times[b]
        if interval > MISSED_RATIO * previous:
            out.append(
                {
                    "after_row": int(b),
                    "before_row": int(c),
                    "interval": float(interval),
                    "previous": float(previous),
                }
            )
    return out


@dataclasses.dataclass(frozen=True)
class RatioResiduals:
    """Impact onsets under bounce-to-bounce scatter of the restitution: residuals that are
    independent, from the onset residuals r (in units of `sigma`, s) and their Jacobian.

    A ball's speed is a multiplicative random walk (v_k = v_0 Π e_i), so with scattered
    e_i the onset residuals accumulate twice and the intervals once; the log ratios of
    successive flights, log(T_k/T_{k−1}) ≈ log e_k, are independent. The rows (over the
    `keep` rows, in order) are:

    - the first onset: (p_0 − t_0)/T_1 (relative to the first interval);
    - the first interval: log(P_1/T_1);
    - every later interval: log(P_k/T_k) − log(P_{k−1}/T_{k−1}), the scatter of log e_k,

    with t the observed and p the predicted onsets, T and P their intervals; rows not
    kept are zero (they carry no weight). All rows are dimensionless, on the scale of the
    relative bounce-to-bounce variation δe/e.

    **Timing noise.** With a stated timing noise (`timing`, s) each onset's error moves
    the rows too, by δt/T: little on long flights, much on short ones (0.5 ms on a 16 ms
    flight is 3% of e, ten times a ball's scatter), and successive rows share an onset.
    The rows of `whiten` (default: every kept row) are then whitened jointly with the
    covariance s² I + timing² S Sᵀ (S: the rows' derivatives by the observed onsets,
    `sensitivity`; s = `scatter`, the ball's relative scatter), to variance s² I: the
    fitted scale is still the relative scatter of e. Without a stated noise nothing is
    whitened.
    """

    times: np.ndarray
    keep: np.ndarray
    sigma: float
    timing: float = 0.0
    scatter: float = 0.0
    whiten: np.ndarray | None = None

    @functools.cached_property
    def _whitened(self) -> tuple[np.ndarray, np.ndarray] | None:
        """(the whitened rows, L⁻¹ with L Lᵀ = I + (timing/s)² S Sᵀ), or None where nothing is
        whitened: rows of variance s² I + timing² S Sᵀ come out with variance s² I."""
        if not (self.timing > 0 and self.scatter > 0):
            return None
        mask = self.keep if self.whiten is None else self.keep & self.whiten
        idx = np.flatnonzero(self.keep)
        rows = np.flatnonzero(mask)
        if rows.size < 2:
            return None
        sens = self.sensitivity()[np.searchsorted(idx, rows)]
        ratio = self.timing / self.scatter
        cov = np.eye(len(rows)) + ratio * ratio * (sens @ sens.T)
        chol = np.linalg.cholesky(cov)
        return rows, np.linalg.solve(chol, np.eye(len(rows)))

    def sensitivity(self) -> np.ndarray:
        """(kept rows, onsets): each row's derivative by the observed onset times (the
        predicted ones held), to first order."""
        idx = np.flatnonzero(self.keep)
        t = self.times
        out = np.zeros((idx.size, len(t)))
        if idx.size < 2:
            return out
        out[0, idx[0]] = -1.0 / (t[idx[1]] - t[idx[0]])
        before = None
        for row, (a, b) in enumerate(zip(idx[:-1], idx[1:], strict=True), start=1):
            gap = t[b] - t[a]
            out[row, b] -= 1.0 / gap
            out[row, a] += 1.0 / gap
            if before is not None:
                prev, prev_gap = before
                out[row, a] += 1.0 / prev_gap
                out[row, prev] -= 1.0 / prev_gap
            before = (a, gap)
        return out

    def __call__(self, r: np.ndarray, jac: np.ndarray):
        idx = np.flatnonzero(self.keep)
        t = self.times
        pred = t + r * self.sigma
        dpred = jac * self.sigma
        out, dout = np.zeros_like(r), np.zeros_like(jac)
        if idx.size < 2:
            return out, dout
        i0, i1 = idx[0], idx[1]
        out[i0] = (pred[i0] - t[i0]) / (t[i1] - t[i0])
        dout[i0] = dpred[i0] / (t[i1] - t[i0])
        prev_log, prev_grad = None, None
        for a, b in zip(idx[:-1], idx[1:], strict=True):
            p_int = max(pred[b] - pred[a], 1e-12)
            log_ratio = math.log(p_int / (t[b] - t[a]))
            grad = (dpred[b] - dpred[a]) / p_int
            if prev_log is None:
                out[b], dout[b] = log_ratio, grad
            else:
                out[b], dout[b] = log_ratio - prev_log, grad - prev_grad
            prev_log, prev_grad = log_ratio, grad
        whitened = self._whitened
        if whitened is not None:
            rows, w = whitened
            out[rows], dout[rows] = w @ out[rows], w @ dout[rows]
        return out, dout


def noise_statement(
    d_observe: str,
    *,
    sigma_known: bool,
    stated,
    scatter: float,
    goodness: dict,
    times,
    height: float | None = None,
    structure: dict | None = None,
) -> dict:
    """The stated σ against the residual scatter, in words and numbers.

    `structure` (drop traces with at least two pairs of complete flights): `{"e_bounces",
    "e_fit", "locked"}`, the flights' own per-bounce e, the fitted e and the p-value of
    bounce-locked residuals. Then the residuals' structure decides, not a fixed cap
    (`trace_structure`): an excess that the bounces' own e spread explains is scatter of
    the ball; one that contradicts them is a misfit.

    **Returns:** `{"stated", "scatter", "unit", "verdict", "text"}`; verdict is one of
    `"estimated"` (no σ stated), `"consistent"`, `"understated"` (the residuals scatter
    more, plausibly from bounce-to-bounce scatter: the intervals use the scatter),
    `"misfit"` (far more than scatter explains: no quantity is identifiable) or
    `"overstated"` (reduced χ² ≪ 1).
    """
    unit = "s" if d_observe == "impacts" else "m"
    show = (lambda v: f"{v * 1e3:.3g} ms") if unit == "s" else (lambda v: f"{v * 1e3:.3g} mm")
    judged = None
    if d_observe == "trace" and structure is not None:
        judged = trace_structure({**structure, "scatter": scatter, "height": height})
    if not sigma_known:
        verdict = "estimated"
        text = f"no noise stated: sigma = residual scatter {show(scatter)}"
        limit = unstated_limit(d_observe, height)
        if judged is not None:
            if not judged[0]:
                verdict = "misfit"
            text += "; " + judged[1]
        elif limit is not None and scatter > limit:
            verdict = "misfit"
            text += (
                f", far more than a {'position trace' if d_observe == 'trace' else 'height measurement'} "
                f"scatters (at most {show(limit)}: {show(MAX_UNSTATED_SCATTER)}, or "
                f"{MAX_RELATIVE_SCATTER:.0%} of the data's {height:.3g} m height scale): the model does not fit"
            )
    elif goodness["consistent"]:
        verdict = "consistent"
        text = f"residual scatter {show(scatter)}, consistent with the stated {show(stated)}"
    else:  # the χ² test against the stated σ failed (p < P_INCONSISTENT)
        verdict = "understated"
        text = f"residual scatter {show(scatter)} against a stated {show(stated)}"
        if d_observe == "impacts" and len(times) > 2:
            variation = scatter * math.sqrt(2.0) / float(np.mean(np.diff(times)))
            text += f": the bounce-to-bounce variation of e is about {variation:.2%}"
            plausible = variation <= MAX_E_VARIATION
        elif judged is not None:
            plausible = judged[0]
            text += "; " + judged[1]
        else:
            plausible = scatter <= MAX_SCATTER_RATIO * stated
        if plausible:
            text += "; the intervals use the residual scatter"
        else:
            verdict = "misfit"
            if judged is None:
                text += "; far more than bounce-to-bounce scatter explains: the model does not fit"
    if sigma_known and _overstated(goodness):
        verdict = "overstated"
        text = (
            f"residual scatter {show(scatter)} against a stated {show(stated)}: the stated noise looks "
            f"{stated / max(scatter, 1e-300):.3g}x too large (reduced chi-square {goodness['reduced_chi2']:.3g}); "
            "the intervals use the stated noise and are too wide"
        )
    return {"stated": stated, "scatter": scatter, "unit": unit, "verdict": verdict, "text": text}


#: A drop trace whose residual scatter exceeds this fraction of its height scale shows no
#: bounces to judge (a clean 1 kHz trace at 10.5 mm is 3.4% of its 0.305 m drop; pure noise
#: of 0.25 m, 82%).
MAX_TRACE_SCATTER = 0.1


def trace_structure(structure: dict) -> tuple[bool, str] | None:
    """Whether a drop trace's excess residuals are the ball's bounce-to-bounce scatter:
    (plausible, why), or None when fewer than two per-bounce e measure it. A residual
    scatter beyond `MAX_TRACE_SCATTER` of the height scale is a misfit first: no bounce
    stands out of it.

    The flights' own per-bounce e (closed form, `apex_ratios`) are the reference: a
    fitted e off their median by more than max(0.03, 4 standard errors of a median) is a
    wrong fit. Otherwise the excess is what the bounces differ by, whether or not the
    residuals are bounce-locked. (Their spread is no verdict: with 10 mm of tracking
    noise it reached 18% on a clean 1 kHz trace.)
    """
    e_b = np.asarray(structure["e_bounces"], dtype=float)
    if e_b.size < 2:
        return None
    median = float(np.median(e_b))
    spread = bounce_spread(e_b)
    tolerance = max(0.03, 4.0 * 1.2533 * spread / math.sqrt(e_b.size))
    scatter, height = structure.get("scatter"), structure.get("height")
    if scatter is not None and height and scatter > MAX_TRACE_SCATTER * height:
        return False, (
            f"the bounces do not stand out of the residual scatter ({scatter * 1e3:.3g} mm, more than "
            f"{MAX_TRACE_SCATTER:.0%} of the {height:.3g} m height scale): the model does not fit"
        )
    e_fit = float(structure["e_fit"])
    listed = f"{e_b.size} per-bounce e from the flights' apexes, median {median:.4f}"
    if not abs(e_fit - median) <= tolerance:
        return False, (
            f"the fit's e = {e_fit:.4f} contradicts the {listed} (± {tolerance:.3f}): the model does not fit"
        )
    locked = structure.get("locked")
    follows = "" if locked is None else f"; the residuals follow the bounces (p = {locked:.2g})"
    return (
        True,
        f"the per-bounce e spread by {spread / median:.2%}, tracking noise included ({listed}){follows}",
    )


def unstated_limit(observe: str, height: float | None) -> float | None:
    """The most residual scatter (m) a trace or apex heights plausibly have when no noise is
    stated: `MAX_UNSTATED_SCATTER`, or `MAX_RELATIVE_SCATTER` of the height scale if smaller.
    None for impact onsets (their scatter is judged as restitution scatter)."""
    if observe not in ("trace", "apex"):
        return None
    limit = MAX_UNSTATED_SCATTER
    if height is not None and math.isfinite(height) and height > 0:
        limit = min(limit, MAX_RELATIVE_SCATTER * height)
    return limit


def height_scale(d) -> float | None:
    """A data set's height scale (m), from its metadata (noise-free): a drop's release
    height x0 (the highest apex where that is higher), the gap between two rackets."""
    if d.observe not in ("trace", "apex"):
        return None
    if d.scene == "rackets":
        return float(d.gap)
    top = float(np.max(d.h)) if d.observe == "apex" else 0.0
    height = max(float(d.x0), top)
    return height if height > 0 else None


def scatter_statement(sigma_known: bool, stated: float, onset_scatter: float, variation: float) -> dict:
    """The statement of a fit under the restitution-scatter error model.

    `variation` is the fitted scale of the log-ratio rows: the bounce-to-bounce relative
    variation of e, δe/e. Beyond `MAX_E_VARIATION` the verdict is `"misfit"`.
    """
    head = (
        f"onset residual scatter {onset_scatter * 1e3:.3g} ms against a stated {stated * 1e3:.3g} ms"
        if sigma_known
        else f"no timing noise stated; onset residual scatter {onset_scatter * 1e3:.3g} ms"
    )
    if variation > MAX_E_VARIATION:
        return {
            "stated": stated if sigma_known else None,
            "scatter": onset_scatter,
            "restitution_scatter": variation,
            "unit": "s",
            "verdict": "misfit",
            "text": f"{head}: a bounce-to-bounce variation of e of {variation:.2%}, more than a ball "
            "does: the model does not fit",
        }
    return {
        "stated": stated if sigma_known else None,
        "scatter": onset_scatter,
        "restitution_scatter": variation,
        "unit": "s",
        "verdict": "understated" if sigma_known else "estimated",
        "text": f"{head}: the bounce-to-bounce variation of e is about {variation:.2%}; fitted as such "
        "(log ratios of successive flights), the intervals use it",
    }


def _overstated(goodness: dict) -> bool:
    """Reduced χ² so small that the chance of it under the stated σ is below 1e-3."""
    p = goodness["p_value"]
    return p is not None and p > 1.0 - P_INCONSISTENT and goodness["reduced_chi2"] < 0.5


def holdout_summary(
    residuals: np.ndarray,
    rows: Rows,
    sigma: np.ndarray,
    fraction: float,
    unit: str,
    variance: np.ndarray,
    *,
    reported: np.ndarray | None = None,
) -> dict:
    """The held-out rows' prediction errors and whether they are within the noise.

    `residuals` are the fitted rows' residuals (in units of `sigma`'s), `variance` each
    row's predictive variance in units of its σ² (1 + JΣJᵀ: the noise plus the fitted
    parameters' uncertainty propagated to that row), `reported` the prediction errors
    in data units (default: `residuals`). Rows beyond `THRESHOLD` predictive sd are
    outliers there too and are counted, not averaged. The prediction is *within the
    noise* when the χ² of the rest against their predictive variance passes the test
    at p ≥ 1e-3.
    """
    held = rows.holdout
    reported = residuals if reported is None else reported
    scaled = residuals[held] / (sigma[held] * np.sqrt(variance[held]))
    inlier = np.abs(scaled) <= THRESHOLD
    use = reported[held][inlier]
    if use.size == 0:
        return {"fraction": fraction, "rows": int(held.sum()), "rms": None, "max": None, "within_noise": None}
    g = goodness_of_fit(float(np.sum(scaled[inlier] ** 2)), int(use.size), 0, sigma_known=True)
    return {
        "fraction": fraction,
        "rows": int(held.sum()),
        "outliers": int((~inlier).sum()),
        "rms": float(np.sqrt(np.mean(use**2))),
        "max": float(np.max(np.abs(use))),
        "unit": unit,
        "p_value": g["p_value"],
        "within_noise": bool(g["consistent"]),
    }
