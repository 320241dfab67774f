"""The event mode: exact contact, located and restarted inside one compiled loop.

The exact model is smooth inside each region (free flight, contact with a wall), so
the loop integrates the region's own smooth right-hand side with Tsit5 and stops at
every region boundary:

1. One loop over steps (`equinox.internal.while_loop`, checkpointed, so it supports
   `jax.jit`, `jax.vmap` and reverse-mode `jax.grad`). diffrax's `Tsit5` takes each
   step; step-size control is an integral controller on its error estimate.
2. After each accepted step the switching functions g_i (signed distances into the
   walls) are checked on a sub-grid of the step's dense interpolant, and at the roots
   of the model's observable (v for the ball: apexes and deepest points). Checking at
   the extremum catches a crossing that enters and leaves within one step, the free
   flight pitfall where a parabola's zero error estimate lets a step jump over a wall.
3. The earliest crossing is located on the interpolant by bisection under
   `stop_gradient` to machine precision, then one differentiable Newton update
   t* ← t* − g(t*)/ġ(t*) gives the implicit-function gradient of the event time.
4. The state at t* comes from the interpolant, the region flips, and the step
   restarts there (FSAL is reset).

Every event (entry, exit, apex, deepest point) is recorded in a fixed-size buffer,
and every accepted step's interpolant in another, from which outputs at the save
times are evaluated after the loop.
"""

from __future__ import annotations

import diffrax as dfx
import equinox as eqx
import equinox.internal as eqxi
import jax
import jax.numpy as jnp
from jaxtyping import Array

#: Event kinds in `EventRecord.kind`.
ENTRY, EXIT, EXTREMUM = 1, 2, 3

_ITERATIONS = 12
_LOOP_KIND = "checkpointed"


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
    """

    t: Array
    y: Array
    kind: Array
    wall: Array
    peak_force: Array
    count: Array
    open_peak_force: Array


def _interp(t0, t1, dense):
    return dfx.Tsit5().interpolation_cls(t0=t0, t1=t1, **dense)


def _locate(f, a, b):
    """A root of f in [a, b], given that f changes sign on (a, b].

    Newton's method safeguarded by bisection, on a bracket that only shrinks, under
    stop_gradient: it stops improving at machine precision instead of failing a
    tolerance float64 cannot meet. Then one differentiable Newton step, whose
    derivative is −(∂f/∂θ)/ḟ: the implicit-function gradient of the root.
    """
    a, b = jax.lax.stop_gradient(a), jax.lax.stop_gradient(b)
    positive_left = jax.lax.stop_gradient(f(a)) > 0

    def body(_, state):
        lo, hi, x = state
        fx, dfx_ = jax.lax.stop_gradient(jax.jvp(f, (x,), (jnp.ones_like(x),)))
        left = (fx > 0) == positive_left
        lo = jnp.where(left, x, lo)
        hi = jnp.where(left, hi, x)
        newton = x - fx / jnp.where(dfx_ == 0, 1.0, dfx_)
        inside = (newton >= lo) & (newton <= hi) & (dfx_ != 0)
        return lo, hi, jnp.where(inside, newton, 0.5 * (lo + hi))

    _, _, root = jax.lax.fori_loop(0, _ITERATIONS, body, (a, b, 0.5 * (a + b)))
    value, slope = jax.jvp(f, (root,), (jnp.ones_like(root),))
    step = jnp.where(slope == 0, 0.0, value / jnp.where(slope == 0, 1.0, slope))
    # Numerically ~0 (the root is located to machine precision); it carries the
    # implicit-function derivative.
    return root - (step - jax.lax.stop_gradient(step))


def event_solve(model, y0, t0, t1, ts, settings, outputs):
    """Integrate `model` in event mode. Returns (ys, y1, status, stats, events)."""
    # The stage loop unrolled into a bounded scan, as diffeqsolve's own
    # RecursiveCheckpointAdjoint does: reverse-mode differentiable and cheap to compile.
    solver = dfx.Tsit5(scan_kind="bounded")
    term = dfx.ODETerm(lambda t, y, args: args[0].region_vector_field(t, y, args[1]))
    n = y0.shape[0]
    n_sw = model.num_switches
    max_steps = settings.max_steps
    max_events = settings.max_events
    fractions = jnp.linspace(0.0, 1.0, settings.subgrid + 1)[1:]
    dtype = y0.dtype

    g0 = model.switches(y0)
    dg0 = jax.jvp(model.switches, (y0,), (model.region_vector_field(t0, y0, g0 > 0),))[1]
    mask0 = (g0 > 0) | ((g0 == 0) & (dg0 > 0))
    span = t1 - t0
    dt0 = span * 1e-4 if settings.dt is None else settings.dt
    dtmax = span if settings.dtmax is None else settings.dtmax

    def contact_force_abs(y, mask):
        # |m a − m a_free|: the contact force magnitude in a region.
        a = model.region_vector_field(t0, y, mask)[1:]
        a_free = model.region_vector_field(t0, y, jnp.zeros_like(mask))[1:]
        return jnp.max(jnp.abs(a - a_free)) * model.contact_mass

    init = dict(
        t=t0,
        y=y0,
        mask=mask0,
        dt=jnp.asarray(dt0, dtype),
        fsal=solver.init(term, t0, t0 + dt0, y0, (model, mask0)),
        jump=jnp.array(True),
        seen_extremum=jnp.array(False),
        peak=jnp.where(jnp.any(mask0), contact_force_abs(y0, mask0), 0.0),
        n_steps=jnp.array(0),
        n_accepted=jnp.array(0),
        n_rejected=jnp.array(0),
        n_events=jnp.array(0),
        overflow=jnp.array(False),
        nonfinite=jnp.array(False),
        rec_t0=jnp.zeros(max_steps, dtype),
        rec_t1=jnp.ones(max_steps, dtype),
        rec_end=jnp.full(max_steps, jnp.inf, dtype),
        rec_y0=jnp.zeros((max_steps, n), dtype),
        rec_k=jnp.zeros((max_steps, 7, n), dtype),
        ev_t=jnp.full(max_events, jnp.inf, dtype),
        ev_y=jnp.zeros((max_events, n), dtype),
        ev_kind=jnp.zeros(max_events, jnp.int32),
        ev_wall=jnp.zeros(max_events, jnp.int32),
        ev_peak=jnp.zeros(max_events, dtype),
    )

    def cond(c):
        return (c["t"] < t1) & ~c["nonfinite"] & ~c["overflow"]

    def record_event(c, pred, t, y, kind, wall, peak):
        i = c["n_events"]
        ok = pred & (i < max_events)
        c = dict(c)
        c["ev_t"] = eqxi.buffer_at_set(c["ev_t"], i, t, pred=ok)
        c["ev_y"] = eqxi.buffer_at_set(c["ev_y"], i, y, pred=ok)
        c["ev_kind"] = eqxi.buffer_at_set(c["ev_kind"], i, jnp.int32(kind), pred=ok)
        c["ev_wall"] = eqxi.buffer_at_set(c["ev_wall"], i, jnp.asarray(wall, jnp.int32), pred=ok)
        c["ev_peak"] = eqxi.buffer_at_set(c["ev_peak"], i, peak, pred=ok)
        c["n_events"] = i + jnp.where(ok, 1, 0)
        c["overflow"] = c["overflow"] | (pred & (i >= max_events))
        return c

    def body(c):
        t, y, mask = c["t"], c["y"], c["mask"]
        h = jnp.minimum(jnp.minimum(c["dt"], dtmax), t1 - t)
        t_next = jnp.where(t1 - (t + h) < 1e-12 * jnp.abs(t1), t1, t + h)
        h = t_next - t
        y1, y_err, dense, fsal, _ = solver.step(term, t, t_next, y, (model, mask), c["fsal"], c["jump"])
        scale = settings.atol + settings.rtol * jnp.maximum(jnp.abs(y), jnp.abs(y1))
        err = jnp.sqrt(jnp.mean((y_err / scale) ** 2))
        finite = jnp.all(jnp.isfinite(y1)) & jnp.isfinite(err)
        accept = (err <= 1.0) & finite
        factor = jnp.clip(0.9 * jnp.where(err > 0, err, 1e-10) ** (-0.2), 0.2, 10.0)
        factor = jnp.where(finite, factor, 0.2)
        dt_new = jax.lax.stop_gradient(h * factor)

        interp = _interp(t, t_next, dense)
        sub_t = t + fractions * h
        sub_y = jax.vmap(interp.evaluate)(sub_t)

        # Extremum of the observable (an apex, or the deepest point) inside the step.
        obs0 = model.observable(y)
        obs_sub = jax.vmap(model.observable)(sub_y)
        prev = jnp.concatenate([obs0[None], obs_sub[:-1]])
        flips = (jnp.sign(prev) != jnp.sign(obs_sub)) & (obs_sub != 0)
        has_ext = jnp.any(flips)
        j = jnp.argmax(flips)
        lo = jnp.where(j == 0, t, sub_t[jnp.maximum(j - 1, 0)])
        hi = sub_t[j]
        t_ext = jax.lax.cond(
            has_ext,
            lambda: _locate(lambda s: model.observable(interp.evaluate(s)), lo, hi),
            lambda: t_next,
        )
        y_ext = interp.evaluate(t_ext)

        # Switching functions on the sub-grid and at the extremum, in time order.
        check_t = jnp.concatenate([sub_t, t_ext[None]])
        check_y = jnp.concatenate([sub_y, y_ext[None]])
        order = jnp.argsort(check_t)
        check_t, check_y = check_t[order], check_y[order]
        g_check = jax.vmap(model.switches)(check_y)  # (points, n_sw)
        wrong = jnp.where(mask, g_check < 0, g_check > 0)  # left the region
        first_pt = jnp.where(jnp.any(wrong, axis=0), jnp.argmax(wrong, axis=0), check_t.shape[0])
        crossing = jnp.any(wrong)

        def root_of(i):
            p = first_pt[i]
            pc = jnp.minimum(p, check_t.shape[0] - 1)
            a = jnp.where(p == 0, t, check_t[jnp.maximum(pc - 1, 0)])
            return _locate(lambda s: model.switches(interp.evaluate(s))[i], a, check_t[pc])

        roots = jax.lax.cond(
            crossing,
            lambda: jax.vmap(root_of)(jnp.arange(n_sw)),
            lambda: jnp.full(n_sw, jnp.inf, dtype),
        )
        roots = jnp.where(first_pt < check_t.shape[0], roots, jnp.inf)
        wall = jnp.argmin(roots)
        t_star = jnp.where(crossing, roots[wall], t_next)
        y_star = jnp.where(crossing, interp.evaluate(t_star), y1)
        t_end = jnp.where(crossing, t_star, t_next)

        c = dict(c)
        c["n_steps"] = c["n_steps"] + 1
        c["n_accepted"] = c["n_accepted"] + jnp.where(accept, 1, 0)
        c["n_rejected"] = c["n_rejected"] + jnp.where(accept, 0, 1)
        c["nonfinite"] = ~finite & (h <= 1e-14 * jnp.maximum(jnp.abs(t), 1.0))

        # Record the accepted step's interpolant, valid on [t, t_end].
        i = c["n_accepted"] - 1
        c["rec_t0"] = eqxi.buffer_at_set(c["rec_t0"], i, t, pred=accept)
        c["rec_t1"] = eqxi.buffer_at_set(c["rec_t1"], i, t_next, pred=accept)
        c["rec_end"] = eqxi.buffer_at_set(c["rec_end"], i, t_end, pred=accept)
        c["rec_y0"] = eqxi.buffer_at_set(c["rec_y0"], i, y, pred=accept)
        c["rec_k"] = eqxi.buffer_at_set(c["rec_k"], i, dense["k"], pred=accept)

        in_contact = jnp.any(mask)
        ext_wall = jnp.where(in_contact, jnp.argmax(mask), -1)
        # An apex in every flight; the first deepest point in each contact.
        rec_ext = accept & has_ext & (t_ext < t_end) & ~(in_contact & c["seen_extremum"])
        c = record_event(c, rec_ext, t_ext, y_ext, EXTREMUM, ext_wall, 0.0)
        seen = c["seen_extremum"] | (rec_ext & in_contact)

        # Peak contact force on the sub-grid of this step (up to t_end).
        valid = sub_t <= t_end
        f_sub = jax.vmap(lambda yy: contact_force_abs(yy, mask))(sub_y)
        peak = jnp.where(
            accept & in_contact, jnp.maximum(c["peak"], jnp.max(jnp.where(valid, f_sub, 0.0))), c["peak"]
        )

        event = accept & crossing
        entering = ~mask[wall]
        c = record_event(c, event & ~entering, t_star, y_star, EXIT, wall, peak)
        c = record_event(c, event & entering, t_star, y_star, ENTRY, wall, 0.0)
        new_mask = jnp.where(event, mask.at[wall].set(entering), mask)
        f_new = contact_force_abs(y_star, new_mask)
        c["peak"] = jnp.where(event, jnp.where(entering, f_new, 0.0), peak)
        c["seen_extremum"] = jnp.where(event, False, seen)

        c["t"] = jnp.where(accept, t_end, t)
        c["y"] = jnp.where(accept, y_star, y)
        c["mask"] = new_mask
        c["fsal"] = jax.tree.map(lambda a, b: jnp.where(accept, a, b), fsal, c["fsal"])
        c["jump"] = jnp.where(accept, event, c["jump"])
        c["dt"] = jnp.where(event, jnp.minimum(dt_new, jax.lax.stop_gradient(h)), dt_new)
        return c

    buffers = lambda c: [  # noqa: E731
        c[k]
        for k in (
            "rec_t0",
            "rec_t1",
            "rec_end",
            "rec_y0",
            "rec_k",
            "ev_t",
            "ev_y",
            "ev_kind",
            "ev_wall",
            "ev_peak",
        )
    ]
    final = eqxi.while_loop(cond, body, init, max_steps=max_steps, buffers=buffers, kind=_LOOP_KIND)

    # Outputs at the save times from the recorded interpolants.
    def evaluate(s):
        r = jnp.clip(jnp.searchsorted(final["rec_end"], s, side="left"), 0, max_steps - 1)
        dense = dict(y0=final["rec_y0"][r], y1=final["rec_y0"][r], k=final["rec_k"][r])
        y = _interp(final["rec_t0"][r], final["rec_t1"][r], dense).evaluate(s)
        y = jnp.where(s == t0, y0, y)
        return {name: model.output(name, s, y) for name in outputs}

    ys = jax.vmap(evaluate)(ts)
    reached = ts <= final["t"]
    ys = {k: jnp.where(reached, v, jnp.nan) for k, v in ys.items()}
    events = EventRecord(
        t=final["ev_t"],
        y=final["ev_y"],
        kind=final["ev_kind"],
        wall=final["ev_wall"],
        peak_force=final["ev_peak"],
        count=final["n_events"],
        open_peak_force=final["peak"],
    )
    stats = dict(
        num_steps=final["n_steps"],
        num_accepted_steps=final["n_accepted"],
        num_rejected_steps=final["n_rejected"],
    )
    done = final["t"] >= t1
    return ys, final["y"], done, final["nonfinite"], final["overflow"], stats, events
