"""The event mode's problem, loop state and piece result (see `jaxunilat._event`).

`Problem` is what every part of the loop reads: the model, the span, the save times and
tolerances (traced) and the static structure that decides the compiled graph. `State` is
the loop's carry, `PieceEnd` and `Piece` what one piece of the loop returns. The carry
outside the two buffers (`rec`, `ev`) is a few dozen numbers, so every step can be a
checkpoint of the reverse-mode loop.
"""

from __future__ import annotations

import typing
from typing import Any

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
from jaxtyping import Array

from . import _dense

#: Event kinds in `EventRecord.kind`.
ENTRY, EXIT, EXTREMUM = 1, 2, 3


class EventRow:
    """Columns of a row of the event buffer (`State.ev`): the event's time (s), kind,
    wall and peak contact force (N), then its state y."""

    T, KIND, WALL, PEAK = 0, 1, 2, 3
    HEAD = 4  # the leading columns; y follows
    Y = slice(HEAD, None)

    @staticmethod
    def pack(t, kind, wall, peak, y):
        """One row (`y`'s dtype)."""
        dtype = y.dtype
        head = [jnp.asarray(v, dtype) for v in (t, kind, wall, peak)]
        return jnp.concatenate([jnp.stack(head), y])


@typing.final
class StepRow(eqx.Module):
    """Columns of a row of the step record (`State.rec`): the recorded piece's start
    t0 and end (s), the observable's sign in it (0: a resting piece), the index of its
    first save time, then its region's mask (n_sw) and the state y0 at t0 (n)."""

    n_sw: int = eqx.field(static=True)

    T0, T_END, DIRECTION, FIRST = 0, 1, 2, 3
    HEAD = 4  # the leading columns; mask and y0 follow

    @property
    def mask(self) -> slice:
        return slice(self.HEAD, self.HEAD + self.n_sw)

    @property
    def y(self) -> slice:
        return slice(self.HEAD + self.n_sw, None)

    def width(self, n: int) -> int:
        """Columns of a row for a state of n components."""
        return self.HEAD + self.n_sw + n

    def pack(self, t0, t_end, direction, first, mask, y):
        """One row (`y`'s dtype)."""
        dtype = y.dtype
        head = jnp.stack([jnp.asarray(v, dtype) for v in (t0, t_end, direction, first)])
        return jnp.concatenate([head, mask.astype(dtype), y])


@typing.final
class Problem(eqx.Module):
    """What the loop integrates: traced values first, then the static structure.

    `rhs`, `contact_force_abs` and `rest_bound` are the model's region vector field and
    the two quantities derived from it that the loop records or decides on.
    """

    model: Any
    t0: Array  # s
    t1: Array  # s
    ts: Array  # save times, s (sorted)
    rtol: Array
    atol: Array
    dtmax: Array  # largest step, s
    fractions: Array  # the detection sub-grid, as fractions of a step in (0, 1]
    solver_cls: type = eqx.field(static=True)  # the Runge–Kutta pair (diffrax class)
    exponent: float = eqx.field(static=True)  # of the step-size controller: 1/(q + 1)
    kink: bool = eqx.field(static=True)  # the vector field has a kink at the observable's root
    settles: bool = eqx.field(static=True)  # the model has a closed-form rest (`rest_error`)
    closed_flight: bool = eqx.field(static=True)  # free flight in the model's closed form
    max_events: int = eqx.field(static=True)  # rows of the event buffer
    rows: int = eqx.field(static=True)  # rows of the step record
    huge: float = eqx.field(static=True)  # every evaluation of the vector field is clipped here

    @property
    def n_sw(self) -> int:
        """The number of switching functions (walls)."""
        return self.model.num_switches

    @property
    def step_row(self) -> StepRow:
        """The columns of the step record's rows."""
        return StepRow(self.n_sw)

    def rhs(self, t, y, mask, direction):
        """The smooth right-hand side of a region (`mask`) and sign of the observable.

        A rejected trial step can overflow (a stiff contact or the drag's v² over a step
        far too long for them). Its values are discarded, but reverse mode still runs
        through them, and a zero cotangent times an infinite partial derivative is NaN.
        Clipping every evaluation at `huge` keeps all values and partials finite; a state
        beyond `huge` counts as non-finite.
        """
        if self.kink:
            f = self.model.region_vector_field(t, y, mask, direction)
        else:
            f = self.model.region_vector_field(t, y, mask)
        return jnp.clip(f, -self.huge, self.huge)

    def contact_force_abs(self, y, mask):
        """|m a − m a_free|: the contact force's magnitude in a region, N."""
        one = jnp.ones((), y.dtype)
        a = self.rhs(self.t0, y, mask, one)[1:]
        a_free = self.rhs(self.t0, y, jnp.zeros_like(mask), one)[1:]
        return jnp.max(jnp.abs(a - a_free)) * self.model.contact_mass

    def rest_bound(self, y, mask, t):
        """(whether the contact at (t, y) provably never ends, whether the closed form
        follows it to t1 within a step's accuracy).

        The model's bound on its closed form's error over [t, t1] (+inf: the contact can
        still end) against the tolerance of the largest state component, in the energy
        norm's units (m for the ball).
        """
        bound = jax.lax.stop_gradient(self.model.rest_error(y, mask, self.t1 - t))
        scale = self.atol + self.rtol * jnp.max(jnp.abs(jax.lax.stop_gradient(y)))
        return bound < jnp.inf, bound <= scale


@typing.final
class State(eqx.Module):
    """The loop's carry."""

    # -- time and state -------------------------------------------------------------
    t: Array  # s
    y: Array
    f0: Array  # the vector field at (t, y) in the current piece (FSAL)
    # -- region ---------------------------------------------------------------------
    mask: Array  # (n_sw,) bool: in contact with switch i
    direction: Array  # the observable's sign in the current piece (±1)
    # -- step-size controller -------------------------------------------------------
    dt: Array  # the next trial step, s
    # The last accepted step's error norm (at least `ERR_FLOOR`), for the PI controller.
    err_prev: Array
    # The last accepted step in each kind of region (free, then in contact with switch
    # i), s: the first step after a crossing starts from the previous visit's.
    dt_region: Array
    # -- rest -----------------------------------------------------------------------
    # The contact provably never ends (from `rest_time` on, s) and the model's closed
    # form follows it to t1 within the tolerance: the next piece is that closed form.
    resting: Array
    rest_time: Array
    # -- the open contact -----------------------------------------------------------
    seen_extremum: Array  # its deepest point is recorded
    peak: Array  # its running peak |contact force|, N
    # -- event buffer ---------------------------------------------------------------
    # One row per event (columns: `EventRow`); a contact open at t0 is recorded as an
    # entry at t0. Padding: t = +inf.
    ev: Array
    n_events: Array
    overflow: Array  # an event found no free row
    # -- step record, for the outputs at the save times ------------------------------
    # One row per accepted step that holds a save time (at most one per save time;
    # columns: `StepRow`), enough to take the piece's step from t0 to any time in
    # [t0, t_end] (unused rows: zeros);
    # `saved` save times lie at or before the last recorded step's end.
    rec: Array
    n_rec: Array
    saved: Array
    # -- statistics -----------------------------------------------------------------
    n_steps: Array
    n_accepted: Array
    n_rejected: Array
    nonfinite: Array  # the last piece failed (non-finite, or its step underflowed)


@typing.final
class PieceEnd(eqx.Module):
    """Where a piece ends, and the events in it."""

    # -- the end of the piece (the start of the next one) ----------------------------
    t_end: Array  # s
    y_end: Array
    mask: Array
    direction: Array
    f0: Array  # the vector field at the end, in the next piece
    # -- the observable's extremum in the piece (with a kink: where it ends) ----------
    has_extremum: Array
    t_extremum: Array  # s
    y_extremum: Array
    # -- the crossing that ends it --------------------------------------------------
    crossed: Array
    t_cross: Array  # s
    y_cross: Array
    entering: Array
    wall: Array


@typing.final
class Piece(eqx.Module):
    """What a piece returns: its end, and the step-size controller's verdict."""

    end: PieceEnd
    accept: Array
    fail: Array  # non-finite, or a rejected step far below the rounding of t
    dt_new: Array  # the next trial step, s
    err: Array  # the step's error norm (1: at the tolerance), floored at `ERR_FLOOR`
    h_used: Array  # the step to remember for this kind of region, s
    f_max: Array  # the peak |contact force| in the piece, N


@typing.final
class Trial(eqx.Module):
    """A trial step of the Runge–Kutta pair from (t, y), and its cheap event tests."""

    # -- the step -------------------------------------------------------------------
    t: Array  # its start, s
    h: Array  # its length, s
    t_next: Array  # its end, s (t1 where it lands within rounding of it)
    y: Array
    y1: Array
    f1: Array  # the vector field at (t_next, y1) (FSAL)
    coeffs: tuple  # its continuous extension (`_dense.coefficients`)
    scale: Array  # the error scale atol + rtol·max(|y|, |y1|), per component
    # -- the step-size controller's verdict -------------------------------------------
    finite: Array
    accept: Array
    err: Array  # the error norm (1: at the tolerance), floored at `ERR_FLOOR`
    dt_new: Array  # the next trial step, s
    # -- detection on the sub-grid ----------------------------------------------------
    sub_t: Array  # s
    sub_y: Array
    obs_start: Array  # the observable at the start (with a kink: its sign there)
    obs_sub: Array
    flips: Array  # the observable changes sign before each sub-grid point
    has_ext: Array
    eventful: Array  # accepted, with an extremum or a switch on the wrong side

    def dense(self, s):
        """The state at time s (s) on the step's continuous extension (`_dense`)."""
        return _dense.evaluate(self.t, self.h, self.y, self.coeffs, s)


def initial_state(problem: Problem, y0, dt0) -> State:
    """The loop's carry at t0: the region and observable sign y0 starts in (where it
    starts on a boundary, the one it enters next), and a contact open at t0 recorded
    as an entry at t0. `dt0`: the first trial step, s."""
    model, t0, n_sw = problem.model, problem.t0, problem.n_sw
    dtype = y0.dtype
    g0 = model.switches(y0)
    dg0 = jax.jvp(model.switches, (y0,), (model.region_vector_field(t0, y0, g0 > 0),))[1]
    mask0 = (g0 > 0) | ((g0 == 0) & (dg0 > 0))
    # The sign of the observable in the first piece (where it starts at 0: the sign
    # it takes next).
    obs0 = model.observable(y0)
    dobs0 = jax.jvp(model.observable, (y0,), (problem.rhs(t0, y0, mask0, jnp.ones((), dtype)),))[1]
    direction0 = jnp.where(obs0 != 0, jnp.sign(obs0), jnp.where(dobs0 != 0, jnp.sign(dobs0), 1.0)).astype(
        dtype
    )
    f_init = problem.rhs(t0, y0, mask0, direction0)
    start_in_contact = jnp.any(mask0)
    if problem.settles:
        proven0, resting0 = problem.rest_bound(y0, mask0, t0)
    else:
        proven0 = resting0 = jnp.array(False)
    first_event = EventRow.pack(t0, ENTRY, jnp.argmax(mask0), 0.0, y0)
    return State(
        t=t0,
        y=y0,
        f0=f_init,
        mask=mask0,
        direction=direction0,
        dt=jnp.asarray(dt0, dtype),
        err_prev=jnp.asarray(1.0, dtype),
        dt_region=jnp.full(n_sw + 1, jnp.inf, dtype),
        resting=resting0,
        rest_time=jnp.where(proven0, t0, jnp.inf).astype(dtype),
        seen_extremum=jnp.array(False),
        peak=jnp.where(jnp.any(mask0), problem.contact_force_abs(y0, mask0), 0.0),
        ev=jnp.where(
            (jnp.arange(problem.max_events)[:, None] == 0) & start_in_contact,
            first_event,
            jnp.zeros((problem.max_events, EventRow.HEAD + y0.shape[0]), dtype)
            .at[:, EventRow.T]
            .set(jnp.inf),
        ),
        n_events=jnp.where(start_in_contact, 1, 0),
        overflow=jnp.array(False),
        rec=jnp.zeros((problem.rows, problem.step_row.width(y0.shape[0])), dtype),
        n_rec=jnp.array(0),
        saved=jnp.array(0),
        n_steps=jnp.array(0),
        n_accepted=jnp.array(0),
        n_rejected=jnp.array(0),
        nonfinite=jnp.array(False),
    )


def region_index(mask):
    """0 in free flight, 1 + i in contact with switch i (the first one in contact)."""
    return jnp.where(jnp.any(mask), jnp.argmax(mask) + 1, 0)


def packed_cond(pred, true_fn, false_fn, dtype):
    """`lax.cond` whose branches return one packed array instead of a pytree.

    XLA:CPU copies every output of a conditional into its own buffer on every call; a
    single packed output makes the common (uneventful) branch one small copy. The
    branches' output structure is recorded while `lax.cond` traces them (the false
    branch's, as for `jax.eval_shape(false_fn)`, which would trace it once more: the
    nested conds of the loop body made that a third of the event mode's tracing time).
    """
    structure = {}

    def packed(fn, key):
        def branch():
            leaves, treedef = jax.tree_util.tree_flatten(fn())
            leaves = [jnp.asarray(x) for x in leaves]
            structure[key] = ([jax.ShapeDtypeStruct(x.shape, x.dtype) for x in leaves], treedef)
            return jnp.concatenate([jnp.ravel(x).astype(dtype) for x in leaves])

        return branch

    flat = jax.lax.cond(pred, packed(true_fn, True), packed(false_fn, False))
    leaves, treedef = structure[False]
    out, start = [], 0
    for leaf in leaves:
        size = int(np.prod(leaf.shape))
        part = flat[start : start + size].reshape(leaf.shape)
        start += size
        if leaf.dtype == jnp.bool_:
            part = part != 0
        elif jnp.issubdtype(leaf.dtype, jnp.integer):
            part = part.astype(leaf.dtype)
        out.append(part)
    return jax.tree_util.tree_unflatten(treedef, out)
