"""Synthetic drops recorded as impact onsets, from closed-form flights (an independent reference).

A ball dropped from rest at height h0 (m) with quadratic drag k (s/m) flies in closed
form: falling from rest through height h takes acosh(exp(g k² h))/(g k) and lands at
tanh(g k t)/k; launched upward at u it rises for atan(k u)/(g k) to the apex
ln(1 + k²u²)/(2 g k²). Each bounce i has its own restitution e_i = e (1 + s N(0, 1))
(the bounce-to-bounce scatter of a real ball) and lasts t_c on the floor; the recorder
adds an unknown clock offset and times each onset to its sample grid.

Nothing here uses jaxunilat or identify: the fits are checked against it.
"""

from __future__ import annotations

import math

import numpy as np

G = 9.81


def _fall(h: float, k: float) -> tuple[float, float]:
    """Time (s) and landing speed (m/s) of a fall from rest through h (m)."""
    if k == 0:
        t = math.sqrt(2 * h / G)
        return t, G * t
    t = math.acosh(math.exp(G * k * k * h)) / (G * k)
    return t, math.tanh(G * k * t) / k


def _rise(u: float, k: float) -> tuple[float, float]:
    """Time (s) to the apex and its height (m) after a launch at u (m/s)."""
    if k == 0:
        return u / G, u * u / (2 * G)
    return math.atan(k * u) / (G * k), math.log1p((k * u) ** 2) / (2 * G * k * k)


def throw(
    seed: int,
    *,
    e: float = 0.9,
    scatter: float = 0.003,
    h0: float = 0.5,
    drag: float = 0.04,
    contact_time: float = 1e-3,
    bounces: int = 10,
    offset: float = 1.7,
    rate: float = 48000.0,
) -> tuple[np.ndarray, np.ndarray]:
    """Onset times (s, recording clock, rounded to the 1/`rate` grid) and the per-bounce e_i."""
    rng = np.random.default_rng(seed)
    e_i = e * (1.0 + scatter * rng.standard_normal(bounces))
    t_fall, w = _fall(h0, drag)
    onsets = [t_fall]
    for i in range(bounces - 1):
        t_up, apex = _rise(e_i[i] * w, drag)
        t_down, w = _fall(apex, drag)
        onsets.append(onsets[-1] + contact_time + t_up + t_down)
    recorded = np.round((np.asarray(onsets) + offset) * rate) / rate
    return recorded, e_i
