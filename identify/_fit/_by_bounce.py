"""Intervals by bounce for position traces: a covariance that counts bounces, not frames.

A real ball's restitution varies from bounce to bounce (0.3–7% measured on real throws),
so a trace's position residuals are not independent: every frame of one flight shares
that flight's launch speed. The Gauss–Newton covariance treats them as independent and
its intervals shrink with the number of frames; on real 30 fps videos they excluded the
reference e, 5–20× too narrow.

Here each flight of a trace is one cluster (rows between two impacts of the fitted
trajectory). Whether the residuals are locked to the bounces is tested first: the
squares each flight's own straight line (mean and slope in time) takes out of its
residuals, against what is left, are an F statistic with (2G, N − 2G) degrees of
freedom under independent noise (G flights); p < `P_BOUNCE_LOCKED` means bounce-locked
residuals.
Only then is the cluster-robust ("sandwich") covariance

    Cov_CR = G/(G − 1) · A⁻¹ (Σ_g J_gᵀ r_g r_gᵀ J_g) A⁻¹,   A = JᵀJ,

(Liang & Zeger 1986; the CR1 small-sample factor, Cameron & Miller 2015, J. Human
Resources 50(2) §VI) is inflated by (t_{G−1, 0.975} / z_0.975)² so that the normal 95%
intervals become Student-t ones with G − 1 degrees of freedom (G flights: with 6 flights
the intervals widen by 2.57/1.96), and the reported covariance is the smallest matrix
at least as large as both this and the Gauss–Newton one (their difference's positive
part added). Clean data keep their frame-counting interval; bounce-to-bounce scatter
widens it to what the bounces carry.
"""

from __future__ import annotations

import numpy as np

from .._data._trace_flights import apex_ratios, bounce_spread
from ._uncertainty import Z95

#: The fewest flights from which a between-flight scatter is estimated.
MIN_FLIGHTS = 3
#: Residuals whose per-flight lines are this unlikely under independent noise are
#: bounce-locked.
P_BOUNCE_LOCKED = 1e-3


def bounce_locked(r: np.ndarray, clusters: np.ndarray, t: np.ndarray) -> float:
    """The p-value of independent residuals against per-flight lines (mean and slope).

    `r`: residuals (any unit), `clusters`: a flight label per row (−1: none), `t`: the
    rows' times (s). The F test of the squares the G flights' own lines take out (2G
    degrees of freedom) against what is left (N − 2G), so the noise level need not be
    known. Returns 1 when fewer than `MIN_FLIGHTS` flights have four rows.
    """
    import scipy.stats  # imported on use: importing identify loads no scipy

    labels = [k for k in np.unique(clusters[clusters >= 0]) if np.sum(clusters == k) >= 4]
    if len(labels) < MIN_FLIGHTS:
        return 1.0
    explained = left = 0.0
    n = 0
    for k in labels:
        rows = clusters == k
        tt = t[rows] - t[rows].mean()
        design = np.stack([np.ones_like(tt), tt], axis=1)
        coef = np.linalg.lstsq(design, r[rows], rcond=None)[0]
        fitted = design @ coef
        explained += float(np.sum(fitted**2))
        left += float(np.sum((r[rows] - fitted) ** 2))
        n += int(rows.sum())
    dof = n - 2 * len(labels)
    if not (left > 0 and dof > 0):
        return 1.0
    return float(scipy.stats.f.sf((explained / (2 * len(labels))) / (left / dof), 2 * len(labels), dof))


def flight_labels(predicted: np.ndarray) -> np.ndarray:
    """One label per row of a drop trace: the flight it belongs to, counted from 0.

    `predicted` are the fitted heights at the sample times (m, noise-free): a drop's
    heights have local maxima only in flight, so each strict local minimum of the
    prediction is an impact, and the rows after it start a new flight.
    """
    x = np.asarray(predicted, dtype=float)
    if x.size < 3:
        return np.zeros(x.size, int)
    interior = (x[1:-1] < x[:-2]) & (x[1:-1] <= x[2:])
    cuts = np.flatnonzero(interior) + 1
    labels = np.zeros(x.size, int)
    for c in cuts:
        labels[c + 1 :] += 1
    return labels


def by_bounce(cov: np.ndarray, jac: np.ndarray, r: np.ndarray, clusters: np.ndarray) -> np.ndarray:
    """`cov` widened to the cluster-robust covariance of the rows' `clusters`.

    **Arguments:** `cov` the Gauss–Newton covariance of the free entries; `jac`, `r` the
    fitted rows' Jacobian and residuals (in σ units, the rows `cov` used); `clusters` one
    integer label per row (−1: a row in no cluster, e.g. an impact file's). The sandwich
    scales itself from the residuals: no noise scale is needed.

    **Returns:** `cov` unchanged when fewer than `MIN_FLIGHTS` clusters or a singular
    problem; otherwise the least matrix ≥ both `cov` and the t-scaled sandwich.
    """
    import scipy.stats

    labels = np.unique(clusters[clusters >= 0])
    g = labels.size
    if g < MIN_FLIGHTS or not np.all(np.isfinite(cov)):
        return cov
    a = jac.T @ jac
    try:
        a_inv = np.linalg.pinv(a, rcond=1e-13, hermitian=True)
    except np.linalg.LinAlgError:
        return cov
    scores = np.stack([jac[clusters == k].T @ r[clusters == k] for k in labels])
    meat = scores.T @ scores
    t_factor = (scipy.stats.t.ppf(0.975, g - 1) / Z95) ** 2
    sandwich = a_inv @ meat @ a_inv * (g / (g - 1)) * t_factor
    diff = sandwich - cov
    lam, vec = np.linalg.eigh(0.5 * (diff + diff.T))
    return cov + (vec * np.maximum(lam, 0.0)) @ vec.T


def trace_clusters(setup, rows, r_data: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """A flight label per data row of a fit (−1 for rows of files that are not drop traces),
    unique across files: the flights of each drop trace, from its fitted heights (data +
    residual·σ); and each row's time (s; NaN for rows of other files)."""
    n = sum(setup.n_rows)
    out = np.full(n, -1, int)
    times = np.full(n, np.nan)
    next_label = 0
    for f, d in enumerate(setup.datasets):
        if d.observe != "trace" or d.scene != "drop":
            continue
        sl = rows.of_file(f)
        predicted = np.asarray(d.x, dtype=float) + r_data[sl] * float(setup.sigmas[f])
        labels = flight_labels(predicted)
        out[sl] = labels + next_label
        times[sl] = np.asarray(d.t, dtype=float)
        next_label += int(labels.max()) + 1
    return out, times


def restitution_spread(setup, z: np.ndarray) -> np.ndarray:
    """The per-bounce e (`apex_ratios`) of every drop trace of a fit, at its fitted level,
    scale and drag."""
    from ._problem import PARAMETERS

    out = []
    for f, d in enumerate(setup.datasets):
        if d.observe == "trace" and d.scene == "drop":
            zf = {name: float(z[setup.layout.index[f, i]]) for i, name in enumerate(PARAMETERS)}
            drag = float(np.exp(zf["drag"])) if d.drag > 0 or setup.layout.index[f, 2] in setup.free else 0.0
            out.append(
                apex_ratios(
                    d.t, d.x, level=zf["level"], scale=zf["scale"], drag=drag, gravity=float(d.gravity)
                )
            )
    return np.concatenate(out) if out else np.zeros(0)


def widen_by_bounce(entry: dict, e_bounces: np.ndarray) -> dict | None:
    """e's entry with its 95% interval at least the bounces' own: ± t_{n−1} s/√n (s the
    spread of the n per-bounce e, `bounce_spread`), clipped to [0, 1]; None when fewer than 2
    bounces measure the spread."""
    import scipy.stats

    n = e_bounces.size
    if n < 2:
        return None
    half = float(scipy.stats.t.ppf(0.975, n - 1) * bounce_spread(e_bounces) / np.sqrt(n))
    lo, hi = entry["ci95"]
    value = entry["value"]
    if not (np.isfinite(lo) and np.isfinite(hi)) or half <= (hi - lo) / 2:
        return dict(entry)
    return {"value": value, "stderr": half / Z95, "ci95": [max(value - half, 0.0), min(value + half, 1.0)]}
