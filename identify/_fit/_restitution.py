"""Per-bounce restitution from impact times, and the restitution curve e(v) of a contact law.

Two views of the same number, for the plot of restitution e against impact speed v:

- **from data** (`bounce_restitution`): the flights between successive contact onsets
  of a ball bouncing on a floor give, with quadratic air drag in closed form, the
  launch speed after each bounce and the landing speed before the next, hence
  e_i = (rebound speed)/(impact speed) per bounce;
- **from a contact law** (`law_restitution`, `law_contact_time`): one impact simulated
  with `jaxunilat.simulate` (event mode) per impact speed, e(v) = v_out/v.

`hunt_crossley_from_restitution` turns a measured (e, t_c) at one impact speed into
Hunt–Crossley (κ, k_r), the n = 3/2 counterpart of
`jaxunilat.parameters_from_restitution`.

**Flight with quadratic drag.** With k = 1/(terminal speed), s/m, a ball launched
upward at u rises with v' = −g(1 + k²v²) and falls with v' = −g(1 − k²v²). With
b = k·u and y = asinh(b) (so cosh y = √(1 + b²)):

    rise time      t_up   = atan(b)/(g k) = gd(y)/(g k),       gd(y) = atan(sinh y)
    apex height    h      = ln(1 + b²)/(2 g k²)
    fall time      t_down = acosh(exp(g k² h))/(g k) = y/(g k)
    landing speed  w      = tanh(g k t_down)/k = tanh(y)/k = u/√(1 + b²)

so a flight of duration T has g k T = gd(y) + y, which fixes y (Newton's method; the
left side is concave with slope in (1, 2]), then u = sinh(y)/k and w = tanh(y)/k.
Everything is written in y, which keeps full relative precision as k → 0 (there
y ≈ gkT/2 and u, w → gT/2, the drag-free values, which are used at k = 0 exactly).
"""

from __future__ import annotations

import dataclasses
import math
import warnings

import jax
import jax.numpy as jnp
import numpy as np

import jaxunilat
from jaxunilat import Status
from jaxunilat._internal import InputError, check_choice, check_finite, check_range

from ._problem import LAW_MODELS

# -- per-bounce restitution from onset times ------------------------------------------------

#: Newton iterations for g k T = gd(y) + y: from the lower bound max(τ/2, τ − π/2) the
#: iteration increases monotonically and converges quadratically (8 suffice in practice).
_NEWTON_MAX = 60


@dataclasses.dataclass(frozen=True)
class BounceRestitution:
    """Per-bounce restitution from the onset times of a ball bouncing on a floor.

    One entry per bounce whose impact and rebound speeds are both known:

    - `index`: the bounce's position in the onset times (0-based; bounce 0 only with
      a drop height).
    - `time`: its contact onset time, s.
    - `impact_speed`: the speed arriving at the bounce, m/s (> 0).
    - `rebound_speed`: the speed leaving it, m/s (> 0).
    - `restitution`: e = rebound_speed / impact_speed.

    And the settings that produced them: `drag` k (s/m), `gravity` g (m/s²),
    `contact_time` t_c (s).
    """

    index: np.ndarray
    time: np.ndarray
    impact_speed: np.ndarray
    rebound_speed: np.ndarray
    restitution: np.ndarray
    drag: float
    gravity: float
    contact_time: float

    def __len__(self) -> int:
        return len(self.index)


def _gd_plus(y):
    """gd(y) + y and its derivative sech(y) + 1 (gd the Gudermannian, atan(sinh y))."""
    return np.arctan(np.sinh(y)) + y, 1.0 / np.cosh(y) + 1.0


def _solve_fall_angle(tau: np.ndarray) -> np.ndarray:
    """y ≥ 0 with gd(y) + y = τ, elementwise, to a few ulps.

    G(y) = gd(y) + y is increasing and concave with G(y) ≤ 2y and G(y) < y + π/2, so
    y₀ = max(τ/2, τ − π/2) is below the root and Newton's iterates rise monotonically to it.
    """
    y = np.maximum(0.5 * tau, tau - 0.5 * math.pi)
    with np.errstate(over="ignore"):  # sinh, cosh → inf beyond y ≈ 710: gd = π/2, slope 1
        for _ in range(_NEWTON_MAX):
            value, slope = _gd_plus(y)
            step = (tau - value) / slope
            y = y + step
            if np.all(np.abs(step) <= 4.0 * np.finfo(float).eps * np.abs(y)):
                break
    return y


def flight_speeds(flight_time, *, drag: float, gravity: float = 9.81) -> tuple[np.ndarray, np.ndarray]:
    """Launch and landing speeds (u, w), m/s, of floor-to-floor flights lasting `flight_time` s.

    Quadratic drag with k = `drag` (s/m), gravity g (m/s²): g k T = gd(y) + y,
    u = sinh(y)/k, w = tanh(y)/k (the module docstring derives them); without drag
    u = w = g T/2. Relative accuracy: a few ulps.
    """
    t = np.asarray(flight_time, dtype=float)
    if drag == 0.0:
        u = 0.5 * gravity * t
        return u, u.copy()
    y = _solve_fall_angle(gravity * drag * t)
    return np.sinh(y) / drag, np.tanh(y) / drag


def drop_speed(height: float, *, drag: float, gravity: float = 9.81) -> float:
    """Speed after falling `height` m from rest, m/s: √(1 − exp(−2 g k² h))/k (√(2 g h) at k = 0)."""
    if drag == 0.0:
        return math.sqrt(2.0 * gravity * height)
    return math.sqrt(-math.expm1(-2.0 * gravity * drag * drag * height)) / drag


def bounce_restitution(
    onsets,
    *,
    drag: float,
    gravity: float = 9.81,
    contact_time: float = 0.0,
    drop_height: float | None = None,
) -> BounceRestitution:
    """Per-bounce restitution e_i from the contact onset times of a ball bouncing on a floor.

    The ball leaves the floor t_c after onset i and lands at onset i + 1, so flight i
    lasts T_i = t_{i+1} − t_i − t_c. With quadratic drag (k = `drag`) each flight's
    launch speed u_i and landing speed w_i follow in closed form from T_i:
    g k T_i = gd(y_i) + y_i, u_i = sinh(y_i)/k, w_i = tanh(y_i)/k (see the module
    docstring; rise time atan(k u)/(g k), apex ln(1 + k²u²)/(2 g k²), fall time
    acosh(exp(g k² h))/(g k), landing speed tanh(g k t_fall)/k). Bounce i + 1 then has

        impact speed w_i,   rebound speed u_{i+1},   e_{i+1} = u_{i+1}/w_i.

    With `drop_height` h₀ (a release from rest h₀ above the contact height), bounce 0
    has impact speed √(1 − exp(−2 g k² h₀))/k (√(2 g h₀) without drag) and rebound
    speed u_0.

    Without drag (k = 0) u_i = w_i = g T_i/2, so e_i = T_i/T_{i−1}: the usual estimate
    from flight times (phyphox's "inelastic collision" experiment, with t_c = 0). With
    drag that estimate is a lower bound on the true e_i, for every k > 0 (sinh(y)/G(y)
    and G(y)/tanh(y), G(y) = gd(y) + y, both increase with y from 1/2 and 2): for a
    light ball such as a table-tennis ball (k ≈ 0.1 s/m) it reads several per cent low.
    Leaving t_c out (when it is not zero) lengthens every T_i by t_c and biases e_i up.

    Assumptions: vertical motion; each contact starts and ends at the same height
    (the floor) and lasts t_c; the onsets are contact starts. The speeds are exact for
    this model to ~1e-15 relative (the onset times' own errors dominate).

    **Arguments:**

    - `onsets`: contact onset times, s, strictly increasing (at least 3; 2 with a drop height).
    - `drag`: k = 1/terminal speed, s/m (≥ 0).
    - `gravity`: g, m/s² (> 0).
    - `contact_time`: t_c, s (≥ 0, less than every interval between onsets).
    - `drop_height`: h₀, m (> 0), or `None` (bounce 0 is then left out).

    **Returns:** a `BounceRestitution`.
    """
    t = np.asarray(onsets, dtype=float)
    if t.ndim != 1:
        raise InputError(f"onsets has shape {t.shape}; expected a 1-D array of onset times in s")
    check_finite("onsets", t)
    check_range("drag", drag, lo=0.0, unit="s/m")
    check_range("gravity", gravity, lo=0.0, lo_open=True, unit="m/s^2")
    check_range("contact_time", contact_time, lo=0.0, unit="s")
    check_range("drop_height", drop_height, lo=0.0, lo_open=True, unit="m", allow_none=True)
    need = 2 if drop_height is not None else 3
    if len(t) < need:
        raise InputError(
            f"onsets has {len(t)} times; valid: at least {need} "
            f"({'with' if drop_height is not None else 'without'} drop_height)"
        )
    gaps = np.diff(t)
    if np.any(gaps <= 0):
        i = int(np.argmax(gaps <= 0))
        raise InputError(
            f"onsets[{i + 1}] = {t[i + 1]:g} s is out of range; valid range is onsets strictly increasing "
            f"(> onsets[{i}] = {t[i]:g} s)"
        )
    drag, gravity, contact_time = float(drag), float(gravity), float(contact_time)
    if not contact_time < gaps.min():
        raise InputError(
            f"contact_time = {contact_time:g} s is out of range; valid range is [0, {gaps.min():g}) s "
            "(below the shortest interval between onsets)"
        )
    launch, landing = flight_speeds(gaps - contact_time, drag=drag, gravity=gravity)
    impact, rebound, index = landing[:-1], launch[1:], np.arange(1, len(t) - 1)
    if drop_height is not None:
        first = drop_speed(float(drop_height), drag=drag, gravity=gravity)
        impact = np.concatenate([[first], impact])
        rebound = np.concatenate([launch[:1], rebound])
        index = np.concatenate([[0], index])
    return BounceRestitution(
        index=index,
        time=t[index],
        impact_speed=impact,
        rebound_speed=rebound,
        restitution=rebound / impact,
        drag=drag,
        gravity=gravity,
        contact_time=contact_time,
    )


# -- restitution of a contact law ----------------------------------------------------------

#: The contact laws `law_restitution` knows, by name.
LAWS = LAW_MODELS  # the fit's laws by name (`_problem.LAW_MODELS`)

#: The simulated horizon in units of the contact's time scale (see `_impact`). A contact
#: that has not ended by then holds the ball: e = 0, t_c = inf.
_HORIZON = 20.0
#: Hertz's contact-time constant: t_c = C δ_max/v for n = 3/2 (≈ 2.9432): the undamped
#: contact time at κ = 5/4, m = v = 1, where δ_max = 1 (`hunt_crossley_from_restitution`'s start).
_HERTZ = jaxunilat.hunt_crossley_contact_time(1.25, 1.0, 1.0)
#: Entry, deepest point, exit, and the apex after it: the loop stops at a fifth event.
_MAX_EVENTS = 4


def _impact(law: str, kappa, k_r, speed, mass, gravity, rtol):
    """One impact at `speed` onto a floor at x = 0: (e, contact time [s], status).

    The horizon is `_HORIZON` times the contact's time scale, the law's `impact_scales`:
    the undamped contact time (Kelvin–Voigt π√(m/κ); Hertz C·δ_max/v), or, with gravity,
    the period of small oscillations about the static penetration δ_s if shorter (slow
    impacts, where gravity sets the contact's duration); its depth scale sets atol. A contact exits before its first upward
    turning point in contact, if at all (there the spring force is below m g and the
    energy below that of the exit point), which this horizon covers with a margin.
    """
    ball = jaxunilat.Ball(
        kappa, k_r, mass=mass, gravity=gravity, drag=None, lower=0.0, upper=None, law=LAWS[law]
    )
    scale, depth = LAWS[law].impact_scales(kappa, mass, speed, gravity)
    sol = jaxunilat.simulate(
        ball,
        jnp.stack([jnp.zeros_like(speed), -speed]),
        _HORIZON * scale,
        solver="event",
        rtol=rtol,
        atol=rtol * depth,
        max_events=_MAX_EVENTS,
        samples=2,
        outputs=("v",),
        throw=False,
    )
    ev = sol.events
    is_exit = (ev.kind == jaxunilat.EventRecord.EXIT) & (jnp.arange(ev.t.shape[0]) < ev.count)
    found = jnp.any(is_exit)
    i = jnp.argmax(is_exit)
    # No exit: a contact that held the ball to the horizon (e = 0), unless the run failed.
    held = (sol.status == Status.SUCCESS) | (sol.status == Status.EVENT_OVERFLOW)
    e = jnp.where(found, ev.y[i, 1] / speed, jnp.where(held, 0.0, jnp.nan))
    t_c = jnp.where(found, ev.t[i], jnp.where(held, jnp.inf, jnp.nan))
    return e, t_c, sol.status


#: One compile per (law, padded batch size): all values are traced.
_impacts = jax.jit(jax.vmap(_impact, in_axes=(None, 0, 0, 0, None, None, None)), static_argnums=0)


def _bucket(n: int) -> int:
    """The padded batch size: a power of two ≥ 8, so that few batch sizes compile."""
    return max(8, 1 << (n - 1).bit_length())


def _impact_rows(law, kappa, k_r, speed, mass, gravity, rtol) -> tuple[np.ndarray, np.ndarray]:
    """(e, t_c) for rows of (κ, k_r, v) (1-D arrays of one length), one compiled batch."""
    n = len(speed)
    size = _bucket(n)

    def pad(a):
        a = np.asarray(a, dtype=float)
        return np.concatenate([a, np.repeat(a[-1:], size - n)])

    e, t_c, _ = _impacts(law, pad(kappa), pad(k_r), pad(speed), float(mass), float(gravity), float(rtol))
    return np.asarray(e)[:n], np.asarray(t_c)[:n]


def _check_law_inputs(law, kappa, k_r, mass, speeds, gravity, rtol):
    check_choice("law", law, tuple(LAWS))
    units = LAWS[law].units
    check_range("kappa", kappa, lo=0.0, lo_open=True, unit=units["kappa"])
    check_range("k_r", k_r, lo=0.0, unit=units["k_r"])
    check_range("mass", mass, lo=0.0, lo_open=True, unit="kg")
    check_range("gravity", gravity, lo=0.0, unit="m/s^2")
    check_range("rtol", rtol, lo=1e-14, hi=1e-3)
    v = np.asarray(speeds, dtype=float)
    if v.size == 0:
        raise InputError("speeds is empty; pass at least one impact speed in m/s")
    check_range("speeds", v, lo=0.0, lo_open=True, unit="m/s")
    if np.ndim(kappa) or np.ndim(k_r) or np.ndim(mass) or np.ndim(gravity):
        raise InputError("kappa, k_r, mass and gravity must be scalars; speeds carries the batch")
    return v


def _law_run(law, kappa, k_r, mass, speeds, gravity, rtol):
    v = _check_law_inputs(law, kappa, k_r, mass, speeds, gravity, rtol)
    flat = v.ravel()
    e, t_c = _impact_rows(
        law, np.full(flat.shape, float(kappa)), np.full(flat.shape, float(k_r)), flat, mass, gravity, rtol
    )
    return e.reshape(v.shape), t_c.reshape(v.shape)


def law_restitution(law: str, kappa, k_r, mass, speeds, *, gravity: float = 9.81, rtol: float = 1e-12):
    """Restitution e(v) of one impact onto a floor at each impact speed, from a contact law.

    One impact per speed v is simulated with `jaxunilat.simulate` (event mode): a
    `Ball(κ, k_r, m, g, drag=None, lower=0, upper=None, law=...)` starting at x = 0
    moving down at −v, until its contact exits; e = v_out/v with v_out the velocity at
    the located exit. The speeds run as one batch (`jax.vmap`), compiled once per law
    and padded batch size (a power of two ≥ 8); new values do not recompile.

    - `"kelvin-voigt"`: F = κδ + k_r δ̇. Without gravity e is the closed form
      exp(−πζ/√(1 − ζ²)), ζ = k_r/(2√(κm)), for every v (`jaxunilat.restitution`);
      gravity lowers e slightly, most at low speeds.
    - `"hunt-crossley"`: F = κδ^1.5 + k_r δ^1.5 δ̇ = κδ^1.5 (1 + χδ̇), χ = k_r/κ
      (`jaxunilat.HuntCrossley(1.5)`). Without gravity e depends on χv alone and falls
      as v rises, e ≈ 1 − (2/3)χv for small χv.

    A contact that has not exited within 20 of its time scales (see `_impact`) holds
    the ball: e = 0 (an overdamped Kelvin–Voigt contact, or a very slow impact held by
    gravity; Kelvin–Voigt with ζ > 0.995, whose true e is below 1e-13). NaN marks a
    failed run. Accuracy: ~1e-12 relative at the default `rtol`
    (Kelvin–Voigt without gravity: 2e-13 against the closed form).

    **Arguments:**

    - `law`: `"kelvin-voigt"` or `"hunt-crossley"`.
    - `kappa`: κ, N/m (Kelvin–Voigt) or N/m^1.5 (Hunt–Crossley), > 0.
    - `k_r`: damping, N·s/m (Kelvin–Voigt) or N·s/m^2.5 (Hunt–Crossley), ≥ 0.
    - `mass`: m, kg (> 0).
    - `speeds`: impact speeds v, m/s (> 0), any shape.
    - `gravity`: g, m/s² (≥ 0), acting during the contact.
    - `rtol`: the event mode's relative tolerance (the absolute one is rtol times the
      contact's depth scale).

    **Returns:** e, a NumPy array shaped like `speeds`.
    """
    return _law_run(law, kappa, k_r, mass, speeds, gravity, rtol)[0]


def law_contact_time(law: str, kappa, k_r, mass, speeds, *, gravity: float = 9.81, rtol: float = 1e-12):
    """Contact duration t_c(v), s, of one impact at each speed: the same runs as
    `law_restitution` (same arguments), from touchdown to the located exit; inf where the
    contact holds the ball. Kelvin–Voigt without gravity: π/ω_d (`jaxunilat.contact_time`);
    Hunt–Crossley without damping: `jaxunilat.hunt_crossley_contact_time`."""
    return _law_run(law, kappa, k_r, mass, speeds, gravity, rtol)[1]


# -- Hunt–Crossley parameters from (e, t_c) ------------------------------------------------

#: Relative step of the finite-difference Jacobian in `hunt_crossley_from_restitution`.
_FD_STEP = 1e-6
#: Both residuals (log e, log t_c) below this end the refinement.
_CONVERGED = 1e-11


def inverse_by_simulation(law: str, e: float, t_c: float, mass: float, speed: float, **options):
    """(κ, k_r) of a registered law without a closed-form inverse, from restitution e and
    contact time t_c (s) at impact speed `speed` (m/s), by simulated impacts: Hunt–Crossley
    with n = 3/2 (`hunt_crossley_from_restitution`, which takes `options`). Any other law
    raises `NoClosedFormError` naming it: a fit of it needs `initial` κ and k_r."""
    model = LAW_MODELS[law]
    if isinstance(model, jaxunilat.HuntCrossley) and model.exponent == 1.5:
        return hunt_crossley_from_restitution(e, t_c, mass, speed, **options)
    raise jaxunilat.NoClosedFormError(
        f"{model!r} has no closed-form map (e, t_c) -> (kappa, k_r) and identify has no simulated one for it; "
        "pass starting values: initial={'kappa': ..., 'k_r': ...}"
    )


def hunt_crossley_from_restitution(
    e: float,
    t_c: float,
    mass: float,
    speed: float,
    *,
    gravity: float = 9.81,
    refine: int = 6,
    rtol: float = 1e-12,
) -> tuple[float, float]:
    """Hunt–Crossley (n = 3/2) parameters (κ, k_r) with restitution e and contact time t_c at one speed.

    Start (closed forms, `refine=0`):

        χ = k_r/κ = 3(1 − e)/(2v)                      (Hunt & Crossley, small χv)
        δ_max = v t_c / C,  C = 2√π Γ(7/5)/Γ(9/10) ≈ 2.9432   (undamped Hertz contact time)
        κ = (5/4) m v² / δ_max^(5/2),  k_r = χ κ.

    The start is good for light damping only (e depends on χv alone without gravity,
    and hardly with it): at v = 3 m/s, t_c = 1 ms its e is high by 0.002 at e = 0.95,
    0.009 at 0.9, 0.032 at 0.8 and 0.16 at 0.5, and its damped contact time is longer
    than t_c (Hertz's undamped one) by 0.6%, 1.1%, 2.2% and 5.9%. Then up to
    `refine` Newton steps on (log κ, log χ) for the residuals (log e_law − log e,
    log t_c,law − log t_c), with the contact law simulated at v as in `law_restitution`
    (gravity included) and a finite-difference Jacobian: one batched simulation per
    step, stopping once both residuals are below 1e-11. With the default 6 steps e and
    t_c match to ~1e-11 relative for 0.1 ≤ e ≤ 1 (3–5 steps are used).

    **Arguments:**

    - `e`: restitution in (0, 1] (e = 1: k_r = 0, only κ is refined).
    - `t_c`: contact time, s (> 0).
    - `mass`: m, kg (> 0).
    - `speed`: the impact speed v, m/s (> 0).
    - `gravity`: g, m/s² (≥ 0) during the contact, as in `law_restitution`.
    - `refine`: Newton steps (≥ 0).
    - `rtol`: the simulations' tolerance.

    **Returns:** `(kappa, k_r)`: κ in N/m^1.5, k_r in N·s/m^2.5.
    """
    check_range("e", e, lo=0.0, hi=1.0, lo_open=True)
    check_range("t_c", t_c, lo=0.0, lo_open=True, unit="s")
    check_range("mass", mass, lo=0.0, lo_open=True, unit="kg")
    check_range("speed", speed, lo=0.0, lo_open=True, unit="m/s")
    check_range("gravity", gravity, lo=0.0, unit="m/s^2")
    if not isinstance(refine, (int, np.integer)) or refine < 0:
        raise InputError(f"refine = {refine!r} is out of range; valid range is integers >= 0")
    e, t_c, mass, v = float(e), float(t_c), float(mass), float(speed)
    chi = 1.5 * (1.0 - e) / v
    dmax = v * t_c / _HERTZ
    kappa = 1.25 * mass * v * v / dmax**2.5
    damped = e < 1.0
    target = np.array([math.log(e), math.log(t_c)])
    h = _FD_STEP
    for step_count in range(refine + 1 if refine else 0):
        # Rows: (κ, χ), (κ(1 + h), χ), (κ, χ(1 + h)).
        kappas = kappa * np.array([1.0, 1.0 + h, 1.0])
        chis = chi * np.array([1.0, 1.0, 1.0 + h])
        e_law, tc_law = _impact_rows(
            "hunt-crossley", kappas, kappas * chis, np.full(3, v), mass, gravity, rtol
        )
        if not (np.all(e_law > 0) and np.all(np.isfinite(tc_law))):
            warnings.warn(
                f"hunt_crossley_from_restitution: no rebound at kappa = {kappa:.6g} N/m^1.5, "
                f"k_r = {chi * kappa:.6g} N*s/m^2.5 after {step_count} steps; returning them unrefined",
                RuntimeWarning,
                stacklevel=2,
            )
            break
        r = np.stack([np.log(e_law), np.log(tc_law)], axis=1) - target  # (row, residual)
        if np.max(np.abs(r[0])) < _CONVERGED:
            break
        if step_count == refine:
            if np.max(np.abs(r[0])) > 1e-6:
                warnings.warn(
                    f"hunt_crossley_from_restitution: after {refine} steps e and t_c are off by "
                    f"{np.expm1(r[0, 0]):.2g} and {np.expm1(r[0, 1]):.2g} (relative); increase refine",
                    RuntimeWarning,
                    stacklevel=2,
                )
            break
        jac = (r[1:] - r[0]).T / math.log1p(h)  # d residual / d (log κ, log χ)
        if damped:
            step = np.linalg.solve(jac, -r[0])
        else:
            step = np.array([-r[0, 1] / jac[1, 0], 0.0])
        step = np.clip(step, -1.0, 1.0)  # at most a factor e per step
        kappa, chi = kappa * math.exp(step[0]), chi * math.exp(step[1])
    return float(kappa), float(chi * kappa)
