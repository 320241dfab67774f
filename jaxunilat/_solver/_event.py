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
   per step: `_dense`); step-size control is an integral controller on the embedded
   error estimate.
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
compile the whole loop into one kernel (`jaxunilat.use_loop_kernels`).
"""

from __future__ import annotations

import functools

import diffrax as dfx
import equinox as eqx
import equinox.internal as eqxi
import jax
import jax.numpy as jnp
import numpy as np
from jaxtyping import Array

from . import _dense

#: Event kinds in `EventRecord.kind`.
ENTRY, EXIT, EXTREMUM = 1, 2, 3

#: Newton iterations of `_locate`. Most roots converge within 5, but grazing crossings
#: need more: with 6 or 8 the stress suite had silent failures (Dopri8, grazing family).
_ITERATIONS = 12
#: A kink whose effect over a step, |Δf|·h, is below this fraction of the error scale
#: does not end a piece (see `event_solve`).
_NEGLIGIBLE_KINK = 1e-3
_REFINE_ITERATIONS = 2
_REC = 4  # leading columns of a step record: t0, t_end, direction, first save time (then mask, y0)
_EV = 4  # leading columns of an event record: t, kind, wall, peak force


class EventRecord(eqx.Module):
    """The events of an event-mode run, in time order, padded to `max_events`.

    **Fields:**

    - `t`: event times, s (padding: +inf).
    - `y`: the state at each event.
    - `kind`: 1 = contact entry, 2 = contact exit, 3 = extremum of the observable
      (an apex in flight, the deepest point in contact); 0 = padding.
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


#: The Runge–Kutta pairs the event mode can integrate its smooth pieces with:
#: diffrax solver class and the exponent of its step-size controller (1/(q+1),
#: q the order of the embedded error estimate).
PIECE_SOLVERS = {"tsit5": (dfx.Tsit5, 1 / 5), "dopri8": (dfx.Dopri8, 1 / 8)}


def _erk_step(solver_cls, f, t, h, y, f0):
    """One step of an FSAL explicit RK pair from diffrax's Butcher tableau, unrolled.

    `f0` = f(t, y) (first same as last). Returns (y1, y_error, k, f1) where k is the
    tuple of stage increments hᵢ·fᵢ (the dense output's `_dense.coefficients` take
    them), and f1 = f(t + h, y1) is the next step's f0. Unrolling the stages lets XLA fuse the
    step into a few kernels; diffrax's generic step loops over its stages.
    """
    tab = solver_cls.tableau
    ks = [h * f0]
    f_last = f0
    for c_i, a_i in zip(tab.c, tab.a_lower, strict=True):
        y_i = y + sum(float(a) * k for a, k in zip(a_i, ks, strict=True) if a != 0)
        f_last = f(t + float(c_i) * h, y_i)
        ks.append(h * f_last)
    y1 = y + sum(float(b) * k for b, k in zip(tab.b_sol, ks, strict=True) if b != 0)
    y_err = sum(float(b) * k for b, k in zip(tab.b_error, ks, strict=True) if b != 0)
    # FSAL: the last stage is evaluated at (t + h, y1).
    return y1, y_err, tuple(ks), f_last


def _locate(f, a, b, positive_left=None, active=None):
    """A root of f in [a, b], given that f changes sign on (a, b].

    `positive_left` (optional) is the sign of f just right of a, where f(a) itself may
    be a rounding-level zero (a piece that starts at a root). With `active` False
    (optional) no iteration runs: a vmapped caller that needs only some of its roots
    does not keep the loop going for the others.

    Newton's method safeguarded by bisection, on a bracket that only shrinks, under
    stop_gradient: it stops when an iterate moves by a few ulps (or after `_ITERATIONS`)
    instead of failing a tolerance float64 cannot meet. Then one differentiable Newton
    step, whose derivative is −(∂f/∂θ)/ḟ: the implicit-function gradient of the root.
    """
    a, b = jax.lax.stop_gradient(a), jax.lax.stop_gradient(b)
    if positive_left is None:
        positive_left = jax.lax.stop_gradient(f(a)) > 0
    eps = 4 * jnp.finfo(a.dtype).eps

    def body(state):
        i, lo, hi, x, _ = state
        fx, dfx_ = jax.lax.stop_gradient(jax.jvp(f, (x,), (jnp.ones_like(x),)))
        left = (fx > 0) == positive_left
        lo = jnp.where(left, x, lo)
        hi = jnp.where(left, hi, x)
        newton = x - fx / jnp.where(dfx_ == 0, 1.0, dfx_)
        inside = (newton >= lo) & (newton <= hi) & (dfx_ != 0)
        new = jnp.where(inside, newton, 0.5 * (lo + hi))
        # Converged: Newton's quadratic convergence makes the next move far smaller.
        return i + 1, lo, hi, new, jnp.abs(new - x) <= eps * jnp.abs(new)

    def going(state):
        return (state[0] < _ITERATIONS) & ~state[4]

    # Most roots converge in 3–5 iterations; a loop that stops there costs less per
    # eventful step than a fixed count (grazing roots still get all `_ITERATIONS`).
    idle = jnp.array(False) if active is None else ~jax.lax.stop_gradient(active)
    state = (jnp.array(0), a, b, 0.5 * (a + b), idle)
    root = jax.lax.while_loop(going, body, state)[3]
    value, slope = jax.jvp(f, (root,), (jnp.ones_like(root),))
    step = jnp.where(slope == 0, 0.0, value / jnp.where(slope == 0, 1.0, slope))
    # Numerically ~0 (the root is located to machine precision); it carries the
    # implicit-function derivative.
    return root - (step - jax.lax.stop_gradient(step))


def _refine(state_at, rate, value_of, t_root, y_root, radius):
    """Polish an event time on the integrator's own step, differentiably.

    `state_at(t)` is the state one step after the piece's start (the pair's step of
    length t − t_start); `rate(t, y)` is its time derivative and `value_of(y)` the event
    function. Up to `_REFINE_ITERATIONS` Newton iterations from the dense-output root
    `t_root` under stop_gradient (the slope ∇g·ẏ needs no derivative of the step), kept
    only within `radius` of t_root (Newton must polish this root, not jump to another
    one: a piece starts at a root); then the state there, with one Newton update whose value is
    ~0 and whose derivative is the implicit-function derivative −(∂g/∂θ)/ġ of the
    event time, carried into the state as ẏ·dt*.

    **Returns:** `(t*, y(t*))`.
    """

    def slope_at(tt, z):
        return jax.jvp(value_of, (z,), (rate(tt, z),))

    t_root = jax.lax.stop_gradient(t_root)

    # Newton on the step: on a long step the dense-output root can be far off, and one
    # iteration from there leaves an error ~ (g''/2ġ)·Δt². The loop stops once an
    # update is at rounding level (often after one step evaluation), or when an iterate
    # leaves the radius (it then ends at the last one inside).
    eps = 16 * jnp.finfo(t_root.dtype).eps

    def body(state):
        i, tt, _, polished = state
        value, slope = jax.lax.stop_gradient(slope_at(tt, state_at(tt)))
        new = tt - jnp.where(slope == 0, 0.0, value / jnp.where(slope == 0, 1.0, slope))
        ok = jnp.abs(new - t_root) <= radius
        moved = jnp.abs(new - tt) > eps * jnp.abs(tt)
        return i + 1, jnp.where(ok, new, tt), ok & moved, polished | ok

    def going(state):
        return (state[0] < _REFINE_ITERATIONS) & state[2]

    _, tt, _, polished = jax.lax.while_loop(
        going, body, (jnp.array(0), t_root, jnp.array(True), jnp.array(False))
    )
    # Not polished (a flat event function, ġ ≈ 0: a graze): keep the dense-output root
    # and its state, which are consistent with each other.
    z = jnp.where(polished, state_at(tt), y_root)
    slope = jax.lax.stop_gradient(slope_at(tt, z)[1])
    value = value_of(z)
    step = jnp.where(slope == 0, 0.0, value / jnp.where(slope == 0, 1.0, slope))
    delta = -(step - jax.lax.stop_gradient(step))  # numerically 0
    return tt + delta, z + rate(tt, jax.lax.stop_gradient(z)) * delta


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


def _rows_of_times(rec, n_rec, n_ts):
    """The recorded row that holds each save time. Rows hold consecutive runs of save
    times (column 3: the index of a row's first one), so marking where each run starts
    and counting the marks gives every time its row."""
    rows = rec.shape[0]
    starts = jax.lax.stop_gradient(rec[1:, 3]).astype(jnp.int32)
    later = jnp.arange(1, rows) < n_rec
    marks = jnp.zeros(n_ts, jnp.int32).at[jnp.where(later, starts, n_ts)].add(1, mode="drop")
    return _running_sum(marks)


def _contact_steps(rec, n_rec, ts, n_sw, step_to):
    """For each save time: its recorded row, whether that row is a contact, and there the
    pair's step from the row's start (`step_to(s, row)`; zeros at times in flight).

    On a CPU one sequential scan over the save times (`_contact_steps_sequential`), all
    in one loop kernel with `use_loop_kernels`; on other platforms vectorized
    (`_contact_steps_vectorized`). Both give the same numbers.
    """
    return jax.lax.platform_dependent(
        rec,
        n_rec,
        ts,
        cpu=functools.partial(_contact_steps_sequential, n_sw=n_sw, step_to=step_to),
        default=functools.partial(_contact_steps_vectorized, n_sw=n_sw, step_to=step_to),
    )


def _row_facts(rec, n_sw):
    """(index of each row's first save time, whether each row is a contact)."""
    rec = jax.lax.stop_gradient(rec)
    return rec[:, 3].astype(jnp.int32), jnp.any(rec[:, _REC : _REC + n_sw] != 0, axis=1)


def _contact_steps_sequential(rec, n_rec, ts, *, n_sw, step_to):
    """`_contact_steps` as one scan over the save times: each time's row is the previous
    time's or the next one (every recorded row holds at least one save time), and a step
    is taken only at the times in contact."""
    n = rec.shape[1] - _REC - n_sw
    firsts, in_contact = _row_facts(rec, n_sw)
    last = jnp.maximum(n_rec - 1, 0)

    def body(r, s_and_p):
        s, p = s_and_p
        r = r + ((r < last) & (firsts[jnp.minimum(r + 1, rec.shape[0] - 1)] <= p))
        row = jax.lax.dynamic_index_in_dim(rec, r, keepdims=False)
        y = jax.lax.cond(in_contact[r], lambda: step_to(s, row), lambda: jnp.zeros(n, rec.dtype))
        return r, (r, in_contact[r], y)

    return jax.lax.scan(body, jnp.zeros((), jnp.int32), (ts, jnp.arange(ts.shape[0])))[1]


def _contact_steps_vectorized(rec, n_rec, ts, *, n_sw, step_to, few=64):
    """`_contact_steps` without a loop over the save times: the rows by
    `_rows_of_times`, and the times in contact gathered into chunks of `few`, a chunk
    with none skipped."""
    n_ts, n = ts.shape[0], rec.shape[1] - _REC - n_sw
    index = _rows_of_times(rec, n_rec, n_ts)
    contact = _row_facts(rec, n_sw)[1][index]
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


def _region_index(mask):
    """0 in free flight, 1 + i in contact with switch i (the first one in contact)."""
    return jnp.where(jnp.any(mask), jnp.argmax(mask) + 1, 0)


def _packed_cond(pred, true_fn, false_fn, dtype):
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


def event_solve(model, y0, t0, t1, ts, settings, outputs):
    """Integrate `model` in event mode.

    **Returns:** `(ys, y1, done, nonfinite, overflow, stats, events)`: the outputs at
    `ts`, the final state, whether t1 was reached, whether the solution became
    non-finite, whether the event buffer overflowed, the step counts and the
    `EventRecord`.
    """
    solver_cls, exponent = PIECE_SOLVERS[settings.piece_solver]
    n = y0.shape[0]
    n_sw = model.num_switches
    max_steps = settings.max_steps
    max_events = settings.max_events
    n_ts = ts.shape[0]
    # Each save time is in one recorded step, so the steps that hold one fit in n_ts rows.
    rows = min(max_steps, n_ts)
    # A contact that can never end (a ball at rest) in closed form, where the model
    # has one (static): one piece from where that is proven, to t1.
    settles = hasattr(type(model), "rest_error")
    fractions = jnp.linspace(0.0, 1.0, settings.subgrid + 1)[1:]
    dtype = y0.dtype

    kink = bool(getattr(model, "observable_kink", False))
    # Free flight in closed form where the model has one (a scene option, static).
    closed_flight = settings.flight == "closed" and hasattr(type(model), "flight_state")

    # A rejected trial step can overflow (a stiff contact or the drag's v² over a step
    # far too long for them). Its values are discarded, but reverse mode still runs
    # through them, and a zero cotangent times an infinite partial derivative is NaN.
    # Clipping every evaluation of the right-hand side at `huge` keeps all values and
    # partials finite; a state beyond `huge` counts as non-finite.
    huge = float(jnp.finfo(dtype).max) ** 0.8

    def rhs(t, y, mask, direction):
        f = (
            model.region_vector_field(t, y, mask, direction)
            if kink
            else model.region_vector_field(t, y, mask)
        )
        return jnp.clip(f, -huge, huge)

    g0 = model.switches(y0)
    dg0 = jax.jvp(model.switches, (y0,), (model.region_vector_field(t0, y0, g0 > 0),))[1]
    mask0 = (g0 > 0) | ((g0 == 0) & (dg0 > 0))
    # The sign of the observable in the first piece (where it starts at 0: the sign
    # it takes next).
    obs0 = model.observable(y0)
    dobs0 = jax.jvp(model.observable, (y0,), (rhs(t0, y0, mask0, jnp.ones((), dtype)),))[1]
    direction0 = jnp.where(obs0 != 0, jnp.sign(obs0), jnp.where(dobs0 != 0, jnp.sign(dobs0), 1.0)).astype(
        dtype
    )
    f_init = rhs(t0, y0, mask0, direction0)
    span = t1 - t0
    dt0 = span * 1e-4 if settings.dt is None else settings.dt
    dtmax = span if settings.dtmax is None else settings.dtmax

    def contact_force_abs(y, mask):
        # |m a − m a_free|: the contact force magnitude in a region.
        a = rhs(t0, y, mask, jnp.ones((), dtype))[1:]
        a_free = rhs(t0, y, jnp.zeros_like(mask), jnp.ones((), dtype))[1:]
        return jnp.max(jnp.abs(a - a_free)) * model.contact_mass

    start_in_contact = jnp.any(mask0)

    def rest_bound(y, mask, t):
        # The model's bound on its closed form's error over [t, t1] (+inf: the contact
        # can still end), and whether it is within a step's accuracy: the tolerance of
        # the largest state component, in the energy norm's units (m for the ball).
        bound = jax.lax.stop_gradient(model.rest_error(y, mask, t1 - t))
        scale = settings.atol + settings.rtol * jnp.max(jnp.abs(jax.lax.stop_gradient(y)))
        return bound < jnp.inf, bound <= scale

    if settles:
        proven0, resting0 = rest_bound(y0, mask0, t0)
    else:
        proven0 = resting0 = jnp.array(False)
    first_event = jnp.concatenate(
        [
            jnp.stack(
                [t0, jnp.asarray(ENTRY, dtype), jnp.argmax(mask0).astype(dtype), jnp.asarray(0.0, dtype)]
            ),
            y0,
        ]
    )
    init = dict(
        t=t0,
        y=y0,
        mask=mask0,
        dt=jnp.asarray(dt0, dtype),
        # The last accepted step in each kind of region (free, then in contact with
        # switch i): the first step after a crossing starts from the previous visit's.
        dt_region=jnp.full(n_sw + 1, jnp.inf, dtype),
        f0=f_init,
        direction=direction0,
        seen_extremum=jnp.array(False),
        # The contact provably never ends (from `rest_time` on) and the model's closed
        # form follows it to t1 within the tolerance: the next piece is that closed form.
        resting=resting0,
        rest_time=jnp.where(proven0, t0, jnp.inf).astype(dtype),
        peak=jnp.where(jnp.any(mask0), contact_force_abs(y0, mask0), 0.0),
        n_steps=jnp.array(0),
        n_accepted=jnp.array(0),
        n_rejected=jnp.array(0),
        n_events=jnp.where(start_in_contact, 1, 0),
        overflow=jnp.array(False),
        nonfinite=jnp.array(False),
        # One row per accepted step that holds a save time (at most one per save time):
        # [t0, t_end, direction, index of its first save time, mask (n_sw), y0 (n)],
        # enough to take the piece's step from t0 to any time in [t0, t_end] (unused
        # rows: zeros); `saved` save times lie at or before the last recorded step's end.
        rec=jnp.zeros((rows, _REC + n_sw + n), dtype),
        n_rec=jnp.array(0),
        saved=jnp.array(0),
        # One row per event: [t, kind, wall, peak force, y (n)]; a contact open at t0
        # is recorded as an entry at t0.
        ev=jnp.where(
            (jnp.arange(max_events)[:, None] == 0) & start_in_contact,
            first_event,
            jnp.zeros((max_events, _EV + n), dtype).at[:, 0].set(jnp.inf),
        ),
    )

    def cond(c):
        return (c["t"] < t1) & ~c["nonfinite"] & ~c["overflow"]

    def record_event(c, pred, t, y, kind, wall, peak):
        i = c["n_events"]
        ok = pred & (i < max_events)
        c = dict(c)
        row = jnp.concatenate(
            [jnp.stack([t, jnp.asarray(kind, dtype), jnp.asarray(wall, dtype), jnp.asarray(peak, dtype)]), y]
        )
        c["ev"] = eqxi.buffer_at_set(c["ev"], i, row, pred=ok)
        c["n_events"] = i + jnp.where(ok, 1, 0)
        c["overflow"] = c["overflow"] | (pred & (i >= max_events))
        return c

    def body(c):
        t, y, mask = c["t"], c["y"], c["mask"]
        direction = c["direction"]
        in_contact = jnp.any(mask)

        def piece_rhs(s, z):
            # The smooth right-hand side of this piece (its region and drag sign).
            return rhs(s, z, mask, direction)

        def rk_piece():
            # One step of the Runge–Kutta pair, and the events inside it.
            h = jnp.minimum(jnp.minimum(c["dt"], dtmax), t1 - t)
            t_next = jnp.where(t1 - (t + h) < 1e-12 * jnp.abs(t1), t1, t + h)
            h = t_next - t
            y1, y_err, k, f1 = _erk_step(solver_cls, piece_rhs, t, h, y, c["f0"])
            coeffs = _dense.coefficients(solver_cls, k)
            scale = settings.atol + settings.rtol * jnp.maximum(jnp.abs(y), jnp.abs(y1))
            err = jnp.sqrt(jnp.mean((y_err / scale) ** 2))
            finite = jnp.all(jnp.abs(y1) < huge) & (err < jnp.inf)  # False for NaN too
            accept = (err <= 1.0) & finite
            factor = jnp.clip(0.9 * jnp.where(err > 0, err, 1e-10) ** (-exponent), 0.2, 10.0)
            factor = jnp.where(finite, factor, 0.2)
            dt_new = jax.lax.stop_gradient(h * factor)

            def dense(s):
                # The pair's continuous extension on this step (`_dense`).
                return _dense.evaluate(t, h, y, coeffs, s)

            sub_t = t + fractions * h
            sub_y = jax.vmap(dense)(sub_t)
            # Cheap tests on the sub-grid: a sign change of the observable (an extremum
            # inside the step) or a switching function on the wrong side (a crossing).
            obs_sub = jax.vmap(model.observable)(sub_y)
            # With a kink the piece may start at a root of the observable (a rounding-level
            # value of either sign): its sign in the piece is `direction`.
            obs_start = direction if kink else model.observable(y)
            prev = jnp.concatenate([obs_start[None], obs_sub[:-1]])
            flips = (jnp.sign(prev) != jnp.sign(obs_sub)) & (obs_sub != 0)
            has_ext = jnp.any(flips)
            g_sub = jax.vmap(model.switches)(sub_y)
            wrong_sub = jnp.where(mask, g_sub < 0, g_sub > 0)
            eventful = accept & (has_ext | jnp.any(wrong_sub))

            def plain():
                no = jnp.array(False)
                return dict(
                    t_end=t_next,
                    y_end=y1,
                    mask=mask,
                    direction=direction,
                    f0=f1,
                    ext=(no, t_next, y1),
                    cross=(no, t_next, y1, no, jnp.array(0)),
                )

            def eventful_step():
                # Locate the observable's extremum, then check the switches there too:
                # it is where a short excursion beyond a wall is deepest.
                j = jnp.argmax(flips)
                lo = jnp.where(j == 0, t, sub_t[jnp.maximum(j - 1, 0)])
                sign_left = (
                    (jnp.where(j == 0, obs_start, obs_sub[jnp.maximum(j - 1, 0)]) > 0) if kink else None
                )
                t_ext = jax.lax.cond(
                    has_ext,
                    lambda: _locate(lambda s: model.observable(dense(s)), lo, sub_t[j], sign_left),
                    lambda: t_next,
                )
                y_ext = dense(t_ext)
                # The sub-grid (sorted) with the extremum inserted in time order (after
                # sub-grid points at the same time): a gather, where a sort would keep
                # XLA:CPU from compiling the loop as one kernel.
                slot = jnp.sum(sub_t <= t_ext)
                pos = jnp.arange(sub_t.shape[0] + 1)
                from_sub = jnp.clip(jnp.where(pos < slot, pos, pos - 1), 0, sub_t.shape[0] - 1)
                is_ext = pos == slot
                check_t = jnp.where(is_ext, t_ext, sub_t[from_sub])
                check_y = jnp.where(is_ext[:, None], y_ext, sub_y[from_sub])
                g_check = jax.vmap(model.switches)(check_y)  # (points, n_sw)
                wrong = jnp.where(mask, g_check < 0, g_check > 0)
                n_pts = check_t.shape[0]
                first_pt = jnp.where(jnp.any(wrong, axis=0), jnp.argmax(wrong, axis=0), n_pts)
                crossing = jnp.any(wrong)

                # Only the walls crossed first on the check points can hold the earliest
                # root (a later first point means a later root): locate only those.
                first = first_pt == jnp.min(first_pt)

                def root_of(i):
                    pc = jnp.minimum(first_pt[i], n_pts - 1)
                    a = jnp.where(first_pt[i] == 0, t, check_t[jnp.maximum(pc - 1, 0)])
                    return _locate(lambda s: model.switches(dense(s))[i], a, check_t[pc], active=first[i])

                roots = jax.lax.cond(
                    crossing,
                    lambda: jax.vmap(root_of)(jnp.arange(n_sw)),
                    lambda: jnp.full(n_sw, jnp.inf, dtype),
                )
                roots = jnp.where((first_pt < n_pts) & first, roots, jnp.inf)
                wall = jnp.argmin(roots)
                t_star = jnp.where(crossing, roots[wall], t_next)
                y_star = jnp.where(crossing, dense(t_star), y1)
                entering = ~mask[wall]
                new_mask = jnp.where(crossing, mask.at[wall].set(entering), mask)
                # With a kink at the observable's root, the piece ends there (before any
                # later crossing, which the next piece finds again) and the sign flips.
                # A kink too weak to matter (|Δf|·h far below the tolerance: a contact at
                # rest, where v only rings at rounding level) does not end the piece: the
                # step is kept and the next one takes the sign v has at its end. Ending a
                # piece at every ring would double the steps of a long rest.
                if kink:
                    jump = jax.vmap(lambda z: rhs(t, z, mask, direction) - rhs(t, z, mask, -direction))(sub_y)
                    kink_err = jnp.max(jnp.abs(jump) * h / scale)
                    flip = has_ext & (t_ext < t_star) & (kink_err > _NEGLIGIBLE_KINK)
                else:
                    flip = jnp.array(False)
                crossing = crossing & ~flip
                t_end = jnp.where(flip, t_ext, t_star)
                y_end = jnp.where(flip, y_ext, y_star)
                new_mask = jnp.where(flip, mask, new_mask)
                if kink:
                    obs_end = model.observable(jnp.where(crossing, y_star, y1))
                    sign_end = jnp.where(obs_end != 0, jnp.sign(obs_end), direction).astype(dtype)
                    new_direction = jnp.where(flip, -direction, jnp.where(has_ext, sign_end, direction))
                else:
                    # The right-hand side ignores it, but a closed-form flight needs the
                    # sign of the observable in the piece a crossing starts.
                    obs_star = model.observable(y_star)
                    new_direction = jnp.where(
                        crossing & (obs_star != 0), jnp.sign(obs_star), direction
                    ).astype(dtype)

                # Refine the event time on the pair's own step (the dense output is less
                # accurate than a step; Dopri8's much less): Newton on t ↦ g(step(t0 → t)),
                # then the state from that step. An error made here would shift every
                # later piece.
                def at(tt):
                    return _erk_step(solver_cls, piece_rhs, t, tt - t, y, c["f0"])[0]

                def event_value(z):
                    return jnp.where(flip, model.observable(z), model.switches(z)[wall])

                t_ref, y_ref = _refine(at, piece_rhs, event_value, t_end, y_end, 1e-3 * h)
                y_end = jnp.where(crossing | flip, y_ref, y1)
                t_end = jnp.where(crossing | flip, t_ref, t_next)
                # The region changed: restart FSAL with the new right-hand side.
                f_end = rhs(t_end, y_end, new_mask, new_direction)
                restart = crossing | flip | (new_direction != direction)
                return dict(
                    t_end=t_end,
                    y_end=y_end,
                    mask=new_mask,
                    direction=new_direction,
                    f0=jnp.where(restart, f_end, f1),
                    # With a kink the extremum ends the piece: its refined time and state.
                    ext=(
                        flip | (has_ext & (t_ext < t_star)),
                        jnp.where(flip, t_end, t_ext),
                        jnp.where(flip, y_end, y_ext),
                    ),
                    # The refined crossing (the dense output's root can be far off on a long
                    # step: the record must hold where the piece really ends).
                    cross=(crossing, t_end, y_end, entering, wall),
                )

            out = _packed_cond(eventful, eventful_step, plain, dtype)
            # Peak contact force on the sub-grid of this step (up to its end).
            f_sub = jax.vmap(lambda yy: contact_force_abs(yy, mask))(sub_y)
            f_max = jnp.max(jnp.where(sub_t <= out["t_end"], f_sub, 0.0))
            return dict(
                out,
                accept=accept,
                fail=~finite & (h <= 1e-14 * jnp.maximum(jnp.abs(t), 1.0)),
                dt_new=dt_new,
                h_used=jax.lax.stop_gradient(h),
                f_max=f_max,
            )

        def flight_piece():
            # Free flight in closed form: the piece ends at the apex, at a wall, or at t1.
            tau_apex, tau_walls, tau_max = model.flight_events(y, direction)
            wall = jnp.argmin(tau_walls)
            tau_wall = tau_walls[wall]
            tau_event = jnp.minimum(tau_apex, tau_wall)
            at_t1 = t1 - t <= jnp.minimum(tau_event, tau_max)
            crossing = ~at_t1 & (tau_wall <= tau_apex) & (tau_wall <= tau_max)
            apex = ~at_t1 & ~crossing & (tau_apex <= tau_max)
            tau = jnp.where(at_t1, t1 - t, jnp.minimum(tau_event, tau_max))
            t_end = jnp.where(at_t1, t1, t + tau)
            y_end = model.flight_state(y, tau, direction)
            new_mask = jnp.where(crossing, mask.at[wall].set(True), mask)
            new_direction = jnp.where(apex, -direction, direction)
            return dict(
                t_end=t_end,
                y_end=y_end,
                mask=new_mask,
                direction=new_direction,
                f0=rhs(t_end, y_end, new_mask, new_direction),
                ext=(apex, t_end, y_end),
                cross=(crossing, t_end, y_end, jnp.array(True), wall),
                accept=jnp.array(True),
                fail=~(jnp.all(jnp.isfinite(y_end)) & jnp.isfinite(t_end)),
                dt_new=c["dt"],
                # The flight leaves the step sizes as they were.
                h_used=c["dt_region"][0],
                f_max=jnp.zeros((), dtype),
            )

        def rest_piece():
            # A contact that never ends, to t1 in one piece: the model's closed form
            # (no events; its record row says so with direction 0).
            y_end = model.rest_state(y, t1 - t)
            no = jnp.array(False)
            return dict(
                t_end=t1,
                y_end=y_end,
                mask=mask,
                direction=direction,
                f0=c["f0"],
                ext=(no, t1, y_end),
                cross=(no, t1, y_end, no, jnp.array(0)),
                accept=jnp.array(True),
                fail=~jnp.all(jnp.isfinite(y_end)),
                dt_new=c["dt"],
                h_used=c["dt_region"][_region_index(mask)],
                f_max=contact_force_abs(y, mask),
            )

        if closed_flight and settles:
            # Nested: with a three-way switch XLA compiled the other pieces' arithmetic
            # differently (outputs of runs that never rest changed in their last bits).
            def contact_piece():
                return _packed_cond(c["resting"], rest_piece, rk_piece, dtype)

            out = _packed_cond(~in_contact, flight_piece, contact_piece, dtype)
        elif closed_flight:
            out = _packed_cond(~in_contact, flight_piece, rk_piece, dtype)
        elif settles:
            out = _packed_cond(c["resting"], rest_piece, rk_piece, dtype)
        else:
            out = rk_piece()
        t_end, accept, h_used, dt_new = out["t_end"], out["accept"], out["h_used"], out["dt_new"]

        c = dict(c)
        c["n_steps"] = c["n_steps"] + 1
        c["n_accepted"] = c["n_accepted"] + jnp.where(accept, 1, 0)
        c["n_rejected"] = c["n_rejected"] + jnp.where(accept, 0, 1)
        c["nonfinite"] = out["fail"]

        # Record the accepted step's start, valid on [t, t_end], if a save time lies in it.
        holds = accept & (c["saved"] < n_ts) & (ts[jnp.minimum(c["saved"], n_ts - 1)] <= t_end)
        first = c["saved"].astype(dtype)
        # Direction 0 marks a resting piece (`step_to` then takes the closed form).
        row_direction = jnp.where(c["resting"], 0.0, direction) if settles else direction
        row = jnp.concatenate([jnp.stack([t, t_end, row_direction, first]), mask.astype(dtype), y])
        c["rec"] = eqxi.buffer_at_set(c["rec"], c["n_rec"], row, pred=holds & (c["n_rec"] < rows))
        c["n_rec"] = c["n_rec"] + jnp.where(holds, 1, 0)
        c["saved"] = jnp.where(holds, _count_at_or_before(ts, t_end), c["saved"])

        # An apex in every flight; the first deepest point in each contact.
        ext_pred, t_ext, y_ext = out["ext"]
        rec_ext = accept & ext_pred & ~(in_contact & c["seen_extremum"])
        ext_wall = jnp.where(in_contact, jnp.argmax(mask), -1)
        c = record_event(c, rec_ext, t_ext, y_ext, EXTREMUM, ext_wall, 0.0)
        seen = c["seen_extremum"] | (rec_ext & in_contact)

        peak = jnp.where(accept & in_contact, jnp.maximum(c["peak"], out["f_max"]), c["peak"])

        crossed, t_star, y_star, entering, wall = out["cross"]
        event = accept & crossed
        c = record_event(c, event & ~entering, t_star, y_star, EXIT, wall, peak)
        c = record_event(c, event & entering, t_star, y_star, ENTRY, wall, 0.0)
        f_new = contact_force_abs(y_star, out["mask"])
        c["peak"] = jnp.where(event, jnp.where(entering, f_new, 0.0), peak)
        c["seen_extremum"] = jnp.where(event, False, seen)

        if settles:
            # From the end of this piece, can the contact never end, and does the closed
            # form follow it to t1? An exit (which a proven rest cannot have) clears the
            # rest time, so that it never outlives its contact.
            proven, ready = rest_bound(out["y_end"], out["mask"], t_end)
            proven, ready = accept & proven, accept & proven & ready
            first_proof = proven & (c["rest_time"] == jnp.inf)
            c["rest_time"] = jnp.where(
                event & ~entering, jnp.inf, jnp.where(first_proof, t_end, c["rest_time"])
            )
            c["resting"] = c["resting"] | ready
        c["t"] = jnp.where(accept, t_end, t)
        c["y"] = jnp.where(accept, out["y_end"], y)
        c["mask"] = jnp.where(accept, out["mask"], mask)
        c["f0"] = jnp.where(accept, out["f0"], c["f0"])
        c["direction"] = jnp.where(accept, out["direction"], direction)
        # A crossing changes the right-hand side, so the step size just used says little
        # about the new region: start from the last accepted step of its previous visit
        # (repeated bounces look alike: no rejections at each contact entry), or on a
        # first visit from min(dt_new, h), shrinking on rejection.
        dt_region = jnp.where(accept, c["dt_region"].at[_region_index(mask)].set(h_used), c["dt_region"])
        remembered = dt_region[_region_index(out["mask"])]
        first_visit = jnp.where(remembered < jnp.inf, remembered, jnp.minimum(dt_new, h_used))
        c["dt_region"] = dt_region
        c["dt"] = jnp.where(event, first_visit, dt_new)
        return c

    buffers = lambda c: [c["rec"], c["ev"]]  # noqa: E731
    # The carry outside the buffers is a few dozen numbers, so every step can be a
    # checkpoint: reverse mode then recomputes nothing.
    if settings.autodiff == "forward":
        # A plain loop: forward mode (jax.jvp, jax.jacfwd) differentiates it as it runs.
        final = eqxi.while_loop(cond, body, init, max_steps=max_steps, buffers=buffers, kind="lax")
    else:
        final = eqxi.while_loop(
            cond, body, init, max_steps=max_steps, buffers=buffers, kind="checkpointed", checkpoints=max_steps
        )

    # Outputs at the save times: the pair's own step from the start of the recorded step
    # that holds each time (as accurate as a step, so the tolerance bounds the outputs
    # too; the dense interpolant is much less accurate inside Dopri8's long flight steps),
    # and in free flight the closed form from there.
    rec = final["rec"]

    def step_to(s, row):
        t_st, sign = row[0], row[2]
        mask, y_st = row[_REC : _REC + n_sw] != 0, row[_REC + n_sw :]

        def piece_rhs(tt, z):
            return rhs(tt, z, mask, sign)

        def rk_step():
            return _erk_step(solver_cls, piece_rhs, t_st, s - t_st, y_st, piece_rhs(t_st, y_st))[0]

        if not settles:
            return rk_step()
        return jax.lax.cond(sign == 0, lambda: model.rest_state(y_st, s - t_st), rk_step)

    if closed_flight:
        # Steps of the pair only at the times in contact (the contacts last milliseconds).
        index, contact, y_contact = _contact_steps(rec, final["n_rec"], ts, n_sw, step_to)
        held = rec[index]
        t_start, direction = held[:, 0], held[:, 2]
        tau = jnp.where(contact, 0.0, ts - t_start)
        y_flight = jax.vmap(model.flight_state)(held[:, _REC + n_sw :], tau, direction)
        y = jnp.where(contact[:, None], y_contact, y_flight)
    else:
        y = jax.vmap(step_to)(ts, rec[_rows_of_times(rec, final["n_rec"], n_ts)])
    y = jnp.where((ts == t0)[:, None], y0, y)
    ys = {name: jax.vmap(lambda s, z, name=name: model.output(name, s, z))(ts, y) for name in outputs}
    reached = ts <= final["t"]
    ys = {k: jnp.where(reached, v, jnp.nan) for k, v in ys.items()}
    ev = final["ev"]
    events = EventRecord(
        t=ev[:, 0],
        y=ev[:, _EV:],
        kind=ev[:, 1].astype(jnp.int32),
        wall=ev[:, 2].astype(jnp.int32),
        peak_force=ev[:, 3],
        count=final["n_events"],
        open_peak_force=final["peak"],
        rest_time=final["rest_time"],
    )
    stats = dict(
        num_steps=final["n_steps"],
        num_accepted_steps=final["n_accepted"],
        num_rejected_steps=final["n_rejected"],
    )
    done = final["t"] >= t1
    return ys, final["y"], done, final["nonfinite"], final["overflow"], stats, events
