"""`fit()`: κ and k_r (and nuisance parameters) from one or several data sets.

The pipeline over the layers below it: arguments (`identify._fit._options`), the
set-up (`_fit._setup`), the stages (`_fit._stages`: starts, growing windows, robust
pass, final pass; `_fit._alone`: starts from each file's own solution), then the
summary (`_fit._summary`: Gauss–Newton covariance with honest noise, per-file tables,
the per-file "alone" restitution, the hold-out prediction), the optional profile of κ
(`_fit._profile`) and the closed-form gate (`_fit._plausible`), with one restart from
the closed form where the gate finds a wrong basin. Each step returns a new frozen
`FitOutcome`; the `FitResult` (`identify._report._result`) is built once, at the end.

The Jacobian's columns are central differences of event-located runs (step 1e-4 in
log κ, log k_r, log k; scaled steps for x0, v0) inside the one compiled call; the time
offset of impact data only shifts the predictions, so its column is 1/σ in closed form
and takes no runs. Forward-mode AD through the event mode is exact too, but compiles
for several times longer than the whole differenced fit takes (design notes:
`identify/README.md`).
"""

from __future__ import annotations

import concurrent.futures
import dataclasses
import functools
import math
import os
import time

import numpy as np
import optax

import jaxunilat as ju
from jaxunilat import NoClosedFormError
from jaxunilat._internal import keep_placement, latency_bound

from ._fit import _plausible as plausible, _stages as stages
from ._fit._alone import alone_starts
from ._fit._initial import CONTACT_TIME_GUESS
from ._fit._options import (
    METHODS,
    Options,
    check_arguments,
    check_start,
    default_nuisance,
    default_optimizer,
    load_all,
    refuse_duplicates,
    shift_clocks,
    shift_offset_arguments,
)
from ._fit._outcome import CONTACT, FitOutcome, InitialGuess, Restart
from ._fit._problem import LAW_MODELS, LAWS, law_name
from ._fit._profile import check_profile_minimum, profile_closes, profile_kappa
from ._fit._restitution import inverse_by_simulation
from ._fit._robust import THRESHOLD, Rows
from ._fit._setup import build, point_at, start_points
from ._fit._summary import restore_clocks, summarize_fit, with_alone
from ._report._result import FitResult

__all__ = ["METHODS", "default_optimizer", "fit"]


@latency_bound
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
    law: str | ju.AbstractContactLaw = "kelvin-voigt",
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
    - `nuisance`: extra parameters to fit, from `("drag", "x0", "v0", "offset", "scale",
      "level")`; `offset` (the recording's unknown time origin, s) applies to impact onsets
      and to traces (a video rarely starts at the release), not to apex heights; `scale`
      and `level` are a trace's length scale and contact level (data = level + scale ·
      model height), fitted by default for traces unless the file lists them as
      `measured`, and held at (1, 0) for other data.
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
      (fit both, report χ², AIC and BIC side by side, keep the lower BIC); or the law
      object itself (`jaxunilat.HuntCrossley(1.5)`), found in identify's law table
      (`_fit._problem.LAW_MODELS`, where a new law is one line).
    - `keep_outliers`: skip the robust pass; every row is fitted by least squares.
    - `outlier_threshold`: rows beyond this many robust residual scales are excluded.
    - `holdout`: fit the first (1 − holdout) of each file's rows and predict the rest
      (0 ≤ holdout < 1).
    - `gradient`: the optax stage's gradient, `"forward"` (Jᵀr from forward-mode
      Jacobians through the event mode: a few solves for κ and k_r, and a quick
      compile) or `"reverse"` (`jax.grad`).

    **Returns:** a frozen `FitResult` (`.params["kappa"].value`, `.report()`,
    `.to_json_dict()`, …).
    """
    began = time.perf_counter()
    datasets = load_all(data)
    refuse_duplicates(datasets)
    originals = list(datasets)
    datasets, clocks = shift_clocks(datasets)
    initial, bounds = shift_offset_arguments(initial, bounds, clocks)
    nuisance, offset_note = default_nuisance(datasets, tuple(nuisance), tuple(freeze))
    opts = check_arguments(
        datasets, nuisance=nuisance, freeze=freeze, starts=starts, steps=steps, max_iterations=max_iterations,
        tol=tol, rel_halfwidth=rel_halfwidth, optimizer=optimizer, method=method, seed=seed, profile=profile,
        progress=progress, keep_outliers=keep_outliers, outlier_threshold=outlier_threshold, holdout=holdout,
        gradient=gradient,
    )  # fmt: skip
    law = law_name(law)
    initial, bounds = check_start(initial, bounds)
    opts = dataclasses.replace(opts, bounds=bounds, tol=tol)
    laws = LAWS if law == "auto" else (law,)
    outcome = plausible.gate(_chosen(_fit_laws(datasets, laws, opts, initial), law, offset_note))
    if plausible.wrong_basin(outcome):
        outcome = _from_closed_form(outcome, datasets, laws, law, opts, initial, offset_note)
    if any(clocks):
        outcome = restore_clocks(outcome, originals, clocks)
    fields = {f.name: getattr(outcome, f.name) for f in dataclasses.fields(FitOutcome)}
    return FitResult(**{**fields, "wall_s": time.perf_counter() - began})


def _chosen(fitted: dict, law: str, offset_note: str | None) -> FitOutcome:
    """The law of `fitted` (`_fit_laws`) with the lowest BIC on the rows every law used,
    finished (its files' "alone" e), with the laws' comparison and the offset's note."""
    results = {name: r for name, (r, _) in fitted.items()}
    common = np.logical_and.reduce([r.used for r in results.values()])
    comparison = {name: r.criteria(common) for name, r in results.items()}
    chosen = min(results, key=lambda n: comparison[n]["bic"])
    result, finish = fitted[chosen]
    if finish is not None:
        result = finish()
    result = dataclasses.replace(
        result, laws=comparison, law_choice="auto (lowest BIC)" if law == "auto" else "given"
    )
    return result.noted(offset_note) if offset_note else result


def _from_closed_form(first: FitOutcome, datasets, laws, law, opts, initial, offset_note) -> FitOutcome:
    """The fit again from the closed form, after `first` landed in a wrong basin
    (`plausible.wrong_basin`): one start at the closed-form e, its release and clock
    settled with the contact held there, on the flights' log ratios wherever the onsets are
    counted. Its result replaces `first` when the closed form does not contradict it; when
    it does too, `first` stands, with its reasons and a note (a real contradiction is not
    hidden: the command line exits 3)."""
    again = dataclasses.replace(opts, from_closed_form=True, starts=1, progress=False)
    second = plausible.gate(_chosen(_fit_laws(datasets, laws, again, initial), law, offset_note))
    e_first = first.derived["restitution"].value
    e_second = second.derived["restitution"].value
    restart = Restart(first_restitution=e_first, reasons=first.contradictions, accepted=False)
    if second.contradictions:
        return dataclasses.replace(first, restart=restart).noted(
            f"restarted from the closed form after the fit (e = {e_first:.4f}) contradicted it: the restart "
            f"(e = {e_second:.4f}) contradicts it too"
        )
    return dataclasses.replace(
        second,
        restart=dataclasses.replace(restart, accepted=True),
        simulations=second.simulations + first.simulations,
    ).noted(
        f"the first fit landed in a wrong basin (e = {e_first:.4f}, contradicted by the flights' closed form); "
        f"restarted from the closed form: e = {e_second:.4f}, which the closed form does not contradict"
    )


def _fit_laws(datasets, laws: tuple[str, ...], opts: Options, initial: dict) -> dict:
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
        futures = {
            name: pool.submit(keep_placement(one), name, opts.progress and k == 0)
            for k, name in enumerate(laws)
        }
        return {name: future.result() for name, future in futures.items()}


def _fit_law(setup, opts: Options):
    """Every stage for one contact law: starts, windows, robust pass, final pass, summary.

    Returns the `FitOutcome` and `finish`: None, or (with `opts.defer_alone` and several
    files) the call that returns it with each file's "alone" e (`_summary.with_alone`)."""
    began = time.perf_counter()
    rows = Rows.make(setup.n_rows, opts.holdout)
    trends = stages.speed_trends(setup)
    rows = stages.leave_out_slow(setup, rows, trends)
    stages.check_counts(setup, rows)
    from_start = stages.scatter_from_start(setup, rows) or (opts.from_closed_form and stages.counted(setup))
    with concurrent.futures.ThreadPoolExecutor(max_workers=1, thread_name_prefix="identify-warm") as pool:
        warming = _warm_evaluator(setup, pool)
        own_starts = alone_starts(setup, opts) if opts.alone_starts else []
        if warming is not None:
            warming.result()
        e0, e_source = stages.start_restitution(setup, rows)
        count = 1 if opts.from_closed_form else opts.starts
        candidates = start_points(setup, e0, count, np.random.default_rng(opts.seed))
    if from_start:
        best, runs, restarts, final, onsets = _scatter_from_start(setup, candidates, own_starts, rows, opts)
        scale = None
    else:
        if opts.from_closed_form:
            candidates = [stages.settle(setup, z, rows, opts) for z in candidates]
        runs = stages.run_starts(setup, candidates, rows, opts)
        best = stages.windows_from(setup, min(runs, key=lambda run: run.cost), rows, opts)
        scale = None
        if not opts.keep_outliers:
            best, rows, scale = stages.robust_pass(setup, best, rows, opts)
        best = stages.final_pass(setup, best, rows, opts)
        best, restarts = _restarts(setup, best, own_starts, rows, opts)
        # The final pass fits the data rows without the steering prior.
        final, onsets = setup.with_evaluator(prior=False), None
        if stages.scatter_model_applies(setup, best, rows):
            ratio = setup.with_evaluator(transforms=stages.ratio_transforms(setup, rows))
            fitted = stages.final_pass(ratio, best, rows, opts)
            onsets = stages.onset_point(setup, fitted, best)
            best, final = fitted, ratio.with_evaluator(prior=False)
    initial = InitialGuess(restitution=e0, contact_time=CONTACT_TIME_GUESS, source=e_source)
    result = summarize_fit(
        final, best, rows, opts, runs=runs, initial=initial, robust_scale=scale, onsets=onsets
    )
    result = _note_trends(result, setup, trends, from_start)
    if from_start:
        result = _judge_law(result, stages.closed_scatter(setup, rows))
    result = _note_restarts(result, setup, restarts)
    confirm = any(result.identifiable[name] for name in CONTACT)
    if setup.layout.index[0, 0] in setup.free and (opts.profile or confirm):
        # Asked for, or to confirm an identifiable κ, k_r or t_c: the Gauss–Newton interval
        # is local and linear (a t_c stuck at the steering prior's centre had ±10%), and a κ
        # whose profile stays flat on one side is not what the data carry.
        profile = profile_kappa(final, best, rows, result, opts, points=13 if opts.profile else 7)
        result = check_profile_minimum(dataclasses.replace(result, profile=profile), best, setup)
        why = profile_closes(result.profile)
        if why is not None:
            result = result.withhold(CONTACT, why)
    result = dataclasses.replace(result, wall_s=time.perf_counter() - began)
    finish = None
    if opts.defer_alone and setup.layout.n_files > 1:
        finish = functools.partial(with_alone, result, final, best, rows, opts)
    return result, finish


def _scatter_from_start(setup, candidates, own_starts, rows, opts):
    """The stages on the flights' log ratios from the first (`stages.scatter_from_start`):
    each start's release and clock settled at its closed-form e, the starts, the growing
    windows and the final pass on the whitened log-ratio rows of the counted onsets, the
    restarts from each file's own solution, then once more with each file's scatter
    re-estimated from the fit where it moved. No robust pass: the counted onsets' chain is
    unbroken (a spurious onset breaks it), and a ratio row is not an onset.

    Returns (best, runs, restarts, the final set-up, the onsets' point)."""
    transforms = stages.ratio_transforms(setup, rows)
    ratio = setup.with_evaluator(transforms=transforms)
    candidates = [stages.settle(ratio, z, rows, opts) for z in candidates]
    runs = stages.run_starts(ratio, candidates, rows, opts)
    best = stages.windows_from(ratio, min(runs, key=lambda run: run.cost), rows, opts)
    best = stages.final_pass(ratio, best, rows, opts)
    best, restarts = _restarts(ratio, best, own_starts, rows, opts)
    scatter = stages.refined_scatter(setup, best, rows, transforms)
    if scatter is not None:
        ratio = setup.with_evaluator(transforms=stages.ratio_transforms(setup, rows, scatter))
        best = stages.final_pass(ratio, best, rows, opts)
    onsets = stages.onset_point(setup, best, best)
    return best, runs, restarts, ratio.with_evaluator(prior=False), onsets


#: A fit's log ratios that scatter by more than twice the flights' own closed-form scatter
#: plus this (relative e) are the law's misfit, not the ball's scatter.
LAW_SCATTER_MARGIN = 0.001


def _judge_law(result: FitOutcome, flights: dict) -> FitOutcome:
    """A misfit verdict where the fit's log-ratio rows scatter far more than the flights'
    own per-bounce e (`stages.closed_scatter`, about a constant e): the law's e(v) follows
    the data worse than a constant e does (Hunt–Crossley's e, which falls as the speed
    rises, fitted to a ball whose e is constant: 3.2% against 0.5%), and that excess is not
    the ball's scatter. Only for a law whose e depends on the speed: Kelvin–Voigt's e is
    constant, so an excess there is not the law's e(v) (on short real throws it was the
    first flight against a stated release height, 1.8% against 0.3% on 3 flights)."""
    if not result.law_model.restitution_depends_on_speed:
        return result
    noise = result.noise or {}
    fitted, own = noise.get("restitution_scatter"), max((s for s, _ in flights.values()), default=None)
    if fitted is None or own is None or noise.get("verdict") == "misfit":
        return result
    if fitted <= 2.0 * own + LAW_SCATTER_MARGIN:
        return result
    return result.nothing_identifiable(
        noise={
            **noise,
            "verdict": "misfit",
            "text": noise["text"]
            + f"; but the flights' own e scatter by only {own:.2%} (closed form, about a constant "
            f"e): the {result.law} law follows the data's e worse than a constant e does (compare laws: --law auto)",
        }
    )


def _note_trends(result: FitOutcome, setup, trends, from_start: bool) -> FitOutcome:
    """Each file's trend of e with impact speed: `result.trends` and a note; and the note
    that the fit used the flights' log ratios from its first stage."""
    pairs = [(f, d, t) for f, (d, t) in enumerate(zip(setup.datasets, trends, strict=True)) if t is not None]
    result = dataclasses.replace(
        result, trends=[{"file": f, "data": d.path, **t.to_json(d.num_rows)} for f, d, t in pairs]
    ).noted(
        *(
            t.note(os.path.basename(d.path) if d.path else f"data set {f + 1}", d.num_rows)
            for f, d, t in pairs
        )
    )
    if from_start:
        result = result.noted(
            "each onset matched to its own bounce (the flights' ratio chain counts them), and the flights' log ratios "
            "fitted from the first stage: the flights' own e scatter beyond the stated timing noise, so onset "
            "residuals of a constant e are a random walk that a least-squares fit of the onsets would follow"
            if setup.sigma_known
            else "each onset matched to its own bounce (the flights' ratio chain counts them), and the flights' log "
            "ratios fitted from the first stage (no timing noise stated)"
        )
    return result


def _restarts(setup, best, own_starts, rows, opts):
    """The same stages from each file's own solution (`alone_starts`), on the rows the
    main path kept: a joint LM can stop on the long κ–k_r–t_c valley well above a point
    it can reach. Returns the best point and each start's (file, final cost)."""
    restarts = []
    for f, z in own_starts:
        point = stages.restart(setup, z, rows, opts)
        restarts.append((f, point.cost))
        if math.isfinite(point.cost) and point.cost < best.cost:
            best = dataclasses.replace(point, iterations=best.iterations + point.iterations)
    return best, restarts


def _note_restarts(result: FitOutcome, setup, restarts) -> FitOutcome:
    """The note of the restarts from each file's own solution, where there were any."""
    if not restarts:
        return result
    names = [d.path or f"data set {f + 1}" for f, d in enumerate(setup.datasets)]
    return result.noted(
        "joint fit also started from each file's own solution (fitted alone, one start); final chi-square "
        "over all fitted rows of this fit: "
        + ", ".join(f"from {os.path.basename(names[f])}: {2 * c:.6g}" for f, c in restarts)
    )


def _warm_evaluator(setup, pool) -> concurrent.futures.Future | None:
    """Hunt–Crossley: compile the fit's program in `pool` while the start is computed.

    Hunt–Crossley's start points simulate single impacts (`inverse_by_simulation`,
    a compiled program of its own), and so does its "alone" fit of a few files: the
    fit's program compiles meanwhile, by one run at the closed-form start (`refine=0`:
    nothing simulated), with the shapes of every later call. Kelvin–Voigt's start is in
    closed form: nothing to overlap (None).
    """
    if not LAW_MODELS[setup.law].restitution_depends_on_speed:
        return None
    e = setup.e0 if setup.e0 is not None else 0.8
    mass = float(setup.datasets[0].mass)
    try:
        kappa, k_r = inverse_by_simulation(setup.law, e, CONTACT_TIME_GUESS, mass, setup.speed, refine=0)
    except NoClosedFormError:
        return None
    return pool.submit(keep_placement(setup.evaluator.warm), point_at(setup, kappa, k_r))
