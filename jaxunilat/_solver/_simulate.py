"""`simulate`: the package's one jitted entry point."""

from __future__ import annotations

import contextlib
import enum
import functools
import logging
import math
import re
import sys
import threading
import warnings
from collections import Counter
from collections.abc import Callable

import diffrax as dfx
import equinox as eqx
import equinox.internal as eqxi
import jax
import jax.numpy as jnp
import numpy as np
from jaxtyping import Array, ArrayLike

from .._internal import _loop_kernels
from .._internal._errors import InputError
from .._internal._executables import kept_call
from .._internal._placement import on_host
from .._internal._validate import (
    InputTypeError,
    as_float_array,
    check_choice,
    check_range,
    is_concrete,
    real_number,
    runtime_check,
)
from .._models._contact import RK4_STEPS_PER_CONTACT
from .._models._heaviside import Exact
from .._models._model import AbstractCanRest, AbstractContactModel, AbstractModel, AbstractSwitchedModel
from ._batching import batching_mode, rowwise_differentiable
from ._device_cache import DeviceCache
from ._event import EventRecord, event_solve
from ._event_state import EventRow
from ._settings import SolverSettings, failure_hints, make_settings

#: The most memory `simulate` lets one run's save times and outputs (or the event
#: mode's event buffer) take, bytes: beyond it, a ValueError names `samples` or
#: `max_events` before anything is allocated.
MAX_OUTPUT_BYTES = 4 * 2**30
#: How many times each jitted function was traced (compiled). Tests and the
#: benchmark read it to prove that new parameter values do not retrace.
_TRACES: Counter = Counter()


def trace_counts() -> dict[str, int]:
    """How many times each jitted entry point has been traced in this process."""
    return dict(_TRACES)


class UncheckedStepWarning(UserWarning):
    """`simulate(solver="rk4")` could not check the step against the model's limit
    (`model.rk4_step_limit()` is None for a model with contacts, e.g. the coupling
    with `HuntCrossley`, whose driven motion has no a-priori bound on its penetration)."""


class Status(enum.IntEnum):
    """Outcome of a run, stored as `Solution.status`."""

    SUCCESS = 0
    MAX_STEPS = 1
    NONFINITE = 2
    SOLVER_FAILED = 3
    EVENT_OVERFLOW = 4
    #: A traced input out of its valid range (concrete ones raise `ValueError` before
    #: the solve): the outputs are meaningless. With `throw=True` the error names it.
    INVALID_INPUT = 5


def _messages(settings: SolverSettings) -> list[str]:
    hints = failure_hints(
        settings.method,
        piece_solver=settings.piece_solver,
        flight=settings.flight,
        dtmax=settings.dtmax is not None,
    )
    return [
        f"jaxunilat.simulate: the solver used all max_steps = {settings.max_steps} steps "
        f"before t1 ({settings.method}); {hints['max_steps']}.",
        f"jaxunilat.simulate: the solution became non-finite (NaN or inf); {hints['nonfinite']}.",
        f"jaxunilat.simulate: the {settings.method} solver failed (diffrax reported an error "
        "other than max_steps); pass throw=False to inspect the partial result.",
        f"jaxunilat.simulate: more than max_events = {settings.max_events} events (entries, exits, "
        f"apexes, deepest points); {hints['max_events']}.",
    ]


class Solution(eqx.Module):
    """The result of `simulate`.

    **Fields:**

    - `ts`: the save times, s.
    - `ys`: a dict of the requested outputs, each an array over `ts`
      (x in m, v in m/s, force in N, penetration in m, energy in J, contact in {0, 1}).
    - `y1`: the state at t1.
    - `status`: a `Status` code (0 = success).
    - `num_steps`, `num_accepted_steps`, `num_rejected_steps`: solver statistics.
    - `events`: the event mode's `EventRecord` (contact entries and exits, apexes,
      deepest points); `None` for the other solvers.
    - `reason`: which of `messages` explains a failed status (−1 on success); with
      `throw=False` under `jax.vmap`, one per row. `message` reads them.
    - `messages`: the failure messages `throw=True` would raise (static).
    """

    ts: Array
    ys: dict[str, Array]
    y1: Array
    status: Array
    num_steps: Array
    num_accepted_steps: Array
    num_rejected_steps: Array
    events: EventRecord | None = None
    reason: Array | None = None
    messages: tuple[str, ...] = eqx.field(static=True, default=())

    def __getitem__(self, name: str) -> Array:
        return self.ys[name]

    def __repr__(self) -> str:
        """A short summary: shapes, the save times' span, the status in words (concrete
        results) and the step counts; the static failure messages are not listed."""
        ys = ", ".join(f"{name!r}: {_shape(value)}" for name, value in self.ys.items())
        parts = [f"ts={_shape(self.ts)}{_span(self.ts)}", f"ys={{{ys}}}", f"y1={_shape(self.y1)}"]
        concrete = not isinstance(self.status, jax.core.Tracer)
        parts.append(f"status={self.message!r}" if concrete else f"status={_shape(self.status)}")
        if concrete and np.size(self.num_steps) == 1:
            parts.append(f"steps={int(self.num_steps)} ({int(self.num_rejected_steps)} rejected)")
        if self.events is not None:
            parts.append(f"events={_shape(self.events.t)}")
        return f"Solution({', '.join(parts)})"

    @property
    def ok(self) -> bool:
        """True when every run in the (possibly batched) result succeeded."""
        return bool(np.all(np.asarray(self.status) == Status.SUCCESS))

    @property
    def message(self) -> str:
        """A human-readable description of the status (concrete results only): `success`,
        or each distinct failure with the message `throw=True` would raise, e.g.
        `invalid_input: jaxunilat.simulate: kappa = ... is out of range ...` (one entry
        per distinct failure of a batch, with its row count)."""
        codes = np.asarray(self.status).ravel()
        reasons = np.full(codes.shape, -1) if self.reason is None else np.asarray(self.reason).ravel()
        failed = sorted(
            {(int(c), int(r)) for c, r in zip(codes, reasons, strict=True) if c != Status.SUCCESS}
        )
        if not failed:
            return Status.SUCCESS.name.lower()
        parts = []
        for code, reason in failed:
            text = Status(code).name.lower()
            if 0 <= reason < len(self.messages):
                text += ": " + self.messages[reason]
            rows = int(np.sum((codes == code) & (reasons == reason)))
            parts.append(text + (f" ({rows} of {codes.size} rows)" if codes.size > 1 else ""))
        return "; ".join(parts)


def _shape(value) -> str:
    """`f64[5]`-style dtype and shape of an array (or a tracer)."""
    dtype = jnp.dtype(value.dtype)
    short = {"f": "f", "i": "i", "u": "u", "b": "bool"}.get(dtype.kind, dtype.kind)
    name = short if short == "bool" else f"{short}{8 * dtype.itemsize}"
    return f"{name}[{','.join(str(n) for n in np.shape(value))}]"


def _span(ts) -> str:
    """` over [t0, t1] s` of concrete save times; empty for traced or empty ones."""
    if isinstance(ts, jax.core.Tracer) or np.size(ts) == 0:
        return ""
    t = np.asarray(ts)
    return f" over [{t.min():.6g}, {t.max():.6g}] s"


_FORWARD_ONLY = (
    "jaxunilat.simulate: autodiff='forward' differentiates in forward mode only (jax.jvp, "
    "jax.jacfwd); for jax.grad, jax.vjp or jax.jacrev pass autodiff='reverse' (the default)."
)


def _input_checks(model, y0, t0, t1, ts, settings: SolverSettings) -> list[tuple[str, Array]]:
    """(message, valid) per run-time check of a solve's inputs, in the order they are
    reported: what `simulate` and the model check on concrete values before compiling,
    for traced ones (under `jax.jit`, `jax.vmap`, `jax.grad`). Each `valid` is a scalar
    bool (per row under `jax.vmap`); all are evaluated once, before the solve."""
    checks = list(model.runtime_checks())
    checks.append(runtime_check("t0", t0, unit="s"))
    checks.append(runtime_check("t1 - t0", t1 - t0, lo=0.0, lo_open=True, unit="s"))
    checks.append(runtime_check("y0", y0))
    checks.append(
        (
            "jaxunilat.simulate: ts must be sorted within [t0, t1] (traced values).",
            jnp.all(jnp.diff(ts) >= 0) & (ts[0] >= t0) & (ts[-1] <= t1),
        )
    )
    checks.append(runtime_check("rtol", settings.rtol, lo=0.0, hi=1.0, lo_open=True))
    checks.append(runtime_check("atol", settings.atol, lo=0.0, lo_open=True))
    for name, value in (("dt", settings.dt), ("dtmax", settings.dtmax)):
        if value is not None:
            checks.append(runtime_check(name, value, lo=0.0, lo_open=True, unit="s"))
    if settings.method == "rk4" and not settings.allow_coarse_dt:
        limit = model.rk4_step_limit(jnp, y0)
        if limit is not None:
            checks.append(
                (
                    "jaxunilat.simulate: dt is beyond rk4's stability limit for this contact, a tenth "
                    "of the contact time t_c = pi/omega_d (the traced dt or parameters); decrease dt, "
                    "or use solver='tsit5' or solver='event' (or pass allow_coarse_dt=True).",
                    jnp.all(settings.dt <= limit[0]),
                )
            )
    return checks


def _finish(ys, y1, status, settings, throw, ts, stats, events=None, checks=()):
    messages = _messages(settings)
    reason = jnp.maximum(status - 1, 0)
    if checks:
        valid = jnp.stack([ok for _, ok in checks])
        # The first failed check, reported instead of whatever the solve did with it.
        reason = jnp.where(jnp.all(valid), reason, len(messages) + jnp.argmin(valid))
        status = jnp.where(jnp.all(valid), status, Status.INVALID_INPUT).astype(jnp.int32)
        messages = messages + [message for message, _ in checks]
    if throw:
        ys = eqx.branched_error_if(ys, status != Status.SUCCESS, reason, messages)
    if settings.autodiff == "forward":
        # A clear error instead of JAX's about transposing a while loop.
        ys, y1, events = eqxi.nondifferentiable_backward((ys, y1, events), msg=_FORWARD_ONLY)
    return Solution(
        ts=ts,
        ys=ys,
        y1=y1,
        status=status,
        num_steps=stats["num_steps"],
        num_accepted_steps=stats["num_accepted_steps"],
        num_rejected_steps=stats["num_rejected_steps"],
        events=events,
        reason=jnp.where(status == Status.SUCCESS, -1, reason).astype(jnp.int32),
        messages=tuple(messages),
    )


def _can_rest(model) -> bool:
    """Whether the time-stepping solve looks for a ball at rest (static): the model has
    a rest criterion (`AbstractCanRest`) that can hold for this instance (`can_rest`)."""
    return isinstance(model, AbstractCanRest) and bool(model.can_rest)


def _rest_event(model, settings: SolverSettings, t1):
    """A terminating diffrax event: the contact provably never ends and the model's
    closed form (`rest_state`) follows it to t1 within the tolerance, atol + rtol·|y|
    (the event mode's test, in the model's amplitude units, m for the ball). The
    criterion's parameter-only part is computed once, not at every step."""
    bound_of = model.rest_error_fn()

    def resting(t, y, args, **kwargs):
        y = jax.lax.stop_gradient(y)
        bound = bound_of(y, args.switches(y) > 0, t1 - t)
        return bound <= settings.atol + settings.rtol * jnp.max(jnp.abs(y))

    return dfx.Event(resting)


def _hold_rest(model, sol, ts, t1, save_fn, ys, y1):
    """After a rest event at t_e (from state y_e): the save times after t_e, and y1,
    from the closed form `model.rest_state(y_e, t − t_e)` (diffrax leaves them unfilled).

    **Returns:** (ys, y1, ok): ok is true for a run that ended at t1 or at a rest event.
    """
    held = sol.result == dfx.RESULTS.event_occurred
    t_e, y_e = sol.ts[1][0], sol.ys[1][0]
    after = held & (ts > t_e)
    tau = jnp.where(after, ts - t_e, 0.0)  # safe: the closed form is unused before t_e
    rest = jax.vmap(lambda s, dt: save_fn(s, model.rest_state(y_e, dt), model))(ts, tau)
    ys = {
        name: jnp.where(after.reshape(after.shape + (1,) * (value.ndim - 1)), rest[name], value)
        for name, value in ys.items()
    }
    y1 = jnp.where(held, model.rest_state(y_e, jnp.where(held, t1 - t_e, 0.0)), y1)
    return ys, y1, (sol.result == dfx.RESULTS.successful) | held


def _stand_in(checks, t0, t1, ts, dt):
    """(t0, t1, ts, dt) for diffrax: the given ones when every input check passes, else
    t0 = 0 s, t1 = 1 s, every ts at t0 and dt = 1 s (one step)."""
    valid = jnp.all(jnp.stack([ok for _, ok in checks]))
    t0_run = jnp.where(valid, t0, 0.0)
    t1_run = jnp.where(valid, t1, 1.0)
    ts_run = jnp.where(valid, ts, t0_run)  # not a constant array: nothing for XLA to fold
    dt_run = None if dt is None else jnp.where(valid, dt, 1.0)
    return t0_run, t1_run, ts_run, dt_run


_CHECKS_LOCK = threading.RLock()


@contextlib.contextmanager
def _diffrax_checks_off():
    """Trace `diffeqsolve` without its run-time input checks (equinox's `error_if`).

    `_solve_impl` checks every input itself and hands diffrax a valid stand-in when one
    fails (`_stand_in`), and it calls diffrax with `throw=False`. diffrax still guards
    `SaveAt(ts)` and `dt0` with `eqx.error_if`, which compiles to a Python host callback
    that can never fire here, yet makes the program impossible to serialise, so the
    command line's executable cache could not keep the tsit5 and rk4 modes.

    equinox reads its `EQX_ON_ERROR` setting (documented: raise, nan, breakpoint, off)
    from the environment once, at import, into the module `equinox._errors`; this
    switches that value to "off" while the solve is traced, and only when it is the
    default "raise" (a user debugging with `EQX_ON_ERROR=breakpoint` keeps it). An
    equinox that keeps the setting elsewhere is left alone: the checks then stay, and
    the cache calls such a program plainly (`internal._executables`). The setting is
    process-wide: solves traced in other threads wait for the lock, but an `error_if`
    traced by other code in another thread during those milliseconds is also off.
    """
    module = sys.modules.get("equinox._errors")
    if getattr(module, "EQX_ON_ERROR", None) != "raise":
        yield
        return
    with _CHECKS_LOCK:
        module.EQX_ON_ERROR = "off"
        try:
            yield
        finally:
            module.EQX_ON_ERROR = "raise"


def _diffeqsolve(model, settings, t0, t1, dt, y0, saveat, rests, t_end):
    """diffrax's solve of the tsit5 and rk4 modes, with `throw=False` (the status is
    read from `result`)."""
    return dfx.diffeqsolve(
        dfx.ODETerm(lambda t, y, args: args.vector_field(t, y)),
        settings.diffrax_solver(),
        t0,
        t1,
        dt,
        y0,
        args=model,
        saveat=saveat,
        stepsize_controller=settings.controller(),
        adjoint=settings.adjoint(),
        max_steps=settings.max_steps,
        event=_rest_event(model, settings, t_end) if rests else None,
        throw=False,
    )


def _solve_impl(model, y0, t0, t1, ts, settings: SolverSettings, outputs: tuple[str, ...], throw: bool):
    _TRACES["simulate"] += 1
    checks = _input_checks(model, y0, t0, t1, ts, settings)
    if settings.method == "event":
        ys, y1, done, nonfinite, overflow, stats, events = event_solve(
            model, y0, t0, t1, ts, settings, outputs
        )
        finite = jnp.all(jnp.isfinite(y1))
        status = jnp.where(
            nonfinite | ~finite,
            Status.NONFINITE,
            jnp.where(overflow, Status.EVENT_OVERFLOW, jnp.where(done, Status.SUCCESS, Status.MAX_STEPS)),
        ).astype(jnp.int32)
        return _finish(ys, y1, status, settings, throw, ts, stats, events, checks)

    def save_fn(t, y, args):
        return {name: args.output(name, t, y) for name in outputs}

    # An invalid traced input is reported as Status.INVALID_INPUT by `_finish`; diffrax
    # gets a harmless stand-in (span [0, 1] s, one step, ts on it) instead, whose own
    # checks (decreasing or outlying ts, a step of the wrong sign) would otherwise raise
    # through a host callback even with throw=False. Valid inputs pass unchanged.
    t0_run, t1_run, ts_run, dt_run = _stand_in(checks, t0, t1, ts, settings.dt)
    saveat = dfx.SaveAt(subs=[dfx.SubSaveAt(ts=ts_run, fn=save_fn), dfx.SubSaveAt(t1=True)])
    # The adaptive solver only: RK4's fixed step is the user's (a diverging run must
    # fail, not pass through a state that looks at rest).
    rests = settings.method == "tsit5" and _can_rest(model)
    with _diffrax_checks_off():
        sol = _diffeqsolve(model, settings, t0_run, t1_run, dt_run, y0, saveat, rests, t1)
    ys, y1 = sol.ys[0], sol.ys[1][0]
    ok = sol.result == dfx.RESULTS.successful
    if rests:
        ys, y1, ok = _hold_rest(model, sol, ts_run, t1_run, save_fn, ys, y1)
    finite = jnp.all(jnp.isfinite(y1))
    for value in ys.values():
        finite = finite & jnp.all(jnp.isfinite(value))
    steps = sol.result == dfx.RESULTS.max_steps_reached
    status = jnp.where(
        ok,
        jnp.where(finite, Status.SUCCESS, Status.NONFINITE),
        jnp.where(steps, Status.MAX_STEPS, jnp.where(finite, Status.SOLVER_FAILED, Status.NONFINITE)),
    ).astype(jnp.int32)
    return _finish(ys, y1, status, settings, throw, ts, sol.stats, checks=checks)


def _solve_uncounted(model, y0, t0, t1, ts, settings, outputs, throw):
    """`_solve_impl` without counting a trace: the batching wrappers trace it more than
    once per compilation (and again when `jax.vmap` applies their rule)."""
    count = _TRACES["simulate"]
    try:
        return _solve_impl(model, y0, t0, t1, ts, settings, outputs, throw)
    finally:
        _TRACES["simulate"] = count


def _solve_batched(model, y0, t0, t1, ts, settings, outputs, throw, vmap):
    """`_solve_impl` with the batching rule `vmap` (`_batching.batching_mode()`): under
    `jax.vmap`, `"rows"` runs the rows one by one (`lax.map`), `"batch"` in lockstep
    (the design and its autodiff limits: `jaxunilat._solver._batching`). RK4 always batches:
    its rows take the same fixed steps through no branches, so lockstep wastes nothing
    and the batch shares each step's overhead (row by row is ~3x slower per row)."""
    if vmap == "batch" or settings.method == "rk4":
        return _solve_impl(model, y0, t0, t1, ts, settings, outputs, throw)
    _TRACES["simulate"] += 1
    solve = functools.partial(_solve_uncounted, outputs=outputs, throw=throw)
    return rowwise_differentiable(solve, settings.autodiff)(model, y0, t0, t1, ts, settings)


#: The compiled solve. Plain `jax.jit` (every leaf of a model or of the settings is an
#: array; structure is in their static fields): its C++ dispatch costs ~80 µs less per
#: call than `equinox.filter_jit`, a fifth of a short event-mode call.
_solve = jax.jit(_solve_batched, static_argnames=("outputs", "throw", "vmap"))


def _run(model, y0, t0, t1, ts, settings, outputs, throw):
    """Call `_solve` (through the command line's executable cache, `_executables`, when it
    is on); with `throw`, wait for the result and turn a solver failure into an
    `equinox.EquinoxRuntimeError` that carries only our message (`_solver_error`)."""
    args = (model, y0, t0, t1, ts, settings)
    static = (outputs, throw, batching_mode())
    with _solver_failures():
        # throw's errors are host callbacks, which a kept executable cannot hold.
        sol = _solve(*args, *static) if throw else kept_call("simulate", _solve, args, static)
        if throw and not isinstance(sol.status, jax.core.Tracer):
            sol.status.block_until_ready()
    return sol


@contextlib.contextmanager
def _solver_failures():
    """Raise a solver failure inside the block as the solver's message alone
    (`_solver_error`); any other error passes unchanged."""
    try:
        yield
    except (jax.errors.JaxRuntimeError, ValueError) as err:
        clean = _solver_error(err)
        if clean is None:
            raise
        raise clean from None


#: Where equinox's message ends in the text of the error JAX raises for a failed host
#: callback: equinox appends advice about `equinox.filter_jit` after three line breaks.
_EQX_ADVICE = re.compile(r"\n\s*\n\s*\n|\n-{5,}")


def _solver_error(err: BaseException) -> eqx.EquinoxRuntimeError | None:
    """The solver's message inside JAX's error for a failed run, as an
    `equinox.EquinoxRuntimeError` of that message alone; None for any other error.

    JAX raises the failure of `throw=True` (an `equinox.branched_error_if` host callback)
    as a `JaxRuntimeError` on a function's first call and as a plain `ValueError`
    (`INTERNAL: CpuCallback error ...`) from its C++ fast path on later calls; both
    carry the callback's traceback and equinox's advice about `equinox.filter_jit`, which
    is not ours to give (`simulate` is already compiled)."""
    text = str(err)
    marker = "_EquinoxRuntimeError: "
    start = text.find(marker)
    if start < 0:
        return None
    message = _EQX_ADVICE.split(text[start + len(marker) :], maxsplit=1)[0].strip()
    return eqx.EquinoxRuntimeError(message or "jaxunilat.simulate: the run failed")


def one_failure_message(fn: Callable) -> Callable:
    """Wrap a public function that runs solves (`sweep`, the `analysis` studies): a solver
    failure inside it raises `equinox.EquinoxRuntimeError` with the solver's message alone
    (`_solver_error`), as `simulate` does, instead of JAX's callback traceback and
    equinox's advice. A concrete result is waited for, so that the failure surfaces here;
    under a user's `jax.jit` the wrapper only passes the call through."""

    @functools.wraps(fn)
    def wrapper(*args, **kwargs):
        with _solver_failures():
            out = fn(*args, **kwargs)
            leaves = [leaf for leaf in jax.tree_util.tree_leaves(out) if isinstance(leaf, jax.Array)]
            if leaves and not any(isinstance(leaf, jax.core.Tracer) for leaf in leaves):
                jax.block_until_ready(leaves)
        return out

    return wrapper


class _OwnFailureLog(logging.Filter):
    """Drop JAX's log record (`jax.pure_callback failed`, with the callback's traceback,
    on stderr) for a failure of `simulate(throw=True)`: the same failure is raised as an
    exception that carries its message, so the record only repeats it with a traceback
    and equinox's advice. Other callbacks' records pass."""

    def filter(self, record: logging.LogRecord) -> bool:
        info = record.exc_info
        error = info[1] if isinstance(info, tuple) and len(info) > 1 else None
        return not (type(error).__name__ == "_EquinoxRuntimeError" and str(error).startswith("jaxunilat."))


logging.getLogger("jax._src.callback").addFilter(_OwnFailureLog())


#: Default save times on the device, by (t0, t1, samples): building them with NumPy and
#: copying them to the device costs ~50 µs per call.
_TIMES = DeviceCache(64)


def _default_times(t0, t1, samples: int):
    """(t0, t1, `samples` uniform save times over [t0, t1]) as device arrays."""
    if not (is_concrete(t0) and is_concrete(t1)):
        return t0, t1, jnp.linspace(t0, t1, samples)
    key = (float(t0), float(t1), samples)
    return _TIMES.get(key, lambda: (t0, t1, np.linspace(key[0], key[1], samples)))


_ZERO = np.zeros((), np.float64)
_ZERO.flags.writeable = False


def _time_span(t_span):
    if _plain_floats((t_span,), 1) is not None and t_span > 0:
        return _ZERO, np.asarray(t_span, dtype=np.float64)  # the common case: t1 > t0 = 0
    if isinstance(t_span, (tuple, list)):
        if len(t_span) != 2:
            raise InputError(f"t_span = {t_span!r} must be t1 or a pair (t0, t1), in s")
        t0, t1 = t_span
    else:
        t0, t1 = 0.0, t_span
    check_range("t0", t0, unit="s")
    check_range("t1", t1, unit="s")
    if is_concrete(t0) and is_concrete(t1) and not float(t1) > float(t0):
        raise InputError(f"t1 = {float(t1):g} s is out of range; valid range is t1 > t0 = {float(t0):g} s")
    return as_float_array(t0), as_float_array(t1)


def simulate(
    model: AbstractModel,
    y0: ArrayLike,
    t_span,
    *,
    solver: str = "tsit5",
    dt: ArrayLike | None = None,
    allow_coarse_dt: bool = False,
    rtol: ArrayLike = 1e-8,
    atol: ArrayLike = 1e-8,
    max_steps: int | None = None,
    max_events: int = 2048,
    dtmax: ArrayLike | None = None,
    piece_solver: str = "tsit5",
    flight: str = "closed",
    autodiff: str = "reverse",
    ts: ArrayLike | None = None,
    samples: int = 1001,
    outputs: tuple[str, ...] = ("x", "v"),
    throw: bool = True,
) -> Solution:
    """Integrate a model from y0 over a time span and save the requested outputs.

    **Arguments:**

    - `model`: a model such as `Ball.table1(2)`: parameters (traced) and structure (static).
    - `y0`: the initial state, e.g. (x0 [m], v0 [m/s]) for the ball.
    - `t_span`: t1, or a pair (t0, t1), in s.
    - `solver`: `"rk4"` (the paper's fixed-step method, needs `dt`), `"tsit5"`
      (adaptive, PID step control with `rtol`, `atol`) or `"event"` (the exact
      model with every contact entry and exit located, integrated piecewise with
      Tsit5 at `rtol`, `atol`; correct gradients through impacts; needs
      `heaviside=Exact()`).
    - `dt`: the RK4 step, s (for the adaptive methods: an optional first step). RK4
      refuses a step above the model's limit, a tenth of the contact time
      (`model.rk4_step_limit()`): coarser steps lose or misplace contacts, and diverge.
    - `allow_coarse_dt`: RK4 only: run such a step anyway, e.g. to reproduce the
      paper's dt = 1 ms with its lost contacts.
    - `rtol`, `atol`: the adaptive methods' tolerances.
    - `max_steps`: the step budget (see `SolverSettings`).
    - `max_events`: the event mode's event buffer size.
    - `dtmax`: the event mode's largest step, s.
    - `piece_solver`: the event mode's Runge–Kutta pair, `"tsit5"` or `"dopri8"`.
    - `flight`: the event mode's free flight: `"closed"` (default: the model's closed
      form where it has one, e.g. the ball's tan/tanh solution with quadratic drag;
      one loop iteration from a wall to the apex and one back) or `"integrated"`
      (Runge–Kutta steps, as in contact).
    - `autodiff`: `"reverse"` (default: `jax.grad`, `jax.vjp`, `jax.jacrev`; the loop
      is checkpointed at every step) or `"forward"` (`jax.jvp`, `jax.jacfwd`; a plain
      loop, where reverse mode raises). For a few parameters forward mode is cheaper:
      `jax.jacfwd` of an event-mode loss in (κ, k_r) costs about 2 forward solves
      against 15–25 for `jax.grad`, and compiles in half the time (README, Performance).
    - `ts`: save times, s, sorted within [t0, t1]. Default: `samples` uniform
      times over [t0, t1], both ends included.
    - `outputs`: which outputs to save, from `model.output_names`
      (ball: x, v, force, penetration, energy, contact). Only these are stored.
    - `throw`: raise on failure (max_steps exhausted, non-finite values) with a
      message that says what to change: an `equinox.EquinoxRuntimeError` whose text
      is that message alone, on the first call and on every later one. With
      `throw=False` the result's `status` says what happened instead. Inside your own
      `jax.jit` the failure surfaces where that function runs, as JAX's error around
      the message; `equinox.filter_jit` reports it as an `EquinoxRuntimeError`, or
      pass `throw=False` and read `Solution.message`.

    **Returns:** a `Solution`.

    Changing only parameter values (model leaves, y0, t_span, ts, dt, rtol, atol)
    does not retrace. Batch with `jax.vmap`, differentiate with `jax.grad` (or
    `jax.jacfwd` with `autodiff="forward"`); use the event mode, or a smooth Heaviside
    option, for meaningful gradients of the penalty model. On a CPU the solvers' step
    loops compile into single kernels (3–8× faster calls, README, Performance) when
    jaxunilat is imported before JAX's first computation; otherwise the first call warns
    once with the fix (`jaxunilat.use_loop_kernels`; `JAXUNILAT_NO_LOOP_KERNELS=1` opts
    out).

    A concrete call's validation is cheap on repeated calls: what depends only on the
    model's class and the static settings is checked once per combination, the solver
    settings and default save times built from plain numbers are cached.
    """
    if not isinstance(model, AbstractModel):
        raise InputError(f"model = {model!r} is not a jaxunilat model (e.g. Ball.table1(2))")
    if not _loop_kernels._CHECKED:
        _loop_kernels.warn_if_missing(stacklevel=3)
    if not jax.config.jax_enable_x64:
        raise InputError(
            "precision = float32 is not supported (jax_enable_x64 is off); valid: float64. In float32 "
            "the step at a contact's kink must shrink below the time resolution (1.2e-7*t, t + dt == t), "
            "so Tsit5 stalls at the first contacts (t ~ 0.1 s), and penetrations below 1.2e-7*|x| are "
            "lost; call jax.config.update('jax_enable_x64', True). float32 input arrays are fine: "
            "simulate casts them to float64."
        )
    # A concrete single call is latency-bound: on the host CPU where the default backend is
    # an accelerator (`internal.on_host`; the user's own placement wins).
    with on_host() if _is_concrete_tree((model, y0)) else contextlib.nullcontext():
        outputs = _check_outputs(model, outputs)
        y0 = _check_y0(model, y0)
        t0, t1 = _time_span(t_span)
        span = t1 - t0  # before the save times put t0 and t1 on the device
        t0, t1, ts = _save_times(t0, t1, ts, samples, len(outputs))
        if solver == "event":
            _check_event_mode(model, max_events)
        settings = make_settings(
            solver,
            span,
            dt=dt,
            rtol=rtol,
            atol=atol,
            max_steps=max_steps,
            max_events=max_events,
            dtmax=dtmax,
            piece_solver=piece_solver,
            flight=flight,
            autodiff=autodiff,
            allow_coarse_dt=allow_coarse_dt,
        )
        if solver == "rk4" and not allow_coarse_dt:
            _check_rk4_step(model, dt, y0)
        return _run(model, y0, t0, t1, ts, settings, outputs, bool(throw))


#: Checks that depend only on static things (the model's class, `outputs`, the event
#: mode's structure), by their key: passed once, they pass again (each costs more than
#: the look-up). Bounded: cleared when it reaches `_STATIC_SIZE` keys.
_STATIC_OK: dict = {}
_STATIC_SIZE = 1024


def _static_once(key, check, *args):
    """`check(*args)`, or its result kept under the hashable `key` (None: not kept)."""
    if key is not None:
        try:
            return _STATIC_OK[key]
        except (KeyError, TypeError):  # new, or not hashable
            pass
    result = check(*args)
    if key is not None:
        if len(_STATIC_OK) >= _STATIC_SIZE:
            _STATIC_OK.clear()
        try:
            _STATIC_OK[key] = result
        except TypeError:
            pass
    return result


def _check_outputs(model, outputs) -> tuple[str, ...]:
    """`outputs` as a tuple of the model's output names (ValueError otherwise); a tuple
    is checked once per model class."""
    key = ("outputs", type(model), outputs) if type(outputs) is tuple else None
    return _static_once(key, _checked_outputs, model, outputs)


def _checked_outputs(model, outputs) -> tuple[str, ...]:
    if isinstance(outputs, str):
        raise InputTypeError(
            f"outputs = {outputs!r} is a string; give a tuple of names from "
            f"{', '.join(model.output_names)} (one name: outputs=({model.output_names[0]!r},))"
        )
    outputs = tuple(outputs)
    if not outputs:
        raise InputError("outputs = () is empty; request at least one of " + ", ".join(model.output_names))
    for name in outputs:
        check_choice("output", name, model.output_names)
    return outputs


def _check_y0(model, y0) -> Array:
    """The initial state as a float64 array of the model's state shape, checked finite
    and (when concrete) physically possible (`model.check_initial_state`)."""
    fast = _plain_floats(y0, len(type(model).state_names))
    if fast is not None:
        host = np.array(fast, dtype=np.float64)
        # Through the class: `model.check_initial_state` builds an equinox bound-method
        # Module, which costs more than the check.
        type(model).check_initial_state(model, host)
        return _INITIAL_STATES.get(host.tobytes(), lambda: host)
    y0 = as_float_array(real_number("y0", y0))
    if y0.shape != (len(model.state_names),):
        raise InputError(
            f"y0 has shape {y0.shape}; expected ({len(model.state_names)},) for the state "
            f"({', '.join(model.state_names)})"
        )
    if is_concrete(y0):
        # The checks read a NumPy view: indexing a device array dispatches an operation.
        host = np.asarray(y0)
        check_range("y0", host)
        type(model).check_initial_state(model, host)
    return y0


#: Initial states given as plain numbers, on the device, by their bytes: a repeated y0
#: is not copied to the device again.
_INITIAL_STATES = DeviceCache(64)


def _plain_floats(value, size: int) -> tuple | None:
    """`value` when it is a tuple or list of `size` finite Python floats or ints (not
    bools, at most 2**53 in magnitude), the common concrete case checked without NumPy;
    None otherwise."""
    if type(value) not in (tuple, list) or len(value) != size:
        return None
    for v in value:
        if type(v) is float:
            if not math.isfinite(v):
                return None
        elif type(v) is not int or not -_EXACT_INT <= v <= _EXACT_INT:
            return None
    return value


_EXACT_INT = 2**53


def _save_times(t0, t1, ts, samples, num_outputs: int):
    """(t0, t1, ts): the given save times `ts` (s) checked, or `samples` uniform ones over
    [t0, t1], refused beyond `MAX_OUTPUT_BYTES` before anything is allocated."""
    if ts is None:
        if not isinstance(samples, (int, np.integer)) or samples < 2:
            raise InputError(f"samples = {samples!r} is out of range; valid range is integers >= 2")
        most = MAX_OUTPUT_BYTES // (8 * (num_outputs + 1))
        if samples > most:
            raise InputError(
                f"samples = {samples!r} is out of range: the save times and {num_outputs} outputs would "
                f"take {8 * samples * (num_outputs + 1) / 2**30:.3g} GiB; valid range is integers 2 to "
                f"{most} (at most {MAX_OUTPUT_BYTES / 2**30:g} GiB)"
            )
        return _default_times(t0, t1, int(samples))
    ts = as_float_array(real_number("ts", ts, unit="s"))
    if ts.ndim != 1 or ts.shape[0] < 1:
        raise InputError(f"ts has shape {ts.shape}; expected a non-empty 1-D array of times in s")
    if is_concrete(ts) and is_concrete(t0) and is_concrete(t1):
        arr = np.asarray(ts)
        if np.any(np.diff(arr) < 0) or arr[0] < float(t0) or arr[-1] > float(t1):
            raise InputError(f"ts must be sorted within [t0, t1] = [{float(t0):g}, {float(t1):g}] s")
    return t0, t1, ts


def _check_event_mode(model, max_events) -> None:
    """Refuse a model the event mode cannot solve, and an event buffer beyond
    `MAX_OUTPUT_BYTES` (once per model class, Heaviside option and `max_events`)."""
    plain = type(max_events) is int
    key = ("event", type(model), _heaviside_type(model), max_events) if plain else None
    _static_once(key, _checked_event_mode, model, max_events)


#: Whether a model class is an `AbstractContactModel`, by class: the look-up costs less
#: than `isinstance` (this runs on every event-mode call).
_CONTACT_CLASSES: dict[type, bool] = {}


def _heaviside_type(model) -> type | None:
    """The class of the model's Heaviside option; None for a model without one."""
    cls = type(model)
    has = _CONTACT_CLASSES.get(cls)
    if has is None:
        has = _CONTACT_CLASSES[cls] = issubclass(cls, AbstractContactModel)
    return type(model.heaviside) if has else None


def _checked_event_mode(model, max_events) -> None:
    if isinstance(model, AbstractContactModel) and not isinstance(model.heaviside, Exact):
        raise InputError(
            f"heaviside = {type(model.heaviside).__name__} is not supported with solver='event'; "
            "the event mode solves the exact model: use heaviside=Exact()"
        )
    if not isinstance(model, AbstractSwitchedModel):
        raise InputError(
            f"solver = 'event' is not supported for {type(model).__name__}: the event mode needs "
            "an AbstractSwitchedModel (switching functions and region vector fields)"
        )
    if isinstance(max_events, (int, np.integer)):
        per_event = 8 * (EventRow.HEAD + len(model.state_names))
        if max_events > MAX_OUTPUT_BYTES // per_event:
            raise InputError(
                f"max_events = {max_events!r} is out of range: the event buffer would take "
                f"{max_events * per_event / 2**30:.3g} GiB; valid range is integers 1 to "
                f"{MAX_OUTPUT_BYTES // per_event} (at most {MAX_OUTPUT_BYTES / 2**30:g} GiB)"
            )


def _is_concrete_tree(tree) -> bool:
    return all(is_concrete(leaf) for leaf in jax.tree_util.tree_leaves(tree))


def _check_rk4_step(model, dt, y0) -> None:
    """Raise `ValueError` when a concrete RK4 step `dt` exceeds the model's limit
    (traced values are checked at run time: `Status.INVALID_INPUT`)."""
    if not (is_concrete(dt) and is_concrete(y0) and _is_concrete_tree(model)):
        return
    # On the host: NumPy copies of the leaves (no device dispatch per operation).
    host = jax.tree_util.tree_map(np.asarray, model)
    found = type(host).rk4_step_limit(host, np, np.asarray(y0))  # no bound-method Module
    step = float(np.max(np.asarray(dt)))
    if found is None:
        if isinstance(model, AbstractSwitchedModel) and model.num_switches > 0:
            law = type(model.law).__name__ if isinstance(model, AbstractContactModel) else "its law"
            warnings.warn(
                f"rk4's step dt = {step:g} s is not checked for this "
                f"{type(model).__name__}: its contact ({law}) has no "
                "known step limit, and a step beyond it runs to wrong values with status SUCCESS; "
                "compare with solver='event', or use solver='tsit5'",
                UncheckedStepWarning,
                stacklevel=3,
            )
        return
    limit, t_c = (float(v) for v in found)
    if not step > limit:
        return
    if math.isfinite(t_c) and limit == t_c / RK4_STEPS_PER_CONTACT:
        form = model.law.step_time_scale if isinstance(model, AbstractContactModel) else "pi/omega_d"
        why = f"a tenth of the contact time t_c = {form} = {t_c:.3g} s"
    else:
        why = "the time scale of the contact's damping (1/|lambda| of its fastest mode)"
    raise InputError(
        f"dt = {step:g} s is beyond rk4's stability limit for this contact; valid range is "
        f"(0, {limit:.3g}] s ({why}); use dt <= {limit:.3g} s, or solver='tsit5' or solver='event' "
        "(allow_coarse_dt=True runs it anyway, losing contacts)"
    )
