"""Solver settings: classic fixed-step RK4 and adaptive Tsit5 with a PID controller."""

from __future__ import annotations

import math
from collections.abc import Callable
from typing import ClassVar

import diffrax as dfx
import equinox as eqx
import numpy as np
from jaxtyping import Array

from .._internal._errors import InputError
from .._internal._validate import as_float_array, check_choice, check_range, is_concrete
from ._device_cache import DeviceCache

_rk4_tableau = dfx.ButcherTableau(
    a_lower=(
        np.array([0.5]),
        np.array([0.0, 0.5]),
        np.array([0.0, 0.0, 1.0]),
    ),
    b_sol=np.array([1 / 6, 1 / 3, 1 / 3, 1 / 6]),
    # Classic RK4 has no embedded method: it is only used with constant steps.
    b_error=np.zeros(4),
    c=np.array([0.5, 0.5, 1.0]),
)


class RK4(dfx.AbstractERK):
    """The classic 4th-order Runge–Kutta method (Kutta 1901), as used in [K90].

    Four stages, no embedded error estimate: use it with constant steps only.
    diffrax ships no classic RK4, so the Butcher tableau is defined here.
    """

    tableau: ClassVar[dfx.ButcherTableau] = _rk4_tableau
    interpolation_cls: ClassVar[Callable[..., dfx.ThirdOrderHermitePolynomialInterpolation]] = (
        dfx.ThirdOrderHermitePolynomialInterpolation.from_k
    )

    def order(self, terms):
        del terms
        return 4


SOLVERS = ("rk4", "tsit5", "event")
#: The step budget of the adaptive methods when `max_steps` is not given (RK4's covers
#: the span: ⌈(t1 − t0)/dt⌉ + 16).
DEFAULT_MAX_STEPS = {"tsit5": 200_000, "event": 16_384}
#: The event mode's event buffer when `max_events` is not given.
DEFAULT_MAX_EVENTS = 2048

#: The largest step budget a solve may have: RK4 takes about 0.1 µs per step on a CPU
#: core with loop kernels (seconds for 1e8 steps), the event mode ~1 µs; a larger budget
#: is more likely a units slip (dt in ms, t1 in ms) than a run anyone waits for.
MAX_STEPS_LIMIT = 100_000_000
#: The automatic differentiation modes a solve supports (`SolverSettings.autodiff`).
AUTODIFF = ("reverse", "forward")


class SolverSettings(eqx.Module):
    """How to integrate: the method and its settings.

    **Arguments:**

    - `method`: `"rk4"` (fixed step `dt`), `"tsit5"` (adaptive, PID controller) or
      `"event"` (exact contact, located: see `jaxunilat._solver._event`).
    - `dt`: the RK4 step, s; for Tsit5 and the event mode an optional first step.
    - `rtol`, `atol`: the adaptive methods' relative and absolute tolerances.
    - `max_steps`: the step budget (static). `None` picks ⌈span/dt⌉ + 16 for RK4,
      200 000 for Tsit5 and 16 384 for the event mode.
    - `pcoeff`, `icoeff`: the PID controller's proportional and integral gains.
    - `max_events`: the event mode's event buffer (static): entries, exits, apexes
      and deepest points. Default 2048.
    - `subgrid`: how many points per step the event mode checks for crossings
      (static, besides the observable's extremum). Default 4.
    - `dtmax`: the event mode's largest step, s (`None`: no cap).
    - `piece_solver`: the event mode's Runge–Kutta pair for the smooth pieces:
      `"tsit5"` (5th order) or `"dopri8"` (8th order, fewer steps at tight
      tolerances). Static.
    - `flight`: the event mode's free flight: `"closed"` (the model's closed form, where
      it has one: one loop iteration per half flight, exact to rounding) or
      `"integrated"` (steps of `piece_solver`, like the contacts). Static.
    - `autodiff`: which automatic differentiation the solve supports. `"reverse"`
      (default): `jax.grad`, `jax.vjp`, `jax.jacrev`, through a loop checkpointed at
      every step. `"forward"`: `jax.jvp`, `jax.jacfwd`, through a plain loop (and
      diffrax's `ForwardMode` for RK4 and Tsit5); reverse mode then raises. For a few
      parameters forward mode is the cheaper one: one tangent per parameter rides
      along with the solve. Static.
    - `allow_coarse_dt`: RK4 only: accept a step above the model's limit (a tenth of
      the contact time, `rk4_step_limit`), e.g. the paper's dt = 1 ms. Static.
    """

    method: str = eqx.field(static=True)
    max_steps: int = eqx.field(static=True)
    dt: Array | None
    rtol: Array
    atol: Array
    pcoeff: float = eqx.field(static=True, default=0.0)
    icoeff: float = eqx.field(static=True, default=1.0)
    max_events: int = eqx.field(static=True, default=2048)
    subgrid: int = eqx.field(static=True, default=4)
    dtmax: Array | None = None
    piece_solver: str = eqx.field(static=True, default="tsit5")
    flight: str = eqx.field(static=True, default="closed")
    autodiff: str = eqx.field(static=True, default="reverse")
    allow_coarse_dt: bool = eqx.field(static=True, default=False)

    def diffrax_solver(self):
        return RK4() if self.method == "rk4" else dfx.Tsit5()

    def controller(self):
        if self.method == "rk4":
            return dfx.ConstantStepSize()
        return dfx.PIDController(rtol=self.rtol, atol=self.atol, pcoeff=self.pcoeff, icoeff=self.icoeff)

    def adjoint(self):
        """diffrax's differentiation of `diffeqsolve` (RK4, Tsit5) for `autodiff`."""
        return dfx.ForwardMode() if self.autodiff == "forward" else dfx.RecursiveCheckpointAdjoint()


def api_spelling(knob: str, value: str | None = None) -> str:
    """How `simulate`'s keyword `knob` (set to `value`) is written in a hint."""
    if knob == "span":
        return "the time span"
    return knob if value is None else f"{knob}={value!r}"


def failure_hints(
    method: str,
    *,
    piece_solver: str = "tsit5",
    flight: str = "closed",
    dtmax: bool = False,
    spell=api_spelling,
) -> dict[str, str]:
    """What to change after a failure, naming only the knobs of `method`.

    **Arguments:** the run's method and event-mode settings (`dtmax`: whether a step
    cap was given), and
    `spell(knob, value=None)`, how a knob is written: `api_spelling` (`max_steps`,
    `piece_solver='dopri8'`), or the command line's flags.

    **Returns:** a dict with a hint per failure: `"max_steps"` (the step budget ran
    out), `"nonfinite"` (NaN or inf) and `"max_events"` (the event buffer is full).
    """
    span = spell("span")
    tolerances = f"{spell('rtol')}/{spell('atol')}"
    if method == "rk4":
        steps = (
            f"increase {spell('max_steps')} (to at least (t1 - t0)/dt) or {spell('dt')}, or shorten {span}"
        )
        nonfinite = (
            f"the fixed step {spell('dt')} is probably beyond RK4's stability limit for this contact "
            f"(contact time ~ pi*sqrt(m/kappa)); decrease {spell('dt')}, or use {spell('solver', 'tsit5')} "
            f"or {spell('solver', 'event')}"
        )
    else:
        cheaper = []
        if method == "event" and piece_solver == "tsit5":
            cheaper.append(f"{spell('piece_solver', 'dopri8')} (fewer steps at tolerances below ~1e-9)")
        if method == "event" and flight == "integrated":
            cheaper.append(f"{spell('flight', 'closed')} (one step per half flight)")
        if method == "event" and dtmax:
            cheaper.append(f"a larger {spell('dtmax')}")
        if method != "event":
            # A stiff contact, above all a ball at rest on a wall, costs about ω·t/3 steps of
            # any time-stepping solver; the event mode holds a resting contact in closed form.
            cheaper.append(
                f"{spell('solver', 'event')} (a stiff or resting contact costs it far fewer steps)"
            )
        steps = f"increase {spell('max_steps')}, loosen {tolerances}, " + (
            f"use {', '.join(cheaper)}, " if cheaper else ""
        )
        steps += f"or shorten {span}"
        nonfinite = f"check the parameters for NaN/inf, or tighten {tolerances}"
    events = f"increase {spell('max_events')} or shorten {span}"
    return {"max_steps": steps, "nonfinite": nonfinite, "max_events": events}


#: Settings built from plain numbers, by their arguments, their arrays on the device:
#: building an equinox Module costs ~0.15 ms, a tenth of a short event-mode call, and
#: copying its arrays to the device on every call more (see `make_settings`).
_CACHE = DeviceCache(128)
_UNCACHED = object()


#: Types whose values are their own cache key (with the type: True, 1 and 1.0 differ).
_KEYED_TYPES = frozenset((float, int, bool, str, type(None)))


def _plain(value):
    """A hashable stand-in for a plain number or None; `_UNCACHED` for anything else."""
    kind = type(value)
    if kind in _KEYED_TYPES:
        return (kind, value)
    if isinstance(value, (bool, np.bool_)):
        return ("bool", bool(value))
    if isinstance(value, (int, float, np.integer, np.floating)):
        return (type(value).__name__, float(value))
    if isinstance(value, np.ndarray) and value.shape == () and value.dtype.kind in "iuf":
        return ("0d", value.dtype.str, float(value))
    return _UNCACHED


def make_settings(method: str, span, **kwargs) -> SolverSettings:
    """Validate the solver arguments and build `SolverSettings` (see `_build_settings`).

    With plain numbers the same arguments give the same (immutable) settings object
    from a small cache, validated once; arrays and tracers are validated every time.
    """
    parts = tuple(map(_plain, kwargs.values()))
    span_key = _plain(span) if method == "rk4" else None
    if type(method) is not str or span_key is _UNCACHED or _UNCACHED in parts:
        return _build_settings(method, span, **kwargs)
    # Keyword order is part of the key (a different order only keeps a second copy).
    key = (method, span_key, tuple(kwargs), parts)
    return _CACHE.get(key, lambda: _build_settings(method, span, **kwargs))


def _build_settings(
    method: str,
    span,
    *,
    dt=None,
    rtol=1e-8,
    atol=1e-8,
    max_steps: int | None = None,
    max_events: int = 2048,
    subgrid: int = 4,
    dtmax=None,
    piece_solver: str = "tsit5",
    flight: str = "closed",
    autodiff: str = "reverse",
    allow_coarse_dt: bool = False,
) -> SolverSettings:
    """Validate the solver arguments and build `SolverSettings`."""
    check_choice("solver", method, SOLVERS)
    check_range("rtol", rtol, lo=0.0, hi=1.0, lo_open=True)
    check_range("atol", atol, lo=0.0, lo_open=True)
    check_range("dt", dt, lo=0.0, lo_open=True, unit="s", allow_none=method != "rk4")
    if method == "rk4" and is_concrete(dt) and is_concrete(span):
        step = float(np.min(np.asarray(dt)))
        needed = float(span) / step
        if needed > MAX_STEPS_LIMIT:
            raise InputError(
                f"dt = {step:g} s needs (t1 - t0)/dt = {needed:.3g} rk4 steps, more than "
                f"{MAX_STEPS_LIMIT:.0e}; valid range for this time span is dt >= "
                f"{float(span) / MAX_STEPS_LIMIT:.3g} s (or shorten the span, or use solver='tsit5' or 'event')"
            )
    if max_steps is not None:
        if not isinstance(max_steps, (int, np.integer)) or not 1 <= max_steps <= MAX_STEPS_LIMIT:
            raise InputError(
                f"max_steps = {max_steps!r} is out of range; valid range is integers >= 1 and <= {MAX_STEPS_LIMIT:.0e}"
            )
        max_steps = int(max_steps)
    elif method == "rk4":
        if not (is_concrete(dt) and is_concrete(span)):
            raise InputError("max_steps must be given when dt or the time span is traced (rk4)")
        max_steps = int(math.ceil(float(span) / float(np.min(np.asarray(dt))))) + 16
    else:
        max_steps = DEFAULT_MAX_STEPS[method]
    for name, value, low in (("max_events", max_events, 1), ("subgrid", subgrid, 1)):
        if not isinstance(value, (int, np.integer)) or value < low:
            raise InputError(f"{name} = {value!r} is out of range; valid range is integers >= {low}")
    check_choice("piece_solver", piece_solver, ("tsit5", "dopri8"))
    check_choice("flight", flight, ("closed", "integrated"))
    check_choice("autodiff", autodiff, AUTODIFF)
    check_range("dtmax", dtmax, lo=0.0, lo_open=True, unit="s", allow_none=True)
    if method == "rk4" and is_concrete(dt) and is_concrete(span):
        needed = math.ceil(float(span) / float(np.min(np.asarray(dt))))
        if needed > max_steps:
            raise InputError(
                f"max_steps = {max_steps} is too small for rk4: (t1 - t0)/dt = {needed} steps; "
                "increase max_steps or dt"
            )
    return SolverSettings(
        method=method,
        max_steps=max_steps,
        dt=None if dt is None else as_float_array(dt),
        rtol=as_float_array(rtol),
        atol=as_float_array(atol),
        max_events=int(max_events),
        subgrid=int(subgrid),
        dtmax=None if dtmax is None else as_float_array(dtmax),
        piece_solver=piece_solver,
        flight=flight,
        autodiff=autodiff,
        allow_coarse_dt=bool(allow_coarse_dt),
    )
