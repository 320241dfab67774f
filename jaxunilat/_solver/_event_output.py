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
        (count == lo + width) & (lo + width < n), lambda: _count_at_or_before(ts, t), lambda: count
    )


def _count_at_or_before(ts, t):
    """How many of the sorted save times `ts` are ≤ t: a binary search, ⌈log2(len + 1)⌉
    iterations."""
    ts, t = jax.lax.stop_gradient(ts), jax.lax.stop_gradient(t)

    def body(state):
        lo, hi = state
        mid = (lo + hi) // 2
        right = ts[jnp.minimum(mid, ts.shape[0] - 1)] <= t
        return jnp.where(right, mid + 1, lo), jnp.where(right, hi, mid)

    start = (jnp.array(0), jnp.array(ts.shape[0]))
    return jax.lax.while_loop(lambda state: state[0] < state[1], body, start)[0]


def _rows_of_times(rec, n_rec, n_ts, layout: StepRow):
    """The recorded row that holds each save time. Rows hold consecutive runs of save
    times (column `FIRST`: the index of a row's first one), so marking where each run
    starts and counting the marks gives every time its row. On a CPU the marks are set
    by a loop over the rows (a scatter would keep the solve's loop from being one
    kernel); elsewhere by a scatter."""
    firsts = _row_facts(rec, layout)[0]
    marks = jax.lax.platform_dependent(
        firsts,
        n_rec,
        cpu=functools.partial(_row_starts_loop, n_ts=n_ts),
        default=functools.partial(_row_starts_scatter, n_ts=n_ts),
    )
    return _running_sum(marks)


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


def _contact_steps(rec, n_rec, ts, layout: StepRow, step_to):
    """For each save time: its recorded row, whether that row is a contact, and there the
    pair's step from the row's start (`step_to(s, row)`; zeros at times in flight).

    On a CPU loops that step only where a contact is (`_contact_steps_sequential`), all
    in one loop kernel with `use_loop_kernels`; on other platforms vectorized
    (`_contact_steps_vectorized`). Both give the same numbers.
    """
    return jax.lax.platform_dependent(
        rec,
        n_rec,
        ts,
        cpu=functools.partial(_contact_steps_sequential, layout=layout, step_to=step_to),
        default=functools.partial(_contact_steps_vectorized, layout=layout, step_to=step_to),
    )


def _row_facts(rec, layout: StepRow):
    """(index of each row's first save time, whether each row is a contact)."""
    rec = jax.lax.stop_gradient(rec)
    return rec[:, layout.FIRST].astype(jnp.int32), jnp.any(rec[:, layout.mask] != 0, axis=1)


#: Save times per chunk in `_contact_steps_sequential`: a chunk with no time in contact
#: costs one branch instead of a loop iteration per time.
_CHUNK = 32


def _contact_steps_sequential(rec, n_rec, ts, *, layout: StepRow, step_to):
    """`_contact_steps` as loops that compile into the solve's kernel: each time's row
    (`_rows_of_times`), then a scan over chunks of `_CHUNK` times that steps only in
    the chunks that hold a time in contact, one time after the other (a contact lasts a
    few save times, so most chunks cost one branch)."""
    n_ts, n = ts.shape[0], rec.shape[1] - layout.width(0)
    index = _rows_of_times(rec, n_rec, n_ts, layout)
    contact = _row_facts(rec, layout)[1][index]
    size = min(n_ts, _CHUNK)
    chunks = -(-n_ts // size)
    pad = chunks * size - n_ts

    def padded(values, fill):
        values = jnp.concatenate([values, jnp.full(pad, fill, values.dtype)]) if pad else values
        return values.reshape(chunks, size)

    def one(_, time):
        s, i, inside = time
        row = jax.lax.dynamic_index_in_dim(rec, i, keepdims=False)
        return None, jax.lax.cond(inside, lambda: step_to(s, row), lambda: jnp.zeros(n, rec.dtype))

    def chunk(_, times):
        return None, jax.lax.cond(
            jnp.any(times[2]),
            lambda: jax.lax.scan(one, None, times)[1],
            lambda: jnp.zeros((size, n), rec.dtype),
        )

    times = (padded(ts, ts[-1]), padded(index, 0), padded(contact, False))
    y = jax.lax.scan(chunk, None, times)[1].reshape(-1, n)[:n_ts]
    return index, contact, y


def _contact_steps_vectorized(rec, n_rec, ts, *, layout: StepRow, step_to, few=64):
    """`_contact_steps` without a loop over the save times: the rows by
    `_rows_of_times`, and the times in contact gathered into chunks of `few`, a chunk
    with none skipped."""
    n_ts, n = ts.shape[0], rec.shape[1] - layout.width(0)
    index = _rows_of_times(rec, n_rec, n_ts, layout)
    contact = _row_facts(rec, layout)[1][index]
    size = min(n_ts, few)
    chunks = -(-n_ts // size)
    count = jnp.cumsum(contact)
    # The times in contact in order (padding: n_ts, out of range), in chunks.
    order = jnp.full(chunks * size, n_ts)
    order = order.at[jnp.where(contact, count - 1, n_ts)].set(jnp.arange(n_ts), mode="drop")

    def chunk(_, idx):
        def work():
            i = jnp.minimum(idx, n_ts - 1)
            return jax.vmap(step_to)(ts[i], rec[index[i]])

        return None, jax.lax.cond(idx[0] < n_ts, work, lambda: jnp.zeros((size, n), rec.dtype))

    y = jax.lax.scan(chunk, None, order.reshape(chunks, size))[1].reshape(-1, n)
    return index, contact, jnp.where(contact[:, None], y[jnp.clip(count - 1, 0, chunks * size - 1)], 0.0)


def _running_sum(values):
    """`jnp.cumsum` of an integer vector. On a CPU a sequential scan: with loop kernels one
    compiled loop of a few ns per element, where XLA:CPU's cumsum (reduce-window) is
    several kernels and ~10 µs for 2001 elements; elsewhere `jnp.cumsum`."""

    def sequential(v):
        return jax.lax.scan(lambda acc, x: (acc + x, acc + x), jnp.zeros((), v.dtype), v)[1]

    return jax.lax.platform_dependent(values, cpu=sequential, default=jnp.cumsum)
