"""`fit()`: κ and k_r (and nuisance parameters) from one or several data sets.

The stages (design notes with the measured reasons: `identify/README.md`):

1. **Set-up** (`identify._setup`): the joint vector (κ, k_r, drag shared; x0, v0,
   offset per file), one batched evaluator per group of files of one structure.
2. **Closed-form start**: e from successive rebound heights or drag-corrected flight
   times (`identify._initial`), t_c from the 0.5–2 ms prior, then (κ, k_r) from the
   law's inverse. Two-racket traces, which have no closed form, start from the best e
   on a grid. Further starts spread t_c over the prior and jitter e by 2%.
3. **Optional gradient stage** (`method="optax"`): the `optax.GradientTransformation`
   passed in (default `default_optimizer()`) minimizes ½Σr² with forward-mode (or
   reverse-mode) derivatives through the event mode, one jitted step per iteration.
4. **Levenberg–Marquardt** on z = (log κ, log k_r, …) with Marquardt scaling, bounds by
   projection and frozen parameters, on growing windows of each file (the first 35%,
   65%, then all of its span): a window that holds the first bounces pins the phase and
   each longer window starts next to its optimum.
5. **Robust pass** (`identify._robust`): Cauchy-weighted LM rounds, then rows beyond the
   outlier threshold are excluded and listed.
6. **Final pass**: least squares on the kept rows; impact onsets whose scatter no
   stated timing noise explains are refitted under the restitution-scatter error model
   (log ratios of successive flights).
7. **Summary** (`identify._summary`): Gauss–Newton covariance with honest noise,
   per-file tables, the per-file "alone" restitution, the hold-out prediction.

The Jacobian's columns are central differences of event-located runs (step 1e-4 in
log κ, log k_r, log k; scaled steps for x0, v0) inside the one compiled call; the time
offset of impact data only shifts the predictions, so its column is 1/σ in closed form
and takes no runs. Forward-mode AD through the event mode is exact too, but compiles
for several times longer than the whole differenced fit takes (design notes).
"""

from __future__ import annotations

import concurrent.futures
import dataclasses
import functools
import math
import os
import time

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
import optax

from jaxunilat.internal import check_choice, check_range

from . import _plausible as plausible
from ._import import ratio_chain
from ._initial import CONTACT_TIME_GUESS
from ._joint import Layout
from ._problem import LAWS, LOG_PARAMETERS, NUISANCE, PARAMETERS
from ._result import FitResult
from ._robust import (
    THRESHOLD,
    RatioResiduals,
    Rows,
    cauchy_weights,
    fitted_count,
    flag_outliers,
    robust_scale,
)
from ._setup import build, point_at, start_point, start_points
from ._summary import derived_quantities, summarize_fit
from ._uncertainty import Z95, covariance, goodness_of_fit

METHODS = ("lm", "optax")
#: Levenberg–Marquardt damping divisor after an accepted step. Along the κ–k_r ridge
#: (correlation ~0.99999) a slowly released damping crawls: with 3, each start of the
#: impacts fit took 12 accepted steps, each step ~3x the last; with 10 it takes 6.
_LAMBDA_DOWN = 10.0


def default_optimizer(learning_rate: float = 0.02) -> optax.GradientTransformation:
    """The default gradient stage: clip the update norm to 1, then Adam (on z, logs)."""
    return optax.chain(optax.clip_by_global_norm(1.0), optax.adam(learning_rate))


_DEFAULT_OPTIMIZER = default_optimizer()


def _load(data):
    from ._data import Dataset, load_dataset

    if isinstance(data, Dataset):
        return data
    if isinstance(data, (str, bytes)) or hasattr(data, "__fspath__"):
        return load_dataset(data)
    raise ValueError(f"data = {data!r} is not an identify.Dataset or a path to a data file")


def _newton_decrement(a, g, d):
    """½ gᵀA⁻¹g, the decrease of ½χ² at the Gauss–Newton step (A = JᵀJ, scaled by d)."""
    s = 1.0 / np.sqrt(d)
    try:
        step = s * np.linalg.lstsq(s[:, None] * a * s[None, :], s * g, rcond=1e-14)[0]
    except np.linalg.LinAlgError:
        return math.inf
    return 0.5 * float(g @ step)


def _levenberg_marquardt(evaluator, z, free, weights, lo, hi, *, max_iterations, dchi2=1e-6, xtol=1e-10):
    """Minimize ½Σ(w·r)² over z[free] within [lo, hi]. Returns (z, r, J, cost, iterations, converged, why).

    Converged when an accepted step lowers χ² = Σ(w·r)² by less than `dchi2` (in units
    of the reduced χ², so the step is far below one standard error), or moves z by
    less than `xtol`, or the scaled gradient vanishes, or before any trial run when
    even the Gauss–Newton step's predicted decrease of χ² (twice the Newton decrement
    ½gᵀ(JᵀJ)⁻¹g) is below that tolerance: at the optimum, trial steps only measure noise,
    and each costs a run of every row. Also converged when `_STALL_STEPS` accepted steps
    together lowered χ² by less than `_STALL_CHI2` reduced χ²: a creep along a flat
    valley (a contact time the data hardly see) that moves the estimate by well under
    one standard error.
    """
    r, jac, ok = evaluator(z)
    if not ok:
        return z, r, jac, math.inf, 0, False, "the simulation failed at the start point"
    cost = 0.5 * float(np.sum((weights * r) ** 2))
    lam = 1e-3
    history = [cost]
    for it in range(1, max_iterations + 1):
        jw = weights[:, None] * jac[:, [evaluator.free.index(i) for i in free]]
        g = jw.T @ (weights * r)
        a = jw.T @ jw
        d = np.maximum(np.diag(a), 1e-12 * max(float(np.max(np.diag(a))), 1e-300))
        if float(np.max(np.abs(g) / np.sqrt(d))) <= 1e-10 * max(math.sqrt(2 * cost), 1e-300):
            return z, r, jac, cost, it - 1, True, "gradient below tolerance"
        # The most any step can gain on the local quadratic model (the Gauss–Newton
        # decrement ½ gᵀA⁻¹g): below the χ² tolerance, no trial step is worth a run.
        reduced = 2.0 * cost / max(int(np.count_nonzero(weights)) - len(free), 1)
        if _newton_decrement(a, g, d) <= 0.5 * dchi2 * reduced:
            return z, r, jac, cost, it - 1, True, "predicted change below tolerance"
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
                lam = max(lam / _LAMBDA_DOWN, 1e-12)
                reduced = 2.0 * cost / max(int(np.count_nonzero(weights)) - len(free), 1)
                if (
                    moved <= xtol * (1.0 + float(np.max(np.abs(z[free]))))
                    or 2.0 * decrease <= dchi2 * reduced
                ):
                    return z, r, jac, cost, it, True, "relative change below tolerance"
                history.append(cost)
                if (
                    len(history) > _STALL_STEPS
                    and 2.0 * (history[-1 - _STALL_STEPS] - cost) <= _STALL_CHI2 * reduced
                ):
                    return z, r, jac, cost, it, True, f"chi-square stalled over {_STALL_STEPS} steps"
                break
            lam *= 4.0
            if lam > 1e12:
                return z, r, jac, cost, it, False, "no decrease found (damping at its limit)"
    return z, r, jac, cost, max_iterations, False, f"max_iterations = {max_iterations} reached"


#: The stall test of the LM: over this many accepted steps, a χ² decrease below this
#: many reduced χ² is convergence.
_STALL_STEPS, _STALL_CHI2 = 10, 0.1
_WINDOWS = (0.35, 0.65, 1.0)
GRADIENTS = ("forward", "reverse")


@dataclasses.dataclass
class _Options:
    """A fit's settings after validation (see `fit`)."""

    nuisance: tuple[str, ...]
    freeze: tuple[str, ...]
    starts: int
    seed: int
    method: str
    optimizer: optax.GradientTransformation
    steps: int
    max_iterations: int
    profile: bool
    rel_halfwidth: float
    progress: bool
    keep_outliers: bool
    threshold: float
    holdout: float
    gradient: str
    bounds: dict = dataclasses.field(default_factory=dict)
    tol: float = 1e-10
    alone_starts: bool = True
    defer_alone: bool = False  # leave each file's "alone" e to `_fill_alone` (law="auto")


@dataclasses.dataclass
class _Point:
    """Where a stage left the fit: the joint z, its residuals, Jacobian and cost."""

    z: np.ndarray
    r: np.ndarray
    jac: np.ndarray
    cost: float
    iterations: int
    converged: bool
    why: str
    gradient_steps: int = 0

    @classmethod
    def from_lm(cls, out, *, iterations: int = 0, gradient_steps: int = 0) -> _Point:
        z, r, jac, cost, it, converged, why = out
        return cls(z, r, jac, cost, iterations + it, converged, why, gradient_steps)

    def then(self, out) -> _Point:
        """The point a further LM stage `out` reached, its iterations added to these."""
        return _Point.from_lm(out, iterations=self.iterations, gradient_steps=self.gradient_steps)


def _load_all(data) -> list:
    if isinstance(data, (list, tuple)):
        if not data:
            raise ValueError("data = [] names no data set; give at least one data file")
        return [_load(d) for d in data]
    return [_load(data)]


def fit(
    data,
    *,
    nuisance: tuple[str, ...] = (),
    freeze: tuple[str, ...] = (),
    initial: dict[str, float] | None = None,
    bounds: dict[str, tuple[float, float]] | None = None,
    starts: int = 3,
    seed: int = 0,
    method: str = "lm",
    optimizer: optax.GradientTransformation | None = None,
    steps: int = 100,
    max_iterations: int = 60,
    tol: float = 1e-10,
    profile: bool = False,
    rel_halfwidth: float = 0.25,
    progress: bool = False,
    law: str = "kelvin-voigt",
    keep_outliers: bool = False,
    outlier_threshold: float = THRESHOLD,
    holdout: float = 0.0,
    gradient: str = "forward",
) -> FitResult:
    """Fit κ and k_r of the ball model [K90 Eq. 3.1–3.3] to one or several data sets.

    **Arguments:**

    - `data`: an `identify.Dataset` or a data file's path, or a list of them: a joint
      fit shares κ, k_r (and the drag, when fitted) and gives each file its own x0, v0
      and offset.
    - `nuisance`: extra parameters to fit, from `("drag", "x0", "v0", "offset")`;
      `offset` (the recording's unknown time origin, s) applies to impact onsets and to
      traces (a video rarely starts at the release), not to apex heights.
    - `freeze`: parameters held at their initial value, e.g. `("k_r",)`.
    - `initial`: starting values in SI units (kappa, k_r in the law's units, drag s/m,
      x0 m, v0 m/s, offset s); default: the closed-form guess and the files' values.
    - `bounds`: `{name: (lo, hi)}` in SI units; the fit stays inside (projection).
    - `starts`: the number of starts (≥ 1); the best final cost wins.
    - `seed`: the seed of the starts' jitter.
    - `method`: `"lm"` (Levenberg–Marquardt only) or `"optax"` (`steps` iterations of
      `optimizer` on ½Σr², then LM).
    - `optimizer`: an `optax.GradientTransformation`; default `default_optimizer()`.
    - `steps`: iterations of the gradient stage per start (`method="optax"`).
    - `max_iterations`: LM iterations per stage.
    - `tol`: the event mode's rtol = atol for every simulation.
    - `profile`: also compute the profile likelihood of κ (13 points, ±3 sd).
    - `rel_halfwidth`: the identifiability threshold (95% half-width / value).
    - `progress`: show a progress bar over the starts (on stderr).
    - `law`: `"kelvin-voigt"` (the paper's linear spring and damper), `"hunt-crossley"`
      (F = κδ^1.5 + k_r δ^1.5 δ̇: restitution falling with impact speed) or `"auto"`
      (fit both, report χ², AIC and BIC side by side, keep the lower BIC).
    - `keep_outliers`: skip the robust pass; every row is fitted by least squares.
    - `outlier_threshold`: rows beyond this many robust residual scales are excluded.
    - `holdout`: fit the first (1 − holdout) of each file's rows and predict the rest
      (0 ≤ holdout < 1).
    - `gradient`: the optax stage's gradient, `"forward"` (Jᵀr from forward-mode
      Jacobians through the event mode: a few solves for κ and k_r, and a quick
      compile) or `"reverse"` (`jax.grad`).

    **Returns:** a `FitResult` (`.report()`, `.to_json_dict()`, `.parameters`, …).
    """
    began = time.perf_counter()
    datasets = _load_all(data)
    _refuse_duplicates(datasets)
    originals = list(datasets)
    datasets, clocks = _shift_clocks(datasets)
    initial, bounds = _shift_offset_arguments(initial, bounds, clocks)
    nuisance, offset_note = _default_nuisance(datasets, tuple(nuisance), tuple(freeze))
    opts = _check_arguments(
        datasets, nuisance, freeze, starts, steps, max_iterations, tol, rel_halfwidth, optimizer, method,
        seed, profile, progress, keep_outliers, outlier_threshold, holdout, gradient,
    )  # fmt: skip
    check_choice("law", law, (*LAWS, "auto"))
    initial, bounds = _check_start(initial, bounds)
    opts = dataclasses.replace(opts, bounds=bounds, tol=tol)
    fitted = _fit_laws(datasets, LAWS if law == "auto" else (law,), opts, initial)
    results = {name: r for name, (r, _) in fitted.items()}
    common = np.logical_and.reduce([r.used for r in results.values()])
    comparison = {name: r.criteria(common) for name, r in results.items()}
    chosen = min(results, key=lambda n: comparison[n]["bic"])
    result, finish = fitted[chosen]
    if finish is not None:
        finish()
    result.laws = comparison
    result.law_choice = "auto (lowest BIC)" if law == "auto" else "given"
    if offset_note:
        result.notes.append(offset_note)
    plausible.apply(result)
    if any(clocks):
        _restore_clocks(result, originals, clocks)
    result.wall_s = time.perf_counter() - began
    return result


def _fit_laws(datasets, laws: tuple[str, ...], opts: _Options, initial: dict) -> dict:
    """Every law's `_fit_law` (result, finish), by law name.

    Several laws (`law="auto"`) are fitted side by side, each in its own thread: the
    fits share nothing but the data, and each law compiles its own program (the law is
    part of the model's structure), so one law's compilation and runs overlap the
    other's (the XLA compiler and the compiled runs release the GIL). The results do
    not depend on it: each fit runs exactly the stages it would run alone. Only the
    first law shows a progress bar. Each file's "alone" e (a batched refit) is left to the
    chosen law's `finish`: the other law's table is never reported.
    """
    defer = len(laws) > 1

    def one(name: str, progress: bool):
        setup = build(
            datasets, law=name, nuisance=opts.nuisance, freeze=opts.freeze, initial=initial,
            bounds=opts.bounds, tol=opts.tol,
        )  # fmt: skip
        return _fit_law(setup, dataclasses.replace(opts, progress=progress, defer_alone=defer))

    if len(laws) == 1:
        return {laws[0]: one(laws[0], opts.progress)}
    with concurrent.futures.ThreadPoolExecutor(
        max_workers=len(laws), thread_name_prefix="identify-law"
    ) as pool:
        futures = {name: pool.submit(one, name, opts.progress and k == 0) for k, name in enumerate(laws)}
        return {name: future.result() for name, future in futures.items()}


def _refuse_duplicates(datasets) -> None:
    """Refuse one data set given twice (the same file, or a copy: identical rows).

    Its rows would count twice and every interval would shrink by √2 with no new
    information."""
    seen = {}
    for f, d in enumerate(datasets):
        columns = tuple(None if c is None else np.asarray(c).tobytes() for c in (d.t, d.x, d.h))
        key = (d.observe, *columns)
        if key in seen:
            g = seen[key]
            raise ValueError(
                f"data = files {g + 1} and {f + 1} ({datasets[g].path or 'in memory'}, {d.path or 'in memory'}) "
                f"hold identical {d.observe} rows ({d.num_rows} rows): the same data given twice would "
                "count every row twice and shrink the intervals by sqrt(2); valid: each data set once"
            )
        seen[key] = f


#: Impact onsets whose first time lies beyond this many seconds are on an absolute clock
#: (e.g. Unix seconds, ~1.7e9 s): the fit runs on times relative to the first onset
#: (float64 keeps ~2e-7 s at 1.7e9 s, and the offset's bounds and tolerances are scaled
#: for recording clocks) and adds that reference back to the reported offset.
ABSOLUTE_CLOCK_S = 1e3


def _shift_clocks(datasets) -> tuple[list, list[float]]:
    """Impact files on an absolute clock, re-timed from their first onset; each file's shift (s)."""
    out, shifts = [], []
    for d in datasets:
        if d.observe == "impacts" and abs(float(d.t[0])) > ABSOLUTE_CLOCK_S:
            ref = float(d.t[0])
            out.append(dataclasses.replace(d, t=np.asarray(d.t) - ref))
            shifts.append(ref)
        else:
            out.append(d)
            shifts.append(0.0)
    return out, shifts


def _shift_offset_arguments(initial, bounds, clocks):
    """`initial`/`bounds` of the offset on the shifted clock (one shift: every file's)."""
    if not any(clocks) or not ({"offset"} & (set(initial or {}) | set(bounds or {}))):
        return initial, bounds
    if len(set(clocks)) > 1:
        raise ValueError(
            "initial/bounds for 'offset' with several files on different absolute clocks: one offset value "
            "cannot be given for all of them; valid: leave the offset's initial value and bounds out"
        )
    ref = clocks[0]
    initial = dict(initial or {})
    bounds = dict(bounds or {})
    if "offset" in initial:
        initial["offset"] = float(initial["offset"]) - ref
    if "offset" in bounds:
        lo, hi = bounds["offset"]
        bounds["offset"] = (float(lo) - ref, float(hi) - ref)
    return initial, bounds


def _restore_clocks(result, originals, clocks) -> None:
    """Report offsets on the files' own absolute clocks again (see `ABSOLUTE_CLOCK_S`)."""
    import jax.numpy as jnp

    from ._joint import Layout

    n = len(originals)
    layout = Layout(n_files=n)
    i_off = PARAMETERS.index("offset")
    if result.joint_z is not None and np.asarray(result.joint_z).size == layout.size:
        z = np.array(result.joint_z, dtype=float)
        for f, ref in enumerate(clocks):
            z[layout.index[f, i_off]] += ref
        result.joint_z = z
    result.z = np.array(result.z, dtype=float)
    result.z[i_off] += clocks[0]
    entry = result.parameters["offset"]
    result.parameters["offset"] = {
        **entry,
        "value": entry["value"] + clocks[0],
        "ci95": [v + clocks[0] for v in entry["ci95"]],
    }
    for f, ref in enumerate(clocks):
        if f < len(result.datasets):
            own = result.datasets[f]["parameters"].get("offset")
            if own is not None:
                own["value"] += ref
                own["ci95"] = [v + ref for v in own["ci95"]]
    result.data = originals[0]
    result.datasets_data = list(originals)
    if clocks[0]:
        problem = result.problem
        result.problem = eqx.tree_at(
            lambda p: (p.y_obs, p.t_obs),
            problem,
            (jnp.asarray(problem.y_obs) + clocks[0], jnp.asarray(problem.t_obs) + clocks[0]),
        )
    result.notes.append(
        "onsets on an absolute clock: fitted relative to each file's first onset, the offset reported on the file's "
        "own clock"
    )


def _default_nuisance(datasets, nuisance: tuple, freeze: tuple) -> tuple[tuple, str]:
    """`nuisance` with what the data determine and no recorder knows added by default.

    - The clock offset where a file holds impact onsets: no recorder knows the release
      instant (hold it with `freeze=("offset",)` when the onsets are timed from the release).
    - The release state x0, v0 of traces whose x0 is their own first sample (the video
      importer's default): held there, every estimate would follow that one sample's noise
      (κ from 13k to 56k N/m across noise seeds of a 1 mm trace, intervals excluding the
      truth); a trace determines both. Only when every file is a trace, and not for x0
      stated apart from the samples (the bundled trace: x0 = 0.305 m, first sample 0.304705 m).

    Returns the nuisance tuple and a note for the report ("" when nothing was added)."""
    notes = []
    if "offset" not in nuisance and "offset" not in freeze and any(d.observe == "impacts" for d in datasets):
        notes.append(
            "clock offset fitted (impact onsets: a recording does not know the release instant; "
            "hold it with --freeze offset, or freeze=('offset',) in Python, if the onsets are timed from the release)"
        )
        nuisance = (*nuisance, "offset")
    if all(_x0_from_sample(d) for d in datasets):
        added = tuple(n for n in ("x0", "v0") if n not in nuisance and n not in freeze)
        if added:
            nuisance = (*nuisance, *added)
            notes.append(
                f"{', '.join(added)} fitted: the file's x0 is its first sample's height, and one noisy sample "
                "must not pin the release (hold them with --freeze x0,v0, or freeze=('x0', 'v0') in Python)"
            )
    return nuisance, "; ".join(notes)


def _x0_from_sample(d) -> bool:
    """Whether a trace's x0 is its first sample's position at t = 0 (as `import video` writes it)."""
    return d.observe == "trace" and float(d.t[0]) == 0.0 and float(d.x[0]) == float(d.x0)


def _check_arguments(
    datasets, nuisance, freeze, starts, steps, max_iterations, tol, rel_halfwidth, optimizer, method,
    seed, profile, progress, keep_outliers, threshold, holdout, gradient,
) -> _Options:  # fmt: skip
    nuisance, freeze = tuple(nuisance), tuple(freeze)
    for name in nuisance:
        check_choice("nuisance", name, NUISANCE)
    for name in freeze:
        check_choice("freeze", name, PARAMETERS)
    if "offset" in nuisance:
        for d in datasets:
            if d.observe == "apex":
                raise ValueError(
                    "nuisance 'offset' (a time offset, s) applies to impact onsets and traces; "
                    f"{d.path or 'a data set'} has observe = 'apex'"
                )
    if set(freeze) >= {"kappa", "k_r"}:
        raise ValueError("freeze = ('kappa', 'k_r') leaves nothing to fit; free at least one of them")
    check_choice("method", method, METHODS)
    check_choice("gradient", gradient, GRADIENTS)
    for name, value, lo in (
        ("starts", starts, 1),
        ("steps", steps, 0),
        ("max_iterations", max_iterations, 1),
    ):
        if not isinstance(value, int) or isinstance(value, bool) or value < lo:
            raise ValueError(f"{name} = {value!r} is out of range; valid range is integers >= {lo}")
    check_range("tol", tol, lo=1e-14, hi=1e-4, unit="")
    check_range("rel_halfwidth", rel_halfwidth, lo=0.0, lo_open=True, unit="")
    check_range("outlier_threshold", threshold, lo=1.0, unit="robust sd")
    check_range("holdout", holdout, lo=0.0, hi=1.0, hi_open=True, unit="")
    if holdout > 0:
        for d in datasets:
            keep = fitted_count(d.num_rows, holdout)
            if keep < MIN_FITTED[d.observe] or keep == d.num_rows:
                raise ValueError(
                    f"holdout = {holdout!r} leaves {keep} of {d.num_rows} rows of {d.path or 'a data set'} to fit "
                    f"and {d.num_rows - keep} to predict; valid: at least {MIN_FITTED[d.observe]} to fit and 1 to predict"
                )
    if optimizer is not None and not isinstance(optimizer, optax.GradientTransformation):
        raise ValueError(f"optimizer = {optimizer!r} is not an optax.GradientTransformation")
    return _Options(
        nuisance, freeze, starts, seed, method, optimizer or _DEFAULT_OPTIMIZER, steps, max_iterations,
        bool(profile), float(rel_halfwidth), bool(progress), bool(keep_outliers), float(threshold),
        float(holdout), gradient,
    )  # fmt: skip


#: The fewest rows a fit may keep per file (the rest held out).
MIN_FITTED = {"trace": 3, "impacts": 3, "apex": 1}


def _check_start(initial, bounds):
    initial = dict(initial or {})
    for name, value in initial.items():
        check_choice("initial", name, PARAMETERS)
        check_range(f"initial[{name!r}]", value, lo=0.0 if name in LOG_PARAMETERS else None, lo_open=True)
    bounds = dict(bounds or {})
    for name, pair in bounds.items():
        check_choice("bounds", name, PARAMETERS)
        if len(pair) != 2 or not pair[0] < pair[1]:
            raise ValueError(f"bounds[{name!r}] = {pair!r} must be a pair (lo, hi) with lo < hi")
        if name in LOG_PARAMETERS and pair[0] <= 0:
            raise ValueError(f"bounds[{name!r}] = {pair!r}: {name} is positive; valid lower bounds are > 0")
    return initial, bounds


def _fit_law(setup, opts: _Options):
    """Every stage for one contact law: starts, windows, robust pass, final pass, summary.

    Returns the `FitResult` and `finish`: None, or (with `opts.defer_alone` and several
    files) the call that adds each file's "alone" e to it (`_fill_alone`)."""
    began = time.perf_counter()
    rows = Rows.make(setup.n_rows, opts.holdout)
    _check_counts(setup, rows)
    prior = setup.evaluator.prior
    with concurrent.futures.ThreadPoolExecutor(max_workers=1, thread_name_prefix="identify-warm") as pool:
        warming = _warm_evaluator(setup, pool)
        alone_starts = _alone_starts(setup, opts) if opts.alone_starts else []
        if warming is not None:
            warming.result()
        e0, e_source = _initial_restitution(setup, rows)
        candidates = start_points(setup, e0, opts.starts, np.random.default_rng(opts.seed))
    runs = _run_starts(setup, candidates, rows, opts)
    best = _windows_from(setup, min(runs, key=lambda run: run.cost), rows, opts)
    scale = None
    if not opts.keep_outliers:
        best, rows, scale = _robust_pass(setup, best, rows, opts)
    best = _final_pass(setup, best, rows, opts)
    restarts = []
    for f, z in alone_starts:
        # The same stages from file f's own solution, on the rows the main path kept: a
        # joint LM can stop on the long κ–k_r–t_c valley well above a point it can reach.
        setup.evaluator.prior = prior
        first = _Point.from_lm(_lm(setup, z, _weights(setup, rows, _windows(setup)[0]), opts, dchi2=1e-2))
        point = _final_pass(setup, _windows_from(setup, first, rows, opts), rows, opts)
        restarts.append((f, point.cost))
        if math.isfinite(point.cost) and point.cost < best.cost:
            best = dataclasses.replace(point, iterations=best.iterations + point.iterations)
    onsets = None
    if _scatter_model_applies(setup, best, rows):
        onsets = best
        _use_ratio_residuals(setup, rows)
        setup.evaluator.prior = bool(set(setup.layout.index[0, :2]) <= set(setup.free))
        best = _final_pass(setup, best, rows, opts)
        onsets = _onset_point(setup, best, onsets)
    initial = dict(restitution=e0, contact_time=CONTACT_TIME_GUESS, source=e_source)
    result = summarize_fit(
        setup, best, rows, opts, runs=runs, initial=initial, robust_scale=scale, onsets=onsets
    )
    if restarts:
        names = [d.path or f"data set {f + 1}" for f, d in enumerate(setup.datasets)]
        result.notes.append(
            "joint fit also started from each file's own solution (fitted alone, one start); final chi-square "
            "over all fitted rows of this fit: "
            + ", ".join(f"from {os.path.basename(names[f])}: {2 * c:.6g}" for f, c in restarts)
        )
    if opts.profile and setup.layout.index[0, 0] in setup.free:
        result.profile = _profile_kappa(setup, best, rows, result, opts)
        _check_profile_minimum(result, best, setup)
    result.wall_s = time.perf_counter() - began
    finish = None
    if opts.defer_alone and setup.layout.n_files > 1:
        finish = functools.partial(_fill_alone, result, setup, best, rows, opts)
    return result, finish


def _fill_alone(result: FitResult, setup, best: _Point, rows, opts) -> None:
    """Each file's "alone" e into `result.datasets` (deferred by `opts.defer_alone`)."""
    before = setup.evaluator.calls
    for entry, alone in zip(result.datasets, alone_restitution(setup, best, rows, opts), strict=True):
        entry["restitution_alone"] = alone
    result.simulations += setup.evaluator.calls - before


def _warm_evaluator(setup, pool) -> concurrent.futures.Future | None:
    """Hunt–Crossley: compile the fit's program in `pool` while the start is computed.

    Hunt–Crossley's start points simulate single impacts (`hunt_crossley_from_restitution`,
    a compiled program of its own), and so does its "alone" fit of a few files: the
    fit's program compiles meanwhile, by one run at the closed-form start (`refine=0`:
    nothing simulated), with the shapes of every later call. Kelvin–Voigt's start is in
    closed form: nothing to overlap (None).
    """
    if setup.law != "hunt-crossley":
        return None
    from ._restitution import hunt_crossley_from_restitution

    e = setup.e0 if setup.e0 is not None else 0.8
    mass = float(setup.datasets[0].mass)
    kappa, k_r = hunt_crossley_from_restitution(e, CONTACT_TIME_GUESS, mass, setup.speed, refine=0)
    return pool.submit(setup.evaluator.warm, point_at(setup, kappa, k_r))


def _windows_from(setup, point: _Point, rows, opts) -> _Point:
    """The growing windows after the first, from `point` (loose LM on each)."""
    for fraction in _windows(setup)[1:]:
        point = point.then(_lm(setup, point.z, _weights(setup, rows, fraction), opts, dchi2=1e-2))
    return point


def _check_counts(setup, rows) -> None:
    """Refuse a fit with more free parameters than fitted data rows (or as many, when the
    noise is estimated from the residuals): its residuals vanish and its values would
    print as exact."""
    n, p = int(rows.fitted.sum()), len(setup.free)
    need = p if setup.sigma_known else p + 1
    if n < need:
        names = ", ".join(
            "/".join(str(x) for x in setup.layout.names()[j] if x is not None) for j in setup.free
        )
        raise ValueError(
            f"data rows = {n} fitted against {p} free parameters ({names}); valid: at least {need} fitted rows "
            + ("(one more than the free parameters, since no noise is stated and it is estimated from the residuals)"
               if not setup.sigma_known else "(one per free parameter)")
            + ": give more data, or fit fewer parameters (--freeze)"
        )  # fmt: skip


#: Joint fits of at most this many files also start from each file's own solution (one
#: alone fit per file: one compilation and a one-start fit each, seconds per file).
MAX_ALONE_STARTS = 4


def _alone_starts(setup, opts) -> list[tuple[int, np.ndarray]]:
    """Joint start points from each file fitted alone (one start, no robust pass):
    κ, k_r (and drag) from file f's own optimum, every file's x0, v0 and offset from its own."""
    n = setup.layout.n_files
    if n < 2 or n > MAX_ALONE_STARTS:
        return []
    alone = dataclasses.replace(
        opts, starts=1, method="lm", alone_starts=False, profile=False, progress=False
    )
    own = []
    for d in setup.datasets:
        one = build(
            [d], law=setup.law, nuisance=opts.nuisance, freeze=opts.freeze, initial=setup.initial,
            bounds=opts.bounds, tol=opts.tol,
        )  # fmt: skip
        rows = Rows.make(one.n_rows, opts.holdout)
        e0, _ = _initial_restitution(one, rows)
        runs = _run_starts(one, start_points(one, e0, 1, np.random.default_rng(opts.seed)), rows, alone)
        point = _final_pass(one, _windows_from(one, runs[0], rows, alone), rows, alone)
        setup.evaluator.calls += one.evaluator.calls
        own.append(np.asarray(point.z) if math.isfinite(point.cost) else None)
    if any(z is None for z in own):
        return []
    out = []
    for f in range(n):
        z = setup.layout.join(own)
        shared = [PARAMETERS.index(name) for name in setup.layout.shared]
        z[setup.layout.index[0, shared]] = own[f][shared]
        out.append((f, np.clip(z, setup.lo, setup.hi)))
    return out


#: A profile point this many χ² units below the fit's own χ² means the fit is not at its
#: minimum (the LM's stall test counts 0.1 reduced χ² over ten steps as flat).
PROFILE_SLACK = 0.1


def _check_profile_minimum(result, best: _Point, setup) -> None:
    """A profile that finds a lower χ² than the fit: the fit is not at its minimum."""
    prof = result.profile
    s2 = (result.sigma / float(setup.sigmas[0])) ** 2
    costs = prof.get("costs")
    if costs is None:
        return
    finite = costs[np.isfinite(costs)]
    if finite.size == 0:
        return
    lower = 2.0 * (best.cost - float(np.min(finite))) / s2
    prof["below_fit"] = float(max(lower, 0.0))
    if lower > PROFILE_SLACK:
        k = float(prof["kappa"][int(np.argmin(np.where(np.isfinite(costs), costs, np.inf)))])
        result.converged = False
        result.identifiable = {name: False for name in result.identifiable}
        result.message = (
            f"the profile of kappa found a chi-square {lower:.3g} below the fit's at kappa = {k:.6g}: "
            "the fit stopped short of its minimum"
        )


def _scatter_model_applies(setup, best: _Point, rows) -> bool:
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


def _use_ratio_residuals(setup, rows) -> None:
    """Switch every file to the log-ratio rows of `RatioResiduals` (kept rows: not outliers).

    A last onset that follows an unheard bounce (its interval spans several flights of
    the ratio chain) is left out of the log-ratio rows: under restitution scatter the
    predicted onsets drift, the nearest-onset matching can pair it with the bounce it
    skipped, and nothing after it would show that. It stays in the data, the onset
    residuals and the plots.
    """
    ev = setup.evaluator
    ev.transforms = {}
    for f in range(setup.layout.n_files):
        keep = ~rows.outlier[rows.of_file(f)]
        kept = np.flatnonzero(keep)
        if len(kept) >= 4 and ratio_chain(setup.times[f][kept]).spans[-1] > 1:
            keep[kept[-1]] = False
        ev.transforms[f] = RatioResiduals(times=setup.times[f], keep=keep, sigma=float(setup.sigmas[f]))


def _onset_point(setup, best: _Point, onsets: _Point) -> _Point:
    """The onset residuals and Jacobian at the final point (for plots, rms and the χ² test)."""
    ev = setup.evaluator
    transforms, prior = ev.transforms, ev.prior
    ev.transforms, ev.prior = {}, False
    try:
        r, jac, _ = ev(best.z)
    finally:
        ev.transforms, ev.prior = transforms, prior
    return dataclasses.replace(onsets, z=best.z, r=r, jac=jac)


def _initial_restitution(setup, rows) -> tuple[float, str]:
    if setup.e0 is not None:
        return setup.e0, setup.e_source
    # No closed form (two-racket traces): the best e on a grid, at the prior's t_c.
    ev = setup.evaluator
    grid = np.linspace(0.3, 0.98, ev.rows)
    w = _weights(setup, rows, _WINDOWS[0])
    costs = [
        np.sum((w * r) ** 2) if ok else np.inf
        for r, ok in ev.values([start_point(setup, e, CONTACT_TIME_GUESS) for e in grid])
    ]
    return float(grid[int(np.argmin(costs))]), "grid search (no closed form for this scene)"


def _windows(setup) -> tuple[float, ...]:
    """Growing windows for traces and for onset sequences (apex heights: all at once)."""
    return _WINDOWS if any(d.observe in ("trace", "impacts") for d in setup.datasets) else (1.0,)


def _weights(setup, rows, fraction: float = 1.0, robust: np.ndarray | None = None) -> np.ndarray:
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


def _lm(setup, z, weights, opts, *, dchi2=1e-6, free=None):
    return _levenberg_marquardt(
        setup.evaluator,
        z,
        setup.free if free is None else free,
        weights,
        setup.lo,
        setup.hi,
        max_iterations=opts.max_iterations,
        dchi2=dchi2,
    )


def _run_starts(setup, candidates, rows, opts) -> list[_Point]:
    """Every start on the first window, loosely (it only has to find the basin)."""
    step_fn = _gradient_step(opts.optimizer, opts.gradient) if opts.method == "optax" else None
    runs = []
    bar = _progress(len(candidates), opts.progress)
    for z in candidates:
        z, gradient_steps = z.copy(), 0
        if step_fn is not None and opts.steps > 0:
            z, gradient_steps = _run_gradient_stage(step_fn, opts, setup, rows, z)
        out = _lm(setup, z, _weights(setup, rows, _windows(setup)[0]), opts, dchi2=1e-2)
        runs.append(_Point.from_lm(out, gradient_steps=gradient_steps))
        bar.update(1)
    bar.close()
    return runs


#: The robust pass excludes at most this fraction of a fit's rows; beyond it the model,
#: not a few rows, is what misfits, and nothing is excluded.
MAX_OUTLIER_FRACTION = 0.2


def _robust_pass(setup, best: _Point, rows, opts):
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
        w = _weights(setup, rows, robust=cauchy_weights(point.r[:n], scale))
        point = point.then(_lm(setup, point.z, w, opts, dchi2=1e-2))
        scale = robust_scale(point.r[:n], rows.fitted, floor=floor)
    outlier = flag_outliers(point.r[:n], rows, scale, opts.threshold)
    if outlier.sum() > MAX_OUTLIER_FRACTION * (~rows.holdout).sum():
        return best, rows, scale
    rows = dataclasses.replace(rows, outlier=outlier)
    kept = rows.fitted

    def kept_cost(p):
        return float(np.sum(p.r[:n][kept] ** 2)) if math.isfinite(p.cost) else math.inf

    return (point if kept_cost(point) <= kept_cost(best) else best), rows, scale


def _final_pass(setup, best: _Point, rows, opts) -> _Point:
    """One tight pass on all fitted rows.

    The steering prior only holds the path where the data say nothing: the tight pass
    drops it when the data determine t_c themselves, and the uncertainty never uses it.
    """
    ev = setup.evaluator
    z = best.z
    use_prior = False
    if ev.prior:
        ev.prior = False
        r_data, jac_data, _ = ev(z)
        keep = rows.fitted
        cov_tc, _ = covariance(jac_data[keep], r_data[keep], sigma_known=setup.sigma_known)
        derived = derived_quantities(setup, z, cov_tc)
        t_c = derived["contact_time"]
        use_prior = not t_c["stderr"] < 0.1 * t_c["value"]  # sd(log t_c) < 0.1
        ev.prior = use_prior
    # The tight pass may have to follow the long κ–k_r–t_c valley of a joint fit: it
    # gets four times the iterations of the loose stages.
    longer = dataclasses.replace(opts, max_iterations=4 * opts.max_iterations)
    point = best.then(_lm(setup, z, _weights(setup, rows), longer))
    if use_prior:
        ev.prior = False
        r, jac, _ = ev(point.z)
        point = dataclasses.replace(point, r=r, jac=jac, cost=0.5 * float(np.sum((rows.fitted * r) ** 2)))
    return point


def alone_restitution(setup, best: _Point, rows, opts) -> list[dict]:
    """Each file's own restitution when fitted alone (its own κ and k_r).

    One batched LM from the joint optimum over a layout where κ and k_r are per file
    (the drag held at the joint value, the steering prior on each file's t_c): the
    files stay in one compiled call. Returns each file's `{"value", "stderr", "ci95"}`.
    """
    layout = Layout(
        n_files=setup.layout.n_files, shared=("drag",), local=("kappa", "k_r", "x0", "v0", "offset")
    )
    joint_of = [
        int(setup.layout.index[f, PARAMETERS.index(n)]) for n, f in ((n, f or 0) for n, f in layout.names())
    ]
    free = [
        j
        for j, (name, _) in enumerate(layout.names())
        if (name in ("kappa", "k_r") or name in opts.nuisance) and name not in opts.freeze and name != "drag"
    ]
    ev = dataclasses.replace(
        setup.evaluator, layout=layout, free=free, steps=setup.evaluator.steps[joint_of], prior=True, calls=0
    )
    alone = dataclasses.replace(
        setup, layout=layout, evaluator=ev, free=free, lo=setup.lo[joint_of], hi=setup.hi[joint_of]
    )
    z = layout.join(list(setup.layout.split(best.z)))
    point = _Point.from_lm(_lm(alone, z, _weights(alone, rows), opts, dchi2=1e-2))
    setup.evaluator.calls += ev.calls
    return [
        derived_quantities(alone, point.z, _alone_covariance(alone, point, rows, f), f=f)["restitution"]
        for f in range(layout.n_files)
    ]


def _alone_covariance(alone, point: _Point, rows, f: int) -> np.ndarray:
    """File f's block of the "alone" covariance, from its own rows only.

    The files share nothing in the alone layout (the drag is held), so each file's
    uncertainty comes from its own residual scatter, as a fit of that file alone would
    give it, not from the scatter pooled over every file. The block keeps the file's
    prior row: one drop alone hardly separates t_c from the release height and the
    clock, and e must not inherit that null direction.
    """
    ev = alone.evaluator
    n_data = len(rows.fitted)
    own = np.arange(n_data)[rows.of_file(f)][rows.fitted[rows.of_file(f)]]
    prior = [n_data + k for k, (pf, _, _) in enumerate(ev._prior_pairs()) if pf == f]
    idx = np.concatenate([own, prior]).astype(int)
    entries = set(int(j) for j in alone.layout.index[f])
    cols = [k for k, j in enumerate(ev.free) if j in entries]
    block, _ = covariance(point.jac[np.ix_(idx, cols)], point.r[idx], sigma_known=alone.sigma_known)
    cov = np.zeros((len(ev.free), len(ev.free)))
    cov[np.ix_(cols, cols)] = block
    return cov


def _profile_kappa(setup, best, rows, result, opts, points: int = 13):
    """χ²(κ) with the other free parameters re-optimized: the profile likelihood of κ.

    Returns the grid, Δχ² = 2(cost − cost_min)/s², the 95% interval where Δχ² ≤ 3.84
    (the χ²₁ quantile, found by linear interpolation on the grid), and the grid points
    whose re-optimization failed (`failed`: never taken as excluded; an interval edge
    next to one is reported as unknown, None).
    """
    ev = setup.evaluator
    i_kappa = int(setup.layout.index[0, 0])
    sd = result.parameters["kappa"]["stderr"] / max(result.kappa, 1e-300)
    sd = sd if math.isfinite(sd) else 5.0
    half = min(3.0 * max(sd, 1e-4), 5.0)
    grid = best.z[i_kappa] + np.linspace(-half, half, points)
    others = [j for j in setup.free if j != i_kappa]
    costs = np.full(points, np.inf)
    failed = np.zeros(points, bool)
    centre = points // 2
    weights = _weights(setup, rows)
    for order in (range(centre, points), range(centre, -1, -1)):
        z = best.z.copy()
        for k in order:
            z[i_kappa] = grid[k]
            if others:
                z, _, _, cost, _, converged, _ = _lm(setup, z, weights, opts, free=others)
                failed[k] = not (converged and math.isfinite(cost))
            else:
                r, _, ok = ev(z)
                cost = 0.5 * float(np.sum((weights * r) ** 2)) if ok else math.inf
                failed[k] = not ok
            costs[k] = cost
    s2 = (result.sigma / float(setup.sigmas[0])) ** 2
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
    return dict(
        kappa=np.exp(grid),
        delta_chi2=delta,
        costs=costs,
        failed=[float(math.exp(g)) for g, bad in zip(grid, failed, strict=True) if bad],
        ci95=[
            (0.0 if ci[0] == -math.inf else math.exp(ci[0])) if not math.isnan(ci[0]) else math.nan,
            math.exp(ci[1]) if not math.isnan(ci[1]) else math.nan,
        ],
    )


@functools.lru_cache(maxsize=8)
def _gradient_step(optimizer, gradient: str):
    """One jitted optax step on ½Σ(w·r)² over every file (cached per optimizer and mode:
    a new jitted step for every fit would recompile the pass through the event mode).

    `gradient="forward"`: each file's Jacobian by `jax.jacfwd` through the event mode in
    forward mode (`autodiff="forward"`, six tangents per file), then g = Jᵀ(w²r);
    `"reverse"`: `jax.grad` of the loss.
    """

    def file_gradient(problem, z6, w):
        if gradient == "forward":
            residuals = lambda z: problem.residuals(z)[0]  # noqa: E731
            r, jac = residuals(z6), jax.jacfwd(residuals)(z6)
            return 0.5 * jnp.sum((w * r) ** 2), jac.T @ (w**2 * r)
        loss = lambda z: 0.5 * jnp.sum((w * problem.residuals(z)[0]) ** 2)  # noqa: E731
        return jax.value_and_grad(loss)(z6)

    @eqx.filter_jit
    def step(problems, indices, weights, z, opt_state, mask):
        value, grad = jnp.zeros(()), jnp.zeros_like(z)
        for problem, index, w in zip(problems, indices, weights, strict=True):
            values, grads = jax.lax.map(lambda args: file_gradient(*args), (problem, z[index], w))
            value = value + jnp.sum(values)
            grad = grad.at[index].add(grads)
        grad = jnp.where(mask, grad, 0.0)
        updates, opt_state = optimizer.update(grad, opt_state, z)
        return optax.apply_updates(z, jnp.where(mask, updates, 0.0)), opt_state, value

    return step


def _run_gradient_stage(step, opts, setup, rows, z):
    """`opts.steps` optax iterations from z; returns the best point seen and the count."""
    mode = "forward" if opts.gradient == "forward" else "reverse"
    problems, indices, weights = [], [], []
    w_rows = _weights(setup, rows, _windows(setup)[0])
    for g in setup.evaluator.groups:
        problems.append(dataclasses.replace(g.problem, autodiff=mode))
        indices.append(jnp.asarray(setup.layout.index[g.files]))
        n_pad = int(np.asarray(g.problem.t_obs).shape[-1])
        w = np.zeros((len(g.files), n_pad))
        for k, f in enumerate(g.files):
            w[k, : g.rows[k]] = w_rows[rows.of_file(f)]
        weights.append(jnp.asarray(w))
    mask = np.zeros(setup.layout.size, bool)
    mask[setup.free] = True
    zj, opt_state = jnp.asarray(z), opts.optimizer.init(jnp.asarray(z))
    best, best_value = np.asarray(zj), math.inf
    for _ in range(opts.steps):
        new, opt_state, value = step(problems, indices, weights, zj, opt_state, jnp.asarray(mask))
        value = float(value)
        if value < best_value:
            best, best_value = np.asarray(zj), value
        zj = jnp.clip(new, setup.lo, setup.hi)
    return best.copy(), opts.steps


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
