"""The event mode's records and outputs: the event buffer, the step record and the
outputs at the save times.

Every event (entry, exit, apex, deepest point) is recorded in a fixed-size buffer
(`record_event`), and the start (time, state, region) of every accepted step that holds
a save time in another, at most one row per save time (`record_step`). After the loop
each output at a save time s is the pair's own step from the start of the recorded step
that holds s, of length s − t_start, or in free flight the model's closed form
(`save_outputs`).
"""

from __future__ import annotations

import dataclasses
import functools
from typing import ClassVar

import equinox as eqx
import equinox.internal as eqxi
import jax
import jax.numpy as jnp
from jaxtyping import Array

from ._batching import batching_mode
from ._event_pieces import erk_step
from ._event_state import ENTRY, EXIT, EXTREMUM, EventRow, Piece, Problem, State, StepRow


class EventRecord(eqx.Module):
    """The events of an event-mode run, in time order, padded to `max_events`.

    **Fields:**

    - `t`: event times, s (padding: +inf).
    - `y`: the state at each event.
    - `kind`: 1 = contact entry, 2 = contact exit, 3 = extremum of the observable
      (an apex in flight, the deepest point in contact); 0 = padding. The codes are
      also `EventRecord.ENTRY`, `EventRecord.EXIT` and `EventRecord.EXTREMUM`.
    - `wall`: the wall's index (lower first) for entries, exits and deepest points;
      −1 for an apex in flight.
    - `peak_force`: for exits, the largest |contact force| seen during that
      contact on the step sub-grid, N.
    - `count`: how many events were recorded.
    - `open_peak_force`: the running peak of a contact still open at t1, N.
    - `rest_time`: the time from which the contact open at t1 provably never ends
      (the ball rests on the lower wall: see `Ball.rest_error`), s; +inf if none.
      Such a contact has no exit and, once resting, no further events.
    """

    t: Array
    y: Array
    kind: Array
    wall: Array
    peak_force: Array
    count: Array
    open_peak_force: Array
    rest_time: Array

    #: The `kind` codes.
    ENTRY: ClassVar[int] = ENTRY
    EXIT: ClassVar[int] = EXIT
    EXTREMUM: ClassVar[int] = EXTREMUM


def record_event(problem: Problem, state: State, pred, t, y, kind, wall, peak) -> State:
    """`state` with the event (time t, s; state y; kind; wall; peak force, N) appended
    to the event buffer where `pred`; a full buffer sets `overflow` instead."""
    i = state.n_events
    ok = pred & (i < problem.max_events)
    return dataclasses.replace(
        state,
        ev=eqxi.buffer_at_set(state.ev, i, EventRow.pack(t, kind, wall, peak, y), pred=ok),
        n_events=i + jnp.where(ok, 1, 0),
        overflow=state.overflow | (pred & (i >= problem.max_events)),
    )


def record_step(problem: Problem, state: State, piece: Piece) -> State:
    """`state` with the accepted piece's start recorded (valid on [t, t_end]) if a save
    time lies in it. Its direction column is 0 for a resting piece (`_step_to` then
    takes the closed form)."""
    ts, n_ts = problem.ts, problem.ts.shape[0]
    t_end = piece.end.t_end
    holds = piece.accept & (state.saved < n_ts) & (ts[jnp.minimum(state.saved, n_ts - 1)] <= t_end)
    direction = jnp.where(state.resting, 0.0, state.direction) if problem.settles else state.direction
    row = problem.step_row.pack(state.t, t_end, direction, state.saved, state.mask, state.y)
    return dataclasses.replace(
        state,
        rec=eqxi.buffer_at_set(state.rec, state.n_rec, row, pred=holds & (state.n_rec < problem.rows)),
        n_rec=state.n_rec + jnp.where(holds, 1, 0),
        saved=jnp.where(holds, count_from(ts, state.saved, t_end), state.saved),
    )


def _step_to(problem: Problem, s, row):
    """The state at save time s (s) from a recorded row: the pair's step of length
    s − t_start, or a resting row's closed form."""
    layout = problem.step_row
    t_st, sign = row[layout.T0], row[layout.DIRECTION]
    mask, y_st = row[layout.mask] != 0, row[layout.y]

    def piece_rhs(tt, z):
        return problem.rhs(tt, z, mask, sign)

    def rk_step():
        return erk_step(problem.solver_cls, piece_rhs, t_st, s - t_st, y_st, piece_rhs(t_st, y_st))[0]

    if not problem.settles:
        return rk_step()
    return jax.lax.cond(sign == 0, lambda: problem.model.rest_state(y_st, s - t_st), rk_step)


def save_outputs(problem: Problem, final: State, y0, outputs) -> dict:
    """The outputs at the save times: NaN after the last time reached.

    The pair's own step from the start of the recorded step that holds each time (as
    accurate as a step, so the tolerance bounds the outputs too; the dense interpolant
    is much less accurate inside Dopri8's long flight steps), and in free flight the
    closed form from there.
    """
    model, ts, layout, rec = problem.model, problem.ts, problem.step_row, final.rec
    step_to = functools.partial(_step_to, problem)
    if problem.closed_flight:
        # Steps of the pair only at the times in contact (the contacts last milliseconds).
        index, contact, y_contact = _contact_steps(rec, final.n_rec, ts, layout, step_to)
        held = rec[index]
        t_start, direction = held[:, layout.T0], held[:, layout.DIRECTION]
        tau = jnp.where(contact, 0.0, ts - t_start)
        y_flight = jax.vmap(model.flight_state)(held[:, layout.y], tau, direction)
        y = jnp.where(contact[:, None], y_contact, y_flight)
    else:
        y = jax.vmap(step_to)(ts, rec[_rows_of_times(rec, final.n_rec, ts.shape[0], layout)])
    y = jnp.where((ts == problem.t0)[:, None], y0, y)
    ys = {name: jax.vmap(lambda s, z, name=name: model.output(name, s, z))(ts, y) for name in outputs}
    reached = ts <= final.t
    return {k: jnp.where(reached, v, jnp.nan) for k, v in ys.items()}


def event_record(final: State) -> EventRecord:
    """The `EventRecord` of the final loop state."""
    ev = final.ev
    return EventRecord(
        t=ev[:, EventRow.T],
        y=ev[:, EventRow.Y],
        kind=ev[:, EventRow.KIND].astype(jnp.int32),
        wall=ev[:, EventRow.WALL].astype(jnp.int32),
        peak_force=ev[:, EventRow.PEAK],
        count=final.n_events,
        open_peak_force=final.peak,
        rest_time=final.rest_time,
    )


#: Save times `count_from` compares at once, from the last count on.
_WINDOW = 32


def count_from(ts, start, t):
    """How many of the sorted save times `ts` are ≤ t (s), given that the first `start`
    are: one vectorized comparison of the next `_WINDOW` times, and the binary search
    `_count_at_or_before` only where all of them are ≤ t (a piece longer than that)."""
    ts, t = jax.lax.stop_gradient(ts), jax.lax.stop_gradient(t)
    n = ts.shape[0]
    width = min(_WINDOW, n)
    lo = jnp.minimum(start, n - width)  # the times before lo are <= t too
    count = lo + jnp.sum(jax.lax.dynamic_slice_in_dim(ts, lo, width) <= t, dtype=start.dtype)
    return jax.lax.cond(
        (count == lo + width) & (lo + width < n),
        lambda: _count_at_or_before(ts, t).astype(count.dtype),
        lambda: count,
    )


def _count_at_or_before(ts, t):
    """How many of the sorted save times `ts` are ≤ t: a binary search unrolled into
    ⌈log2(len + 1)⌉ vectorized steps (a `while` loop would run in lockstep under
    `jax.vmap`, a select over its carry at every trip)."""
    ts, t = jax.lax.stop_gradient(ts), jax.lax.stop_gradient(t)
    return jnp.searchsorted(ts, t, side="right", method="scan_unrolled")


def _rows_of_times(rec, n_rec, n_ts, layout: StepRow):
    """The recorded row that holds each save time: the last row whose first save time
    (column `FIRST`) is at or before it. Rows hold consecutive runs of save times, so
    marking where each run starts and counting the marks gives every time its row.

    Solves that run one row at a time (`batching_mode() == "rows"`, a CPU) set the marks
    by a loop over the rows: a scatter would keep the solve's loop from being one kernel.
    Solves batched in lockstep set them by one scatter: under `jax.vmap` that loop's trip
    count differs between rows and runs behind a select over all marks at every trip.
    """
    firsts = _row_facts(rec, layout)[0]
    starts = _row_starts_loop if batching_mode() == "rows" else _row_starts_scatter
    return _running_sum(starts(firsts, n_rec, n_ts=n_ts))


def _row_starts_loop(firsts, n_rec, *, n_ts):
    """1 at the first save time of each recorded row after the first, else 0 (n_ts
    entries): a loop over the rows."""

    def mark(r, marks):
        return jax.lax.dynamic_update_index_in_dim(marks, marks[firsts[r]] + 1, firsts[r], 0)

    return jax.lax.fori_loop(1, n_rec, mark, jnp.zeros(n_ts, jnp.int32))


def _row_starts_scatter(firsts, n_rec, *, n_ts):
    """`_row_starts_loop` as one scatter."""
    later = jnp.arange(1, firsts.shape[0]) < n_rec
    return jnp.zeros(n_ts, jnp.int32).at[jnp.where(later, firsts[1:], n_ts)].add(1, mode="drop")


def _row_facts(rec, layout: StepRow):
    """(index of each row's first save time, whether each row is a contact)."""
    rec = jax.lax.stop_gradient(rec)
    return rec[:, layout.FIRST].astype(jnp.int32), jnp.any(rec[:, layout.mask] != 0, axis=1)


#: Save times in contact stepped at once in `_contact_steps`.
_FEW = 32


def _contact_steps(rec, n_rec, ts, layout: StepRow, step_to, few: int = _FEW):
    """For each save time: its recorded row, whether that row is a contact, and there the
    pair's step from the row's start (`step_to(s, row)`; zeros at times in flight).

    A contact spans a few save times, so the pair steps only there: a loop over chunks
    of `few` times in contact, the k-th of them found by a binary search of the running
    count of times in contact, until every one is stepped. Under `jax.vmap` the loop runs
    as many chunks as the row with most times in contact needs (usually one or two), not
    a step per save time; without a scatter it stays inside the solve's loop kernel on a
    CPU.
    """
    n_ts, n = ts.shape[0], rec.shape[1] - layout.width(0)
    index = _rows_of_times(rec, n_rec, n_ts, layout)
    contact = _row_facts(rec, layout)[1][index]
    count = _running_sum(contact.astype(jnp.int32))
    total = count[-1]
    size = min(n_ts, few)
    chunks = -(-n_ts // size)

    def body(carry):
        k, out = carry
        # The (k·size + j + 1)-th time in contact: the first index where the count reaches it.
        wanted = k * size + jnp.arange(1, size + 1, dtype=count.dtype)
        i = jnp.minimum(jnp.searchsorted(count, wanted, side="left", method="scan_unrolled"), n_ts - 1)
        y = jax.vmap(step_to)(ts[i], rec[index[i]])
        return k + 1, eqxi.buffer_at_set(out, k, y.astype(rec.dtype))

    # A bounded loop (nested scans whose branches skip the chunks past the last time in
    # contact, for every row at once under `jax.vmap`): reverse and forward mode both
    # differentiate it; the stepped times are a buffer, not a checkpoint.
    init = (jnp.zeros((), count.dtype), jnp.zeros((chunks, size, n), rec.dtype))
    y = eqxi.while_loop(
        lambda carry: carry[0] * size < total,
        body,
        init,
        max_steps=chunks,
        buffers=lambda carry: carry[1],
        kind="bounded",
    )[1].reshape(chunks * size, n)
    y = y[jnp.clip(count - 1, 0, chunks * size - 1)]
    return index, contact, jnp.where(contact[:, None], y, 0.0)


def _running_sum(values):
    """`jnp.cumsum` of an integer vector. On a CPU a sequential scan: with loop kernels one
    compiled loop of a few ns per element, where XLA:CPU's cumsum (reduce-window) is
    several kernels and ~10 µs for 2001 elements; elsewhere `jnp.cumsum`."""

    def sequential(v):
        return jax.lax.scan(lambda acc, x: (acc + x, acc + x), jnp.zeros((), v.dtype), v)[1]

    return jax.lax.platform_dependent(values, cpu=sequential, default=jnp.cumsum)
