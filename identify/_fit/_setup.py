"""A fit's set-up: data sets in, the joint problem, its bounds and its start points out.

One or several data sets are fitted together (`Layout`): κ, k_r (and the drag, when
fitted) are shared; each file keeps its own release height x0, release speed v0, clock
offset, and (traces) length scale and contact level. The start is the closed form of
`identify._fit._initial` (e from successive rebound heights or flight times, t_c from
the 0.5–2 ms prior, then (κ, k_r) from the law's inverse), per file for its nuisance
values and from the median over files for the shared e; a drop trace's scale and level
start from its flights' parabolas (`trace_calibration`).
"""

from __future__ import annotations

import dataclasses
import math

import numpy as np

from jaxunilat import NoClosedFormError
from jaxunilat._internal import InputError, check_range

from .._data._trace_flights import trace_release
from ._initial import (
    CONTACT_TIME_GUESS,
    CONTACT_TIME_PRIOR,
    first_impact_time,
    initial_restitution,
    trace_calibration,
)
from ._joint import JointEvaluator, Layout, make_groups
from ._problem import (
    EXTRA_ONSETS,
    LAW_MODELS,
    LOG_PARAMETERS,
    NEUTRAL,
    PARAMETERS,
    TRACE_ONLY,
    applies,
    default_max_steps,
    make_problem,
    to_z,
)

#: Central-difference steps (scale and level have closed-form columns: unused there).
_FD_STEP = {
    "kappa": 1e-4,
    "k_r": 1e-4,
    "drag": 1e-4,
    "x0": 1e-6,
    "v0": 1e-5,
    "offset": 1e-6,
    "scale": 1e-6,
    "level": 1e-6,
}
#: A trace's scale within a factor 2 (a ruler 10–20% off is the expected error), its level
#: within ±0.5 m of the file's floor (a level set by hand is off by pixels, millimetres).
DEFAULT_BOUNDS = {
    "kappa": (1.0, 1e12),
    "k_r": (1e-12, 1e4),
    "drag": (1e-6, 10.0),
    "x0": (-1e3, 1e3),
    "v0": (-1e3, 1e3),
    "offset": (-1e4, 1e4),
    "scale": (0.5, 2.0),
    "level": (-0.5, 0.5),
}
#: The residual scale a fit starts from when the files state no noise: a real onset's
#: scatter (s) and a video's or a ruler's resolution (m).
NOMINAL_NOISE = {"impacts": 5e-4, "trace": 1e-3, "apex": 1e-3}
#: Hunt–Crossley's κ (N/m^1.5) and k_r = χκ (N·s/m^2.5) run far larger than Kelvin–Voigt's.
LAW_BOUNDS = {"hunt-crossley": {"kappa": (1.0, 1e15), "k_r": (1e-12, 1e14)}}


@dataclasses.dataclass
class Setup:
    """Everything a fit's stages share (host side).

    **Fields:** the `datasets`; the contact `law`; the joint `layout`; the `evaluator`;
    the `free` joint entries; the bounds `lo`, `hi` (joint, in z units); whether the
    noise σ is the files' (`sigma_known`) and each file's σ (`sigmas`, data units; 1
    when estimated); each file's observation `times` (s; trace and impacts sample or
    onset times, apex indices otherwise) and first-guess `values`; the start's `e0`,
    its `e_source` and the typical impact `speed` (m/s) of the data.
    """

    datasets: list
    law: str
    layout: Layout
    evaluator: JointEvaluator
    free: list[int]
    lo: np.ndarray
    hi: np.ndarray
    sigma_known: bool
    sigmas: np.ndarray
    times: list[np.ndarray]
    values: list[dict]
    e0: float | None
    e_source: str
    speed: float
    initial: dict

    @property
    def n_rows(self) -> list[int]:
        return [len(t) for t in self.times]

    def with_evaluator(self, **changes) -> Setup:
        """This set-up with its evaluator's fields changed (`JointEvaluator.with_`)."""
        return dataclasses.replace(self, evaluator=self.evaluator.with_(**changes))

    def per_row(self, values) -> np.ndarray:
        """One value per file (e.g. `sigmas`) repeated over that file's data rows."""
        return np.repeat(np.asarray(values, dtype=float), self.n_rows)


def _noise(datasets) -> tuple[bool, np.ndarray]:
    stated = [d.noise for d in datasets]
    if all(s is not None for s in stated):
        return True, np.asarray(stated, dtype=float)
    if len({d.observe for d in datasets}) > 1:
        raise InputError(
            "a joint fit of different observation types needs the noise of every file (the residual "
            f"scale cannot be shared between metres and seconds); missing in: {_missing_noise(datasets)}"
        )
    # A nominal scale only balances the data against the steering prior's rows and
    # sets the LM tolerances' units; the uncertainty rescales it by the residual scatter.
    return False, np.array([NOMINAL_NOISE[d.observe] for d in datasets])


def _missing_noise(datasets) -> str:
    return ", ".join(d.path or f"data set {i}" for i, d in enumerate(datasets) if d.noise is None)


def _observation_times(d) -> np.ndarray:
    if d.observe in ("trace", "impacts"):
        return np.asarray(d.t, dtype=float)
    return np.asarray(d.t if d.t is not None else np.arange(len(d.h)), dtype=float)


def _file_values(d, initial: dict, nuisance: tuple[str, ...]) -> tuple[dict, float | None]:
    """A file's first-guess nuisance values and its prediction horizon (s)."""
    values = dict(
        drag=initial.get("drag", d.drag if d.drag > 0 else 0.12),
        x0=initial.get("x0", d.x0),
        v0=initial.get("v0", d.v0),
        offset=initial.get("offset", 0.0),
        **_calibration(d, initial, nuisance),
    )
    if d.observe == "trace" and d.scene == "drop" and "offset" in nuisance and "offset" not in initial:
        values.update(_release(d, values, fit_x0="x0" in nuisance and "x0" not in initial))
    if values["scale"] != 1.0 or values["level"] != 0.0:
        # The file's release state is in the data's units; the model's is physical.
        if "x0" in nuisance and "x0" not in initial:
            values["x0"] = (values["x0"] - values["level"]) / values["scale"]
        if "v0" in nuisance and "v0" not in initial:
            values["v0"] = values["v0"] / values["scale"]
    horizon = None
    g = d.gravity
    if d.observe == "impacts":
        fall = first_impact_time(d.x0, d.v0, g) if d.scene == "drop" else 0.0
        if "offset" in nuisance and "offset" not in initial:
            values["offset"] = float(d.t[0]) - fall
        # Just past the last observed impact (a longer run only adds ever shorter bounces).
        last_flight = float(d.t[-1] - d.t[-2])
        horizon = float(d.t[-1]) - values["offset"] + 0.5 * last_flight + 0.05
        if onset_bounces(d) is not None:
            # Each onset is matched to its own bounce, which must be predicted: room for a
            # start (or a trial step) whose bounces run late by a tenth of the recording.
            horizon += COUNTED_MARGIN * float(d.t[-1] - d.t[0])
    elif d.observe == "apex":
        fall = first_impact_time(d.x0, d.v0, g) if d.scene == "drop" else 0.0
        flights = 2.0 * np.sqrt(2.0 * np.asarray(d.h) / g)
        horizon = fall + 1.05 * float(np.sum(flights)) + 0.05
        if d.t is not None:
            horizon = max(horizon, float(d.t[-1]) + 0.6 * float(flights[-1]) + 0.05)
    return values, horizon


def _release(d, values: dict, *, fit_x0: bool) -> dict:
    """A drop trace's first-guess release instant (`offset`, s) and, when fitted, height
    (x0, data units) from its first fall (`trace_release`); {} where it has none."""
    noise = d.noise if d.noise is not None else NOMINAL_NOISE["trace"]
    found = trace_release(d.t, d.x, curvature=d.gravity * values["scale"], noise=noise)
    if found is None:
        return {}
    offset, height = found
    return {"offset": offset, "x0": height} if fit_x0 else {"offset": offset}


def _calibration(d, initial: dict, nuisance: tuple[str, ...]) -> dict:
    """A file's first-guess scale and level: `NEUTRAL` except for a trace's (the given
    initial values, or for a drop trace whose scale or level is fitted, the closed form)."""
    if d.observe != "trace":
        return dict(NEUTRAL)
    out = {n: float(initial.get(n, NEUTRAL[n])) for n in TRACE_ONLY}
    guess = [n for n in TRACE_ONLY if n in _free_names(d, nuisance, ()) and n not in initial]
    if guess and d.scene == "drop":
        found = trace_calibration(d.t, d.x, d.gravity)
        if found is not None:
            out.update({n: v for n, v in zip(TRACE_ONLY, found, strict=True) if n in guess})
    return out


def _free_names(d, nuisance: tuple[str, ...], freeze: tuple[str, ...]) -> tuple[str, ...]:
    """The nuisance entries fitted for data set d: those of `nuisance` that apply to its
    observations, not frozen, and (scale, level) not stated as measured by the file."""
    measured = tuple(getattr(d, "measured", ()) or ())
    return tuple(
        n
        for n in nuisance
        if n not in freeze and applies(n, d.observe) and not (n in TRACE_ONLY and n in measured)
    )


def _typical_speed(datasets) -> float:
    """The median first impact speed of the drops (m/s), for laws whose e depends on it."""
    speeds = []
    for d in datasets:
        if d.scene == "drop":
            speeds.append(math.sqrt(max(d.v0**2 + 2.0 * d.gravity * max(d.x0, 0.0), 1e-12)))
        else:
            speeds.append(max(abs(d.v0), 1.0))
    return float(np.median(speeds))


def build(datasets, *, law, nuisance, freeze, initial, bounds, tol) -> Setup:
    """The joint problem of `datasets` under `law`, from validated arguments."""
    sigma_known, sigmas = _noise(datasets)
    has_drag = any(d.drag > 0 for d in datasets) or "drag" in nuisance
    layout = Layout(n_files=len(datasets))
    per_file = [_file_values(d, initial, nuisance) for d in datasets]
    rows = [d.num_rows for d in datasets]
    shift_trace = "offset" in nuisance
    problems = _padded_problems(
        datasets, per_file, rows, law=law, has_drag=has_drag, sigmas=sigmas, tol=tol, shift_trace=shift_trace
    )
    fitted = [_free_names(d, nuisance, freeze) for d in datasets]
    free = [
        j
        for j, (name, f) in enumerate(layout.names())
        if (name in ("kappa", "k_r") and name not in freeze) or name in fitted[f or 0]
    ]
    bounds = {**DEFAULT_BOUNDS, **LAW_BOUNDS.get(law, {}), **bounds}
    lo6, hi6 = to_z({n: bounds[n][0] for n in PARAMETERS}), to_z({n: bounds[n][1] for n in PARAMETERS})
    lo = np.array([lo6[PARAMETERS.index(n)] for n, _ in layout.names()])
    hi = np.array([hi6[PARAMETERS.index(n)] for n, _ in layout.names()])
    for j, (name, f) in enumerate(layout.names()):
        if f is not None and not applies(name, datasets[f].observe):
            lo[j] = hi[j] = NEUTRAL[name]  # impact onsets and apexes: no scale or level
    steps = np.array(
        [
            _FD_STEP[n] * (1.0 if n in LOG_PARAMETERS else max(1.0, abs(per_file[f or 0][0][n])))
            for n, f in layout.names()
        ]
    )
    speed = _typical_speed(datasets)
    evaluator = JointEvaluator(
        groups=make_groups(problems, rows),
        layout=layout,
        free=free,
        steps=steps,
        masses=np.array([d.mass for d in datasets]),
        sigmas=sigmas,
        law=law,
        prior=layout.index[0, 0] in free and layout.index[0, 1] in free,
        speed=speed,
    )
    e_values = [initial_restitution(d) for d in datasets]
    e_known = [e for e in e_values if e is not None]
    e0 = float(np.median(e_known)) if e_known else None
    return Setup(
        datasets=list(datasets),
        law=law,
        layout=layout,
        evaluator=evaluator,
        free=free,
        lo=lo,
        hi=hi,
        sigma_known=sigma_known,
        sigmas=sigmas,
        times=[_observation_times(d) for d in datasets],
        values=[v for v, _ in per_file],
        e0=e0,
        e_source=_e_source(datasets) if e0 is not None else "",
        speed=speed,
        initial=dict(initial),
    )


def _e_source(datasets) -> str:
    kinds = {"impacts": "flight times", "apex": "rebound heights", "trace": "rebound heights"}
    what = sorted({kinds[d.observe] for d in datasets})
    median = " (median over files)" if len(datasets) > 1 else ""
    return "closed form (" + ", ".join(what) + ")" + median


#: The fewest onsets whose ratio chain is trusted to count the bounces (3 flights).
MIN_COUNTED_ONSETS = 4
#: The prediction of counted onsets runs this fraction of the recording's span past its
#: last onset.
COUNTED_MARGIN = 0.1


def onset_bounces(d) -> np.ndarray | None:
    """Each onset's bounce (0 = the first impact after the release), counted by the
    onsets' own ratio chain (an interval that spans m flights follows m − 1 unheard
    bounces), or None where the chain cannot count them: not a drop recorded as impact
    onsets, fewer than `MIN_COUNTED_ONSETS`, a broken chain (a spurious or mistimed onset:
    then each onset is matched to the nearest predicted one), or more unheard bounces than
    the prediction has room for."""
    from .._data._import import ratio_chain

    if d.observe != "impacts" or d.scene != "drop" or len(d.t) < MIN_COUNTED_ONSETS:
        return None
    t = np.asarray(d.t, dtype=float)
    if np.any(np.diff(t) <= 0):
        return None
    chain = ratio_chain(t)
    if not math.isfinite(chain.restitution) or np.any(chain.broken):
        return None
    index = np.concatenate([[0], np.cumsum(chain.spans)])
    return index if index[-1] < len(t) + EXTRA_ONSETS else None


def _padded_problems(datasets, per_file, rows, *, law, has_drag, sigmas, tol, shift_trace):
    """One Problem per file, padded so that files of one structure stack."""
    keys = [(d.scene, d.observe) for d in datasets]
    longest = {k: max(r for r, kk in zip(rows, keys, strict=True) if kk == k) for k in set(keys)}
    budget = {}
    for d, (_, horizon), k in zip(datasets, per_file, keys, strict=True):
        n_events = 0 if d.observe == "trace" else longest[k]
        h = float(d.t[-1]) if d.observe == "trace" else horizon
        budget[k] = max(budget.get(k, 0), default_max_steps(n_events, h))
    out = []
    for d, (_, horizon), sigma, k in zip(datasets, per_file, sigmas, keys, strict=True):
        pad = longest[k] if len(datasets) > 1 else None
        out.append(
            make_problem(
                d,
                tol=tol,
                has_drag=has_drag,
                sigma=float(sigma),
                horizon=horizon,
                law=law,
                shift_trace=shift_trace and d.observe == "trace",
                rows=pad,
                max_steps=budget[k] if len(datasets) > 1 else None,
                bounce=onset_bounces(d),
            )
        )
    return out


def start_points(setup: Setup, e0: float, starts: int, rng) -> list[np.ndarray]:
    """The closed-form start and `starts − 1` others spread over the t_c prior (e jittered 2%)."""
    candidates = [start_point(setup, e0, CONTACT_TIME_GUESS)]
    if starts > 1:
        for t_c in np.geomspace(*CONTACT_TIME_PRIOR, max(starts - 1, 1) + 2)[1:-1]:
            e = float(np.clip(e0 * (1.0 + 0.02 * rng.standard_normal()), 0.05, 0.995))
            candidates.append(start_point(setup, e, float(t_c)))
    return candidates


def start_point(setup: Setup, e: float, t_c: float) -> np.ndarray:
    """The joint z at restitution e and contact time t_c (s), other entries at their guesses."""
    mass = float(setup.datasets[0].mass)
    return point_at(setup, *contact_parameters(setup.law, e, t_c, mass, setup.speed))


def point_at(setup: Setup, kappa: float, k_r: float) -> np.ndarray:
    """The joint z at (κ, k_r) in the law's units, other entries at their guesses."""
    per_file = []
    for values in setup.values:
        v = {"kappa": kappa, "k_r": k_r, **values}
        v.update({k: setup.initial[k] for k in ("kappa", "k_r") if k in setup.initial})
        per_file.append(to_z(v))
    return np.clip(setup.layout.join(per_file), setup.lo, setup.hi)


def contact_parameters(law: str, e: float, t_c: float, mass: float, speed: float) -> tuple[float, float]:
    """(κ, k_r) of `law` with restitution e and contact time t_c (s) at impact speed `speed`
    (m/s): the law's closed-form inverse on the host, or where it has none its inverse by
    simulated impacts (`_restitution.inverse_by_simulation`)."""
    model = LAW_MODELS[law]
    check_range("e", e, lo=0.0, hi=1.0, lo_open=True)
    check_range("t_c", t_c, lo=0.0, lo_open=True, unit="s")
    check_range("mass", mass, lo=0.0, lo_open=True, unit="kg")
    try:
        kappa, k_r = model.parameters_from_restitution(float(e), float(t_c), float(mass), speed, xp=np)
    except NoClosedFormError:
        from ._restitution import inverse_by_simulation

        kappa, k_r = inverse_by_simulation(law, e, t_c, mass, speed)
    return float(kappa), float(k_r)
