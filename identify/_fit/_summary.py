"""A finished fit in numbers: estimates with honest uncertainty, per-file tables, outliers.

The covariance is Gauss–Newton over every fitted joint entry (`_uncertainty`); the
headline `params` are the view of file 0 (the shared contact parameters and file 0's own
x0, v0 and offset), so a fit of one file reads exactly as before. Each file's own
entries, rows, outliers, missed bounces and residual scatter go to `datasets`. Every
function here returns a new `FitOutcome`; none changes one.
"""

from __future__ import annotations

import dataclasses
import math

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np

from .._data._format import plausibility_notes
from ._alone import alone_restitution
from ._by_bounce import (
    P_BOUNCE_LOCKED,
    bounce_locked,
    by_bounce,
    restitution_spread,
    trace_clusters,
    widen_by_bounce,
)
from ._derived import law_derived, view
from ._estimate import Estimate, estimate
from ._joint import Layout
from ._outcome import CONTACT, FileFit, FitOutcome, MissedBounce, Outlier, StartRun
from ._problem import PARAMETERS, units
from ._robust import height_scale, holdout_summary, missed_bounces, noise_statement, scatter_statement
from ._uncertainty import covariance, goodness_of_fit, summarize

__all__ = ["CONTACT", "restore_clocks", "summarize_fit", "with_alone"]


def _estimates(setup, entries: dict, free: list[int], verdicts: dict | None = None) -> dict[str, Estimate]:
    """`summarize`'s entries as `Estimate`s, with units, whether held, and the verdicts."""
    u = {**units(setup.law), "restitution": "", "contact_time": "s"}
    verdicts = verdicts or {}
    held = {PARAMETERS[i] for i in range(len(PARAMETERS)) if i not in free}
    return {
        name: estimate(name, entry, u[name], fixed=name in held, identifiable=verdicts.get(name))
        for name, entry in entries.items()
    }


def _file_entries(setup, z, cov, rows, *, r_data, sigma_used) -> list[FileFit]:
    """One `FileFit` per file: its rows, outliers, missed bounces, scatter and own entries."""
    out = []
    for f, d in enumerate(setup.datasets):
        sl = rows.of_file(f)
        used = rows.fitted[sl]
        res = r_data[sl] * setup.sigmas[f]
        z6, cov6, free6 = view(setup, z, cov, f)
        own = _estimates(
            setup, summarize(z6, cov6, free6, float(d.mass), derived=law_derived(setup))[0], free6
        )
        own = {
            name: own[name]
            for name in setup.layout.local
            if setup.layout.index[f, PARAMETERS.index(name)] in setup.free
        }
        times = setup.times[f]
        outliers = [
            Outlier(
                row=int(i),
                t=float(times[i]) if d.observe != "apex" or d.t is not None else None,
                residual=float(res[i]),
                reason="beyond the outlier threshold (robust pass)",
            )
            for i in np.flatnonzero(rows.outlier[sl])
        ]
        missed = missed_bounces(times, ~rows.outlier[sl]) if d.observe == "impacts" else []
        out.append(
            FileFit(
                data=d.path,
                observe=d.observe,
                rows=int(d.num_rows),
                used=int(used.sum()),
                held_out=int(rows.holdout[sl].sum()),
                outliers=tuple(outliers),
                missed=tuple(
                    MissedBounce(
                        after_row=m["after_row"],
                        before_row=m["before_row"],
                        interval=m["interval"],
                        previous=m["previous"],
                    )  # fmt: skip
                    for m in missed
                ),
                rms=float(np.sqrt(np.mean(res[used] ** 2))) if used.any() else None,
                sigma=float(sigma_used[f]),
                params=own,
            )
        )
    return out


@dataclasses.dataclass(frozen=True)
class _Covariance:
    """The covariance of the free joint entries with honest noise (`_uncertainty`):
    `goodness` (the χ² test), whether s² was `estimated` from the residuals, `cov`, `s2`,
    the p-value of bounce-locked trace residuals (`locked`, None where not tested), the
    data rows' χ², the free entries `p` and the fitted rows `n_kept`."""

    goodness: dict
    estimated: bool
    cov: np.ndarray
    s2: float
    locked: float | None
    chi2_data: float
    p: int
    n_kept: int


def _uncertainty(setup, rows, r_fit, jac, r_data, *, scatter_model: bool) -> _Covariance:
    """The covariance with honest noise: the χ² test against the stated σ, s² from the
    residuals where σ is estimated or understated, widened by flight where a trace's
    residuals are locked to its bounces."""
    keep = rows.fitted
    p = len(setup.free)
    chi2_data = float(np.sum(r_data[keep] ** 2))
    goodness = goodness_of_fit(chi2_data, int(keep.sum()), p, sigma_known=setup.sigma_known)
    understated = setup.sigma_known and goodness["consistent"] is False
    estimated = scatter_model or not setup.sigma_known or understated
    cov, s2 = covariance(jac[keep], r_fit[keep], sigma_known=not estimated)
    locked = None
    if not scatter_model:
        clusters, times = (a[keep] for a in trace_clusters(setup, rows, r_data))
        if np.any(clusters >= 0):
            locked = bounce_locked(r_fit[keep], clusters, times)
            if locked < P_BOUNCE_LOCKED:
                cov = by_bounce(cov, jac[keep], r_fit[keep], clusters)
    return _Covariance(
        goodness=goodness, estimated=estimated, cov=cov, s2=s2, locked=locked, chi2_data=chi2_data, p=p,
        n_kept=int(keep.sum()),
    )  # fmt: skip


def _noise(setup, u: _Covariance, scatter_model: bool, structure) -> tuple[np.ndarray, dict]:
    """Each file's σ used, and the stated noise against the residual scatter (`noise`)."""
    onset_scatter = math.sqrt(u.chi2_data / max(u.n_kept - u.p, 1)) * float(np.median(setup.sigmas))
    if scatter_model:
        sigma_used = np.full(len(setup.sigmas), math.sqrt(u.s2))
        noise = scatter_statement(setup.sigma_known, float(setup.sigmas[0]), onset_scatter, math.sqrt(u.s2))
        return sigma_used, noise
    sigma_used = setup.sigmas * math.sqrt(u.s2)
    noise = noise_statement(
        setup.datasets[0].observe, sigma_known=setup.sigma_known, stated=float(setup.sigmas[0]),
        scatter=onset_scatter if setup.sigma_known else float(sigma_used[0]), goodness=u.goodness,
        times=setup.times[0], height=_height(setup), structure=structure,
    )  # fmt: skip
    return sigma_used, noise


def _verdicts(identifiable: dict, goodness: dict, *, converged: bool, misfit: bool) -> tuple[dict, dict]:
    """The verdicts after the whole fit's checks, and `{name: reason}` of those withheld."""
    if not converged or misfit:
        return dict.fromkeys(identifiable, False), {}
    identifiable, withheld = dict(identifiable), {}
    if goodness["consistent"] is False:
        # The contact's own time scale is the first thing a wrong model or a wrong fixed
        # value (x0, drag, a calibration) bends to fit: never claim it from such a fit.
        why = (
            f"the fit is inconsistent with its noise (reduced chi-square {goodness['reduced_chi2']:.3g}): "
            "its contact time is not trusted"
        )
        for name in CONTACT:
            if identifiable[name]:
                identifiable[name], withheld[name] = False, why
    return identifiable, withheld


def summarize_fit(setup, best, rows, opts, *, runs, initial, robust_scale, onsets=None) -> FitOutcome:
    """The `FitOutcome` of a finished fit (honest noise, per-file tables, hold-out).

    `onsets` is None when the fitted rows are the onsets (or positions, heights)
    themselves; under the restitution-scatter error model it is the point's onset
    residuals, and `best` holds the log-ratio rows that were fitted. `initial` is the
    closed-form start (`InitialGuess`).
    """
    n = sum(setup.n_rows)
    r_fit, jac = best.r[:n], best.jac[:n]
    r_data = (onsets or best).r[:n]
    keep = rows.fitted
    scatter_model = onsets is not None
    u = _uncertainty(setup, rows, r_fit, jac, r_data, scatter_model=scatter_model)
    cov = u.cov
    z6, cov6, free6 = view(setup, best.z, cov)
    d0 = setup.datasets[0]
    parameters, derived, identifiable, corr, names = summarize(
        z6, cov6, free6, float(d0.mass), rel_halfwidth=opts.rel_halfwidth, derived=law_derived(setup)
    )
    bounce_notes, structure = [], None
    if u.locked is not None:
        e_bounces = restitution_spread(setup, best.z)
        structure = {"e_bounces": e_bounces, "e_fit": derived["restitution"]["value"], "locked": u.locked}
        # Always: a scatter of e below the frames' noise still moves the mean e of a few
        # bounces (on 40 video-like seeds, widening only where the residuals showed it
        # covered the mean e in 33 of 38 fits; always, 37 of 38).
        derived, identifiable, bounce_notes = _e_by_bounce(
            e_bounces, derived, identifiable, opts, locked=u.locked < P_BOUNCE_LOCKED
        )
    sigma_used, noise = _noise(setup, u, scatter_model, structure)
    at_bound = [
        "/".join(str(x) for x in setup.layout.names()[j] if x is not None)
        for j in setup.free
        if np.isclose(best.z[j], setup.lo[j], rtol=0, atol=1e-9)
        or np.isclose(best.z[j], setup.hi[j], rtol=0, atol=1e-9)
    ]
    converged = bool(best.converged and math.isfinite(best.cost) and not at_bound)
    verdicts, withheld = _verdicts(
        identifiable, u.goodness, converged=converged, misfit=noise["verdict"] == "misfit"
    )
    several = setup.layout.n_files > 1
    alone = alone_restitution(setup, best, rows, opts) if several and not opts.defer_alone else None
    row_sigma = setup.per_row(setup.sigmas)
    residuals = r_data * row_sigma  # prediction − data, in the data's units
    holdout = None
    if opts.holdout > 0:
        holdout = _holdout(
            setup, rows, r_fit=r_fit, jac=jac, cov=cov, s2=u.s2, data_units=residuals, fraction=opts.holdout,
            scatter_model=scatter_model,
        )  # fmt: skip
    files = _file_entries(setup, best.z, cov, rows, r_data=r_data, sigma_used=sigma_used)
    if alone is not None:
        files = _with_alone_entries(files, alone)
    return FitOutcome(
        data=d0,
        problem=_file_problem(setup, 0),
        z=z6 if setup.layout.n_files == 1 else np.asarray(best.z)[setup.layout.index[0]],
        free=tuple(names),
        params=_estimates(setup, parameters, free6, verdicts),
        derived=_estimates(setup, derived, free6, verdicts),
        correlation=corr,
        cost=float(best.cost),
        residuals=residuals,
        chi2=float(np.sum(r_fit[keep] ** 2)),
        sigma=float(sigma_used[0]),
        sigma_source="restitution scatter" if scatter_model else "residuals" if u.estimated else "file",
        goodness=u.goodness,
        converged=converged,
        message=best.why if not at_bound else f"stopped at a bound: {', '.join(at_bound)}",
        iterations=int(best.iterations),
        gradient_steps=int(best.gradient_steps),
        method=opts.method,
        starts=tuple(StartRun(cost=run.cost, converged=run.converged, z=run.z) for run in runs),
        initial=initial,
        profile=None,
        rel_halfwidth=opts.rel_halfwidth,
        simulations=setup.evaluator.calls,
        wall_s=0.0,
        law=setup.law,
        datasets=tuple(files),
        used=rows.fitted.copy(),
        noise=noise,
        holdout=holdout,
        robust=None
        if opts.keep_outliers
        else {"threshold": opts.threshold, "scale": robust_scale, "loss": "cauchy"},
        n_parameters=u.p,
        joint_z=np.asarray(best.z),
        datasets_data=tuple(setup.datasets),
        notes=tuple(
            [note for d in setup.datasets for note in plausibility_notes(d)]
            + _locked_note(u.locked)
            + bounce_notes
        ),
        row_sigma=row_sigma,
        sigma_known=setup.sigma_known,
        withheld=withheld,
    )


def _with_alone_entries(files: list[FileFit], alone: list[dict]) -> list[FileFit]:
    """The files' entries with each one's "alone" e (`alone_restitution`'s entries)."""
    return [
        dataclasses.replace(entry, restitution_alone=estimate("restitution", e, ""))
        for entry, e in zip(files, alone, strict=True)
    ]


def with_alone(outcome: FitOutcome, setup, best, rows, opts) -> FitOutcome:
    """`outcome` with each file's "alone" e (deferred by `opts.defer_alone` until the law is
    chosen) and the simulations they took."""
    before = setup.evaluator.calls
    alone = alone_restitution(setup, best, rows, opts)
    return dataclasses.replace(
        outcome,
        datasets=tuple(_with_alone_entries(list(outcome.datasets), alone)),
        simulations=outcome.simulations + setup.evaluator.calls - before,
    )


def _e_by_bounce(e_bounces, derived, identifiable, opts, *, locked: bool):
    """e's interval from the spread of the drop traces' own per-bounce e, where that is
    wider: (derived, identifiable, notes). With bounce-locked residuals and fewer than two
    per-bounce values, e is not identifiable."""
    wide = widen_by_bounce(derived["restitution"], e_bounces)
    derived, identifiable = dict(derived), dict(identifiable)
    if wide is None and not locked:
        return derived, identifiable, []
    if wide is None:
        identifiable["restitution"] = False
        return (
            derived,
            identifiable,
            [
                f"e: the bounces differ, and {e_bounces.size} pair(s) of complete flights cannot measure by how "
                "much: e's interval is not trusted"
            ],
        )
    derived["restitution"] = wide
    lo, hi = wide["ci95"]
    identifiable["restitution"] = bool(
        identifiable["restitution"] and (hi - lo) / 2 <= opts.rel_halfwidth * wide["value"]
    )
    return (
        derived,
        identifiable,
        [
            f"e's 95% interval is at least what its {e_bounces.size} bounces give (per-bounce e from successive apex "
            f"heights: {', '.join(_fixed(v) for v in e_bounces[:12])}{', ...' if e_bounces.size > 12 else ''}; "
            "Student-t with bounces - 1 degrees of freedom)"
        ],
    )


def _fixed(value: float) -> str:
    """A per-bounce e with 3 decimals (`0.934`), in 4 significant digits where that would
    run long (`1.234e+170` from a wild pair of heights, never 171 digits)."""
    return f"{value:.3f}" if abs(value) < 1e6 else f"{value:.4g}"


def _locked_note(p: float | None) -> list[str]:
    """The report's note when a trace's residuals are locked to its bounces."""
    if p is None or p >= P_BOUNCE_LOCKED:
        return []
    return [
        f"the trace's residuals follow its bounces (each flight's residuals have their own level and slope, "
        f"p = {p:.2g} for independent noise): the bounces differ, so the intervals count bounces, not frames "
        "(cluster-robust covariance by flight, Student-t with flights - 1 degrees of freedom)"
    ]


def _height(setup) -> float | None:
    """The smallest height scale of the files (`height_scale`), None where none has one."""
    scales = [h for h in (height_scale(d) for d in setup.datasets) if h is not None]
    return min(scales) if scales else None


def _holdout(setup, rows, *, r_fit, jac, cov, s2, data_units, fraction, scatter_model) -> dict:
    """The held-out rows: prediction errors in data units, judged against the noise plus
    the fitted parameters' uncertainty in the rows the fit used (onsets, or log ratios
    under the restitution-scatter model)."""
    if not np.all(np.isfinite(cov)):
        # A parameter the fit leaves unbounded propagates an unbounded prediction band:
        # nothing can be judged against it.
        return {
            "fraction": fraction,
            "rows": int(rows.holdout.sum()),
            "rms": None,
            "max": None,
            "within_noise": None,
            "reason": "cannot judge: a fitted parameter has an unbounded (infinite) uncertainty, so the "
            "prediction band of the held-out rows is unbounded",
        }
    variance = 1.0 + np.einsum("ij,jk,ik->i", jac, cov, jac) / s2
    unit = "s" if setup.datasets[0].observe == "impacts" else "m"
    sigma = np.sqrt(s2) * (np.ones(len(r_fit)) if scatter_model else setup.per_row(setup.sigmas))
    scale = 1.0 if scatter_model else sigma
    return holdout_summary(r_fit * scale, rows, sigma, fraction, unit, variance, reported=data_units)


def _file_problem(setup, f: int):
    """File f's own (unstacked) Problem."""
    for g in setup.evaluator.groups:
        if f in g.files:
            k = g.files.index(f)
            # NumPy indexing then one transfer: eager jax indexing would compile.
            return jax.tree.map(lambda leaf, k=k: jax.device_put(np.asarray(leaf)[k]), g.problem)
    raise AssertionError(f)


def _shifted(entry: Estimate, by: float) -> Estimate:
    """An offset's estimate moved by `by` seconds (its interval with it)."""
    return dataclasses.replace(entry, value=entry.value + by, ci95=tuple(v + by for v in entry.ci95))


def restore_clocks(outcome: FitOutcome, originals, clocks) -> FitOutcome:
    """`outcome` with its offsets on the files' own absolute clocks again (the fit ran
    each file relative to its first onset: `_options.shift_clocks`), the original files,
    and a note."""
    n = len(originals)
    layout = Layout(n_files=n)
    i_off = PARAMETERS.index("offset")
    joint_z = outcome.joint_z
    if joint_z is not None and joint_z.size == layout.size:
        joint_z = np.array(joint_z, dtype=float)
        for f, ref in enumerate(clocks):
            joint_z[layout.index[f, i_off]] += ref
    z = np.array(outcome.z, dtype=float)
    z[i_off] += clocks[0]
    files = list(outcome.datasets)
    for f, ref in enumerate(clocks[: len(files)]):
        own = files[f].params.get("offset")
        if own is not None:
            files[f] = dataclasses.replace(files[f], params={**files[f].params, "offset": _shifted(own, ref)})
    problem = outcome.problem
    if clocks[0]:
        problem = eqx.tree_at(
            lambda p: (p.y_obs, p.t_obs),
            problem,
            (jnp.asarray(problem.y_obs) + clocks[0], jnp.asarray(problem.t_obs) + clocks[0]),
        )
    return dataclasses.replace(
        outcome,
        z=z,
        joint_z=joint_z,
        params={**outcome.params, "offset": _shifted(outcome.params["offset"], clocks[0])},
        datasets=tuple(files),
        data=originals[0],
        datasets_data=tuple(originals),
        problem=problem,
    ).noted(
        "onsets on an absolute clock: fitted relative to each file's first onset, the offset reported on the file's "
        "own clock"
    )
