"""The flights' own restitution, bounce by bounce: its scatter and its trend with speed.

Before any fit, the onsets of a drop say in closed form (`bounce_restitution`: each
flight's launch and landing speeds from its duration, drag included) what e each bounce
had, at what impact speed. Two things follow, file by file (`flight_ratios`):

- **Scatter beyond the timing noise** (`FlightRatios.scatter`, `scatter_evident`). A
  timing noise σ on every onset moves log e_k (flights T_{k−1} then T_k) by
  δt_{k−1}/T_{k−1} − δt_k (1/T_{k−1} + 1/T_k) + δt_{k+1}/T_k (drag-free derivatives), so
  the per-bounce e of successive bounces are correlated (they share an onset), and the
  mean log e over a run of bounces telescopes to the ratio of its end flights: a run of
  short, noisy flights still has a precise mean e. Their covariance is
  V(s) = s² I + σ² M Mᵀ (M: those derivatives; s: the ball's own relative scatter).
  Both s and σ are estimated by restricted maximum likelihood (`components`; σ at most
  the stated noise: a phone importer's estimate is the intervals' scatter about a smooth
  decay, the ball's scatter included, and taken as timing noise it left a 0.3% ball
  0.13%). Where the per-bounce e scatter more than
  σ explains (χ² of their generalised least-squares residuals about a mean linear in
  the impact speed under V(0), chance below `P_SCATTER`), the ball's e varies from
  bounce to bounce, and the onset residuals of
  any constant-e model are a random walk: over 50–100 bounces it runs to tens of ms,
  past half the last intervals, and a least-squares fit of the onsets bends its contact
  time and release height to follow it (a steel ball's 81 onsets: t_c = 48 ms). Such
  files are fitted on the flights' log ratios from the first stage
  (`_stages.scatter_from_start`), whitened with the same covariance.
- **A trend with impact speed** (`restitution_trend`). A constant e is the model; a
  real ball's e can depend on the impact speed. A ping-pong ball's e falls at LOW speed
  (0.945 above 0.15 m/s, 0.89 below, on a phone's 52 bounces), which no contact law here
  gives (Hunt–Crossley's e falls as the speed RISES). The test splits the bounces by
  impact speed (the slowest below) and compares the two sides' generalised
  least-squares mean e (V(s), s re-estimated per split); the largest standard score is
  a trend when it reaches `Z_TREND` and the two sides differ by `MIN_E_CHANGE`, whatever
  the contact time (0 to 2 ms: a contact time left out of the flights raises the slow
  bounces' e, so each direction is tested at the end of that range that works against
  it). e falling at low speed: the fit keeps the onsets of the speed range above the
  split (at least half the bounces; the split is repeated on that side until none is
  left), where e is constant; e rising at low speed: the report says so (the
  Hunt–Crossley law describes that direction: `law="auto"`).
"""

from __future__ import annotations

import dataclasses
import math

import numpy as np

from ._initial import CONTACT_TIME_PRIOR

#: The fewest single-flight bounces from which scatter and trend are judged.
MIN_BOUNCES = 8
#: Scatter is evident when the per-bounce e's χ² under the timing noise alone has a
#: chance below this.
P_SCATTER = 1e-3
#: The least relative scatter s a covariance assumes (it keeps V(s) well conditioned).
SCATTER_FLOOR = 1e-5
#: A split of the bounces by impact speed is a trend at this many standard errors (the
#: largest of some 50 correlated splits of a constant e stays below about 3).
Z_TREND = 4.5
#: ... and when the two sides' e differ by at least this much.
MIN_E_CHANGE = 0.005
#: The fewest bounces on the slow side of a split.
MIN_SLOW = 3
#: The most of a file's bounces a trend may leave out (the slowest ones).
MAX_LEFT_OUT = 0.5


@dataclasses.dataclass(frozen=True)
class FlightRatios:
    """A file's per-bounce restitution in closed form (single flights on both sides).

    - `onset`: the onset row of each bounce (it joins flights `onset − 1` and `onset`).
    - `speed`: its impact speed, m/s; `restitution`: its e.
    - `noise`: the stated timing noise σ, s (0 where none is stated); `sensitivity`:
      (bounces, onsets), ∂ log e_k / ∂ t_j (drag-free).
    """

    onset: np.ndarray
    speed: np.ndarray
    restitution: np.ndarray
    noise: float
    sensitivity: np.ndarray

    def __len__(self) -> int:
        return len(self.onset)

    @property
    def timing(self) -> np.ndarray:
        """Each bounce's standard deviation of log e from the timing noise alone."""
        return self.noise * np.sqrt(np.sum(self.sensitivity**2, axis=1))

    def covariance(self, keep: np.ndarray | None = None, noise: float | None = None) -> np.ndarray:
        """σ² M Mᵀ over the kept bounces: the timing noise's part of V(s) (σ: `noise`,
        default the stated one)."""
        m = self.sensitivity if keep is None else self.sensitivity[keep]
        sigma = self.noise if noise is None else noise
        return sigma**2 * (m @ m.T)

    def components(self, keep: np.ndarray | None = None, *, trend: bool = False) -> tuple[float, float]:
        """(s, σ): the ball's relative scatter of e and the timing noise that the per-bounce e
        show (restricted maximum likelihood; σ at most the stated noise: an importer's
        estimate, the intervals' scatter about a smooth decay, holds the ball's scatter too),
        about a constant e (or, with `trend`, one linear in the impact speed)."""
        keep = np.ones(len(self), bool) if keep is None else keep
        x = np.log(self.restitution[keep])
        design = np.ones((len(x), 1))
        if trend:
            design = np.stack([design[:, 0], self.speed[keep]], axis=1)
        m = self.sensitivity[keep]
        return reml_components(x, design, m @ m.T, self.noise)

    def scatter(self, keep: np.ndarray | None = None) -> float:
        """The ball's relative bounce-to-bounce scatter s of e beyond the timing noise
        (`components`, about a constant e)."""
        return self.components(keep)[0]


def _reml_cost(xq, dq, v) -> float:
    """½(log|V| + log|DᵀV⁻¹D| + rᵀV⁻¹r) in V's eigenbasis (eigenvalues v); without columns
    in D, the plain likelihood of residuals x."""
    if dq.shape[1] == 0:
        return 0.5 * float(np.sum(np.log(v)) + np.sum(xq * xq / v))
    a = dq.T @ (dq / v[:, None])
    beta = np.linalg.solve(a, dq.T @ (xq / v))
    r = xq - dq @ beta
    return 0.5 * float(np.sum(np.log(v)) + np.linalg.slogdet(a)[1] + np.sum(r * r / v))


def reml_components(
    x: np.ndarray, design: np.ndarray, kernel: np.ndarray, noise: float
) -> tuple[float, float]:
    """(s, σ) of V = s² I + σ² `kernel` that maximise the restricted likelihood of x under
    the linear mean `design` (columns; none: x are residuals), s in 1e-5 to 1, σ in 0 to
    `noise` (σ = 0 where `noise` is 0)."""
    if not noise > 0:
        return reml_scatter(x, design, np.zeros_like(kernel)), 0.0
    lam, q = np.linalg.eigh(kernel)
    lam = np.maximum(lam, 0.0)
    xq, dq = q.T @ x, q.T @ design

    def cost(p):
        sigma = noise / (1.0 + math.exp(-p[1]))  # a logistic: σ from 0 to the stated noise
        return _reml_cost(xq, dq, math.exp(2 * p[0]) + sigma * sigma * lam)

    grid = [(a, b) for a in np.linspace(math.log(SCATTER_FLOOR), 0.0, 13) for b in np.linspace(-6.0, 6.0, 7)]
    start = min(grid, key=cost)
    from scipy.optimize import minimize

    found = minimize(cost, np.asarray(start), method="Nelder-Mead", options={"xatol": 1e-3, "fatol": 1e-6})
    log_s = float(np.clip(found.x[0], math.log(SCATTER_FLOOR), 0.0))
    return math.exp(log_s), noise / (1.0 + math.exp(-float(found.x[1])))


def reml_scatter(x: np.ndarray, design: np.ndarray, timing: np.ndarray, eigen=None) -> float:
    """The s of V(s) = s² I + `timing` that maximises the restricted likelihood of x under
    the linear mean `design` (columns; none: x are residuals already, and the likelihood
    is the plain one), over 1e-5 to 1 (relative). `eigen`: `timing`'s `np.linalg.eigh`,
    where already computed."""
    lam, q = np.linalg.eigh(timing) if eigen is None else eigen
    lam = np.maximum(lam, 0.0)
    xq, dq = q.T @ x, q.T @ design

    def cost(log_s):
        return _reml_cost(xq, dq, np.exp(2 * log_s) + lam)

    from scipy.optimize import minimize_scalar

    grid = np.linspace(math.log(SCATTER_FLOOR), 0.0, 41)
    k = int(np.argmin([cost(g) for g in grid]))
    lo, hi = grid[max(k - 1, 0)], grid[min(k + 1, len(grid) - 1)]
    if hi <= lo:
        return float(np.exp(grid[k]))
    found = minimize_scalar(cost, bounds=(lo, hi), method="bounded", options={"xatol": 1e-3})
    return float(np.exp(found.x))


def ratio_sensitivity(t: np.ndarray, onset: np.ndarray) -> np.ndarray:
    """∂ log e_k / ∂ t_j (bounces × onsets) of the bounces at rows `onset` (each joins
    the flights before and after it): log e_k ≈ log T_k − log T_{k−1}."""
    out = np.zeros((len(onset), len(t)))
    gaps = np.diff(t)
    for row, k in enumerate(onset):
        before, after = gaps[k - 1], gaps[k]
        out[row, k - 1] = 1.0 / before
        out[row, k] = -1.0 / before - 1.0 / after
        out[row, k + 1] = 1.0 / after
    return out


def flight_ratios(
    t, *, drag: float, gravity: float, noise: float | None, contact_time: float = 0.0
) -> FlightRatios | None:
    """The per-bounce e of onsets `t` (s) whose ratio chain counts the bounces (flights
    that span a missed bounce are left out), or None with fewer than `MIN_BOUNCES`."""
    from .._data._import import ratio_chain
    from ._restitution import bounce_restitution

    t = np.asarray(t, dtype=float)
    if len(t) < MIN_BOUNCES + 2 or np.any(np.diff(t) <= contact_time):
        return None
    spans = ratio_chain(t).spans
    try:
        b = bounce_restitution(t, drag=drag, gravity=gravity, contact_time=contact_time)
    except ValueError:
        return None
    index = np.asarray(b.index)
    single = (spans[index - 1] == 1) & (spans[index] == 1) & np.isfinite(b.restitution)
    index = index[single]
    if len(index) < MIN_BOUNCES:
        return None
    return FlightRatios(
        onset=index,
        speed=np.asarray(b.impact_speed)[single],
        restitution=np.asarray(b.restitution)[single],
        noise=0.0 if noise is None else float(noise),
        sensitivity=ratio_sensitivity(t, index),
    )


def of_dataset(d, *, contact_time: float = 0.0) -> FlightRatios | None:
    """`flight_ratios` of a data set's onsets (a drop recorded as impact onsets), or None."""
    if d.observe != "impacts" or d.scene != "drop":
        return None
    return flight_ratios(
        d.t, drag=float(d.drag), gravity=float(d.gravity), noise=d.noise, contact_time=contact_time
    )


def scatter_evident(ratios: FlightRatios | None, keep: np.ndarray | None = None) -> bool:
    """Whether the per-bounce e scatter beyond the timing noise about a mean linear in the
    impact speed (χ² under V(0), chance below `P_SCATTER`); always without a stated noise
    (then nothing else explains any scatter)."""
    if ratios is None:
        return False
    if ratios.noise <= 0:
        return True
    keep = np.ones(len(ratios), bool) if keep is None else keep
    x = np.log(ratios.restitution[keep])
    # About a mean linear in the impact speed: e changing smoothly with the speed (a
    # Hunt–Crossley ball's) is a trend, not scatter.
    design = np.stack([np.ones(len(x)), ratios.speed[keep]], axis=1)
    v = ratios.covariance(keep) + SCATTER_FLOOR**2 * np.eye(len(x))
    vd = np.linalg.solve(v, design)
    r = x - design @ np.linalg.solve(design.T @ vd, vd.T @ x)
    from scipy.stats import chi2

    return float(chi2.sf(float(r @ np.linalg.solve(v, r)), len(x) - 2)) < P_SCATTER


@dataclasses.dataclass(frozen=True)
class Trend:
    """A significant change of a file's e with impact speed (`restitution_trend`).

    - `direction`: `"falls at low speed"` (e lower on the slow bounces: the fit keeps
      the onsets above `speed`) or `"rises at low speed"` (e falls as the speed rises,
      Hunt–Crossley's direction: reported only).
    - `speed`: the impact speed (m/s) that splits the bounces.
    - `fast`, `slow`: the weighted mean e above and below it; `z`: the split's standard
      scores; `bounces`: (above, below).
    - `rows`: with e falling at low speed, the onset rows the fit keeps (0 to `rows − 1`);
      else None.
    """

    direction: str
    speed: float
    fast: float
    slow: float
    z: float
    bounces: tuple[int, int]
    rows: int | None

    def to_json(self, n_rows: int) -> dict:
        return {
            "direction": self.direction,
            "speed": self.speed,
            "e_above": self.fast,
            "e_below": self.slow,
            "z": self.z,
            "bounces": {"above": self.bounces[0], "below": self.bounces[1]},
            "rows_used": [0, (self.rows if self.rows is not None else n_rows) - 1],
            "rows": n_rows,
        }

    def note(self, name: str, n_rows: int) -> str:
        head = (
            f"{name}: e varies with the impact speed (the flights' own per-bounce e, drag-corrected): "
            f"{self.fast:.4f} over {self.bounces[0]} bounces above {self.speed:.3g} m/s, {self.slow:.4f} "
            f"over {self.bounces[1]} below ({self.z:.1f} standard errors)"
        )
        if self.rows is not None:
            return (
                head
                + f"; e falls at low speed, which no contact law here describes (Hunt-Crossley's falls as the "
                f"speed rises): the fit uses rows 1-{self.rows} of {n_rows} (impact speeds above {self.speed:.3g} "
                "m/s), where e is constant, and predicts the rest"
            )
        return (
            head
            + "; e falls as the speed rises: a constant e averages it (--law hunt-crossley, or auto, follows it)"
        )


def _best_split(ratios: FlightRatios, keep: np.ndarray, sign: int, noise: float):
    """The split of the kept bounces (slowest below) with the largest standard score of
    sign·(fast − slow), as ((z, cut, fast e, slow e), the kept bounces fastest first)."""
    order = np.flatnonzero(keep)[np.argsort(-ratios.speed[keep])]
    x = np.log(ratios.restitution[order])
    timing = ratios.covariance(noise=noise)[np.ix_(order, order)]
    eigen = np.linalg.eigh(timing)
    n = len(x)
    best = (-math.inf, None, math.nan, math.nan)
    lowest = max(int(math.ceil((1.0 - MAX_LEFT_OUT) * n)), MIN_BOUNCES // 2)
    for cut in range(lowest, n - MIN_SLOW + 1):
        design = np.zeros((n, 2))
        design[:cut, 0] = design[cut:, 1] = 1.0
        s = reml_scatter(x, design, timing, eigen)
        v = timing + max(s, SCATTER_FLOOR) ** 2 * np.eye(n)
        vd = np.linalg.solve(v, design)
        cov = np.linalg.inv(design.T @ vd)
        beta = cov @ (vd.T @ x)
        z = sign * (beta[0] - beta[1]) / math.sqrt(cov[0, 0] + cov[1, 1] - 2 * cov[0, 1])
        if z > best[0]:
            best = (float(z), cut, math.exp(beta[0]), math.exp(beta[1]))
    return best, order


def _split(ratios: FlightRatios, sign: int) -> tuple[float, float, float, float, np.ndarray] | None:
    """The significant split of `ratios` in direction `sign` (+1: e lower at low speed),
    repeated on the fast side until none is left: (z, speed, fast e, slow e, kept mask of
    the fast side), or None."""
    keep = np.ones(len(ratios), bool)
    noise = ratios.components(trend=True)[1]  # the timing noise the flights show (≤ the stated)
    found = None
    while True:
        (z, cut, fast, slow), order = _best_split(ratios, keep, sign, noise)
        if cut is None or not (z >= Z_TREND and sign * (fast - slow) >= MIN_E_CHANGE):
            return found
        fast_side = np.zeros(len(ratios), bool)
        fast_side[order[:cut]] = True
        if fast_side.sum() < (1.0 - MAX_LEFT_OUT) * len(ratios):
            return found
        speed = float(0.5 * (ratios.speed[order[cut - 1]] + ratios.speed[order[cut]]))
        if found is None:
            found = (z, speed, fast, slow, fast_side)
        else:  # the split moves up; the score and the slow side's e stay the first split's
            found = (found[0], speed, fast, found[3], fast_side)
        if sign < 0:
            return found
        keep = fast_side


def restitution_trend(d) -> Trend | None:
    """A significant trend of data set `d`'s per-bounce e with impact speed, or None.

    e lower on the slow bounces is tested with the flights at t_c = 0 (a left-out contact
    time raises the slow bounces' e: the test is conservative), e higher there at the
    prior's longest contact time, 2 ms (which lowers them)."""
    low = of_dataset(d)
    if low is None:
        return None
    falls = _split(low, +1)
    if falls is not None:
        z, speed, fast, slow, fast_side = falls
        # Keep the onsets up to the flight after the last kept bounce, all of them fast.
        slow_onsets = low.onset[~fast_side]
        rows = int(slow_onsets.min()) if slow_onsets.size else len(d.t)
        n_fast = int(np.sum(low.onset[fast_side] < rows))
        return Trend("falls at low speed", speed, fast, slow, z, (n_fast, len(low) - n_fast), rows)
    t_c = min(CONTACT_TIME_PRIOR[1], 0.5 * float(np.min(np.diff(np.asarray(d.t, dtype=float)))))
    high = of_dataset(d, contact_time=t_c)
    rises = None if high is None else _split(high, -1)
    if rises is not None:
        z, speed, fast, slow, fast_side = rises
        return Trend(
            "rises at low speed", speed, fast, slow, z, (int(fast_side.sum()), int((~fast_side).sum())), None
        )
    return None
