"""The event mode's pieces: what one iteration of the loop integrates.

A piece starts at the loop's (t, y) in one region and ends at the first event in it,
or after one accepted step:

- `rk_piece`: one step of the Runge–Kutta pair on the region's smooth right-hand side;
  on a step with an event in it, the step is cut at the event (`_eventful_end`).
- `flight_piece`: a free flight in the model's closed form, to its apex, a wall or t1.
- `rest_piece`: a contact that provably never ends, in the model's closed form to t1.

`next_piece` picks one with `packed_cond`s, so that each iteration runs only its own.
"""

from __future__ import annotations

import functools

import diffrax as dfx
import jax
import jax.numpy as jnp

from . import _dense
from ._event_locate import first_crossing, locate_extremum, refine
from ._event_state import Piece, PieceEnd, Problem, State, Trial, packed_cond, region_index

#: The Runge–Kutta pairs the event mode can integrate its smooth pieces with:
#: diffrax solver class and the exponent of its step-size controller (1/(q+1),
#: q the order of the embedded error estimate).
PIECE_SOLVERS = {"tsit5": (dfx.Tsit5, 1 / 5), "dopri8": (dfx.Dopri8, 1 / 8)}
#: A kink whose effect over a step, |Δf|·h, is below this fraction of the error scale
#: does not end a piece (see `_kink_ends_piece`).
_NEGLIGIBLE_KINK = 1e-3
#: The PI step-size controller's β (`_step_factor`), and the floor of the previous
#: error norm it uses (Hairer–Wanner's `facold`).
PI_BETA = 0.04
ERR_FLOOR = 1e-4


def erk_step(solver_cls, f, t, h, y, f0):
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


def _piece_rhs(problem: Problem, mask, direction):
    """The smooth right-hand side f(t, y) of one piece (its region and drag sign)."""
    return functools.partial(problem.rhs, mask=mask, direction=direction)


def next_piece(problem: Problem, state: State) -> Piece:
    """The piece that starts at `state`: a closed-form flight, a closed-form rest or a
    step of the pair, as the model and the state allow."""
    dtype = state.y.dtype
    rk = functools.partial(rk_piece, problem, state)
    flight = functools.partial(flight_piece, problem, state)
    rest = functools.partial(rest_piece, problem, state)
    in_contact = jnp.any(state.mask)
    if problem.closed_flight and problem.settles:
        # Nested: with a three-way switch XLA compiled the other pieces' arithmetic
        # differently (outputs of runs that never rest changed in their last bits).
        def contact_piece():
            return packed_cond(state.resting, rest, rk, dtype)

        return packed_cond(~in_contact, flight, contact_piece, dtype)
    if problem.closed_flight:
        return packed_cond(~in_contact, flight, rk, dtype)
    if problem.settles:
        return packed_cond(state.resting, rest, rk, dtype)
    return rk()


def trial_step(problem: Problem, state: State) -> Trial:
    """A step of the pair from the state (at most `dtmax` and up to t1), its error
    control (an integral controller on the embedded error estimate) and the cheap event
    tests on a sub-grid of its interpolant: a sign change of the observable (an extremum
    inside the step) or a switching function on the wrong side (a crossing)."""
    model, t1, t, y = problem.model, problem.t1, state.t, state.y
    mask, direction = state.mask, state.direction
    h = jnp.minimum(jnp.minimum(state.dt, problem.dtmax), t1 - t)
    t_next = jnp.where(t1 - (t + h) < 1e-12 * jnp.abs(t1), t1, t + h)
    h = t_next - t
    y1, y_err, k, f1 = erk_step(problem.solver_cls, _piece_rhs(problem, mask, direction), t, h, y, state.f0)
    coeffs = _dense.coefficients(problem.solver_cls, k)
    scale = problem.atol + problem.rtol * jnp.maximum(jnp.abs(y), jnp.abs(y1))
    err = jnp.sqrt(jnp.mean((y_err / scale) ** 2))
    finite = jnp.all(jnp.abs(y1) < problem.huge) & (err < jnp.inf)  # False for NaN too
    accept = (err <= 1.0) & finite
    err = jax.lax.stop_gradient(err)
    dt_new = jax.lax.stop_gradient(h * _step_factor(problem, state, err, accept, finite))

    sub_t = t + problem.fractions * h
    sub_y = jax.vmap(lambda s: _dense.evaluate(t, h, y, coeffs, s))(sub_t)
    obs_sub = jax.vmap(model.observable)(sub_y)
    # With a kink the piece may start at a root of the observable (a rounding-level
    # value of either sign): its sign in the piece is `direction`.
    obs_start = direction if problem.kink else model.observable(y)
    prev = jnp.concatenate([obs_start[None], obs_sub[:-1]])
    flips = (jnp.sign(prev) != jnp.sign(obs_sub)) & (obs_sub != 0)
    has_ext = jnp.any(flips)
    g_sub = jax.vmap(model.switches)(sub_y)
    wrong_sub = jnp.where(mask, g_sub < 0, g_sub > 0)
    eventful = accept & (has_ext | jnp.any(wrong_sub))
    return Trial(
        t=t,
        h=h,
        t_next=t_next,
        y=y,
        y1=y1,
        f1=f1,
        coeffs=coeffs,
        scale=scale,
        finite=finite,
        accept=accept,
        err=jnp.maximum(err, ERR_FLOOR),
        dt_new=dt_new,
        sub_t=sub_t,
        sub_y=sub_y,
        obs_start=obs_start,
        obs_sub=obs_sub,
        flips=flips,
        has_ext=has_ext,
        eventful=eventful,
    )


def _step_factor(problem: Problem, state: State, err, accept, finite):
    """The next trial step over this one.

    After an accepted step a PI controller (Gustafsson; Hairer–Wanner's DOPRI5 with
    β = `PI_BETA`): 0.9·err^−α·err_prev^β, α = 1/(q+1) − 0.75β, where err_prev is the
    previous accepted step's error norm; after a rejected one the integral controller
    0.9·err^−1/(q+1). In [0.2, 10], and 0.2 after a non-finite step. The β term damps
    the growth that follows a step of small error (an error rising along a contact):
    it halved the rejected steps of Table 1 example 2 at equal accuracy.
    """
    err = jnp.where(err > 0, err, 1e-10)
    alpha = problem.exponent - 0.75 * PI_BETA
    pi = 0.9 * err ** (-alpha) * state.err_prev**PI_BETA
    integral = 0.9 * err ** (-problem.exponent)
    factor = jnp.clip(jnp.where(accept, pi, integral), 0.2, 10.0)
    return jnp.where(finite, factor, 0.2)


def rk_piece(problem: Problem, state: State) -> Piece:
    """One step of the Runge–Kutta pair, cut at the first event in it."""
    trial = trial_step(problem, state)
    end = packed_cond(
        trial.eventful,
        functools.partial(_eventful_end, problem, state, trial),
        functools.partial(_plain_end, state, trial),
        state.y.dtype,
    )
    # Peak contact force on the sub-grid of this step (up to its end).
    f_sub = jax.vmap(lambda yy: problem.contact_force_abs(yy, state.mask))(trial.sub_y)
    f_max = jnp.max(jnp.where(trial.sub_t <= end.t_end, f_sub, 0.0))
    t, h = state.t, trial.h
    return Piece(
        end=end,
        accept=trial.accept,
        fail=~trial.finite & (h <= 1e-14 * jnp.maximum(jnp.abs(t), 1.0)),
        dt_new=trial.dt_new,
        err=trial.err,
        h_used=jax.lax.stop_gradient(h),
        f_max=f_max,
    )


def _plain_end(state: State, trial: Trial) -> PieceEnd:
    """The end of a step without events: the whole step, in the same region."""
    no = jnp.array(False)
    return PieceEnd(
        t_end=trial.t_next,
        y_end=trial.y1,
        mask=state.mask,
        direction=state.direction,
        f0=trial.f1,
        has_extremum=no,
        t_extremum=trial.t_next,
        y_extremum=trial.y1,
        crossed=no,
        t_cross=trial.t_next,
        y_cross=trial.y1,
        entering=no,
        wall=jnp.array(0),
    )


def _eventful_end(problem: Problem, state: State, trial: Trial) -> PieceEnd:
    """The end of a step with an event in it: the earliest crossing, or with a kink the
    observable's root before it, refined on the pair's own step; the region and the
    observable's sign after it, and FSAL restarted where they changed."""
    model, mask, direction = problem.model, state.mask, state.direction
    t_ext, y_ext = locate_extremum(model, trial, direction, problem.kink)
    crossing, wall, t_star, y_star = first_crossing(model, trial, mask, t_ext, y_ext)
    entering = ~mask[wall]
    new_mask = jnp.where(crossing, mask.at[wall].set(entering), mask)
    flip = _kink_ends_piece(problem, state, trial, t_ext, t_star)
    crossing = crossing & ~flip
    t_end = jnp.where(flip, t_ext, t_star)
    y_end = jnp.where(flip, y_ext, y_star)
    new_mask = jnp.where(flip, mask, new_mask)
    new_direction = _direction_after(problem, state, trial, crossing, flip, y_star)
    t_end, y_end = _refined_end(problem, state, trial, crossing, flip, wall, t_end, y_end)
    # The region changed: restart FSAL with the new right-hand side.
    f_end = problem.rhs(t_end, y_end, new_mask, new_direction)
    restart = crossing | flip | (new_direction != direction)
    return PieceEnd(
        t_end=t_end,
        y_end=y_end,
        mask=new_mask,
        direction=new_direction,
        f0=jnp.where(restart, f_end, trial.f1),
        # With a kink the extremum ends the piece: its refined time and state.
        has_extremum=flip | (trial.has_ext & (t_ext < t_star)),
        t_extremum=jnp.where(flip, t_end, t_ext),
        y_extremum=jnp.where(flip, y_end, y_ext),
        # The refined crossing (the dense output's root can be far off on a long step:
        # the record must hold where the piece really ends).
        crossed=crossing,
        t_cross=t_end,
        y_cross=y_end,
        entering=entering,
        wall=wall,
    )


def _kink_ends_piece(problem: Problem, state: State, trial: Trial, t_ext, t_star):
    """Whether the piece ends at the observable's root `t_ext` (before the crossing at
    `t_star`, which the next piece finds again), where the vector field has a kink.

    A kink too weak to matter (|Δf|·h far below the tolerance: a contact at rest, where
    v only rings at rounding level) does not end the piece: the step is kept and the
    next one takes the sign v has at its end. Ending a piece at every ring would double
    the steps of a long rest.
    """
    if not problem.kink:
        return jnp.array(False)
    t, mask, direction = state.t, state.mask, state.direction

    def jump_at(z):
        return problem.rhs(t, z, mask, direction) - problem.rhs(t, z, mask, -direction)

    jump = jax.vmap(jump_at)(trial.sub_y)
    kink_err = jnp.max(jnp.abs(jump) * trial.h / trial.scale)
    return trial.has_ext & (t_ext < t_star) & (kink_err > _NEGLIGIBLE_KINK)


def _direction_after(problem: Problem, state: State, trial: Trial, crossing, flip, y_star):
    """The observable's sign (±1) in the next piece."""
    model, direction, dtype = problem.model, state.direction, state.y.dtype
    if problem.kink:
        obs_end = model.observable(jnp.where(crossing, y_star, trial.y1))
        sign_end = jnp.where(obs_end != 0, jnp.sign(obs_end), direction).astype(dtype)
        return jnp.where(flip, -direction, jnp.where(trial.has_ext, sign_end, direction))
    # The right-hand side ignores it, but a closed-form flight needs the sign of the
    # observable in the piece a crossing starts.
    obs_star = model.observable(y_star)
    return jnp.where(crossing & (obs_star != 0), jnp.sign(obs_star), direction).astype(dtype)


def _refined_end(problem: Problem, state: State, trial: Trial, crossing, flip, wall, t_end, y_end):
    """The event time (s) and state, refined on the pair's own step: Newton on
    t ↦ g(step(t0 → t)), then the state from that step (the dense output is less
    accurate than a step; Dopri8's much less). An error made here would shift every
    later piece. Without an event: the step's end."""
    model, t, y = problem.model, state.t, state.y
    piece_rhs = _piece_rhs(problem, state.mask, state.direction)

    def at(tt):
        return erk_step(problem.solver_cls, piece_rhs, t, tt - t, y, state.f0)[0]

    def event_value(z):
        return jnp.where(flip, model.observable(z), model.switches(z)[wall])

    t_ref, y_ref = refine(at, piece_rhs, event_value, t_end, y_end, 1e-3 * trial.h)
    y_end = jnp.where(crossing | flip, y_ref, trial.y1)
    t_end = jnp.where(crossing | flip, t_ref, trial.t_next)
    return t_end, y_end


def flight_piece(problem: Problem, state: State) -> Piece:
    """Free flight in closed form: the piece ends at the apex, at a wall, or at t1."""
    model, t1, t, y = problem.model, problem.t1, state.t, state.y
    mask, direction = state.mask, state.direction
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
    end = PieceEnd(
        t_end=t_end,
        y_end=y_end,
        mask=new_mask,
        direction=new_direction,
        f0=problem.rhs(t_end, y_end, new_mask, new_direction),
        has_extremum=apex,
        t_extremum=t_end,
        y_extremum=y_end,
        crossed=crossing,
        t_cross=t_end,
        y_cross=y_end,
        entering=jnp.array(True),
        wall=wall,
    )
    return Piece(
        end=end,
        accept=jnp.array(True),
        fail=~(jnp.all(jnp.isfinite(y_end)) & jnp.isfinite(t_end)),
        dt_new=state.dt,
        err=state.err_prev,
        # The flight leaves the step sizes as they were.
        h_used=state.dt_region[0],
        f_max=jnp.zeros((), y.dtype),
    )


def rest_piece(problem: Problem, state: State) -> Piece:
    """A contact that never ends, to t1 in one piece: the model's closed form (no
    events; its record row says so with direction 0)."""
    t1, mask = problem.t1, state.mask
    y_end = problem.model.rest_state(state.y, t1 - state.t)
    no = jnp.array(False)
    end = PieceEnd(
        t_end=t1,
        y_end=y_end,
        mask=mask,
        direction=state.direction,
        f0=state.f0,
        has_extremum=no,
        t_extremum=t1,
        y_extremum=y_end,
        crossed=no,
        t_cross=t1,
        y_cross=y_end,
        entering=no,
        wall=jnp.array(0),
    )
    return Piece(
        end=end,
        accept=jnp.array(True),
        fail=~jnp.all(jnp.isfinite(y_end)),
        dt_new=state.dt,
        err=state.err_prev,
        h_used=state.dt_region[region_index(mask)],
        f_max=problem.contact_force_abs(state.y, mask),
    )
