"""Free flights in a tracked image trace: parabolas, impacts, gravity in pixels.

Image y points down; in free flight the ball's centre follows y(t) = A + B τ + G τ² / 2
(τ = t - t_ref, one A and B per flight, G = g in px/s² common to all flights). A bounce is
a lowest point of the trace (a peak of y) at least `prominence` px below its neighbouring
highest points. Each segment between bounces keeps the longest run of frames that one
parabola with the current G fits within `tol` px (at most one glitch inside it); what it
leaves at the start of the clip is the ball held before the release, at the end the ball
resting, rolling or leaving. All flights are then fitted together (G free, weighted least
squares, an extra scatter s added to every frame's tracking uncertainty so that the fit's
chi-square equals its degrees of freedom), and frames beyond `OUTLIER` sigma are dropped.
Impacts are where successive parabolas meet (with a common G their difference is linear
in t, so they meet once); the contact level is the parabolas' height there.

A rolling shutter exposes each sensor row a little later than the one before, so a frame
shows the ball at its time stamp plus the readout's share at the ball's row: a free fall
becomes a sheared parabola (a falling ball stretched, a rising one squeezed, the release's
fall alone curved by a few to tens of percent more or less). Given each frame's position
down the sensor's rows, the readout is fitted to the flights and, where it shows beyond
chance, the flights are fitted on the corrected times (`find_flights`, `fit_readout`).
"""

from __future__ import annotations

import dataclasses
import math

import numpy as np
from scipy.signal import find_peaks

#: Frames off their flight's joint fit by more than this many sigma are dropped.
OUTLIER = 4.0
#: The least tracking uncertainty assumed, px.
MIN_SIGMA = 0.01
#: Successive flights more than this many frame steps apart, and further apart than the
#: later flight lasts, meet at no impact (a bounce or more was missed between them: the
#: flight missed would last longer than the later one).
MAX_GAP = 5.5
#: The fewest frames a flight needs (two parameters and one check).
MIN_FRAMES = 3
#: The flights are selected on this many trial readouts besides 0 (up to a frame interval)
#: before the readout is fitted to each selection.
READOUT_TRIALS = 3
#: The readout's fit weighs frames beyond this many sigma linearly (Huber), not squared.
HUBER = 2.0
#: A rolling shutter's readout is fitted only where it lowers the flights' robust residual
#: sum (`_robust_cost`, in units of sigma squared) by this much (one parameter: 25 is 5 sigma).
READOUT_SIGNIFICANCE = 25.0


@dataclasses.dataclass(frozen=True)
class Flight:
    """One free flight (between impacts), in source px and s on the container's clock.

    - `frames`: indices (into the tracked unique frames) of the frames it keeps.
    - `t_ref`: s; `a`, `b`: px and px/s, y(t) = a + b (t - t_ref) + G (t - t_ref)² / 2.
    - `apex_t`, `apex_y`: the highest point of the parabola (s, px).
    - `gravity_alone`, `gravity_alone_sigma`: G from this flight alone and its standard
      error, px/s² (NaN with fewer than 5 frames).
    """

    frames: np.ndarray
    t_ref: float
    a: float
    b: float
    apex_t: float
    apex_y: float
    gravity_alone: float
    gravity_alone_sigma: float

    def y(self, t, gravity: float):
        """The parabola's y (px) at times `t` (s)."""
        tau = np.asarray(t) - self.t_ref
        return self.a + self.b * tau + 0.5 * gravity * tau**2


@dataclasses.dataclass(frozen=True)
class Flights:
    """The flights of a trace and what joins them.

    - `flights`: the `Flight`s in time order; `segment`: the bounce segment of each.
    - `gravity`, `gravity_sigma`: G and its standard error, px/s².
    - `scatter`: the extra scatter s, px; `sigma`: each kept frame's uncertainty, px
      (tracking and scatter), aligned with `kept`.
    - `kept`: the indices of the frames kept (all flights, time order).
    - `impacts`: (k, 2) array of (t, y) where successive flights meet (s, px), only
      between flights with no segment left out between them; `impact_after`: the index
      of the flight before each impact.
    - `residual`: each kept frame's residual, px.
    - `t`: s, the time of every tracked frame that the flights are fitted on: the frame's
      time stamp, plus `readout` (s) × its sensor row (0-1) where a rolling shutter was found.
    """

    flights: tuple[Flight, ...]
    segment: tuple[int, ...]
    gravity: float
    gravity_sigma: float
    scatter: float
    sigma: np.ndarray
    kept: np.ndarray
    impacts: np.ndarray
    impact_after: tuple[int, ...]
    residual: np.ndarray
    t: np.ndarray
    readout: float = 0.0


def _fit_fixed(t, y, w, gravity):
    """A, B of y = A + B τ + G τ²/2 with G fixed (τ = t - mean t), weights w; and t_ref."""
    t_ref = float(np.mean(t))
    tau = t - t_ref
    z = y - 0.5 * gravity * tau**2
    X = np.stack([np.ones_like(tau), tau], 1) * np.sqrt(w)[:, None]
    (a, b), *_ = np.linalg.lstsq(X, z * np.sqrt(w), rcond=None)
    return float(a), float(b), t_ref


def _residuals(t, y, gravity, a, b, t_ref):
    tau = t - t_ref
    return y - (a + b * tau + 0.5 * gravity * tau**2)


def best_run(t, y, gravity: float, tol: float) -> np.ndarray:
    """The positions (into t, y) of the longest contiguous run that one parabola with
    `gravity` fits within `tol` px, allowing one interior point off it (of two equally long,
    the one with the smaller squared residuals); empty if none of `MIN_FRAMES` points."""
    n = len(t)
    best = np.zeros(0, dtype=int)
    best_cost = math.inf
    for lo in range(n):
        for hi in range(n - 1, lo + MIN_FRAMES - 2, -1):
            if hi - lo + 1 < len(best):
                break
            idx = np.arange(lo, hi + 1)
            found = _fits(t[idx], y[idx], gravity, tol)
            if found is None:
                continue
            keep, cost = found
            if keep.sum() > len(best) or (keep.sum() == len(best) and cost < best_cost):
                best, best_cost = idx[keep], cost
    return best


def _fits(t, y, gravity, tol) -> tuple[np.ndarray, float] | None:
    """If one parabola fits the run within `tol` (all points, or all but one interior
    point): which points it keeps and their sum of squared residuals; else None."""
    w = np.ones(len(t))
    r = _residuals(t, y, gravity, *_fit_fixed(t, y, w, gravity))
    if np.all(np.abs(r) <= tol):
        return np.ones(len(t), dtype=bool), float(np.sum(r**2))
    if len(t) < MIN_FRAMES + 2:
        return None
    k = int(np.argmax(np.abs(r)))
    if k in (0, len(t) - 1):
        return None
    keep = np.ones(len(t), dtype=bool)
    keep[k] = False
    r = _residuals(t[keep], y[keep], gravity, *_fit_fixed(t[keep], y[keep], w[keep], gravity))
    return (keep, float(np.sum(r**2))) if np.all(np.abs(r) <= tol) else None


def segments(y: np.ndarray, prominence: float) -> list[np.ndarray]:
    """The positions of the frames of each segment between bounces (a bounce frame, a
    lowest point, belongs to both of its segments)."""
    peaks, _ = find_peaks(np.concatenate([[-np.inf], y, [-np.inf]]), prominence=prominence)
    peaks = peaks - 1
    edges = [0, *[int(p) for p in peaks], len(y) - 1]
    return [np.arange(a, b + 1) for a, b in zip(edges[:-1], edges[1:], strict=True) if b > a]


def joint_fit(groups, t, y, sigma_track, gravity0):
    """G free, A and B per flight: weighted least squares with an extra scatter s.

    Returns (G, sigma_G, [(a, b, t_ref)], s, residuals (aligned with the concatenated groups))."""
    rows = np.concatenate(groups)
    k = len(groups)
    X = np.zeros((len(rows), 1 + 2 * k))
    t_refs = []
    at = 0
    for j, g in enumerate(groups):
        t_ref = float(np.mean(t[g]))
        tau = t[g] - t_ref
        X[at : at + len(g), 0] = 0.5 * tau**2
        X[at : at + len(g), 1 + 2 * j] = 1.0
        X[at : at + len(g), 2 + 2 * j] = tau
        t_refs.append(t_ref)
        at += len(g)
    z = y[rows]
    s = 0.0
    dof = max(1, len(rows) - X.shape[1])
    for _ in range(30):
        w = 1.0 / (sigma_track[rows] ** 2 + s**2)
        sw = np.sqrt(w)
        p, *_ = np.linalg.lstsq(X * sw[:, None], z * sw, rcond=None)
        r = z - X @ p
        chi2 = float(np.sum(w * r**2))
        if abs(chi2 / dof - 1.0) < 1e-3 or (chi2 < dof and s == 0.0):
            break
        s = _scatter_for(r, sigma_track[rows], dof)
    cov = np.linalg.pinv((X * w[:, None]).T @ X)
    params = [(float(p[1 + 2 * j]), float(p[2 + 2 * j]), t_refs[j]) for j in range(k)]
    return float(p[0]), float(math.sqrt(max(cov[0, 0], 0.0))), params, s, r


def _scatter_for(r, sigma, dof) -> float:
    """The extra scatter s (px) with sum r² / (sigma² + s²) = dof (bisection)."""
    lo, hi = 0.0, float(np.max(np.abs(r))) + 1e-9
    if np.sum(r**2 / sigma**2) <= dof:
        return 0.0
    for _ in range(60):
        mid = 0.5 * (lo + hi)
        if np.sum(r**2 / (sigma**2 + mid**2)) > dof:
            lo = mid
        else:
            hi = mid
    return 0.5 * (lo + hi)


def find_flights(
    t,
    y,
    sigma_track,
    gravity0: float,
    *,
    prominence: float,
    tol: float,
    level_spread: float,
    rows=None,
    max_readout: float = 0.0,
) -> Flights | None:
    """The free flights of a trace (`t`: s; `y`: px, NaN where not tracked; `sigma_track`:
    px), starting from `gravity0` px/s²; None if not one flight of `MIN_FRAMES` frames.

    `prominence`, `tol`: px (see the module docstring); `level_spread`: px, how far an
    impact's level may be from the impacts' median (farther: not an impact). A flight with
    no impact at either end is dropped when others have one (it is not the ball's).

    `rows`: each frame's position down the sensor's rows (0 at the first row read, 1 at the
    last; None: no rolling shutter is looked for) and `max_readout` (s, at most a frame
    interval): a rolling shutter exposes each row `readout` × row later than the first, so
    the ball's time is t + readout × row (a sensor reads the rows it stores from the first
    to the last: readout ≥ 0). The flights are found on the time stamps and on
    `READOUT_TRIALS` trial readouts (a sheared flight, the release's fall, may fit
    one parabola only near the right one), the readout is fitted (`fit_readout`) to each
    selection and, where it improves the fit beyond chance, the flights are found again on
    those times; of the outcomes, the one that keeps the most frames (then the least
    scatter) is taken."""
    found = np.flatnonzero(np.isfinite(y))
    sig = np.where(np.isfinite(sigma_track), sigma_track, np.nanmedian(sigma_track))
    sig = np.maximum(sig, MIN_SIGMA)
    segs = [found[s] for s in segments(y[found], prominence)]
    t = np.asarray(t, dtype=float)
    step = float(np.median(np.diff(t)))
    out = _flights_on(segs, t, y, sig, gravity0, step, tol, level_spread)
    if out is None or rows is None or not max_readout > 0:
        return None if out is None else _result(*out, t, sig, 0.0)
    rows = np.where(np.isfinite(rows), rows, 0.0)
    # a flight that the shutter shears (the release: it only falls) may miss the selection on
    # the time stamps: select on a few trial readouts, then fit the readout to the best one's
    best, best_score = (out, t, 0.0), _score(out)
    for trial in np.linspace(0.0, max_readout, READOUT_TRIALS + 1):
        found = (
            out
            if trial == 0
            else _flights_on(segs, t + trial * rows, y, sig, out[1][0], step, tol, level_spread)
        )
        if found is None:
            continue
        readout = fit_readout([g for g, _ in found[0]], t, y, sig, found[1][2], rows, max_readout)
        again = _flights_on(segs, t + readout * rows, y, sig, found[1][0], step, tol, level_spread)
        if again is not None and _score(again) > best_score:
            best, best_score = (again, t + readout * rows, readout), _score(again)
    (groups, solved), t_best, readout = best
    return _result(groups, solved, t_best, sig, readout)


def _score(out) -> tuple[int, float]:
    """Which of two flight selections is better: more frames kept, then less scatter."""
    groups, solved = out
    return sum(len(g) for g, _ in groups), -solved[2]


def _flights_on(segs, t, y, sig, gravity0, step, tol, level_spread):
    """(groups, the joint solution `_solve`) of the segments' flights on times `t`, or None."""
    gravity = gravity0
    for _ in range(3):
        groups = _select(segs, t, y, gravity, tol)
        if not groups:
            return None
        g_new = joint_fit([g for g, _ in groups], t, y, sig, gravity)[0]
        converged = abs(g_new - gravity) < 1e-3 * abs(gravity)
        gravity = g_new
        if converged:
            break
    for _ in range(6):
        solved = _solve(groups, t, y, sig, gravity, step, tol, level_spread)
        gravity = solved[0]
        drop, lonely = solved[-2], solved[-1]
        if not drop and not lonely:
            break
        groups = [
            (np.asarray([i for i in g if i not in drop]), seg)
            for k, (g, seg) in enumerate(groups)
            if k not in lonely
        ]
        groups = [(g, seg) for g, seg in groups if len(g) >= MIN_FRAMES]
        if not groups:
            return None
    else:
        solved = _solve(groups, t, y, sig, gravity, step, tol, level_spread)
    return groups, solved


def _result(groups, solved, t, sig, readout) -> Flights:
    gravity, g_sigma, s, r, flights, impacts, after, _, _ = solved
    kept = np.concatenate([g for g, _ in groups])
    order = np.argsort(kept)
    return Flights(
        flights=tuple(flights),
        segment=tuple(j for _, j in groups),
        gravity=gravity,
        gravity_sigma=g_sigma,
        scatter=s,
        sigma=np.sqrt(sig[kept[order]] ** 2 + s**2),
        kept=kept[order],
        impacts=np.asarray(impacts, dtype=float).reshape(-1, 2),
        impact_after=tuple(after),
        residual=r[order],
        t=t,
        readout=float(readout),
    )


def fit_readout(groups, t, y, sig, scatter, rows, max_readout) -> float:
    """The rolling shutter's readout time (s, 0 to `max_readout`) that best fits the
    flights (G free, A and B per flight; a robust sum, `_chi2`) on the times t + readout ×
    rows, or 0 where it lowers that sum by less than `READOUT_SIGNIFICANCE` (weights: the
    tracking noise and the extra scatter left at the fitted readout, starting from `scatter`). A
    free fall read out row by row is a sheared parabola: a falling ball is stretched (its
    rows read later), a rising one squeezed, and a flight that only falls (the release)
    shows a curvature off by about 3 × readout × its speed over the picture's height."""
    from scipy.optimize import minimize_scalar

    best = 0.0
    for _ in range(3):
        w = 1.0 / (sig**2 + scatter**2)

        def cost(readout, w=w):
            return _robust_cost(groups, t + readout * rows, y, w)

        found = minimize_scalar(
            cost, bounds=(0.0, max_readout), method="bounded", options={"xatol": 1e-3 * max_readout}
        )
        best = float(found.x)
        left = joint_fit(groups, t + best * rows, y, sig, 0.0)[3]
        if abs(left - scatter) <= 0.05 * scatter:
            break
        scatter = left
    w = 1.0 / (sig**2 + scatter**2)
    gain = _robust_cost(groups, t, y, w) - _robust_cost(groups, t + best * rows, y, w)
    return best if gain > READOUT_SIGNIFICANCE else 0.0


def _robust_cost(groups, t, y, w) -> float:
    """The robust residual sum (Huber: quadratic within `HUBER` sigma, linear beyond; the
    weights refined 5 times) of the joint parabola fit (G free) of `groups` on times `t`: a
    frame taken across an impact (its blur a V) or still in the hand weighs little."""
    rows = np.concatenate(groups)
    X = np.zeros((len(rows), 1 + 2 * len(groups)))
    at = 0
    for j, g in enumerate(groups):
        tau = t[g] - np.mean(t[g])
        X[at : at + len(g), 0] = 0.5 * tau**2
        X[at : at + len(g), 1 + 2 * j] = 1.0
        X[at : at + len(g), 2 + 2 * j] = tau
        at += len(g)
    w0, z = w[rows], y[rows]
    wr = w0
    for _ in range(5):
        sw = np.sqrt(wr)
        p, *_ = np.linalg.lstsq(X * sw[:, None], z * sw, rcond=None)
        u = np.abs(z - X @ p) * np.sqrt(w0)
        wr = w0 * np.minimum(1.0, HUBER / np.maximum(u, 1e-12))
    return float(np.sum(np.where(u <= HUBER, u**2, 2.0 * HUBER * u - HUBER**2)))


def _solve(groups, t, y, sig, gravity, step, tol, level_spread):
    """The joint fit of `groups` and what follows from it: (G, sigma_G, s, residuals,
    flights, impacts, impact_after, frames beyond `OUTLIER` sigma, flights with no impact
    at either end when others have one)."""
    gravity, g_sigma, params, s, r = joint_fit([g for g, _ in groups], t, y, sig, gravity)
    rows = np.concatenate([g for g, _ in groups])
    drop = set(rows[np.abs(r) > OUTLIER * np.sqrt(sig[rows] ** 2 + s**2)].tolist())
    flights = _flights(groups, params, t, y, gravity, np.sqrt(sig**2 + s**2))
    impacts, after = _impacts(flights, [j for _, j in groups], t, y, gravity, step, tol, level_spread)
    ends = set(after) | {j + 1 for j in after}
    lonely = {j for j in range(len(flights)) if j not in ends} if impacts else set()
    return gravity, g_sigma, s, r, flights, impacts, after, drop, lonely


def _select(segs, t, y, gravity, tol) -> list[tuple[np.ndarray, int]]:
    """(frames, segment) of each segment's best run of `MIN_FRAMES` or more (`best_run`); a
    bounce frame kept by two successive runs stays with the one it fits better."""
    groups = []
    for j, seg in enumerate(segs):
        run = best_run(t[seg], y[seg], gravity, tol)
        if len(run) >= MIN_FRAMES:
            groups.append((seg[run], j))
    for k in range(len(groups) - 1):
        (g1, _), (g2, _) = groups[k], groups[k + 1]
        for i in np.intersect1d(g1, g2):
            miss = [_miss(g, i, t, y, gravity) for g in (g1, g2)]
            drop = k + 1 if miss[0] <= miss[1] else k
            g, seg = groups[drop]
            groups[drop] = (g[g != i], seg)
            g1, g2 = groups[k][0], groups[k + 1][0]
    return [(g, seg) for g, seg in groups if len(g) >= MIN_FRAMES]


def _miss(group, i, t, y, gravity) -> float:
    """How far frame i is from the parabola (G fixed) through the rest of `group`, px."""
    rest = group[group != i]
    if len(rest) < 2:
        return math.inf
    a, b, t_ref = _fit_fixed(t[rest], y[rest], np.ones(len(rest)), gravity)
    return abs(float(_residuals(t[i], y[i], gravity, a, b, t_ref)))


def _flights(groups, params, t, y, gravity, sigma) -> list[Flight]:
    out = []
    for (g, _), (a, b, t_ref) in zip(groups, params, strict=True):
        apex_tau = -b / gravity
        g_alone = _gravity_alone(t[g], y[g], sigma[g]) if len(g) >= 5 else (math.nan, math.nan)
        apex_y = a + b * apex_tau + 0.5 * gravity * apex_tau**2
        out.append(Flight(g, t_ref, a, b, t_ref + apex_tau, apex_y, *g_alone))
    return out


def _impacts(flights, seg_of, t, y, gravity, step, tol, level_spread):
    """Where successive flights meet: (t, y) and the index of the flight before, for flights
    of successive segments at most `MAX_GAP` frame steps apart (or less than the later
    flight's frames span: at a high frame rate a bounce hides more frames) whose parabolas
    meet between them,
    below (image y above) both flights' frames, within `level_spread` of the median level."""
    hits, after = [], []
    for j in range(len(flights) - 1):
        f1, f2 = flights[j], flights[j + 1]
        t_last, t_next = t[f1.frames[-1]], t[f2.frames[0]]
        span = t[f2.frames[-1]] - t_next  # no whole flight (at least as long) fits in a shorter gap
        if seg_of[j + 1] != seg_of[j] + 1 or t_next - t_last > max(MAX_GAP * step, span):
            continue
        hit = _meet(f1, f2, gravity)
        lowest = max(np.max(y[f1.frames]), np.max(y[f2.frames]))
        if hit is None or not (t_last - 0.5 * step <= hit[0] <= t_next + 0.5 * step) or hit[1] < lowest - tol:
            continue
        hits.append(hit)
        after.append(j)
    if hits:
        level = np.median([h[1] for h in hits])
        keep = [k for k, h in enumerate(hits) if abs(h[1] - level) <= level_spread]
        hits, after = [hits[k] for k in keep], [after[k] for k in keep]
    return hits, after


def _gravity_alone(t, y, sigma) -> tuple[float, float]:
    """G (px/s²) of a parabola fitted to one flight alone (weights 1/sigma), and its
    standard error."""
    tau = t - np.mean(t)
    p, cov = np.polyfit(tau, y, 2, w=1.0 / sigma, cov="unscaled")
    return float(2.0 * p[0]), float(2.0 * math.sqrt(max(cov[0, 0], 0.0)))


def _meet(f1: Flight, f2: Flight, gravity: float):
    """Where two parabolas with the same G meet: (t, y), or None if parallel."""
    # y_k(t) = c_k + d_k t + G t²/2 in absolute t
    d1 = f1.b - gravity * f1.t_ref
    d2 = f2.b - gravity * f2.t_ref
    c1 = f1.a - f1.b * f1.t_ref + 0.5 * gravity * f1.t_ref**2
    c2 = f2.a - f2.b * f2.t_ref + 0.5 * gravity * f2.t_ref**2
    if d1 == d2:
        return None
    t_hit = (c2 - c1) / (d1 - d2)
    return float(t_hit), float(f1.y(t_hit, gravity))
