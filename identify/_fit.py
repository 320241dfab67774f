"""`fit()`: κ and k_r (and optional nuisance parameters) from one data set.

The pipeline (SPEC §5):

1. **Closed-form start.** e from successive rebound heights or flight times
   (`identify._initial`), t_c from the 0.5–2 ms prior, then (κ, k_r) from the
   Kelvin–Voigt inverse. Two-racket traces, which have no closed form, start from the
   best e on a grid.
2. **Multi-start.** The first start is the closed form; the others spread t_c over
   the prior (log-uniform) and jitter e by 2%.
3. **Optional gradient stage** (`method="optax"`): the `optax.GradientTransformation`
   passed in (default `default_optimizer()`) minimizes ½Σr² with reverse-mode
   gradients through the event mode (correct through impacts), one jitted step per
   iteration.
4. **Levenberg–Marquardt** on z = (log κ, log k_r, …) with Marquardt scaling, bounds
   by projection and frozen parameters. Long traces are fitted on growing windows
   (the first 35%, 65%, then all of the trace): Adam or LM on a raw 2 s trace from a
   2× wrong start goes out of phase (SPEC §5), while a window that holds the first
   bounces pins the phase and each longer window starts next to its optimum.

The Jacobian's columns are central differences of the event-located solution (step
1e-4 in log κ, log k_r, log k; scaled steps for x0, v0), one compiled map over the
2p + 1 runs; the time offset of impact data only shifts the predictions, so its column
is 1/σ in closed form and takes no runs. The event mode has no forward-mode AD, and its reverse mode would
need one backward pass per residual (2500 for a 2.5 s, 1 kHz trace): central
differences of runs whose events are located to machine precision are accurate to
about 1e-6 relative here, and cost 2p + 1 forward runs.
"""

from __future__ import annotations

import dataclasses
import functools
import math
import time

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
import optax

from jaxunilat._validate import check_choice, check_range

from ._initial import CONTACT_TIME_GUESS, CONTACT_TIME_PRIOR, first_impact_time, initial_restitution
from ._kelvin_voigt import parameters_from_restitution
from ._problem import LOG_PARAMETERS, NUISANCE, PARAMETERS, Problem, evaluate_rows, make_problem, to_z
from ._result import FitResult
from ._uncertainty import Z95, covariance, goodness_of_fit, summarize

METHODS = ("lm", "optax")
_WINDOWS = (0.35, 0.65, 1.0)
#: Levenberg–Marquardt damping divisor after an accepted step. Along the κ–k_r ridge
#: (correlation ~0.99999) a slowly released damping crawls: with 3, each start of the
#: impacts fit took 12 accepted steps, each step ~3x the last; with 10 it takes 6.
_LAMBDA_DOWN = 10.0
#: sd of log t_c in the steering prior: the 0.5–2 ms prior as ±2 sd around 1 ms.
_PRIOR_SD = math.log(2.0) / 2.0
_FD_STEP = {"kappa": 1e-4, "k_r": 1e-4, "drag": 1e-4, "x0": 1e-6, "v0": 1e-5, "offset": 1e-6}
_DEFAULT_BOUNDS = {
    "kappa": (1.0, 1e12),
    "k_r": (1e-12, 1e4),
    "drag": (1e-6, 10.0),
    "x0": (-1e3, 1e3),
    "v0": (-1e3, 1e3),
    "offset": (-1e4, 1e4),
}


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


#: Parameters that shift every prediction by their own value (impact onsets + offset):
#: their Jacobian column is 1/σ exactly, so they take no runs.
_SHIFTS = ("offset",)


@dataclasses.dataclass
class _Evaluator:
    """r and J at a point: one compiled map over the point and its neighbours.

    A parameter in `_SHIFTS` gets its column in closed form; every other free one
    gets a central difference (2 runs).
    """

    problem: Problem
    free: list[int]
    steps: np.ndarray
    mass: float
    prior: bool = True
    calls: int = 0

    @property
    def differenced(self) -> list[int]:
        """The free parameters whose columns are central differences."""
        return [i for i in self.free if PARAMETERS[i] not in _SHIFTS]

    @property
    def rows(self) -> int:
        """Runs per compiled call: the point and two neighbours per differenced parameter."""
        return 2 * len(self.differenced) + 1

    def _prior(self, zs):
        """The steering prior's residual: (log t_c − log t_c,prior)/sd, per row of zs."""
        kappa, k_r = np.exp(zs[:, 0]), np.exp(zs[:, 1])
        omega2 = kappa / self.mass - (k_r / (2 * self.mass)) ** 2
        t_c = np.pi / np.sqrt(np.maximum(omega2, 1e-300))
        return (np.log(t_c) - math.log(CONTACT_TIME_GUESS)) / _PRIOR_SD

    def __call__(self, z):
        fd = self.differenced
        p = len(fd)
        h = np.zeros((self.rows, len(PARAMETERS)))
        h[1 + np.arange(p), fd] = self.steps[fd]
        h[1 + p + np.arange(p), fd] = -self.steps[fd]
        zs = z[None, :] + h
        res, ok = evaluate_rows(self.problem, jax.device_put(zs))
        res, ok = np.asarray(res), np.asarray(ok)
        n_data = res.shape[1]
        if self.prior:
            res = np.concatenate([res, self._prior(zs)[:, None]], axis=1)
        self.calls += 1
        jac = np.zeros((res.shape[1], len(self.free)))
        jac[:, [self.free.index(i) for i in fd]] = (res[1 : 1 + p] - res[1 + p :]).T / (2 * self.steps[fd])
        # A shift: r = (prediction + value − data)/σ, so ∂r/∂value = 1/σ on the data rows.
        shifts = [j for j, i in enumerate(self.free) if i not in fd]
        jac[:n_data, shifts] = (1.0 / np.broadcast_to(np.asarray(self.problem.sigma), (n_data,)))[:, None]
        return res[0], jac, bool(ok[0] and np.all(ok))

    def values(self, zs):
        """Residuals at several points (padded to the compiled row count)."""
        rows = self.rows
        out = []
        for k in range(0, len(zs), rows):
            chunk = np.asarray(zs[k : k + rows])
            pad = np.concatenate([chunk, np.repeat(chunk[-1:], rows - len(chunk), axis=0)])
            res, ok = evaluate_rows(self.problem, jax.device_put(pad))
            res, ok = np.asarray(res), np.asarray(ok)
            if self.prior:
                res = np.concatenate([res, self._prior(pad)[:, None]], axis=1)
            out += [(res[i], bool(ok[i])) for i in range(len(chunk))]
        return out


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
    and each costs a run of every row.
    """
    r, jac, ok = evaluator(z)
    if not ok:
        return z, r, jac, math.inf, 0, False, "the simulation failed at the start point"
    cost = 0.5 * float(np.sum((weights * r) ** 2))
    lam = 1e-3
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
                break
            lam *= 4.0
            if lam > 1e12:
                return z, r, jac, cost, it, False, "no decrease found (damping at its limit)"
    return z, r, jac, cost, max_iterations, False, f"max_iterations = {max_iterations} reached"


def _window_weights(problem: Problem, fraction: float, prior: bool = True) -> np.ndarray:
    """Weights of the data rows (1 inside the window), plus the prior's row when used."""
    t = np.asarray(problem.t_obs)
    if problem.observe != "trace" or fraction >= 1.0:
        w = np.ones_like(t)
    else:
        w = (t <= t[0] + fraction * (t[-1] - t[0])).astype(float)
    return np.concatenate([w, [1.0]]) if prior else w


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
) -> FitResult:
    """Fit κ and k_r of the Kelvin–Voigt ball model [K90 Eq. 3.1–3.3] to one data set.

    **Arguments:**

    - `data`: an `identify.Dataset` or the path of a data file (`identify.load_dataset`).
    - `nuisance`: extra parameters to fit, from `("drag", "x0", "v0", "offset")`;
      `offset` (the recording's unknown time origin, s) applies to impact data only.
    - `freeze`: parameters held at their initial value, e.g. `("k_r",)`.
    - `initial`: starting values in SI units (kappa N/m, k_r N·s/m, drag s/m, x0 m,
      v0 m/s, offset s); default: the closed-form guess and the file's values.
    - `bounds`: `{name: (lo, hi)}` in SI units; the fit stays inside (projection).
    - `starts`: the number of starts (≥ 1); the best final cost wins.
    - `seed`: the seed of the starts' jitter.
    - `method`: `"lm"` (Levenberg–Marquardt only) or `"optax"` (`steps` iterations of
      `optimizer` with reverse-mode gradients through the event mode, then LM).
    - `optimizer`: an `optax.GradientTransformation`; default `default_optimizer()`.
    - `steps`: iterations of the gradient stage per start (`method="optax"`).
    - `max_iterations`: LM iterations per window.
    - `tol`: the event mode's rtol = atol for every simulation.
    - `profile`: also compute the profile likelihood of κ (13 points, ±3 sd).
    - `rel_halfwidth`: the identifiability threshold (95% half-width / value).
    - `progress`: show a progress bar over the starts (on stderr).

    **Returns:** a `FitResult` (`.report()`, `.to_json_dict()`, `.parameters`, …).
    """
    began = time.perf_counter()
    data = _load(data)
    nuisance = tuple(nuisance)
    freeze = tuple(freeze)
    for name in nuisance:
        check_choice("nuisance", name, NUISANCE)
    for name in freeze:
        check_choice("freeze", name, PARAMETERS)
    if "offset" in nuisance and data.observe != "impacts":
        raise ValueError(
            f"nuisance 'offset' (a time offset, s) applies to impact data only; this data set has "
            f"observe = {data.observe!r}"
        )
    if set(freeze) >= {"kappa", "k_r"}:
        raise ValueError("freeze = ('kappa', 'k_r') leaves nothing to fit; free at least one of them")
    check_choice("method", method, METHODS)
    if not isinstance(starts, int) or starts < 1:
        raise ValueError(f"starts = {starts!r} is out of range; valid range is integers >= 1")
    if not isinstance(steps, int) or steps < 0:
        raise ValueError(f"steps = {steps!r} is out of range; valid range is integers >= 0")
    if not isinstance(max_iterations, int) or max_iterations < 1:
        raise ValueError(f"max_iterations = {max_iterations!r} is out of range; valid range is integers >= 1")
    check_range("tol", tol, lo=1e-14, hi=1e-4, unit="")
    check_range("rel_halfwidth", rel_halfwidth, lo=0.0, lo_open=True, unit="")
    if optimizer is not None and not isinstance(optimizer, optax.GradientTransformation):
        raise ValueError(f"optimizer = {optimizer!r} is not an optax.GradientTransformation")
    initial = dict(initial or {})
    for name, value in initial.items():
        check_choice("initial", name, PARAMETERS)
        check_range(f"initial[{name!r}]", value, lo=0.0 if name in LOG_PARAMETERS else None, lo_open=True)
    bounds = {**_DEFAULT_BOUNDS, **(bounds or {})}
    for name, pair in bounds.items():
        check_choice("bounds", name, PARAMETERS)
        if len(pair) != 2 or not pair[0] < pair[1]:
            raise ValueError(f"bounds[{name!r}] = {pair!r} must be a pair (lo, hi) with lo < hi")
        if name in LOG_PARAMETERS and pair[0] <= 0:
            raise ValueError(f"bounds[{name!r}] = {pair!r}: {name} is positive; valid lower bounds are > 0")

    mass, gravity = float(data.mass), float(data.gravity)
    has_drag = data.drag > 0 or "drag" in nuisance
    sigma_known = data.noise is not None
    sigma = float(data.noise) if sigma_known else 1.0

    # -- the closed-form start --------------------------------------------------------
    e0 = initial_restitution(data)
    values = dict(
        drag=initial.get("drag", data.drag if data.drag > 0 else 0.12),
        x0=initial.get("x0", data.x0),
        v0=initial.get("v0", data.v0),
        offset=initial.get("offset", 0.0),
    )
    horizon = None
    if data.observe == "impacts":
        fall = first_impact_time(data.x0, data.v0, gravity) if data.scene == "drop" else 0.0
        if "offset" in nuisance and "offset" not in initial:
            values["offset"] = float(data.t[0]) - fall
        # Just past the last observed impact (a longer run only adds ever shorter bounces).
        last_flight = float(data.t[-1] - data.t[-2])
        horizon = float(data.t[-1]) - values["offset"] + 0.5 * last_flight + 0.05
    elif data.observe == "apex":
        fall = first_impact_time(data.x0, data.v0, gravity) if data.scene == "drop" else 0.0
        flights = 2.0 * np.sqrt(2.0 * np.asarray(data.h) / gravity)
        horizon = fall + 1.05 * float(np.sum(flights)) + 0.05
        if data.t is not None:
            horizon = max(horizon, float(data.t[-1]) + 0.6 * float(flights[-1]) + 0.05)
    problem = make_problem(data, tol=tol, has_drag=has_drag, sigma=sigma, horizon=horizon)

    free = [
        i for i, n in enumerate(PARAMETERS) if (n in ("kappa", "k_r") or n in nuisance) and n not in freeze
    ]
    lo = to_z({n: bounds[n][0] for n in PARAMETERS})
    hi = to_z({n: bounds[n][1] for n in PARAMETERS})
    fd = np.array(
        [_FD_STEP[n] * (1.0 if n in LOG_PARAMETERS else max(1.0, abs(values[n]))) for n in PARAMETERS]
    )
    evaluator = _Evaluator(problem, free, fd, mass, prior=0 in free and 1 in free)

    def start_point(e, t_c):
        kappa, k_r = parameters_from_restitution(e, t_c, mass)
        v = {"kappa": kappa, "k_r": k_r, **values}
        v.update({k: initial[k] for k in ("kappa", "k_r") if k in initial})
        return np.clip(to_z(v), lo, hi)

    rng = np.random.default_rng(seed)
    if e0 is None:
        # No closed form (two-racket traces): the best e on a grid, at the prior's t_c.
        grid = np.linspace(0.3, 0.98, evaluator.rows)
        weights = _window_weights(problem, _WINDOWS[0], evaluator.prior)
        costs = [
            np.sum((weights * r) ** 2) if ok else np.inf
            for r, ok in evaluator.values([start_point(e, CONTACT_TIME_GUESS) for e in grid])
        ]
        e0 = float(grid[int(np.argmin(costs))])
        e_source = "grid search (no closed form for this scene)"
    else:
        e_source = (
            "closed form (" + ("flight times" if data.observe == "impacts" else "rebound heights") + ")"
        )
    candidates = [start_point(e0, CONTACT_TIME_GUESS)]
    prior_t = np.geomspace(*CONTACT_TIME_PRIOR, max(starts - 1, 1) + 2)[1:-1] if starts > 1 else []
    for t_c in prior_t:
        e = float(np.clip(e0 * (1.0 + 0.02 * rng.standard_normal()), 0.05, 0.995))
        candidates.append(start_point(e, float(t_c)))

    # -- optional gradient stage, then LM on growing windows ----------------------------
    optimizer = optimizer if optimizer is not None else _DEFAULT_OPTIMIZER
    step_fn = _gradient_step(optimizer) if method == "optax" else None
    # Every start is fitted on the first window loosely (it only has to find the basin);
    # the best one goes on through the longer windows, then one tight pass on all data.
    windows = _WINDOWS if data.observe == "trace" else (1.0,)
    runs = []
    bar = _progress(len(candidates), progress)
    for z in candidates:
        z = z.copy()
        gradient_iterations = 0
        if step_fn is not None and steps > 0:
            z, gradient_iterations = _run_gradient_stage(step_fn, optimizer, problem, z, free, lo, hi, steps)
        z, r, jac, cost, it, converged, why = _levenberg_marquardt(
            evaluator,
            z,
            free,
            _window_weights(problem, windows[0], evaluator.prior),
            lo,
            hi,
            max_iterations=max_iterations,
            dchi2=1e-2,
        )
        runs.append(
            dict(
                z=z,
                r=r,
                jac=jac,
                cost=cost,
                iterations=it,
                gradient_steps=gradient_iterations,
                converged=converged,
                why=why,
            )
        )
        bar.update(1)
    bar.close()
    best = min(runs, key=lambda run: run["cost"])
    for fraction in windows[1:]:
        z, r, jac, cost, it, converged, why = _levenberg_marquardt(
            evaluator,
            best["z"],
            free,
            _window_weights(problem, fraction, evaluator.prior),
            lo,
            hi,
            max_iterations=max_iterations,
            dchi2=1e-2,
        )
        best = dict(
            best,
            z=z,
            r=r,
            jac=jac,
            cost=cost,
            iterations=best["iterations"] + it,
            converged=converged,
            why=why,
        )
    z = best["z"]
    # The steering prior only holds the path where the data say nothing: the tight pass
    # drops it when the data determine t_c themselves, and the uncertainty never uses it.
    use_prior = False
    if evaluator.prior:
        evaluator.prior = False
        r_data, jac_data, _ = evaluator(z)
        cov_tc, _ = covariance(jac_data, r_data, sigma_known=sigma_known)
        contact_time = summarize(z, cov_tc, free, mass)[1]["contact_time"]
        use_prior = not contact_time["stderr"] < 0.1 * contact_time["value"]  # sd(log t_c) < 0.1
        evaluator.prior = use_prior
    z, r, jac, cost, it, converged, why = _levenberg_marquardt(
        evaluator, z, free, _window_weights(problem, 1.0, use_prior), lo, hi, max_iterations=max_iterations
    )
    if use_prior:
        evaluator.prior = False
        r, jac, _ = evaluator(z)
        cost = 0.5 * float(np.sum(r**2))
    best = dict(best, z=z, cost=cost, iterations=best["iterations"] + it, converged=converged, why=why)
    at_bound = [
        PARAMETERS[i]
        for i in free
        if np.isclose(z[i], lo[i], rtol=0, atol=1e-9) or np.isclose(z[i], hi[i], rtol=0, atol=1e-9)
    ]
    cov, s2 = covariance(jac, r, sigma_known=sigma_known)
    parameters, derived, identifiable, corr, names = summarize(
        z, cov, free, mass, rel_halfwidth=rel_halfwidth
    )
    goodness = goodness_of_fit(float(np.sum(r**2)), r.size, len(free), sigma_known=sigma_known)
    if goodness["consistent"] is False:
        # The intervals assume a fit consistent with the noise; this one is not.
        identifiable = {name: False for name in identifiable}
    finite_cost = math.isfinite(best["cost"])
    converged = bool(best["converged"] and finite_cost and not at_bound)
    message = best["why"] if not at_bound else f"stopped at a bound: {', '.join(at_bound)}"
    profile_result = None
    if profile and 0 in free:
        profile_result = _profile_kappa(evaluator, z, free, lo, hi, cov, s2, max_iterations, best["cost"])
    return FitResult(
        data=data,
        problem=problem,
        z=z,
        free=names,
        parameters=parameters,
        derived=derived,
        identifiable=identifiable,
        correlation=corr,
        cost=float(best["cost"]),
        residuals=r * sigma,  # r = (prediction − data)/σ, σ = 1 when the file states none
        chi2=float(np.sum(r**2)),
        sigma=math.sqrt(s2) * sigma if not sigma_known else sigma,
        sigma_source="file" if sigma_known else "residuals",
        goodness=goodness,
        converged=converged,
        message=message,
        iterations=int(best["iterations"]),
        gradient_steps=int(best["gradient_steps"]),
        method=method,
        starts=[dict(cost=run["cost"], converged=run["converged"], z=run["z"]) for run in runs],
        initial=dict(restitution=e0, contact_time=CONTACT_TIME_GUESS, source=e_source),
        profile=profile_result,
        rel_halfwidth=rel_halfwidth,
        simulations=evaluator.calls,
        wall_s=time.perf_counter() - began,
    )


def _profile_kappa(evaluator, z_hat, free, lo, hi, cov, s2, max_iterations, cost_hat, points: int = 13):
    """χ²(κ) with the other free parameters re-optimized: the profile likelihood of κ.

    Returns the grid, Δχ² = 2(cost − cost_min)/s², and the 95% interval where
    Δχ² ≤ 3.84 (the χ²₁ quantile), found by linear interpolation on the grid.
    """
    sd = math.sqrt(cov[0, 0]) if math.isfinite(cov[0, 0]) else 5.0
    half = min(3.0 * max(sd, 1e-4), 5.0)
    grid = z_hat[0] + np.linspace(-half, half, points)
    others = [i for i in free if i != 0]
    costs = np.full(points, np.inf)
    centre = points // 2
    for order in (range(centre, points), range(centre, -1, -1)):
        z = z_hat.copy()
        for k in order:
            z[0] = grid[k]
            weights = np.ones_like(np.asarray(evaluator.problem.t_obs))
            if others:
                z, _, _, cost, _, _, _ = _levenberg_marquardt(
                    evaluator, z, others, weights, lo, hi, max_iterations=max_iterations
                )
            else:
                r, _, ok = evaluator(z)
                cost = 0.5 * float(np.sum(r**2)) if ok else math.inf
            costs[k] = cost
    delta = 2.0 * (costs - min(cost_hat, float(np.min(costs)))) / s2
    threshold = Z95**2
    inside = np.flatnonzero(delta <= threshold)
    lo_k, hi_k = inside[0], inside[-1]

    def cross(k_in, k_out):
        if k_out < 0 or k_out >= points:
            return -math.inf if k_out < 0 else math.inf
        d0, d1 = delta[k_in], delta[k_out]
        frac = (threshold - d0) / (d1 - d0) if d1 != d0 else 0.5
        return float(grid[k_in] + frac * (grid[k_out] - grid[k_in]))

    ci = [cross(lo_k, lo_k - 1), cross(hi_k, hi_k + 1)]
    return dict(
        kappa=np.exp(grid),
        delta_chi2=delta,
        ci95=[math.exp(ci[0]) if math.isfinite(ci[0]) else 0.0, math.exp(ci[1])],
    )


@functools.lru_cache(maxsize=8)
def _gradient_step(optimizer):
    # Cached per optimizer: a new jitted step for every fit would recompile the
    # reverse-mode pass through the event mode each time.
    @eqx.filter_jit
    def step(problem, z, opt_state, mask):
        def loss(z):
            r, _ = problem.residuals(z)
            return 0.5 * jnp.sum(r**2)

        value, grad = jax.value_and_grad(loss)(z)
        grad = jnp.where(mask, grad, 0.0)
        updates, opt_state = optimizer.update(grad, opt_state, z)
        return optax.apply_updates(z, jnp.where(mask, updates, 0.0)), opt_state, value

    return step


def _run_gradient_stage(step, optimizer, problem, z, free, lo, hi, steps):
    mask = jnp.zeros(len(PARAMETERS), bool).at[jnp.asarray(free)].set(True)
    zj = jnp.asarray(z)
    opt_state = optimizer.init(zj)
    best, best_value = np.asarray(zj), math.inf
    for _ in range(steps):
        new, opt_state, value = step(problem, zj, opt_state, mask)
        value = float(value)
        if value < best_value:
            best, best_value = np.asarray(zj), value
        zj = jnp.clip(new, lo, hi)
    return best.copy(), steps


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
