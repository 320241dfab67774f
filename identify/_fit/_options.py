"""A fit's arguments: loading, validation (`check_arguments`), the default nuisance
parameters, refused duplicates and impact onsets on an absolute clock."""

from __future__ import annotations

import dataclasses

import numpy as np
import optax

from jaxunilat._internal import InputError, check_choice, check_range

from ._problem import LOG_PARAMETERS, NUISANCE, PARAMETERS, TRACE_ONLY
from ._robust import fitted_count

METHODS = ("lm", "optax")
GRADIENTS = ("forward", "reverse")


def default_optimizer(learning_rate: float = 0.02) -> optax.GradientTransformation:
    """The default gradient stage: clip the update norm to 1, then Adam (on z, logs)."""
    return optax.chain(optax.clip_by_global_norm(1.0), optax.adam(learning_rate))


_DEFAULT_OPTIMIZER = default_optimizer()


def _load(data):
    from .._data._format import Dataset, load_dataset

    if isinstance(data, Dataset):
        return data
    if isinstance(data, (str, bytes)) or hasattr(data, "__fspath__"):
        return load_dataset(data)
    raise InputError(f"data = {data!r} is not an identify.Dataset or a path to a data file")


@dataclasses.dataclass(frozen=True, kw_only=True)
class Options:
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
    defer_alone: bool = False  # leave each file's "alone" e to the caller (law="auto")
    from_closed_form: bool = False  # the restart after a contradicted fit (`identify._pipeline`)


def load_all(data) -> list:
    if isinstance(data, (list, tuple)):
        if not data:
            raise InputError("data = [] names no data set; give at least one data file")
        return [_load(d) for d in data]
    return [_load(data)]


def refuse_duplicates(datasets) -> None:
    """Refuse one data set given twice (the same file, or a copy: identical rows).

    Its rows would count twice and every interval would shrink by √2 with no new
    information."""
    seen = {}
    for f, d in enumerate(datasets):
        columns = tuple(None if c is None else np.asarray(c).tobytes() for c in (d.t, d.x, d.h))
        key = (d.observe, *columns)
        if key in seen:
            g = seen[key]
            raise InputError(
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


def shift_clocks(datasets) -> tuple[list, list[float]]:
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


def shift_offset_arguments(initial, bounds, clocks):
    """`initial`/`bounds` of the offset on the shifted clock (one shift: every file's)."""
    if not any(clocks) or not ({"offset"} & (set(initial or {}) | set(bounds or {}))):
        return initial, bounds
    if len(set(clocks)) > 1:
        raise InputError(
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


def default_nuisance(datasets, nuisance: tuple, freeze: tuple) -> tuple[tuple, str]:
    """`nuisance` with what the data determine and no recorder knows added by default.

    - The clock offset where a file holds impact onsets: no recorder knows the release
      instant (hold it with `freeze=("offset",)` when the onsets are timed from the release).
    - The release of traces whose x0 is their own first sample (the video importer's
      default): held there, every estimate would follow that one sample's noise (κ from
      13k to 56k N/m across noise seeds of a 1 mm trace, intervals excluding the truth).
      For drops, the release height x0 and instant (`offset`), v0 held as stated (0: from
      rest): a video track starts with the ball held still, or enters mid-fall, and a
      free v0 fitted the held frames as an upward launch. For rackets, x0 and v0. Only
      when every file is a trace, and not for x0 stated apart from the samples (the
      bundled trace: x0 = 0.305 m, first sample 0.304705 m).
    - x0, v0 where a file says they were estimated (`Dataset.estimated`, as `import wav`
      and `import phyphox` write it without `--x0`): held at an estimate, the fit puts the
      estimate's error into the contact time (a phone recording gave κ = 620 N/m ± 4% for a
      truth of 54 000 with x0 estimated 6% low).
    - A trace's length scale and contact level (`scale`, `level`; data = level + scale ·
      model position): a video's pixels-to-metres factor comes from a ruler that
      perspective puts 10–20% off, and its floor is set by hand to a pixel; held at (1, 0),
      the contact time followed them (one pixel of level doubled t_c on a real trace),
      while gravity and the bounces determine both. Fitted unless every trace states them
      measured (`Dataset.measured`); a file that does holds its own (`_setup._free_names`).

    Returns the nuisance tuple and a note for the report ("" when nothing was added)."""
    notes = []
    nuisance = _free_estimated(datasets, nuisance, freeze, notes)
    if "offset" not in nuisance and "offset" not in freeze and any(d.observe == "impacts" for d in datasets):
        notes.append(
            "clock offset fitted (impact onsets: a recording does not know the release instant; "
            "hold it with --freeze offset, or freeze=('offset',) in Python, if the onsets are timed from the release)"
        )
        nuisance = (*nuisance, "offset")
    if all(_x0_from_sample(d) for d in datasets):
        # A drop from rest: the release height and instant (the frames before it show the
        # ball held; a clip that starts mid-fall has its release before its first frame).
        # Other scenes: the state at the first frame.
        drops = all(d.scene == "drop" for d in datasets)
        wanted = ("x0", "offset") if drops else ("x0", "v0")
        added = tuple(n for n in wanted if n not in nuisance and n not in freeze)
        if added:
            nuisance = (*nuisance, *added)
            why = (
                "the ball is released from rest (v0 as stated) at an instant the frames do not know: frames before "
                "it show the ball held, and a clip that starts mid-fall has it before its first frame"
                if drops
                else "one noisy sample must not pin the state"
            )
            notes.append(
                f"{', '.join(added)} fitted: the file's x0 is its first sample's height; {why} (hold them with "
                f"--freeze {','.join(added)}, or freeze={added!r} in Python)"
            )
    nuisance = _free_calibration(datasets, nuisance, freeze, notes)
    return nuisance, "; ".join(notes)


def _free_calibration(datasets, nuisance: tuple, freeze: tuple, notes: list) -> tuple:
    """`nuisance` plus a trace's scale and level where some trace does not state them measured."""
    traces = [d for d in datasets if d.observe == "trace"]
    added = tuple(
        n for n in TRACE_ONLY
        if n not in nuisance and n not in freeze and any(n not in _measured(d) for d in traces)
    )  # fmt: skip
    if added:
        notes.append(
            f"{', '.join(added)} fitted (trace: data = level + scale * model position): a trace's length scale "
            "and contact level are set by hand (a ruler, a floor pixel), and gravity and the bounces determine "
            f"them (hold with --freeze {','.join(added)}, or freeze={added!r} in Python, or state them "
            f"measured in the file: # measured = {','.join(added)})"
        )
    nuisance = (*nuisance, *added)
    held = [
        f"{n} of {d.path or 'a data set'}"
        for d in traces
        for n in TRACE_ONLY
        if n in nuisance and n in _measured(d)
    ]
    if held:
        notes.append(f"held where the file states them measured: {', '.join(held)}")
    return nuisance


def _measured(d) -> tuple[str, ...]:
    """The names a data set states as measured (`Dataset.measured`)."""
    return tuple(getattr(d, "measured", ()) or ())


def _free_estimated(datasets, nuisance: tuple, freeze: tuple, notes: list) -> tuple:
    """`nuisance` plus x0, v0 where some file says the importer estimated them."""
    added = tuple(
        n for n in ("x0", "v0")
        if n not in nuisance and n not in freeze and any(n in d.estimated for d in datasets)
    )  # fmt: skip
    if added:
        notes.append(
            f"{', '.join(added)} fitted: the data file says {'they were' if len(added) > 1 else 'it was'} "
            f"estimated, not measured (hold with --freeze {','.join(added)} only if you measured "
            f"{'them' if len(added) > 1 else 'it'}; better, give the measured value to the importer)"
        )
    return (*nuisance, *added)


def _x0_from_sample(d) -> bool:
    """Whether a trace's x0 is its first sample's position at t = 0 (as `import video` writes it)."""
    return d.observe == "trace" and float(d.t[0]) == 0.0 and float(d.x[0]) == float(d.x0)


def check_arguments(
    datasets,
    *,
    nuisance,
    freeze,
    starts: int,
    steps: int,
    max_iterations: int,
    tol: float,
    rel_halfwidth: float,
    optimizer,
    method: str,
    seed: int,
    profile: bool,
    progress: bool,
    keep_outliers: bool,
    outlier_threshold: float,
    holdout: float,
    gradient: str,
) -> Options:
    """`fit`'s settings validated (a ValueError names the argument, value and valid range)."""
    nuisance, freeze = tuple(nuisance), tuple(freeze)
    _check_names(datasets, nuisance, freeze)
    check_choice("method", method, METHODS)
    check_choice("gradient", gradient, GRADIENTS)
    for name, value, lo in (
        ("starts", starts, 1),
        ("steps", steps, 0),
        ("max_iterations", max_iterations, 1),
    ):
        if not isinstance(value, int) or isinstance(value, bool) or value < lo:
            raise InputError(f"{name} = {value!r} is out of range; valid range is integers >= {lo}")
    check_range("tol", tol, lo=1e-14, hi=1e-4, unit="")
    check_range("rel_halfwidth", rel_halfwidth, lo=0.0, lo_open=True, unit="")
    check_range("outlier_threshold", outlier_threshold, lo=1.0, unit="robust sd")
    _check_holdout(datasets, holdout)
    if optimizer is not None and not isinstance(optimizer, optax.GradientTransformation):
        raise InputError(f"optimizer = {optimizer!r} is not an optax.GradientTransformation")
    return Options(
        nuisance=nuisance,
        freeze=freeze,
        starts=starts,
        seed=seed,
        method=method,
        optimizer=optimizer or _DEFAULT_OPTIMIZER,
        steps=steps,
        max_iterations=max_iterations,
        profile=bool(profile),
        rel_halfwidth=float(rel_halfwidth),
        progress=bool(progress),
        keep_outliers=bool(keep_outliers),
        threshold=float(outlier_threshold),
        holdout=float(holdout),
        gradient=gradient,
    )


def _check_names(datasets, nuisance: tuple, freeze: tuple) -> None:
    """The nuisance and frozen parameters' names, and what they ask of the data."""
    for name in nuisance:
        check_choice("nuisance", name, NUISANCE)
    for name in freeze:
        check_choice("freeze", name, PARAMETERS)
    if "offset" in nuisance:
        for d in datasets:
            if d.observe == "apex":
                raise InputError(
                    "nuisance 'offset' (a time offset, s) applies to impact onsets and traces; "
                    f"{d.path or 'a data set'} has observe = 'apex'"
                )
    for name in TRACE_ONLY:
        if name in nuisance and not any(d.observe == "trace" for d in datasets):
            what = "length scale, data = level + scale * model" if name == "scale" else "contact level, m"
            raise InputError(
                f"nuisance {name!r} (a trace's {what}) applies to traces (observe = trace); "
                f"{datasets[0].path or 'the data set'} has observe = {datasets[0].observe!r}"
            )
    if set(freeze) >= {"kappa", "k_r"}:
        raise InputError("freeze = ('kappa', 'k_r') leaves nothing to fit; free at least one of them")


def _check_holdout(datasets, holdout: float) -> None:
    """`holdout` in [0, 1), leaving every file enough rows to fit and one to predict."""
    check_range("holdout", holdout, lo=0.0, hi=1.0, hi_open=True, unit="")
    if holdout > 0:
        for d in datasets:
            keep = fitted_count(d.num_rows, holdout)
            if keep < MIN_FITTED[d.observe] or keep == d.num_rows:
                raise InputError(
                    f"holdout = {holdout!r} leaves {keep} of {d.num_rows} rows of {d.path or 'a data set'} to fit "
                    f"and {d.num_rows - keep} to predict; valid: at least {MIN_FITTED[d.observe]} to fit and 1 to predict"
                )


#: The fewest rows a fit may keep per file (the rest held out).
MIN_FITTED = {"trace": 3, "impacts": 3, "apex": 1}


def check_start(initial, bounds):
    initial = dict(initial or {})
    for name, value in initial.items():
        check_choice("initial", name, PARAMETERS)
        positive = name in LOG_PARAMETERS or name == "scale"
        check_range(f"initial[{name!r}]", value, lo=0.0 if positive else None, lo_open=True)
    bounds = dict(bounds or {})
    for name, pair in bounds.items():
        check_choice("bounds", name, PARAMETERS)
        if len(pair) != 2 or not pair[0] < pair[1]:
            raise InputError(f"bounds[{name!r}] = {pair!r} must be a pair (lo, hi) with lo < hi")
        if (name in LOG_PARAMETERS or name == "scale") and pair[0] <= 0:
            raise InputError(f"bounds[{name!r}] = {pair!r}: {name} is positive; valid lower bounds are > 0")
    return initial, bounds
