"""The fit's stages, each on a `Setup` and returning a `Point` (the order is
`identify._pipeline`'s; design notes with the measured reasons: `identify/README.md`).

1. **Closed-form start** (`start_restitution`, `_setup.start_points`): e from successive
   rebound heights or drag-corrected flight times, t_c from the 0.5–2 ms prior, then
   (κ, k_r) from the law's inverse. Two-racket traces, which have no closed form, start
   from the best e on a grid.
2. **Starts** (`run_starts`): each start loosely on the first window, after the optional
   optax stage (`identify._fit._gradient`).
3. **Growing windows** (`windows_from`): the first 35%, 65%, then all of each file's
   span: a window that holds the first bounces pins the phase and each longer window
   starts next to its optimum.
4. **Robust pass** (`robust_pass`): Cauchy-weighted LM rounds, then rows beyond the
   outlier threshold are excluded.
5. **Final pass** (`final_pass`): least squares on the kept rows, the steering prior
   dropped where the data fix t_c; impact onsets whose scatter no stated timing noise
   explains are refitted under the restitution-scatter error model (`ratio_transforms`).

A stage that fits other rows than its input (no prior, the log-ratio rows) derives
its own evaluator (`Setup.with_evaluator`); nothing changes the set-up it was given.
"""

from __future__ import annotations

import dataclasses
import math

import numpy as np

from jaxunilat._internal import InputError

from .._data._import import ratio_chain
from ._derived import derived_quantities
from ._gradient import gradient_step, run_gradient_stage
from ._initial import CONTACT_TIME_GUESS
from ._lm import LMPoint, levenberg_marquardt
from ._robust import RatioResiduals, cauchy_weights, flag_outliers, robust_scale
from ._setup import onset_bounces, start_point
from ._trend import (
    MIN_BOUNCES,
    SCATTER_FLOOR,
    of_dataset,
    reml_components,
    restitution_trend,
    scatter_evident,
)
from ._uncertainty import covariance, goodness_of_fit

_WINDOWS = (0.35, 0.65, 1.0)
#: The robust pass excludes at most this fraction of a fit's rows; beyond it the model,
#: not a few rows, is what misfits, and nothing is excluded.
MAX_OUTLIER_FRACTION = 0.2


@dataclasses.dataclass(frozen=True)
class Point(LMPoint):
    """Where a stage left the fit: an `LMPoint` whose `iterations` count every LM stage
    that led there, and the gradient steps spent on the way."""

    gradient_steps: int = 0

    @classmethod
    def from_lm(cls, out: LMPoint, *, iterations: int = 0, gradient_steps: int = 0) -> Point:
        fields = {f.name: getattr(out, f.name) for f in dataclasses.fields(LMPoint)}
        fields["iterations"] += iterations
        return cls(**fields, gradient_steps=gradient_steps)

    def then(self, out: LMPoint) -> Point:
        """The point a further LM stage `out` reached, its iterations added to these."""
        return Point.from_lm(out, iterations=self.iterations, gradient_steps=self.gradient_steps)


def windows(setup) -> tuple[float, ...]:
    """Growing windows for traces and for onset sequences (apex heights: all at once)."""
    return _WINDOWS if any(d.observe in ("trace", "impacts") for d in setup.datasets) else (1.0,)


def row_weights(setup, rows, fraction: float = 1.0, robust: np.ndarray | None = None) -> np.ndarray:
    """Weights of the data rows (fitted rows inside the window), then 1 per prior row in use.

    A trace's or an onset sequence's window keeps the rows in the first `fraction` of
    its span: Adam or LM on a raw 2 s trace from a 2× wrong start goes out of phase,
    and late onsets predicted from a wrong start get matched to the wrong bounce, while
    a window that holds the first bounces pins the phase and each longer window starts
    next to its optimum.
    """
    w = rows.fitted.astype(float)
    if fraction < 1.0:
        for f, d in enumerate(setup.datasets):
            if d.observe in ("trace", "impacts"):
                t = setup.times[f]
                w[rows.of_file(f)] *= t <= t[0] + fraction * (t[-1] - t[0])
    if robust is not None:
        w = w * robust
    ev = setup.evaluator
    return np.concatenate([w, np.ones(len(ev._prior_pairs()))]) if ev.prior else w


def lm(setup, z, weights, opts, *, dchi2=1e-6, free=None) -> LMPoint:
    """The LM on `setup`'s evaluator, free entries (or `free`) and bounds."""
    return levenberg_marquardt(
        setup.evaluator,
        z,
        setup.free if free is None else free,
        weights,
        setup.lo,
        setup.hi,
        max_iterations=opts.max_iterations,
        dchi2=dchi2,
    )


def start_restitution(setup, rows) -> tuple[float, str]:
    """The start's e and where it comes from (the closed form, or a grid search)."""
    if setup.e0 is not None:
        return setup.e0, setup.e_source
    # No closed form (two-racket traces): the best e on a grid, at the prior's t_c.
    ev = setup.evaluator
    grid = np.linspace(0.3, 0.98, ev.rows)
    w = row_weights(setup, rows, _WINDOWS[0])
    costs = [
        np.sum((w * r) ** 2) if ok else np.inf
        for r, ok in ev.values([start_point(setup, e, CONTACT_TIME_GUESS) for e in grid])
    ]
    return float(grid[int(np.argmin(costs))]), "grid search (no closed form for this scene)"


def run_starts(setup, candidates, rows, opts) -> list[Point]:
    """Every start on the first window, loosely (it only has to find the basin)."""
    step_fn = gradient_step(opts.optimizer, opts.gradient) if opts.method == "optax" else None
    first = row_weights(setup, rows, windows(setup)[0])
    runs = []
    bar = _progress(len(candidates), opts.progress)
    for z in candidates:
        z, gradient_steps = z.copy(), 0
        if step_fn is not None and opts.steps > 0:
            z, gradient_steps = run_gradient_stage(step_fn, opts, setup, rows, first, z)
        runs.append(Point.from_lm(lm(setup, z, first, opts, dchi2=1e-2), gradient_steps=gradient_steps))
        bar.update(1)
    bar.close()
    return runs


def windows_from(setup, point: Point, rows, opts) -> Point:
    """The growing windows after the first, from `point` (loose LM on each)."""
    for fraction in windows(setup)[1:]:
        point = point.then(lm(setup, point.z, row_weights(setup, rows, fraction), opts, dchi2=1e-2))
    return point


def robust_pass(setup, best: Point, rows, opts):
    """Cauchy-weighted LM rounds, then the rows beyond the threshold are excluded.

    Returns the point to go on from, the rows (with `outlier` set) and the robust scale.
    The point is the robust one unless the plain least-squares point fits the kept
    rows better; when more than `MAX_OUTLIER_FRACTION` of the rows would go, nothing
    is excluded and the least-squares point is kept.
    """
    n = sum(setup.n_rows)
    floor = 1.0 if setup.sigma_known else 0.0
    scale = robust_scale(best.r[:n], rows.fitted, floor=floor)
    if not np.any(flag_outliers(best.r[:n], rows, scale, opts.threshold)):
        return best, rows, scale  # nothing beyond the threshold: least squares is already robust
    point = best
    for _ in range(3):
        w = row_weights(setup, rows, robust=cauchy_weights(point.r[:n], scale))
        point = point.then(lm(setup, point.z, w, opts, dchi2=1e-2))
        scale = robust_scale(point.r[:n], rows.fitted, floor=floor)
    outlier = flag_outliers(point.r[:n], rows, scale, opts.threshold)
    if outlier.sum() > MAX_OUTLIER_FRACTION * (~rows.holdout).sum():
        return best, rows, scale
    rows = dataclasses.replace(rows, outlier=outlier)
    kept = rows.fitted

    def kept_cost(p):
        return float(np.sum(p.r[:n][kept] ** 2)) if math.isfinite(p.cost) else math.inf

    return (point if kept_cost(point) <= kept_cost(best) else best), rows, scale


def final_pass(setup, best: Point, rows, opts) -> Point:
    """One tight pass on all fitted rows; the point's r, J and cost are the data's.

    The steering prior only holds the path where the data say nothing: the tight pass
    drops it when the data determine t_c themselves (sd(log t_c) < 0.1 without it), and
    the uncertainty never uses it.
    """
    data = setup.with_evaluator(prior=False)
    stage = data
    if setup.evaluator.prior:
        r_data, jac_data, _ = data.evaluator(best.z)
        keep = rows.fitted
        cov_tc, _ = covariance(jac_data[keep], r_data[keep], sigma_known=setup.sigma_known)
        t_c = derived_quantities(setup, best.z, cov_tc)["contact_time"]
        if not t_c["stderr"] < 0.1 * t_c["value"]:
            stage = setup
    # The tight pass may have to follow the long κ–k_r–t_c valley of a joint fit: it
    # gets four times the iterations of the loose stages.
    longer = dataclasses.replace(opts, max_iterations=4 * opts.max_iterations)
    point = best.then(lm(stage, best.z, row_weights(stage, rows), longer))
    if stage.evaluator.prior:
        r, jac, _ = data.evaluator(point.z)
        point = dataclasses.replace(point, r=r, jac=jac, cost=0.5 * float(np.sum((rows.fitted * r) ** 2)))
    return point


def restart(setup, z, rows, opts) -> Point:
    """Every stage but the robust pass from the joint point z (the first window loosely,
    the growing windows, the final pass)."""
    first = Point.from_lm(lm(setup, z, row_weights(setup, rows, windows(setup)[0]), opts, dchi2=1e-2))
    return final_pass(setup, windows_from(setup, first, rows, opts), rows, opts)


def scatter_model_applies(setup, best: Point, rows) -> bool:
    """Whether impact onsets need the restitution-scatter error model.

    When every file holds impact onsets and their residuals are not explained by a
    stated timing noise (none stated, or the χ² test fails), the scatter is the ball's:
    onset residuals then accumulate from bounce to bounce, and least squares on them
    would take drifts for signal (a contact time of 20 ms fitted to a random walk).
    """
    if any(d.observe != "impacts" for d in setup.datasets):
        return False
    if not setup.sigma_known:
        return True
    n = sum(setup.n_rows)
    keep = rows.fitted
    g = goodness_of_fit(
        float(np.sum(best.r[:n][keep] ** 2)), int(keep.sum()), len(setup.free), sigma_known=True
    )
    return g["consistent"] is False


def counted(setup) -> bool:
    """Whether every file is a drop recorded as impact onsets whose own ratio chain counts
    the bounces (each onset matched to its own predicted bounce: `_setup.onset_bounces`)."""
    return all(onset_bounces(d) is not None for d in setup.datasets)


def speed_trends(setup) -> list:
    """Each file's trend of e with impact speed (`_trend.restitution_trend`), or None."""
    return [restitution_trend(d) for d in setup.datasets]


def leave_out_slow(setup, rows, trends):
    """`rows` with the onsets below each file's constant-e speed range marked `slow`."""
    slow = rows.slow.copy()
    for f, trend in enumerate(trends):
        if trend is not None and trend.rows is not None:
            sl = rows.of_file(f)
            slow[sl] = np.arange(setup.n_rows[f]) >= trend.rows
    return dataclasses.replace(rows, slow=slow)


def _file_ratios(setup, rows, f):
    """File f's closed-form flight ratios (`_trend.flight_ratios`) and the bounces whose
    three onsets are all fitted, or (None, None)."""
    d = setup.datasets[f]
    ratios = of_dataset(d)
    if ratios is None:
        return None, None
    fitted = rows.fitted[rows.of_file(f)]
    k = ratios.onset
    keep = fitted[k - 1] & fitted[k] & fitted[np.minimum(k + 1, len(fitted) - 1)] & (k + 1 < len(fitted))
    return ratios, keep


def scatter_from_start(setup, rows) -> bool:
    """Whether the fit uses the flights' log ratios from its first stage: every file's
    onsets are counted (no drift can slip an onset onto another bounce), and some file's
    own flights scatter beyond its timing noise (`_trend.scatter_evident`; always without
    a stated noise), so that onset residuals of a constant e are a random walk that a
    least-squares stage on the onsets would bend the contact time and the release to
    follow."""
    if not counted(setup):
        return False
    if not setup.sigma_known:
        return True
    for f in range(setup.layout.n_files):
        ratios, keep = _file_ratios(setup, rows, f)
        if ratios is not None and keep.sum() >= MIN_BOUNCES and scatter_evident(ratios, keep):
            return True
    return False


#: The relative scatter of e a ratio row's weights assume where the flights cannot measure
#: it (a real ball's: 0.2-0.5%).
TYPICAL_SCATTER = 0.003


def closed_scatter(setup, rows) -> dict:
    """Each file's (s, σ): the relative bounce-to-bounce scatter of e and the timing noise
    (at most the stated one) that its own flights show (`_trend.FlightRatios.components`,
    about a constant e), for the weights of its log-ratio rows; where the flights cannot
    measure them, a typical ball's scatter and the stated noise."""
    out = {}
    for f in range(setup.layout.n_files):
        ratios, keep = _file_ratios(setup, rows, f)
        stated = float(setup.sigmas[f]) if setup.sigma_known else 0.0
        if ratios is not None and keep.sum() >= MIN_BOUNCES:
            s, sigma = ratios.components(keep)
            out[f] = (max(s, SCATTER_FLOOR), sigma if setup.sigma_known else 0.0)
        else:
            out[f] = (TYPICAL_SCATTER, stated)
    return out


def ratio_transforms(setup, rows, scatter: dict | None = None) -> dict:
    """Every file's log-ratio rows of `RatioResiduals` (kept rows: not outliers, not below
    the file's constant-e speed range), as the evaluator's `transforms`.

    A last onset that follows an unheard bounce (its interval spans several flights of
    the ratio chain) is left out of the log-ratio rows: under restitution scatter the
    predicted onsets drift, the nearest-onset matching can pair it with the bounce it
    skipped, and nothing after it would show that. It stays in the data, the onset
    residuals and the plots. With a stated timing noise the fitted rows are whitened
    (`RatioResiduals`) with each file's (s, σ) in `scatter` (default: `closed_scatter`).
    """
    scatter = closed_scatter(setup, rows) if scatter is None else scatter
    transforms = {}
    for f in range(setup.layout.n_files):
        sl = rows.of_file(f)
        keep = ~rows.outlier[sl] & ~rows.slow[sl]
        kept = np.flatnonzero(keep)
        if len(kept) >= 4 and ratio_chain(setup.times[f][kept]).spans[-1] > 1:
            keep[kept[-1]] = False
        s, sigma = scatter[f]
        transforms[f] = RatioResiduals(
            times=setup.times[f],
            keep=keep,
            sigma=float(setup.sigmas[f]),
            timing=float(sigma) if setup.sigma_known else 0.0,
            scatter=float(s),
            whiten=~rows.holdout[sl],
        )
    return transforms


def refined_scatter(setup, point: Point, rows, transforms: dict) -> dict | None:
    """Each file's (s, σ) re-estimated from its log-ratio rows at `point` (REML, σ at most
    the stated noise), or None when none moves by more than 25% from what its rows were
    weighted with (then the fit stands)."""
    if not setup.sigma_known:
        return None
    r, _, _ = setup.with_evaluator(transforms={}, prior=False).evaluator(point.z)
    offsets = np.concatenate([[0], np.cumsum(setup.n_rows)])
    out, moved = {}, False
    for f, tr in transforms.items():
        rf = r[offsets[f] : offsets[f + 1]]
        raw, _ = dataclasses.replace(tr, timing=0.0)(rf, np.zeros((len(rf), 0)))
        mask = tr.keep & tr.whiten & rows.fitted[rows.of_file(f)]
        if mask.sum() < MIN_BOUNCES:
            out[f] = (tr.scatter, tr.timing)
            continue
        sens = tr.sensitivity()[np.searchsorted(np.flatnonzero(tr.keep), np.flatnonzero(mask))]
        none = np.zeros((int(mask.sum()), 0))
        s, sigma = reml_components(raw[mask], none, sens @ sens.T, float(setup.sigmas[f]))
        s = max(s, SCATTER_FLOOR)
        out[f] = (s, sigma)
        floor = 0.05 * float(setup.sigmas[f])  # a timing noise this small whitens nothing
        moved = (
            moved
            or abs(math.log(s / tr.scatter)) > math.log(1.25)
            or abs(math.log(max(sigma, floor) / max(tr.timing, floor))) > math.log(1.25)
        )
    return out if moved else None


def settle(setup, z, rows, opts) -> np.ndarray:
    """z with its nuisance entries (release, clock offset) fitted while the contact is held
    (loose LM): a start where the flights' own e holds while the release and the clock
    follow it. z itself where nothing else is free or the step fails."""
    contact = set(setup.layout.index[:, :2].ravel().tolist())
    free = [j for j in setup.free if j not in contact]
    if not free:
        return z
    out = lm(setup, z, row_weights(setup, rows), opts, dchi2=1e-2, free=free)
    return out.z if math.isfinite(out.cost) else z


def onset_point(setup, best: Point, onsets: Point) -> Point:
    """The onset residuals and Jacobian at the final point (for plots, rms and the χ² test)."""
    r, jac, _ = setup.with_evaluator(transforms={}, prior=False).evaluator(best.z)
    return dataclasses.replace(onsets, z=best.z, r=r, jac=jac)


def check_counts(setup, rows) -> None:
    """Refuse a fit with more free parameters than fitted data rows (or as many, when the
    noise is estimated from the residuals): its residuals vanish and its values would
    print as exact."""
    n, p = int(rows.fitted.sum()), len(setup.free)
    need = p if setup.sigma_known else p + 1
    if n < need:
        names = ", ".join(
            "/".join(str(x) for x in setup.layout.names()[j] if x is not None) for j in setup.free
        )
        raise InputError(
            f"data rows = {n} fitted against {p} free parameters ({names}); valid: at least {need} fitted rows "
            + ("(one more than the free parameters, since no noise is stated and it is estimated from the residuals)"
               if not setup.sigma_known else "(one per free parameter)")
            + ": give more data, or fit fewer parameters (--freeze)"
        )  # fmt: skip


class _NoBar:
    def update(self, n):
        pass

    def close(self):
        pass


def _progress(total: int, show: bool):
    if not show:
        return _NoBar()
    from tqdm.auto import tqdm

    return tqdm(total=total, desc="starts", unit="start", leave=False)
