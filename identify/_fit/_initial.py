"""Closed-form initial guesses for the restitution e.

The contact time t_c is not visible in rebound heights or flight times to first order,
so the guess takes it from a prior (0.5–2 ms, assumed for a table-tennis ball); the
multi-start spreads over that prior. With (e, t_c) the Kelvin–Voigt inverse gives
(κ, k_r), `jaxunilat.parameters_from_restitution`.
"""

from __future__ import annotations

import math

import numpy as np

from .._data._trace_flights import apex_ratios, flight_meetings, trace_flights

#: The contact-time prior, s: an assumed range, not a measurement.
CONTACT_TIME_PRIOR = (0.5e-3, 2.0e-3)
#: The prior's centre (geometric mean), s.
CONTACT_TIME_GUESS = math.sqrt(CONTACT_TIME_PRIOR[0] * CONTACT_TIME_PRIOR[1])

_E_RANGE = (0.05, 0.995)


def _clip_e(e: float) -> float:
    return float(np.clip(e, *_E_RANGE)) if np.isfinite(e) else 0.8


def restitution_from_heights(heights, drop_height: float | None = None) -> float:
    """e ≈ √(h_{k+1}/h_k), the median over successive rebound apex heights (drag-free).

    With only one height, the drop height h_0 supplies the first ratio.
    """
    h = np.asarray(heights, dtype=float)
    if drop_height is not None and drop_height > 0:
        h = np.concatenate([[drop_height], h])
    h = h[h > 0]
    if len(h) < 2:
        return 0.8
    return _clip_e(float(np.median(np.sqrt(h[1:] / h[:-1]))))


def restitution_from_impacts(times) -> float:
    """e ≈ T_{k+1}/T_k, the median ratio of successive flight times (drag-free: T = 2v/g)."""
    t = np.asarray(times, dtype=float)
    flights = np.diff(t)
    if len(flights) < 2:
        return 0.8
    return _clip_e(float(np.median(flights[1:] / flights[:-1])))


def restitution_from_impacts_with_drag(times, drag: float, gravity: float) -> float:
    """The median per-bounce e of drag-corrected flights (`identify.bounce_restitution`).

    With quadratic drag the drag-free ratio T_{k+1}/T_k reads low (0.924 for a
    ping-pong ball whose e is 0.955); the flights' launch and landing speeds do not.
    Falls back to the drag-free ratio when the onsets are not strictly increasing.
    """
    from ._restitution import bounce_restitution

    try:
        e = bounce_restitution(np.asarray(times, dtype=float), drag=drag, gravity=gravity).restitution
    except ValueError:
        return restitution_from_impacts(times)
    e = np.asarray(e)[np.isfinite(e)]
    return _clip_e(float(np.median(e))) if e.size else restitution_from_impacts(times)


def apex_heights_of_trace(t, x, noise: float | None = None) -> np.ndarray:
    """Rebound apex heights of a drop-test trace: the maxima of x between contacts.

    A contact is where x falls within a band above the trace's minimum (3σ or 2% of
    the range); the release flight (before the first contact) is dropped.
    """
    x = np.asarray(x, dtype=float)
    span = float(np.max(x) - np.min(x))
    band = max(3.0 * (noise or 0.0), 0.02 * span)
    low = x <= np.min(x) + band
    heights = []
    start = None
    seen_contact = False
    for i, is_low in enumerate(low):
        if is_low:
            if start is not None and seen_contact and i - start > 2:
                heights.append(float(np.max(x[start:i])))
            start = None
            seen_contact = True
        elif start is None:
            start = i
    return np.asarray(heights)


def initial_restitution(data) -> float | None:
    """The closed-form e for a data set, or None where there is none (two-racket traces)."""
    if data.observe == "apex":
        drop = data.x0 if data.scene == "drop" and data.v0 == 0 else None
        return restitution_from_heights(data.h, drop)
    if data.observe == "impacts":
        if data.drag > 0 and len(data.t) >= 3:
            return restitution_from_impacts_with_drag(data.t, data.drag, data.gravity)
        return restitution_from_impacts(data.t)
    if data.scene == "drop":
        # Successive flights' parabolas, at the closed-form scale and level: at video rates
        # the samples never reach the contact, and a band above the lowest one merged flights.
        found = trace_calibration(data.t, data.x, data.gravity)
        if found is not None:
            e = apex_ratios(
                data.t,
                data.x,
                level=found[1],
                scale=found[0],
                drag=float(data.drag),
                gravity=float(data.gravity),
            )
            if e.size:
                return _clip_e(float(np.median(e)))
        heights = apex_heights_of_trace(data.t, data.x, data.noise)
        if len(heights) >= 1:
            drop = data.x0 if data.v0 == 0 else None
            return restitution_from_heights(heights, drop)
    return None


def first_impact_time(x0: float, v0: float, gravity: float) -> float:
    """Drag-free fall time from height x0 > 0 with upward speed v0 to x = 0, s."""
    return (v0 + math.sqrt(v0 * v0 + 2.0 * gravity * max(x0, 0.0))) / gravity


def trace_calibration(t, x, gravity: float) -> tuple[float, float] | None:
    """A drop-test trace's length scale and contact level in closed form, or None.

    x_data = level + scale · x_model: every complete rebound flight gets a least-squares
    parabola (`trace_flights`); its curvature against gravity gives the scale (flights
    weighted by n·T⁴, the inverse variance of the curvature; drag cancels to first order
    over a flight symmetric about its apex), and where two successive parabolas meet
    (`flight_meetings`) gives the contact level (the median over contacts). None when
    fewer than one complete flight is found, or the scale is outside 0.5–2.
    """
    t, x = np.asarray(t, dtype=float), np.asarray(x, dtype=float)
    fits = trace_flights(t, x)
    if not fits:
        return None
    weights = np.array([f.weight for f in fits])
    curvature = np.array([-2.0 * f.coef[0] for f in fits])
    scale = float(np.sum(weights * curvature) / np.sum(weights) / gravity)
    if not 0.5 < scale < 2.0:
        return None
    levels = [height for _, _, height in flight_meetings(fits, t)]
    if not levels:
        return None
    return scale, float(np.median(levels))
