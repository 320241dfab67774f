"""The event mode: exact contact, located and restarted inside one compiled loop.

Each region (free flight, contact with a wall) is integrated on its own smooth
right-hand side by an explicit Runge–Kutta pair (or the model's closed forms for free
flight and for a contact that can never end), and every region boundary is located to
machine precision and restarted from; the outputs at the save times are steps of the
pair from recorded step starts. `event_solve` sets up the static `Problem` and runs the
loop, whose carry is the typed `State` (`_event_state`) and whose body (`_body`) takes
one piece (`_event_pieces`, root finding in `_event_locate`) and records it
(`_event_output`). The design, its measurements and what was rejected:
`jaxunilat/_solver/README.md`, "The event mode".
"""

from __future__ import annotations

import dataclasses

import equinox.internal as eqxi
import jax.numpy as jnp

from .._models._heaviside import jumps_located
from .._models._model import AbstractCanRest, AbstractClosedFormFlight, AbstractKinkedObservable
from ._event_output import EventRecord as EventRecord, event_record, record_event, record_step, save_outputs
from ._event_pieces import PIECE_SOLVERS, next_piece
from ._event_state import (
    ENTRY as ENTRY,
    EXIT as EXIT,
    EXTREMUM as EXTREMUM,
    Piece,
    Problem,
    State,
    initial_state,
    region_index,
)


def event_solve(model, y0, t0, t1, ts, settings, outputs):
    """Integrate `model` in event mode from (t0, y0) to t1 (s), saving `outputs` at `ts`.

    **Returns:** `(ys, y1, done, nonfinite, overflow, stats, events)`: the outputs at
    `ts`, the final state, whether t1 was reached, whether the solution became
    non-finite, whether the event buffer overflowed, the step counts and the
    `EventRecord`.
    """
    problem = _problem(model, y0, t0, t1, ts, settings)
    span = t1 - t0
    dt0 = span * 1e-4 if settings.dt is None else settings.dt
    init = initial_state(problem, y0, dt0)
    max_steps = settings.max_steps

    def cond(state):
        return _cond(problem, state)

    def body(state):
        return _body(problem, state)

    def buffers(state):
        return [state.rec, state.ev]

    # The carry outside the buffers is a few dozen numbers, so every step can be a
    # checkpoint: reverse mode then recomputes nothing.
    if settings.autodiff == "forward":
        # A plain loop: forward mode (jax.jvp, jax.jacfwd) differentiates it as it runs.
        final = eqxi.while_loop(cond, body, init, max_steps=max_steps, buffers=buffers, kind="lax")
    else:
        final = eqxi.while_loop(
            cond, body, init, max_steps=max_steps, buffers=buffers, kind="checkpointed", checkpoints=max_steps
        )
    with jumps_located():  # every contact entry and exit is located: no jump term is missed
        ys = save_outputs(problem, final, y0, outputs)
    stats = dict(
        num_steps=final.n_steps,
        num_accepted_steps=final.n_accepted,
        num_rejected_steps=final.n_rejected,
    )
    done = final.t >= t1
    return ys, final.y, done, final.nonfinite, final.overflow, stats, event_record(final)


def _problem(model, y0, t0, t1, ts, settings) -> Problem:
    """The static structure and traced values of a solve (see `Problem`)."""
    solver_cls, exponent = PIECE_SOLVERS[settings.piece_solver]
    dtype = y0.dtype
    return Problem(
        model=model,
        t0=t0,
        t1=t1,
        ts=ts,
        rtol=settings.rtol,
        atol=settings.atol,
        dtmax=t1 - t0 if settings.dtmax is None else settings.dtmax,
        fractions=jnp.linspace(0.0, 1.0, settings.subgrid + 1)[1:],
        solver_cls=solver_cls,
        exponent=exponent,
        kink=isinstance(model, AbstractKinkedObservable) and bool(model.observable_kink),
        # A contact that can never end (a ball at rest) in closed form, where the model
        # has one (static): one piece from where that is proven, to t1.
        settles=isinstance(model, AbstractCanRest),
        # Free flight in closed form where the model has one (a scene option, static).
        closed_flight=settings.flight == "closed" and isinstance(model, AbstractClosedFormFlight),
        max_events=settings.max_events,
        # Each save time is in one recorded step, so the steps that hold one fit in
        # len(ts) rows.
        rows=min(settings.max_steps, ts.shape[0]),
        huge=float(jnp.finfo(dtype).max) ** 0.8,
    )


def _cond(problem: Problem, state: State):
    """Whether the loop goes on: t1 not reached, and nothing has failed."""
    return (state.t < problem.t1) & ~state.nonfinite & ~state.overflow


def _body(problem: Problem, state: State) -> State:
    """One iteration: the next piece, then its records, the rest test and the advance."""
    piece = next_piece(problem, state)
    accept = piece.accept
    state = dataclasses.replace(
        state,
        n_steps=state.n_steps + 1,
        n_accepted=state.n_accepted + jnp.where(accept, 1, 0),
        n_rejected=state.n_rejected + jnp.where(accept, 0, 1),
        nonfinite=piece.fail,
    )
    state = record_step(problem, state, piece)
    state = _record_piece_events(problem, state, piece)
    if problem.settles:
        state = _update_rest(problem, state, piece)
    return _advance(state, piece)


def _record_piece_events(problem: Problem, state: State, piece: Piece) -> State:
    """Record the piece's events (an apex in every flight, the first deepest point in
    each contact, the crossing that ends it) and update the open contact's peak force."""
    end, accept = piece.end, piece.accept
    in_contact = jnp.any(state.mask)
    rec_ext = accept & end.has_extremum & ~(in_contact & state.seen_extremum)
    ext_wall = jnp.where(in_contact, jnp.argmax(state.mask), -1)
    state = record_event(problem, state, rec_ext, end.t_extremum, end.y_extremum, EXTREMUM, ext_wall, 0.0)
    seen = state.seen_extremum | (rec_ext & in_contact)
    peak = jnp.where(accept & in_contact, jnp.maximum(state.peak, piece.f_max), state.peak)
    event = accept & end.crossed
    # An entry, or an exit with the contact's peak force: one row either way.
    kind = jnp.where(end.entering, ENTRY, EXIT)
    state = record_event(
        problem, state, event, end.t_cross, end.y_cross, kind, end.wall, jnp.where(end.entering, 0.0, peak)
    )
    f_new = problem.contact_force_abs(end.y_cross, end.mask)
    return dataclasses.replace(
        state,
        peak=jnp.where(event, jnp.where(end.entering, f_new, 0.0), peak),
        seen_extremum=jnp.where(event, False, seen),
    )


def _update_rest(problem: Problem, state: State, piece: Piece) -> State:
    """From the end of this piece, can the contact never end, and does the closed form
    follow it to t1? An exit (which a proven rest cannot have) clears the rest time, so
    that it never outlives its contact."""
    end = piece.end
    proven, ready = problem.rest_bound(end.y_end, end.mask, end.t_end)
    proven, ready = piece.accept & proven, piece.accept & proven & ready
    first_proof = proven & (state.rest_time == jnp.inf)
    exit_ = piece.accept & end.crossed & ~end.entering
    return dataclasses.replace(
        state,
        rest_time=jnp.where(exit_, jnp.inf, jnp.where(first_proof, end.t_end, state.rest_time)),
        resting=state.resting | ready,
    )


def _advance(state: State, piece: Piece) -> State:
    """Move to the end of an accepted piece, and pick the next trial step (s).

    A crossing changes the right-hand side, so the step size just used says little
    about the new region: the next step starts from the last accepted step of its
    previous visit (repeated bounces look alike: no rejections at each contact entry),
    or on a first visit from min(dt_new, h), shrinking on rejection.
    """
    end, accept = piece.end, piece.accept
    event = accept & end.crossed
    dt_region = jnp.where(
        accept, state.dt_region.at[region_index(state.mask)].set(piece.h_used), state.dt_region
    )
    remembered = dt_region[region_index(end.mask)]
    first_visit = jnp.where(remembered < jnp.inf, remembered, jnp.minimum(piece.dt_new, piece.h_used))
    return dataclasses.replace(
        state,
        t=jnp.where(accept, end.t_end, state.t),
        y=jnp.where(accept, end.y_end, state.y),
        mask=jnp.where(accept, end.mask, state.mask),
        f0=jnp.where(accept, end.f0, state.f0),
        direction=jnp.where(accept, end.direction, state.direction),
        dt_region=dt_region,
        dt=jnp.where(event, first_visit, piece.dt_new),
        # The PI controller's memory: the last accepted step's error norm (a flight or
        # a rest piece passes it on).
        err_prev=jnp.where(accept, piece.err, state.err_prev),
    )
