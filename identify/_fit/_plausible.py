"""The closed-form check of a fit: what the data say on their own, before any model.

A drop recorded as impact onsets carries its restitution in closed form: each flight's
launch and landing speeds follow from its duration (drag included,
`identify.bounce_restitution`), and their ratios are the per-bounce e. A least-squares
fit through the event mode can still land in a wrong basin (onsets matched to the
wrong predicted bounces, a release height that does not fit the first flight) and
report a confident number there. This check compares the fit with the closed form,
file by file; a fit that contradicts it is not reported as converged, nothing is
called identifiable, and the command line exits 3 saying why.
"""

from __future__ import annotations

import dataclasses
import math
import os

import numpy as np

from ._outcome import FitOutcome
from ._problem import LAW_MODELS

#: The fewest onsets from which a file's closed-form e is trusted (3 flights).
MIN_ONSETS = 4
#: The least disagreement in e that counts as a contradiction (drag and contact-time
#: corrections of the closed form are good to about 1%).
E_TOLERANCE = 0.03
#: Contact laws whose e depends on the impact speed get a wider tolerance.
E_TOLERANCE_SPEED_DEPENDENT = 0.06
#: A first flight whose e (from the stated release height) departs from the later
#: bounces' by more than this does not follow from that height.
FIRST_TOLERANCE = 0.08


@dataclasses.dataclass(frozen=True)
class ClosedForm:
    """A file's restitution from its flight times alone.

    - `restitution`: the median per-bounce e of the flights after the first (drag-
      corrected; a flight that spans a missed bounce is left out).
    - `spread`: the robust standard deviation of those per-bounce e.
    - `count`: how many bounces the median is over.
    - `first`: bounce 1's e computed from the stated release height x0 (None where the
      file is not a drop from rest).
    - `launch`: the speed leaving the first recorded bounce, m/s (from the first flight).
    """

    restitution: float
    spread: float
    count: int
    first: float | None
    launch: float = math.nan

    @property
    def standard_error(self) -> float:
        """The closed form's own uncertainty, ≈ 1.25 spread / √count (a median's)."""
        return 1.2533 * self.spread / math.sqrt(max(self.count, 1))


def closed_form(d, rows: int | None = None) -> ClosedForm | None:
    """The closed-form restitution of an impacts data set `d` of a drop (of its first `rows`
    onsets: a fit restricted to the speed range where e is constant); None where the file
    has no closed form (another observation or scene, too few onsets)."""
    from .._data._import import ratio_chain
    from ._restitution import bounce_restitution

    if d.observe != "impacts" or d.scene != "drop" or len(d.t[:rows]) < MIN_ONSETS:
        return None
    t = np.asarray(d.t[:rows], dtype=float)
    if np.any(np.diff(t) <= 0):
        return None
    drop = float(d.x0) if d.v0 == 0 and d.x0 > 0 else None
    try:
        b = bounce_restitution(t, drag=float(d.drag), gravity=float(d.gravity), drop_height=drop)
    except ValueError:
        return None
    spans = ratio_chain(t).spans  # flights per interval: > 1 after a missed bounce
    index = np.asarray(b.index)
    later_bounce = (index >= 1) & (index < len(spans))
    i = index[later_bounce]
    single = (spans[i - 1] == 1) & (spans[i] == 1)  # bounce i joins flights i - 1 and i
    later = np.asarray(b.restitution)[later_bounce][single]
    later = later[np.isfinite(later)]
    if len(later) < 2:
        return None
    median = float(np.median(later))
    spread = 1.4826 * float(np.median(np.abs(later - median)))
    first = None
    if drop is not None and len(b.index) and b.index[0] == 0 and spans[0] == 1:
        first = float(b.restitution[0])
    launch = float(b.rebound_speed[0]) if len(index) and index[0] == 0 else math.nan
    return ClosedForm(restitution=median, spread=spread, count=len(later), first=first, launch=launch)


def _tolerance(law: str, form: ClosedForm) -> float:
    """How far a fitted e may lie from the closed form: wider for a law whose e depends on
    the impact speed (its e is the one at the data's typical speed)."""
    base = E_TOLERANCE_SPEED_DEPENDENT if LAW_MODELS[law].restitution_depends_on_speed else E_TOLERANCE
    return max(base, 4.0 * form.standard_error)


def _name(d, f: int) -> str:
    return os.path.basename(d.path) if d.path else f"data set {f + 1}"


def contradictions(result) -> list[str]:
    """Why `result` (a `FitOutcome`) contradicts its data's closed forms; [].

    Per file of impact onsets: the fitted e (the file's own "alone" e in a joint fit)
    must lie within max(0.03, 4 standard errors) of the closed form (0.06 for a law whose
    e depends on the impact speed), and, where x0 is held at the stated release height,
    the first flight must follow from that height (its e within 0.08 of the later
    bounces'). A joint fit's shared e must lie within the files' own closed forms.
    """
    out = []
    files = result.datasets_data or []
    forms = _forms(result)
    fitted_x0 = "x0" in result.free
    missed = {f: (e_fit, tol) for f, e_fit, tol in _basin_misses(result, forms)}
    for f, (d, form) in enumerate(zip(files, forms, strict=True)):
        if form is None:
            continue
        if f in missed:
            e_fit, tol = missed[f]
            out.append(
                f"{_name(d, f)}: the fit's e = {e_fit:.4g} contradicts the e = {form.restitution:.4g} "
                f"(± {tol:.3g}) that the file's own flight times give in closed form (drag-corrected "
                f"median of {form.count} bounces): a wrong basin of the fit"
            )
        if not fitted_x0 and form.first is not None and abs(form.first - form.restitution) > FIRST_TOLERANCE:
            h = _implied_height(d, form)
            out.append(
                f"{_name(d, f)}: the first flight ({float(d.t[1] - d.t[0]):.4g} s) cannot follow a drop from "
                f"the stated x0 = {float(d.x0):.4g} m with e = {form.restitution:.3g}; it implies about "
                f"{h:.3g} m. The recording may start at a later bounce, or x0 is wrong: give the right "
                "height, or fit it (--fit x0)"
            )
    known = [form.restitution for form in forms if form is not None]
    if len(files) > 1 and len(known) >= 2:
        e_joint = result.derived["restitution"].value
        lo, hi = min(known) - E_TOLERANCE, max(known) + E_TOLERANCE
        if not lo <= e_joint <= hi:
            out.append(
                f"the joint fit's e = {e_joint:.4g} lies outside the files' own closed-form range "
                f"{min(known):.4g}-{max(known):.4g}"
            )
    return out


def _forms(result) -> list:
    """Each file's closed form, over the rows the fit used where a trend of e with impact
    speed restricted it (`result.trends`)."""
    files = result.datasets_data or []
    used = {t.get("file"): t["rows_used"][1] + 1 for t in getattr(result, "trends", None) or []}
    return [closed_form(d, used.get(f)) for f, d in enumerate(files)]


def _basin_misses(result, forms) -> list[tuple[int, float, float]]:
    """(file, fitted e, tolerance) of every file whose fitted e lies beyond the tolerance of
    its closed form."""
    out = []
    files = result.datasets_data or []
    for f, form in enumerate(forms):
        if form is None:
            continue
        e_fit = _file_restitution(result, f, len(files))
        tol = _tolerance(result.law, form)
        if e_fit is not None and not abs(e_fit - form.restitution) <= tol:
            out.append((f, e_fit, tol))
    return out


def wrong_basin(result) -> bool:
    """Whether the fit sits in a wrong basin that the closed form can lead out of: a file's
    fitted e contradicts a sound closed form (`contradictions`' "wrong basin"), or the fit
    is a misfit of its noise (residuals no ball's scatter explains) while every file is
    impact onsets with a sound closed form (an e of 1.0000 for the flights' 0.987 is within
    0.03, yet its onsets miss by seconds). Sound: the flights' own e scatter by no more than
    a ball's bounce-to-bounce variation (`MAX_E_VARIATION`); a closed form that scatters
    more is no reference to restart from. Then a fit restarted from the closed form
    (`identify._pipeline`) can reach the basin the flights give."""
    from ._robust import MAX_E_VARIATION

    forms = _forms(result)

    def sound(form):
        return form is not None and form.spread <= MAX_E_VARIATION * form.restitution

    if any(sound(forms[f]) for f, _, _ in _basin_misses(result, forms)):
        return True
    misfit = (result.noise or {}).get("verdict") == "misfit"
    return bool(misfit and forms and all(sound(form) for form in forms))


#: A trace whose first this-many rows are all outliers starts with something the fit
#: cannot follow (a ball held before the release, a hand): never a silent trim.
LEADING_OUTLIERS = 3


def release_problems(result) -> list[str]:
    """Why a trace's start contradicts a release from rest or a fall: [] when it does not.

    - A block of at least `LEADING_OUTLIERS` outliers at the very start of a trace: the
      robust pass took the frames before the release (the ball held still) for outliers
      and fitted a launch through the rest.
    - An upward launch speed v0 fitted at t = 0 (beyond its 95% interval): a "release"
      that throws the ball up is a held ball's frames read as a flight, or a throw that
      the file does not say was one.
    """
    out = []
    files = result.datasets_data or []
    for f, d in enumerate(files):
        if d.observe != "trace" or d.scene != "drop" or f >= len(result.datasets):
            continue
        entry = result.datasets[f]
        rows = sorted(o.row for o in entry.outliers)
        lead = next((k for k, row in enumerate(rows) if row != k), len(rows))
        if lead >= LEADING_OUTLIERS:
            out.append(
                f"{_name(d, f)}: the first {lead} rows are all outliers of the fit: the trace starts with "
                "frames it cannot follow (a ball held still before the release, or a hand); trim them "
                "(or import the track with jaxunilat import video, which finds the release)"
            )
        v0 = entry.params.get("v0")
        if v0 is not None and math.isfinite(v0.value) and v0.ci95[0] > 0.0 and not _rises(d, entry):
            out.append(
                f"{_name(d, f)}: the fit launches the ball upward at the start (v0 = {v0.value:.3g} m/s, "
                f"95% CI from {v0.ci95[0]:.3g} m/s): a drop does not; the trace may start with the "
                "ball held, or x0 and the time origin are off"
            )
    return out


def _rises(d, entry) -> bool:
    """Whether a trace's own first samples rise (by 3 noise σ within its first 5 rows):
    then an upward v0 is what the recording shows (it started after a bounce)."""
    x = np.asarray(d.x[:5], dtype=float)
    sigma = float(entry.sigma or 0.0)
    return bool(x.size > 1 and np.max(x[1:]) - x[0] > 3.0 * sigma)


def _file_restitution(result, f: int, n_files: int) -> float | None:
    if n_files == 1:
        value = result.derived["restitution"].value
    else:
        alone = result.datasets[f].restitution_alone if f < len(result.datasets) else None
        value = None if alone is None else alone.value
    return float(value) if value is not None and math.isfinite(value) else None


def _implied_height(d, form: ClosedForm) -> float:
    """The release height (m) whose first impact speed, times e, launches the first flight."""
    w = form.launch / form.restitution  # the first impact speed
    k, g = float(d.drag), float(d.gravity)
    if k > 0 and k * w < 1:
        return -math.log(1.0 - (k * w) ** 2) / (2.0 * g * k * k)
    return w * w / (2.0 * g)


def gate(result: FitOutcome) -> FitOutcome:
    """`result` judged against its data's closed forms: `contradictions` (and a misfit
    verdict of its noise statement, taken as one) in `result.contradictions`; where any,
    also not converged, nothing identifiable, and the reasons in the message."""
    found = contradictions(result) + release_problems(result)
    noise = result.noise or {}
    if noise.get("verdict") == "misfit":
        # Far more residual scatter than the data kind (or the stated noise, or a ball's
        # bounce-to-bounce variation) can have: the model does not describe the data.
        found.insert(0, f"the model does not fit the data: {noise.get('text', '')}")
    if not found:
        return dataclasses.replace(result, contradictions=())
    return result.nothing_identifiable(
        contradictions=tuple(found),
        converged=False,
        message="the fit contradicts the data's closed form: " + "; ".join(found),
    )
