"""A finished fit in numbers: estimates with honest uncertainty, per-file tables, outliers.

The covariance is Gauss–Newton over every fitted joint entry (`_uncertainty`); the
headline `parameters` are the view of file 0 (the shared contact parameters and file
0's own x0, v0 and offset), so a fit of one file reads exactly as before. Each file's
own entries, rows, outliers, missed bounces and residual scatter go to `datasets`.
"""

from __future__ import annotations

import math
import os

import jax
import numpy as np

from .._data._format import plausibility_notes
from .._fit._alone import alone_restitution
from .._fit._by_bounce import (
    P_BOUNCE_LOCKED,
    bounce_locked,
    by_bounce,
    restitution_spread,
    trace_clusters,
    widen_by_bounce,
)
from .._fit._derived import law_derived, view
from .._fit._problem import PARAMETERS
from .._fit._robust import missed_bounces, noise_statement, scatter_statement
from .._fit._uncertainty import covariance, goodness_of_fit, summarize
from ._result import FitResult

#: The quantities that carry the contact's time scale: κ, k_r and t_c (e does not need it).
CONTACT = ("kappa", "k_r", "contact_time")


def _file_entries(setup, z, cov, rows, *, r_data, sigma_used, best_alone):
    """One dict per file: its rows, outliers, missed bounces, scatter and own entries."""
    out = []
    for f, d in enumerate(setup.datasets):
        sl = rows.of_file(f)
        used = rows.fitted[sl]
        res = r_data[sl] * setup.sigmas[f]
        own = {}
        z6, cov6, free6 = view(setup, z, cov, f)
        params = summarize(z6, cov6, free6, float(d.mass), derived=law_derived(setup))[0]
        for name in setup.layout.local:
            if setup.layout.index[f, PARAMETERS.index(name)] in setup.free:
                own[name] = params[name]
        times = setup.times[f]
        outliers = [
            {
                "row": int(i),
                "t": float(times[i]) if d.observe != "apex" or d.t is not None else None,
                "residual": float(res[i]),
                "reason": "beyond the outlier threshold (robust pass)",
            }
            for i in np.flatnonzero(rows.outlier[sl])
        ]
        missed = missed_bounces(times, ~rows.outlier[sl]) if d.observe == "impacts" else []
        out.append(
            {
                "data": d.path,
                "observe": d.observe,
                "rows": int(d.num_rows),
                "used": int(used.sum()),
                "held_out": int(rows.holdout[sl].sum()),
                "outliers": outliers,
                "missed": missed,
                "rms": float(np.sqrt(np.mean(res[used] ** 2))) if used.any() else None,
                "sigma": float(sigma_used[f]),
                "parameters": own,
                "restitution_alone": None if best_alone is None else best_alone[f],
            }
        )
    return out


def summarize_fit(setup, best, rows, opts, *, runs, initial, robust_scale, onsets=None) -> FitResult:
    """The `FitResult` of a finished fit (honest noise, per-file tables, hold-out).

    `onsets` is None when the fitted rows are the onsets (or positions, heights)
    themselves; under the restitution-scatter error model it is the point's onset
    residuals, and `best` holds the log-ratio rows that were fitted.
    """
    n = sum(setup.n_rows)
    r_fit, jac = best.r[:n], best.jac[:n]
    r_data = (onsets or best).r[:n]
    keep = rows.fitted
    p = len(setup.free)
    chi2_data = float(np.sum(r_data[keep] ** 2))
    goodness = goodness_of_fit(chi2_data, int(keep.sum()), p, sigma_known=setup.sigma_known)
    scatter_model = onsets is not None
    understated = setup.sigma_known and goodness["consistent"] is False
    estimate = scatter_model or not setup.sigma_known or understated
    cov, s2 = covariance(jac[keep], r_fit[keep], sigma_known=not estimate)
    locked = None
    if not scatter_model:
        clusters, times = (a[keep] for a in trace_clusters(setup, rows, r_data))
        if np.any(clusters >= 0):
            locked = bounce_locked(r_fit[keep], clusters, times)
            if locked < P_BOUNCE_LOCKED:
                cov = by_bounce(cov, jac[keep], r_fit[keep], clusters)
    z6, cov6, free6 = view(setup, best.z, cov)
    d0 = setup.datasets[0]
    parameters, derived, identifiable, corr, names = summarize(
        z6, cov6, free6, float(d0.mass), rel_halfwidth=opts.rel_halfwidth, derived=law_derived(setup)
    )
    bounce_notes, structure = [], None
    if locked is not None:
        e_bounces = restitution_spread(setup, best.z)
        structure = {"e_bounces": e_bounces, "e_fit": derived["restitution"]["value"], "locked": locked}
        # Always: a scatter of e below the frames' noise still moves the mean e of a few
        # bounces (on 40 video-like seeds, widening only where the residuals showed it
        # covered the mean e in 33 of 38 fits; always, 37 of 38).
        derived, identifiable, bounce_notes = _e_by_bounce(
            e_bounces, derived, identifiable, opts, locked=locked < P_BOUNCE_LOCKED
        )
    onset_scatter = math.sqrt(chi2_data / max(int(keep.sum()) - p, 1)) * float(np.median(setup.sigmas))
    if scatter_model:
        sigma_used = np.full(len(setup.sigmas), math.sqrt(s2))
        noise = scatter_statement(setup.sigma_known, float(setup.sigmas[0]), onset_scatter, math.sqrt(s2))
    else:
        sigma_used = setup.sigmas * math.sqrt(s2)
        noise = noise_statement(
            d0.observe, sigma_known=setup.sigma_known, stated=float(setup.sigmas[0]),
            scatter=onset_scatter if setup.sigma_known else float(sigma_used[0]), goodness=goodness,
            times=setup.times[0], height=_height(setup), structure=structure,
        )  # fmt: skip
    at_bound = [
        "/".join(str(x) for x in setup.layout.names()[j] if x is not None)
        for j in setup.free
        if np.isclose(best.z[j], setup.lo[j], rtol=0, atol=1e-9)
        or np.isclose(best.z[j], setup.hi[j], rtol=0, atol=1e-9)
    ]
    converged = bool(best.converged and math.isfinite(best.cost) and not at_bound)
    if not converged or noise["verdict"] == "misfit":
        identifiable = {name: False for name in identifiable}
    withheld = {}
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
    several = setup.layout.n_files > 1
    alone = alone_restitution(setup, best, rows, opts) if several and not opts.defer_alone else None
    row_sigma = setup.per_row(setup.sigmas)
    residuals = r_data * row_sigma  # prediction − data, in the data's units
    holdout = None
    if opts.holdout > 0:
        holdout = _holdout(
            setup, rows, r_fit=r_fit, jac=jac, cov=cov, s2=s2, data_units=residuals, fraction=opts.holdout,
            scatter_model=scatter_model,
        )  # fmt: skip
    chi2 = float(np.sum(r_fit[keep] ** 2))
    return FitResult(
        data=d0,
        problem=_file_problem(setup, 0),
        z=z6 if setup.layout.n_files == 1 else np.asarray(best.z)[setup.layout.index[0]],
        free=names,
        parameters=parameters,
        derived=derived,
        identifiable=identifiable,
        correlation=corr,
        cost=float(best.cost),
        residuals=residuals,
        chi2=chi2,
        sigma=float(sigma_used[0]),
        sigma_source="restitution scatter" if scatter_model else "residuals" if estimate else "file",
        goodness=goodness,
        converged=converged,
        message=best.why if not at_bound else f"stopped at a bound: {', '.join(at_bound)}",
        iterations=int(best.iterations),
        gradient_steps=int(best.gradient_steps),
        method=opts.method,
        starts=[dict(cost=run.cost, converged=run.converged, z=run.z) for run in runs],
        initial=initial,
        profile=None,
        rel_halfwidth=opts.rel_halfwidth,
        simulations=setup.evaluator.calls,
        wall_s=0.0,
        law=setup.law,
        datasets=_file_entries(
            setup, best.z, cov, rows, r_data=r_data, sigma_used=sigma_used, best_alone=alone
        ),
        used=rows.fitted.copy(),
        noise=noise,
        holdout=holdout,
        robust=None
        if opts.keep_outliers
        else {"threshold": opts.threshold, "scale": robust_scale, "loss": "cauchy"},
        n_parameters=p,
        joint_z=np.asarray(best.z),
        datasets_data=list(setup.datasets),
        notes=[note for d in setup.datasets for note in plausibility_notes(d)]
        + _locked_note(locked)
        + bounce_notes,
        row_sigma=row_sigma,
        sigma_known=setup.sigma_known,
        withheld=withheld,
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
    from .._fit._robust import height_scale

    scales = [h for h in (height_scale(d) for d in setup.datasets) if h is not None]
    return min(scales) if scales else None


def _holdout(setup, rows, *, r_fit, jac, cov, s2, data_units, fraction, scatter_model) -> dict:
    """The held-out rows: prediction errors in data units, judged against the noise plus
    the fitted parameters' uncertainty in the rows the fit used (onsets, or log ratios
    under the restitution-scatter model)."""
    from .._fit._robust import holdout_summary

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
    finite = cov
    variance = 1.0 + np.einsum("ij,jk,ik->i", jac, finite, jac) / s2
    unit = "s" if setup.datasets[0].observe == "impacts" else "m"
    sigma = np.sqrt(s2) * (np.ones(len(r_fit)) if scatter_model else setup.per_row(setup.sigmas))
    scale = 1.0 if scatter_model else sigma
    return holdout_summary(r_fit * scale, rows, sigma, fraction, unit, variance, reported=data_units)


def bounce_points(result) -> list[tuple[str, object]]:
    """Each impact file's per-bounce restitution from its kept onsets (drag-corrected).

    Uses the fitted drag and contact time; a missed bounce splits the sequence (an
    interval spanning two flights says nothing about either), and the first segment
    of a drop from rest also gets its first bounce from the fitted release height.
    **Returns:** `(label, BounceRestitution)` pairs, one per segment of ≥ 3 onsets.
    """
    from .._fit._restitution import bounce_restitution

    drag = result.parameters["drag"]["value"] if result.data.drag > 0 or "drag" in result.free else 0.0
    t_c = result.derived["contact_time"]["value"]
    t_c = t_c if math.isfinite(t_c) else 0.0
    out = []
    for f, entry in enumerate(result.datasets):
        d = result.datasets_data[f]
        if d.observe != "impacts":
            continue
        keep = np.ones(d.num_rows, bool)
        keep[[o["row"] for o in entry["outliers"]]] = False
        cuts = [m["before_row"] for m in entry["missed"]]
        kept = np.flatnonzero(keep)
        segments = np.split(kept, [int(np.searchsorted(kept, c)) for c in cuts])
        label = os.path.basename(d.path) if d.path else f"data {f + 1}"
        x0 = entry["parameters"].get("x0", {}).get("value", d.x0)
        offset = entry["parameters"].get("offset", {}).get("value")
        for k, seg in enumerate(segments):
            if seg.size < 3:
                continue
            from_rest = k == 0 and d.v0 == 0 and offset is not None and seg[0] == 0
            try:
                points = bounce_restitution(
                    np.asarray(d.t)[seg],
                    drag=drag,
                    gravity=d.gravity,
                    contact_time=min(t_c, 0.5 * float(np.min(np.diff(np.asarray(d.t)[seg])))),
                    drop_height=x0 if from_rest and x0 > 0 else None,
                )
            except ValueError:
                continue
            out.append((label if len(segments) == 1 else f"{label} ({k + 1})", points))
    return out


def _file_problem(setup, f: int):
    """File f's own (unstacked) Problem."""
    for g in setup.evaluator.groups:
        if f in g.files:
            k = g.files.index(f)
            # NumPy indexing then one transfer: eager jax indexing would compile.
            return jax.tree.map(lambda leaf, k=k: jax.device_put(np.asarray(leaf)[k]), g.problem)
    raise AssertionError(f)
