"""Event location: where on a step the observable turns and a switching function crosses.

Detection is cheap and runs after every accepted step (`Trial.eventful`: a sign change on
the step's sub-grid); location runs only on a step with an event in it. Roots are found
on the step's dense interpolant under `stop_gradient` (`locate`), then polished on the
pair's own step (`refine`), and each carries its implicit-function derivative through
one differentiable Newton update whose value is ~0.
"""

from __future__ import annotations

import jax
import jax.numpy as jnp

from ._event_state import Trial

#: Newton iterations of `locate`. Most roots converge within 5, but grazing crossings
#: need more: with 6 or 8 the stress suite had silent failures (Dopri8, grazing family).
_ITERATIONS = 12
_REFINE_ITERATIONS = 2


@jax.custom_jvp
def pick(x, i):
    """`x[i]` for a short vector x and a traced integer index i, whose derivative is a
    chain of selects between x's static slices.

    Under `vmap` (a batched i) `x[i]` is a gather, and in reverse mode the derivative of
    a gather is a scatter: one scatter in the backward loop keeps XLA:CPU from compiling
    that loop into one kernel (README, Differentiation). The selects are exact and
    transpose to selects and pads. The value is still the gather: `locate` picks the
    value and the s-derivative of its vector function with it, so a solve that is not
    differentiated computes exactly what indexing did."""
    return x[i]


@pick.defjvp
def _pick_jvp(primals, tangents):
    x, i = primals
    x_dot = tangents[0]
    out = x_dot[0]
    for k in range(1, x.shape[0]):
        out = jnp.where(i == k, x_dot[k], out)
    # `pick` again, not x[i]: an enclosing derivative differentiates this rule too.
    return pick(x, i), out


def locate(f, a, b, positive_left=None, active=None, index=None):
    """A root of f in [a, b], given that f changes sign on (a, b].

    With `index` (a traced integer) f is vector-valued and the root is that of its
    component `index`, picked from f's value and s-derivative by `pick`: reverse mode
    then meets no gather.

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
    if index is not None:
        f_vec = f

        def f(s):
            return pick(f_vec(s), index)

        def f_jvp(s):
            value, slope = jax.jvp(f_vec, (s,), (jnp.ones_like(s),))
            return pick(value, index), pick(slope, index)

    else:

        def f_jvp(s):
            return jax.jvp(f, (s,), (jnp.ones_like(s),))

    if positive_left is None:
        positive_left = jax.lax.stop_gradient(f(a)) > 0
    eps = 4 * jnp.finfo(a.dtype).eps

    def body(state):
        i, lo, hi, x, _ = state
        fx, dfx_ = jax.lax.stop_gradient(f_jvp(x))
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
    value, slope = f_jvp(root)
    step = jnp.where(slope == 0, 0.0, value / jnp.where(slope == 0, 1.0, slope))
    # Numerically ~0 (the root is located to machine precision); it carries the
    # implicit-function derivative.
    return root - (step - jax.lax.stop_gradient(step))


def refine(state_at, rate, value_of, t_root, y_root, radius):
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


def locate_extremum(model, trial: Trial, direction, kink: bool):
    """The first root of the observable on the step (an apex, a deepest point), s, and
    the interpolated state there; (t_next, its interpolant) if the sub-grid saw none.
    With a kink the piece may start at a root (a rounding-level value of either sign):
    the observable's sign just right of the start is `direction`."""
    obs_start, obs_sub, sub_t = trial.obs_start, trial.obs_sub, trial.sub_t
    j = jnp.argmax(trial.flips)
    lo = jnp.where(j == 0, trial.t, sub_t[jnp.maximum(j - 1, 0)])
    sign_left = (jnp.where(j == 0, obs_start, obs_sub[jnp.maximum(j - 1, 0)]) > 0) if kink else None
    t_ext = jax.lax.cond(
        trial.has_ext,
        lambda: locate(lambda s: model.observable(trial.dense(s)), lo, sub_t[j], sign_left),
        lambda: trial.t_next,
    )
    return t_ext, trial.dense(t_ext)


def _check_points(trial: Trial, t_ext, y_ext):
    """The sub-grid (sorted) with the extremum inserted in time order (after sub-grid
    points at the same time): a gather, where a sort would keep XLA:CPU from compiling
    the loop as one kernel. Returns (times, s; states)."""
    sub_t, sub_y = trial.sub_t, trial.sub_y
    slot = jnp.sum(sub_t <= t_ext)
    pos = jnp.arange(sub_t.shape[0] + 1)
    from_sub = jnp.clip(jnp.where(pos < slot, pos, pos - 1), 0, sub_t.shape[0] - 1)
    is_ext = pos == slot
    check_t = jnp.where(is_ext, t_ext, sub_t[from_sub])
    check_y = jnp.where(is_ext[:, None], y_ext, sub_y[from_sub])
    return check_t, check_y


def first_crossing(model, trial: Trial, mask, t_ext, y_ext):
    """The earliest crossing of a switching function on the step's interpolant.

    The switches are checked on the sub-grid and at the observable's extremum (where a
    short excursion beyond a wall is deepest: a crossing that enters and leaves within
    one step). Only the walls crossed first on those points can hold the earliest root
    (a later first point means a later root), so only those are located.

    **Returns:** `(crossing, wall, t*, y*)`: whether there is one, the switch's index,
    and its time (s) and interpolated state; (t_next, y1) without one.
    """
    t, n_sw = trial.t, mask.shape[0]
    check_t, check_y = _check_points(trial, t_ext, y_ext)
    g_check = jax.vmap(model.switches)(check_y)  # (points, n_sw)
    wrong = jnp.where(mask, g_check < 0, g_check > 0)
    n_pts = check_t.shape[0]
    first_pt = jnp.where(jnp.any(wrong, axis=0), jnp.argmax(wrong, axis=0), n_pts)
    crossing = jnp.any(wrong)
    first = first_pt == jnp.min(first_pt)

    def root_of(i):
        pc = jnp.minimum(first_pt[i], n_pts - 1)
        a = jnp.where(first_pt[i] == 0, t, check_t[jnp.maximum(pc - 1, 0)])
        return locate(lambda s: model.switches(trial.dense(s)), a, check_t[pc], active=first[i], index=i)

    roots = jax.lax.cond(
        crossing,
        lambda: jax.vmap(root_of)(jnp.arange(n_sw)),
        lambda: jnp.full(n_sw, jnp.inf, trial.y.dtype),
    )
    roots = jnp.where((first_pt < n_pts) & first, roots, jnp.inf)
    wall = jnp.argmin(roots)
    t_star = jnp.where(crossing, roots[wall], trial.t_next)
    y_star = jnp.where(crossing, trial.dense(t_star), trial.y1)
    return crossing, wall, t_star, y_star
