"""The event mode: exact contact, located and restarted inside one compiled loop.

The exact model is smooth inside each region (free flight, contact with a wall), so
the loop integrates the region's own smooth right-hand side with an explicit
Runge–Kutta pair (Tsit5, or Dopri8 for tight tolerances) and stops at every region
boundary:

1. One loop over steps (`equinox.internal.while_loop`, checkpointed with every step
   a checkpoint, so it supports `jax.jit`, `jax.vmap` and reverse-mode `jax.grad`;
   with `autodiff="forward"` a plain loop, for `jax.jvp` and `jax.jacfwd`).
   Each step uses diffrax's Butcher tableau with the stages unrolled, and the pair's
   continuous extension (diffrax's interpolant, as a polynomial in θ collected once
   per step: `_dense`); step-size control is a PI controller on the embedded
   error estimate (`_event_pieces._step_factor`).
2. After each accepted step the switching functions g_i (signed distances into the
   walls) are checked on a sub-grid of the step's dense interpolant, and at the roots
   of the model's observable (v for the ball: apexes and deepest points). Checking at
   the extremum catches a crossing that enters and leaves within one step, the free
   flight pitfall where a parabola's zero error estimate lets a step jump over a wall.
3. The earliest crossing is located on the interpolant by safeguarded Newton under
   `stop_gradient` to machine precision, polished by Newton on the pair's own step
   (the dense output is less accurate than a step), then one differentiable Newton
   update t* ← t* − g(t*)/ġ(t*) gives the implicit-function gradient of the event time.
4. The state at t* comes from that step, the region flips, and the step restarts
   there (FSAL is reset) with the last accepted step size of the previous visit to
   the new kind of region. With the drag's kink (|v|·v), a piece also ends at every
   root of v unless the kink's effect over the step is negligible.

5. A contact that can provably never end (a ball resting on the lower wall under
   gravity: inside the contact the energy about the static deflection never increases,
   and below the exit threshold the ball cannot get back to the wall; the model's
   `rest_error`) costs one piece instead of explicit steps at ω = √(κ/m) to t1. After
   every accepted piece the model bounds the error of its closed form (`rest_state`)
   over the rest of the span; once that bound is within the tolerance (atol + rtol·|y|,
   in the model's energy-norm units) the next piece is that closed form, to t1 in one
   loop iteration (its record row has direction 0, so that the outputs at the save
   times in it come from the closed form too). For the ball that is
   the damped oscillator about x = wall − mg/κ (Kelvin–Voigt: exact without drag, and
   with drag once the drag's effect is provably below the tolerance) or the exact rest
   state (Hunt–Crossley, once the energy keeps the ball that close to it). Until then
   the steps go on (the damping brings the bound down); the contact gets no exit, and
   `EventRecord.rest_time` says from when it provably never ends. The decisions are
   under `stop_gradient` and the closed forms are plain `jax.numpy`, so the rest is
   differentiable (the rest position carries the derivatives in κ, m, g) and vmapped
   (resting rows and flying rows in one batch).

Every event (entry, exit, apex, deepest point) is recorded in a fixed-size buffer,
and the start (time, state, region) of every accepted step that holds a save time in
another (at most one row per save time). After the loop each output at a save time s
is the pair's own step from the start of the recorded step that holds s, of length
s − t_start (or, in free flight, the model's closed form): as accurate as a step,
where the dense interpolant inside a long flight step is not (Dopri8 at tol 1e-10:
7.0e-10 m against 1.5e-9 m over example 2), and a row of 4 + n_sw + n numbers instead
of the interpolant's 3 + 15n.

Nothing in the loop body is a sort, a scatter or a host callback, so that XLA:CPU can
compile the whole loop into one kernel (`jaxunilat.use_loop_kernels`). The body picks
its piece with `lax.cond`s whose branches return one packed array (`packed_cond`:
XLA:CPU copies every output of a conditional on every call), nested two-way rather
than one three-way switch (which changed how XLA compiled the other branches).

Layout (as diffrax's `_integrate.py`): this module holds `event_solve`, which sets up
the static `Problem` and runs the loop, and the loop body (`_body`: one piece, then
its bookkeeping). The loop's carry is one typed `State` and a piece returns a `Piece`
(`_event_state`); the pieces are `_event_pieces` (a step of the pair, a closed-form
flight, a closed-form rest), root finding is `_event_locate`, and the event buffer,
the step record and the outputs at the save times are `_event_output`.
"""

from __future__ import annotations

import dataclasses

import equinox.internal as eqxi
import jax.numpy as jnp

from .._models._heaviside import jumps_located
from ._event_locate import locate as _locate  # noqa: F401 (the tests import it from here)
from ._event_output import (
    EventRecord as EventRecord,
    _contact_steps_sequential as _contact_steps_sequential,
    _contact_steps_vectorized as _contact_steps_vectorized,
    _count_at_or_before as _count_at_or_before,
    event_record,
    record_event,
    record_step,
    save_outputs,
)
from ._event_pieces import (
    PIECE_SOLVERS as PIECE_SOLVERS,
    erk_step as _erk_step,  # noqa: F401 (the tests import it from here)
    next_piece,
)
from ._event_state import (
    _EV as _EV,
    _REC as _REC,
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
    init = _carry(initial_state(problem, y0, dt0))
    max_steps = settings.max_steps

    def cond(carry):
        return _cond(problem, State(**carry))

    def body(carry):
        return _carry(_body(problem, State(**carry)))

    def buffers(carry):
        return [carry["rec"], carry["ev"]]

    # The carry outside the buffers is a few dozen numbers, so every step can be a
    # checkpoint: reverse mode then recomputes nothing.
    if settings.autodiff == "forward":
        # A plain loop: forward mode (jax.jvp, jax.jacfwd) differentiates it as it runs.
        final = eqxi.while_loop(cond, body, init, max_steps=max_steps, buffers=buffers, kind="lax")
    else:
        final = eqxi.while_loop(
            cond, body, init, max_steps=max_steps, buffers=buffers, kind="checkpointed", checkpoints=max_steps
        )
    final = State(**final)
    with jumps_located():  # every contact entry and exit is located: no jump term is missed
        ys = save_outputs(problem, final, y0, outputs)
    stats = dict(
        num_steps=final.n_steps,
        num_accepted_steps=final.n_accepted,
        num_rejected_steps=final.n_rejected,
    )
    done = final.t >= t1
    return ys, final.y, done, final.nonfinite, final.overflow, stats, event_record(final)


def _carry(state: State) -> dict:
    """The loop's carry: the `State`'s fields by name.

    A dict flattens in the order of its keys, so the loop carries the fields in
    alphabetical order rather than the `State`'s grouped order. XLA:CPU's compiled loop
    depends on the order of its carry: in forward mode (a plain loop with tangents) the
    grouped order changed the last bits of the derivatives (4e-12 relative on Table 1
    example 2), and this order is the one the outputs were first computed with.
    """
    return {field.name: getattr(state, field.name) for field in dataclasses.fields(state)}


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
        kink=bool(getattr(model, "observable_kink", False)),
        # A contact that can never end (a ball at rest) in closed form, where the model
        # has one (static): one piece from where that is proven, to t1.
        settles=hasattr(type(model), "rest_error"),
        # Free flight in closed form where the model has one (a scene option, static).
        closed_flight=settings.flight == "closed" and hasattr(type(model), "flight_state"),
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
    state = record_event(
        problem, state, event & ~end.entering, end.t_cross, end.y_cross, EXIT, end.wall, peak
    )
    state = record_event(problem, state, event & end.entering, end.t_cross, end.y_cross, ENTRY, end.wall, 0.0)
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
