"""A drop trace's flights in closed form: parabolas, where they meet, per-bounce e.

At 24–60 fps a contact of a few ms falls between frames, and the frames near a contact
are a poor guide to where it is: a band "within 2% of the span" merged flights at video
rates (closed-form starts of 0.22–0.50 for a truth of 0.72–0.79). Here each complete
flight gets its own least-squares parabola from the samples away from its two contacts,
and a contact is where two successive parabolas meet (time and height). Successive
flights' apex heights give the per-bounce restitution with drag (`apex_ratios`), and a
drop's first fall its release (`trace_release`). Plain NumPy: the importers' checks and
the fit's closed-form starts share it.
"""

from __future__ import annotations

import dataclasses
import math

import numpy as np

#: A free flight needs this many samples away from its contacts for its parabola (three
#: coefficients and one degree of freedom).
MIN_FLIGHT_SAMPLES = 4
#: Contacts are the samples lowest within this window either side (s; ±1 sample at least).
CONTACT_WINDOW = 0.02
#: A parabola leaves out the samples within this time of a contact sample (s; at least
#: the contact sample's neighbour): a real contact lasts up to about 10 ms.
CONTACT_GUARD = 0.012


@dataclasses.dataclass(frozen=True)
class Flight:
    """One complete flight of a trace: between contact samples `first` and `last` (row
    indices), the parabola `coef` (highest power first) in t − `centre` (s, data units),
    and `weight` = n·T⁴, the inverse variance of its curvature up to a constant."""

    first: int
    last: int
    coef: np.ndarray
    centre: float
    weight: float


def trace_flights(t, x) -> list[Flight]:
    """The complete rebound flights of a drop trace (times s, heights in data units).

    Contacts are the samples lowest within ±`CONTACT_WINDOW` and below the trace's
    median, so a video whose frames miss the floor by centimetres still splits into
    flights; each flight's parabola leaves out the samples within `CONTACT_GUARD` of
    either contact (and the contact samples' neighbours).
    """
    t, x = np.asarray(t, dtype=float), np.asarray(x, dtype=float)
    if len(t) < 3 * MIN_FLIGHT_SAMPLES:
        return []
    dt = float(np.median(np.diff(t)))
    contacts = contact_rows(t, x)
    guard = max(1, int(math.ceil(CONTACT_GUARD / dt)))
    fits = []
    for a, b in zip(contacts[:-1], contacts[1:], strict=True):
        inner = np.arange(a + guard, b - guard + 1)
        if inner.size < MIN_FLIGHT_SAMPLES:
            continue
        centre = float(t[inner].mean())
        coef = np.polyfit(t[inner] - centre, x[inner], 2)
        if not coef[0] < 0:
            continue  # not a flight (a ball at rest, or noise)
        span = float(t[inner[-1]] - t[inner[0]])
        fits.append(Flight(int(a), int(b), coef, centre, inner.size * span**4))
    return fits


def flight_meetings(fits: list[Flight], t) -> list[tuple[int, float, float]]:
    """Where successive flights' parabolas meet: (contact row, time s, height).

    Flights that are not successive (a flight between them was too short for a
    parabola) give no meeting; of the two roots, the one nearest the contact sample,
    within two frame intervals of it.
    """
    t = np.asarray(t, dtype=float)
    dt = float(np.median(np.diff(t)))
    out = []
    for f1, f2 in zip(fits[:-1], fits[1:], strict=True):
        if f1.last != f2.first:
            continue
        q1 = np.polynomial.Polynomial(f1.coef[::-1])(np.polynomial.Polynomial([-f1.centre, 1.0]))
        q2 = np.polynomial.Polynomial(f2.coef[::-1])(np.polynomial.Polynomial([-f2.centre, 1.0]))
        roots = (q1 - q2).roots()
        roots = roots[np.isreal(roots)].real
        if roots.size:
            at = float(roots[np.argmin(np.abs(roots - t[f1.last]))])
            if abs(at - t[f1.last]) <= 2 * dt:
                out.append((f1.last, at, float(q1(at))))
    return out


def apex_ratios(t, x, *, level: float, scale: float, drag: float, gravity: float) -> np.ndarray:
    """Per-bounce e of a drop trace from its successive complete flights' apex heights.

    Heights H above `level` in metres (data units / `scale`). With quadratic drag k
    (s/m) a flight with apex H leaves at u = √(exp(2gk²H) − 1)/k and lands at
    w = √(1 − exp(−2gk²H))/k (the closed forms of `bounce_restitution`), so bounce k
    between flights k − 1 and k has e_k = u_k / w_{k−1}; without drag, √(H_k / H_{k−1}).
    """
    fits = trace_flights(t, x)
    out = []
    for f1, f2 in zip(fits[:-1], fits[1:], strict=True):
        if f1.last != f2.first:
            continue
        h1, h2 = ((f.coef[2] - f.coef[1] ** 2 / (4.0 * f.coef[0]) - level) / scale for f in (f1, f2))
        if not (h1 > 0 and h2 > 0):
            continue
        if drag > 0:
            a = 2.0 * gravity * drag * drag
            w = np.sqrt(-np.expm1(-a * h1)) / drag
            u = np.sqrt(np.expm1(a * h2)) / drag
            out.append(float(u / w))
        else:
            out.append(float(np.sqrt(h2 / h1)))
    return np.asarray(out)


def contact_rows(t, x) -> np.ndarray:
    """The rows of a drop trace's contact samples: each the lowest within
    ±`CONTACT_WINDOW` (±1 sample at least), below the trace's median, not an end row."""
    t, x = np.asarray(t, dtype=float), np.asarray(x, dtype=float)
    if len(t) < 3:
        return np.zeros(0, int)
    m = max(1, int(round(CONTACT_WINDOW / float(np.median(np.diff(t))))))
    padded = np.concatenate([np.full(m, np.inf), x, np.full(m, np.inf)])
    window = np.lib.stride_tricks.sliding_window_view(padded, 2 * m + 1)
    contacts = np.flatnonzero((np.argmin(window, axis=1) == m) & (x < np.median(x)))
    return contacts[(contacts > 0) & (contacts < len(x) - 1)]


def bounce_spread(e_bounces) -> float:
    """The standard deviation of per-bounce e (`apex_ratios`): 1.4826·MAD from five values
    on (a flight split wrongly by noise gives one wild ratio), the sample standard deviation
    below."""
    e = np.asarray(e_bounces, dtype=float)
    if e.size >= 5:
        return float(1.4826 * np.median(np.abs(e - np.median(e))))
    return float(np.std(e, ddof=1))


def first_contact(t, x) -> int | None:
    """The row of a drop trace's first contact sample (`contact_rows`), or None."""
    contacts = contact_rows(t, x)
    return int(contacts[0]) if contacts.size else None


def trace_release(t, x, *, curvature: float, noise: float) -> tuple[float, float] | None:
    """The release (time s, height in data units) of a drop from rest, from the frames
    before its first contact, or None.

    Frames that stay within 5·`noise` of the first three frames' median are the ball held
    still (a frame or two of the fall may count among them); the frames after them,
    before the first contact and its guard, fit x = h − (c/2)(t − t_r)² with the
    curvature c known (g times the length scale): a linear least-squares problem in
    (h − (c/2)t_r², c·t_r). t_r is never after the first frame that left the hold, and
    where the clip starts held, never before its first frame; a clip that enters
    mid-fall gets t_r before its first frame.
    """
    t, x = np.asarray(t, dtype=float), np.asarray(x, dtype=float)
    end = first_contact(t, x)
    if end is None or not curvature > 0:
        return None
    dt = float(np.median(np.diff(t)))
    guard = max(1, int(math.ceil(CONTACT_GUARD / dt)))
    ref = float(np.median(x[: min(3, end)]))
    away = np.abs(x[:end] - ref) > 5.0 * noise
    held = int(np.argmax(away)) if np.any(away) else end
    fall = np.arange(held, end - guard + 1)
    if fall.size < 2:
        return None
    a = 0.5 * curvature
    design = np.stack([np.ones(fall.size), t[fall]], axis=1)
    c0, c1 = np.linalg.lstsq(design, x[fall] + a * t[fall] ** 2, rcond=None)[0]
    t_r = min(float(c1 / (2.0 * a)), float(t[held]))
    if held >= 3:
        t_r = max(t_r, float(t[0]))
    return t_r, float(c0 + a * t_r**2)
