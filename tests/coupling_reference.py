"""An independent reference for the rolling-mill coupling [K90 Eq. 4.5–4.9, Table 2].

Nothing here imports `jaxunilat`: the right-hand side is written from the paper's
equations (reading A, Eq. 4.5 as printed, with the stiff contact constants) in plain
NumPy/SciPy, with the exact (discontinuous) contact switch.

- `CouplingParams`: the constants and the right-hand side of one contact region.
- `exact_run`: scipy `solve_ivp(DOP853)` with event location at the four clearance
  edges ψ_ξ = ±δ_ξ, ψ_η = ±δ_η and one smooth right-hand side per contact region (ψ_ξ
  and ψ_η each below, within or above the clearance: 9 regions), restarted at each event.
- `benettin_ftle`: the largest finite-time Lyapunov exponent from two nearby exact
  trajectories, renormalised every Δt (Benettin et al. 1980).
"""

from __future__ import annotations

import dataclasses
import math

import numpy as np
from scipy.integrate import solve_ivp

# The paper's constants [K90 §5.2]: m (kg), l (m), d (m), l_p (m), a (1/s), c, g (m/s²).
MASS, LENGTH, DIAMETER, LEVER, SPINUP, C, GRAVITY = 24000.0, 13.0, 0.545, 6.5, 0.768, 1.0, 9.81
#: Table 2 of [K90]: example → (α = P/(m g), Δ [m], b [1/s]).
TABLE2 = {
    1: (-0.5, 0.010, 12.0),
    2: (-0.5, 0.005, 12.0),
    3: (-0.5, 0.001, 12.0),
    4: (-0.1, 0.005, 12.0),
    5: (-0.001, 0.005, 12.0),
    6: (-0.1, 0.005, 6.0),
}


@dataclasses.dataclass(frozen=True)
class CouplingParams:
    """The coupling in SI units (reading A, Kelvin–Voigt joints, no viscous damping h).

    The stiff constants: κ = 0.05 J_t·1e5 N/rad, k_r = 0.02 J_t·√1e5 N·s/rad, with
    J_t = m l²/3 (kg·m²) and J_p = m d²/8.
    """

    alpha: float
    clearance: float
    b: float

    @classmethod
    def table2(cls, example: int) -> CouplingParams:
        return cls(*TABLE2[example])

    @property
    def j_t(self) -> float:
        return MASS * LENGTH**2 / 3.0

    @property
    def j_p(self) -> float:
        return MASS * DIAMETER**2 / 8.0

    @property
    def kappa(self) -> float:
        return 0.05 * self.j_t * 1e5

    @property
    def k_r(self) -> float:
        return 0.02 * self.j_t * math.sqrt(1e5)

    @property
    def delta(self) -> float:
        """δ = arctan(Δ/l), rad (the same for ψ_ξ and ψ_η)."""
        return math.atan(self.clearance / LENGTH)

    @property
    def omega_c(self) -> float:
        """√(κ l/J_t), rad/s: the contact's natural frequency."""
        return math.sqrt(self.kappa * LENGTH / self.j_t)

    @property
    def scale(self) -> np.ndarray:
        """(δ, δω_c, δ, δω_c): the unit of the separation norm."""
        d, w = self.delta, self.omega_c
        return np.array([d, d * w, d, d * w])

    def initial_state(self) -> np.ndarray:
        """ψ_ξ(0) = −δ, everything else 0 [K90 §5.2]."""
        return np.array([-self.delta, 0.0, 0.0, 0.0])

    def rhs(self, region: tuple[int, int]):
        """dy/dt in one region: `region` = (s_ξ, s_η), each −1 (beyond −δ), 0 (free) or +1 (beyond +δ)."""
        j, jp, kappa, k_r, delta = self.j_t, self.j_p, self.kappa, self.k_r, self.delta
        p_lp = self.alpha * MASS * GRAVITY * LEVER
        a, b = SPINUP, self.b
        sx, se = region

        def joint(q, dq, s):  # T = κ D(q; δ) + k_r q̇ C(q; δ)   [K90 Eq. 4.8]
            return 0.0 if s == 0 else kappa * (q - s * delta) + k_r * dq

        def f(t, y):
            px, dpx, pe, dpe = y
            e = math.exp(-a * t)
            w = b * (C - e)  # ω = b(c − e^(−at))            [K90 Eq. 4.6]
            phi = b * (C * t - (1.0 - e) / a)
            t_eta, t_xi = joint(px, dpx, sx), joint(pe, dpe, se)
            m_xi = p_lp * math.cos(phi) - LENGTH * t_eta  # [K90 Eq. 4.7]
            m_eta = -p_lp * math.sin(phi) - LENGTH * t_xi
            return [dpx, (m_xi + (j - jp) * w * dpe) / j, dpe, (m_eta - (j - jp) * w * dpx) / j]  # Eq. 4.5

        return f


def _side(q: float, dq: float, ddq: float, delta: float) -> int:
    """The region of one coordinate; on an edge, the side the motion is heading to."""
    for s in (-1, 1):
        z = s * (q - s * delta)  # > 0: beyond the edge s·δ
        if z > 0 or (z == 0 and (s * dq > 0 or (dq == 0 and s * ddq > 0))):
            return s
    return 0


def initial_region(p: CouplingParams, t: float, y) -> tuple[int, int]:
    """(s_ξ, s_η) of a state, edges resolved by the velocity and then the acceleration."""
    acc = p.rhs((0, 0))(t, y)
    return _side(y[0], y[1], acc[1], p.delta), _side(y[2], y[3], acc[3], p.delta)


def exact_run(p, t0, y0, t1, region, *, rtol=1e-11, atol=1e-16, max_step=np.inf, fresh=None):
    """Integrate the exact model from (t0, y0) in `region` to t1, restarting at every edge event.

    Times in s, y = (ψ_ξ, ψ̇_ξ, ψ_η, ψ̇_η) in rad and rad/s; `max_step` caps DOP853's step (s).
    `fresh`: (coordinate index 0 or 2, edge) of an edge crossed at t0 (its event function is
    divided by t − t0, so that the root at the start is not found again), or None.

    **Returns:** (y(t1), region at t1, number of events, `fresh` at t1).
    """
    delta, t, y = p.delta, float(t0), np.asarray(y0, float)
    events = 0
    while t < t1:
        watched = []  # (coordinate, edge, direction, next side)
        for k, s in ((0, region[0]), (2, region[1])):
            if s == 0:
                watched += [(k, -delta, -1.0, -1), (k, delta, 1.0, 1)]
            else:
                watched.append((k, s * delta, -float(s), 0))
        evs = []
        for k, edge, direction, _ in watched:
            if (k, edge) == fresh:

                def ev(tt, yy, k=k, edge=edge, ts=t):
                    return yy[k + 1] if tt <= ts else (yy[k] - edge) / (tt - ts)

            else:

                def ev(_t, yy, k=k, edge=edge):
                    return yy[k] - edge

            ev.terminal, ev.direction = True, direction
            evs.append(ev)
        sol = solve_ivp(
            p.rhs(region), (t, t1), y, method="DOP853", rtol=rtol, atol=atol, events=evs, max_step=max_step
        )
        if sol.status < 0:
            raise RuntimeError(f"exact_run: solve_ivp failed: {sol.message}")
        hit = [i for i, te in enumerate(sol.t_events) if len(te)]
        if sol.status == 1 and hit:
            i = min(hit, key=lambda n: sol.t_events[n][0])
            k, edge, _, nxt = watched[i]
            t, y = float(sol.t_events[i][0]), np.array(sol.y_events[i][0], float)
            y[k] = edge  # the event is ψ = edge
            region = (nxt, region[1]) if k == 0 else (region[0], nxt)
            fresh, events = (k, edge), events + 1
        else:
            t, y = float(t1), sol.y[:, -1].copy()
            fresh = None
    return y, region, events, fresh


def benettin_ftle(p, windows, *, dt=0.05, d0=1e-7, rtol=1e-11, direction=(1.0, 1.0, 1.0, 1.0)):
    """The largest FTLE of the exact model over each window [t0, t1], 1/s, from two trajectories.

    Both start at 0 from the paper's initial state, the second displaced by d0 along
    `direction` in the scaled norm ‖(Δψ/δ, Δψ̇/(δω_c))‖. Every `dt` the separation d is
    measured, ln(d/d0) accumulated, and the second trajectory put back at distance d0
    along the separation. λ over a window is the accumulated log between its ends over
    its length; window ends must be multiples of `dt`.

    **Returns:** (array of λ, 1/s; total number of edge events of the two runs).
    """
    scale = p.scale
    t_end = max(t1 for _, t1 in windows)
    n = int(round(t_end / dt))
    times = dt * np.arange(n + 1)
    for w in windows:
        for t in w:
            if abs(t / dt - round(t / dt)) > 1e-9:
                raise ValueError(f"window end {t} is not a multiple of dt = {dt}")
    ya = p.initial_state()
    u = np.asarray(direction, float)
    yb = ya + d0 * scale * u / np.linalg.norm(u)
    ra, rb = initial_region(p, 0.0, ya), initial_region(p, 0.0, yb)
    fa = fb = None
    cum = np.zeros(n + 1)
    total = 0
    for i in range(n):
        ya, ra, ea, fa = exact_run(p, times[i], ya, times[i + 1], ra, rtol=rtol, fresh=fa)
        yb, rb, eb, fb = exact_run(p, times[i], yb, times[i + 1], rb, rtol=rtol, fresh=fb)
        total += ea + eb
        sep = (yb - ya) / scale
        d = float(np.linalg.norm(sep))
        cum[i + 1] = cum[i] + math.log(d / d0)
        yb = ya + (d0 / d) * sep * scale
        rb = initial_region(p, times[i + 1], yb)
        fb = None
    lam = []
    for t0, t1 in windows:
        i0, i1 = int(round(t0 / dt)), int(round(t1 / dt))
        lam.append((cum[i1] - cum[i0]) / (t1 - t0))
    return np.asarray(lam), total
