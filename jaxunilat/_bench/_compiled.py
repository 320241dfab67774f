"""The benchmark's compiled-loop peer: an event-located DOP853 in Numba.

The ball between two rackets [K90 Eq. 3.1–3.3] as plain scalar code, compiled with
Numba: what a hand-written, compiled solver for this one model costs, beside scipy's
`solve_ivp` (a general-purpose interpreter loop) in the work–precision rows, and with
a `prange` loop over trajectories in the throughput rows.

The integrator is Dormand–Prince 8(5,3) [HNW93 §II.10] with its 7th-order dense output
(the coefficients are scipy's `dop853_coefficients`, Hairer's tables), written for
the 2-state model with smooth right-hand sides per segment (as the event mode does):

- a segment holds the contact region (free, lower, upper) and the sign of v fixed, so
  that the drag's −k²g|v|v is the smooth −k²g·s·v² (s = ±1) and the contact force the
  exact Kelvin–Voigt κδ + k_r δ̇ of that region (exact Heaviside);
- the gap functions x − wall and v are checked at each accepted step's end; a sign
  change is located as a root of the step's dense output (Illinois regula falsi) and
  the segment restarts there (wall entries and exits, apexes and deepest points); a wall
  that x passes and leaves again within one step (a grazing contact: x − wall has the
  same sign at both ends) is found where v turns, from x there;
- the error norm and tolerances are scipy's (scale atol + rtol·max(|y|, |y_new|),
  the 5th/3rd-order blended estimate), with Hairer's PI step control (β = 0.04);
- the three extra dense-output stages are computed only on steps that contain a save
  time or an event; after an event the first step of a segment is warm-started from the
  last segment of the same kind (region and sign of v);
- every stage is written out as scalar code with the coefficients as literals
  (`_generated_source`), compiled with fused multiply-adds allowed (fastmath "contract"
  only: no reassociation, NaN and inf keep their IEEE meaning).

In the bench's throughput rows every trajectory is checked against jaxunilat's own row of
the same pairs (`check_rows`: within the two accuracy contracts, else judged against the
scipy reference); only the right rows count towards the peer's throughput, and
`peer_wrong_rows` says how many were wrong.

Numba is optional (`numba` is in the `bench` extra): `available()` says whether it
imports. Compilation happens on the first call of each function (`warm_up`).

References: [HNW93] E. Hairer, S. P. Nørsett, G. Wanner, *Solving Ordinary
Differential Equations I*, 2nd ed., Springer (1993), §II.4 (initial step), §II.6 (dense
output), §II.10 (DOP853, PI control).
"""

from __future__ import annotations

import math
import os
import time

import numpy as np

try:
    import numba
except ImportError:  # the bench says so and leaves the column out
    numba = None

FREE, LOWER, UPPER = 0, -1, 1
#: Event kinds, as in the event mode's `EventRecord`.
ENTRY, EXIT, EXTREMUM = 1, 2, 3
#: Hairer's PI step control for DOP853: β, safety, and the step ratio bounds.
BETA = 0.04
SAFE = 0.9
FAC_MIN = 0.333  # h_new / h >= 1/3 ... (Hairer's fac1)
FAC_MAX = 6.0  # ... and <= 6 (fac2)
MAX_STEPS = 100_000
MAX_EVENTS = 1024


def available() -> bool:
    """Whether Numba imports (the compiled-loop peer can run)."""
    return numba is not None


def why_missing() -> str:
    """One line for the bench when Numba is missing."""
    return "compiled loop (Numba DOP853) skipped: numba is not installed (pip install 'jaxunilat[bench]')"


def _coefficients():
    from scipy.integrate._ivp import dop853_coefficients as c

    a = np.ascontiguousarray(c.A[:16, :16], dtype=np.float64)
    return a, np.asarray(c.B, float), np.asarray(c.C[:16], float), c.E3.astype(float), c.E5.astype(float), c.D


def _sum(coefs, names) -> str:
    """The literal sum Σ c·name over the nonzero coefficients, in index order (the
    newest stage last, so that the earlier terms add up while it is computed)."""
    terms = [f"{float(c)!r} * {n}" for c, n in zip(coefs, names, strict=True) if c != 0.0]
    return " + ".join(terms) if terms else "0.0"


def _accel_source(x: str, v: str) -> str:
    """ẍ of a segment: gravity, drag k²g·s·v² (cs = k²g·s) and the region's contact
    (kxm = κ/m, kvm = k_r/m and the wall w; all 0 in free flight)."""
    return f"-g - cs * {v} * {v} + kxm * (w - {x}) - kvm * {v}"


def _generated_source() -> str:
    """Two functions with every DOP853 stage written out as scalar code (coefficients as
    literals): `_step` (stages 1–12, the FSAL stage 13 and scipy's error norm, the
    stages stored into kx, kv for the dense output) and `_extra` (stages 14–16 and the
    interpolant's coefficients)."""
    a, b, _c, e3, e5, d = _coefficients()
    seg = "g, cs, kxm, w, kvm"
    out = [f"def _step(x, v, k0x, k0v, h, {seg}, rtol, atol, kx, kv):"]
    for s in range(1, 12):
        out.append(f"    xs = x + h * ({_sum(a[s, :s], [f'k{j}x' for j in range(s)])})")
        out.append(f"    k{s}x = v + h * ({_sum(a[s, :s], [f'k{j}v' for j in range(s)])})")
        out.append(f"    k{s}v = {_accel_source('xs', f'k{s}x')}")
    out.append(f"    x_new = x + h * ({_sum(b, [f'k{j}x' for j in range(12)])})")
    out.append(f"    v_new = v + h * ({_sum(b, [f'k{j}v' for j in range(12)])})")
    out.append("    k12x = v_new")
    out.append(f"    k12v = {_accel_source('x_new', 'v_new')}")
    for j in range(13):
        out.append(f"    kx[{j}] = k{j}x")
        out.append(f"    kv[{j}] = k{j}v")
    out.append("    sx = atol + rtol * max(abs(x), abs(x_new))")
    out.append("    sv = atol + rtol * max(abs(v), abs(v_new))")
    for name, e in (("5", e5), ("3", e3)):
        for c in "xv":
            out.append(f"    e{name}{c} = ({_sum(e, [f'k{j}{c}' for j in range(13)])}) / s{c}")
    out.append("    n5 = e5x * e5x + e5v * e5v")
    out.append("    n3 = e3x * e3x + e3v * e3v")
    out.append("    if n5 == 0.0 and n3 == 0.0:")
    out.append("        return x_new, v_new, 0.0")
    out.append("    return x_new, v_new, abs(h) * n5 / math.sqrt((n5 + 0.01 * n3) * 2.0)")
    out.append("")
    out.append(f"def _extra(x, v, x_new, v_new, h, {seg}, kx, kv, fx, fv):")
    for s in range(16):
        out.append(f"    k{s}x = kx[{s}]" if s < 13 else "")
        out.append(f"    k{s}v = kv[{s}]" if s < 13 else "")
    for s in range(13, 16):
        out.append(f"    xs = x + h * ({_sum(a[s, :s], [f'k{j}x' for j in range(s)])})")
        out.append(f"    k{s}x = v + h * ({_sum(a[s, :s], [f'k{j}v' for j in range(s)])})")
        out.append(f"    k{s}v = {_accel_source('xs', f'k{s}x')}")
    for c, y, y_new in (("x", "x", "x_new"), ("v", "v", "v_new")):
        out.append(f"    d{c} = {y_new} - {y}")
        out.append(f"    f{c}[0] = d{c}")
        out.append(f"    f{c}[1] = h * k0{c} - d{c}")
        out.append(f"    f{c}[2] = 2.0 * d{c} - h * (k12{c} + k0{c})")
        for i in range(4):
            out.append(f"    f{c}[{3 + i}] = h * ({_sum(d[i], [f'k{j}{c}' for j in range(16)])})")
    return "\n".join(line for line in out if line) + "\n"


if numba is not None:
    _jit = numba.njit(cache=False, fastmath={"contract"}, error_model="numpy")
    _namespace = {"math": math}
    exec(compile(_generated_source(), "<jaxunilat._bench._compiled generated>", "exec"), _namespace)
    _step = _jit(_namespace["_step"])
    _extra = _jit(_namespace["_extra"])

    @_jit
    def _segment(region, sgn, p):
        """A segment's right-hand side coefficients (g, cs, kxm, w, kvm) for `_step`.
        p = (κ, k_r, m, g, k²g, lower, upper)."""
        if region == FREE:
            return p[3], p[4] * sgn, 0.0, 0.0, 0.0
        wall = p[5] if region == LOWER else p[6]
        return p[3], p[4] * sgn, p[0] / p[2], wall, p[1] / p[2]

    @_jit
    def _accel(region, sgn, x, v, p):
        """ẍ (m/s²) with the region and the drag's sign held fixed."""
        g, cs, kxm, w, kvm = _segment(region, sgn, p)
        return -g - cs * v * v + kxm * (w - x) - kvm * v

    @_jit
    def _start_region(x, v, p):
        if x < p[5] or (x == p[5] and v < 0.0):
            return LOWER
        if x > p[6] or (x == p[6] and v > 0.0):
            return UPPER
        return FREE

    @_jit
    def _start_sign(region, x, v, p):
        """The sign of v in the segment starting at (x, v): at v = 0, that of ẍ."""
        if v > 0.0:
            return 1.0
        if v < 0.0:
            return -1.0
        return 1.0 if _accel(region, 1.0, x, 0.0, p) > 0.0 else -1.0

    @_jit
    def _initial_step(region, sgn, t, x, v, fx, fv, t1, rtol, atol, p):
        """Hairer's starting step [HNW93 §II.4] for an order-7 error estimate (scipy's)."""
        sx, sv = atol + rtol * abs(x), atol + rtol * abs(v)
        d0 = math.sqrt(((x / sx) ** 2 + (v / sv) ** 2) / 2.0)
        d1 = math.sqrt(((fx / sx) ** 2 + (fv / sv) ** 2) / 2.0)
        h0 = 1e-6 if d0 < 1e-5 or d1 < 1e-5 else 0.01 * d0 / d1
        h0 = min(h0, t1 - t)
        x1, v1 = x + h0 * fx, v + h0 * fv
        gx, gv = v1, _accel(region, sgn, x1, v1, p)
        d2 = math.sqrt((((gx - fx) / sx) ** 2 + ((gv - fv) / sv) ** 2) / 2.0) / h0
        if d1 <= 1e-15 and d2 <= 1e-15:
            h1 = max(1e-6, h0 * 1e-3)
        else:
            h1 = (0.01 / max(d1, d2)) ** (1.0 / 8.0)
        return min(100.0 * h0, h1, t1 - t)

    @_jit
    def _dense(theta, y_old, f):
        """The step's 7th-order interpolant at θ ∈ [0, 1] (scipy's nested form)."""
        u = 1.0 - theta
        s = f[6] * theta
        s = (s + f[5]) * u
        s = (s + f[4]) * theta
        s = (s + f[3]) * u
        s = (s + f[2]) * theta
        s = (s + f[1]) * u
        s = (s + f[0]) * theta
        return y_old + s

    @_jit
    def _root(theta_lo, theta_hi, g_lo, g_hi, target, y_old, f, h, t):
        """θ ∈ (θ_lo, θ_hi] where the interpolant crosses `target` (Illinois regula falsi);
        g_lo, g_hi: its values minus target at θ_lo and θ_hi, of opposite signs."""
        lo, hi = theta_lo, theta_hi
        side = 0
        for _ in range(200):
            if (hi - lo) * h <= 4e-16 * max(abs(t), abs(h)):
                break
            m = hi - g_hi * (hi - lo) / (g_hi - g_lo)
            if not lo < m < hi:
                m = 0.5 * (lo + hi)
            gm = _dense(m, y_old, f) - target
            if gm == 0.0:
                return m
            if (gm < 0.0) == (g_lo < 0.0):
                lo, g_lo = m, gm
                if side == -1:
                    g_hi *= 0.5
                side = -1
            else:
                hi, g_hi = m, gm
                if side == 1:
                    g_lo *= 0.5
                side = 1
        return hi

    @_jit
    def _crossing(g0, g1, inside, target, y_old, f, h, t, theta_end):
        """θ of the crossing of `target` by the interpolant, from g0 (θ = 0, which should
        be on the `inside` sign ±1, or 0 at a segment's start) to g1 (θ = θ_end, outside)."""
        g0 = g0 if inside * g0 > 0.0 else inside * 1e-300
        return _root(0.0, theta_end, g0, g1, target, y_old, f, h, t)

    @_jit
    def _turns(sgn, v, v_new, p):
        """Whether v changes sign over the step: the segment's sign of v (an extremum
        event) with drag, v's own sign change without (then v is not an event)."""
        if p[4] > 0.0:
            return sgn * v_new < 0.0
        return v * v_new < 0.0

    @_jit
    def _next_event(region, sgn, x_new, v_new, t, h, x, v, fx_, fv_, p):
        """The step's first event: (θ, kind, wall) with θ > 1 for none. wall: −1 lower,
        1 upper, 0 the observable v (apex, deepest point).

        A wall that x passes and comes back from within one step (a grazing contact, or
        a grazing exit: x − wall has the same sign at both ends of the step) is found
        where x turns, at the root of v: if x there is beyond a wall of the region, the
        wall is crossed before it (located on [0, θ_turn]), else the turn is an extremum.
        """
        theta, kind, wall = 2.0, 0, 0
        lo, hi = p[5], p[6]
        if region == FREE and x_new < lo:
            theta, kind, wall = _crossing(x - lo, x_new - lo, 1.0, lo, x, fx_, h, t, 1.0), ENTRY, LOWER
        if region == FREE and x_new > hi:
            th = _crossing(x - hi, x_new - hi, -1.0, hi, x, fx_, h, t, 1.0)
            if th < theta:
                theta, kind, wall = th, ENTRY, UPPER
        if region == LOWER and x_new > lo:
            theta, kind, wall = _crossing(x - lo, x_new - lo, -1.0, lo, x, fx_, h, t, 1.0), EXIT, LOWER
        if region == UPPER and x_new < hi:
            theta, kind, wall = _crossing(x - hi, x_new - hi, 1.0, hi, x, fx_, h, t, 1.0), EXIT, UPPER
        if _turns(sgn, v, v_new, p):
            inside = sgn if p[4] > 0.0 else (1.0 if v > 0.0 else -1.0)
            th = _crossing(v, v_new, inside, 0.0, v, fv_, h, t, 1.0)
            if th < theta:
                xt = _dense(th, x, fx_)
                if region == FREE and xt > hi:
                    theta, kind, wall = _crossing(x - hi, xt - hi, -1.0, hi, x, fx_, h, t, th), ENTRY, UPPER
                elif region == FREE and xt < lo:
                    theta, kind, wall = _crossing(x - lo, xt - lo, 1.0, lo, x, fx_, h, t, th), ENTRY, LOWER
                elif region == LOWER and xt > lo:
                    theta, kind, wall = _crossing(x - lo, xt - lo, -1.0, lo, x, fx_, h, t, th), EXIT, LOWER
                elif region == UPPER and xt < hi:
                    theta, kind, wall = _crossing(x - hi, xt - hi, 1.0, hi, x, fx_, h, t, th), EXIT, UPPER
                elif p[4] > 0.0:
                    theta, kind, wall = th, EXTREMUM, 0
        return theta, kind, wall

    @_jit
    def _crosses(region, sgn, v, x_new, v_new, p):
        """Whether a gap function changed sign over the step, or v did (where x may have
        passed a wall and come back): then `_next_event` looks for the first event."""
        if region == FREE:
            wall = x_new < p[5] or x_new > p[6]
        elif region == LOWER:
            wall = x_new > p[5]
        else:
            wall = x_new < p[6]
        return wall or _turns(sgn, v, v_new, p)

    @_jit
    def _after_event(kind, wall, region, sgn, xe, ve, p):
        """The next segment's (region, sign of v, x, v) at an event: x on the wall at a
        crossing, v = 0 at an extremum (the values the roots stand for)."""
        if kind == EXTREMUM:
            return region, -sgn, xe, 0.0
        xw = p[5] if wall == LOWER else p[6]
        return (wall if kind == ENTRY else FREE), sgn, xw, ve

    @_jit
    def _save(out_x, ts, i_save, t_end, t, h, x, fx_):
        """x at the save times up to t_end from the step's interpolant; the next index."""
        while i_save < ts.shape[0] and ts[i_save] <= t_end:
            out_x[i_save] = _dense((ts[i_save] - t) / h, x, fx_)
            i_save += 1
        return i_save

    @_jit
    def _solve(p, x0, v0, ts, rtol, atol, warm, out_x, ev_t, ev_kind):
        """One trajectory: x at `ts` into out_x, events into ev_t/ev_kind.

        **Returns:** (accepted steps, rejected steps, events, status: 0 ok, 1 step
        limit, 2 event buffer full, 3 step size underflow).
        """
        kx, kv, fx_, fv_ = np.empty(16), np.empty(16), np.empty(7), np.empty(7)
        warm_h = np.zeros(6)  # the first step of the last segment of each kind
        n_ts = ts.shape[0]
        t, t1 = ts[0], ts[n_ts - 1]
        x, v = x0, v0
        region = _start_region(x, v, p)
        sgn = _start_sign(region, x, v, p)
        i_save = 0
        while i_save < n_ts and ts[i_save] <= t:
            out_x[i_save] = x
            i_save += 1
        n_acc, n_rej, n_ev, status = 0, 0, 0, 0
        start = True  # a segment starts
        expo = 1.0 / 8.0 - 0.75 * BETA
        while t < t1:
            if start:
                g, cs, kxm, w, kvm = _segment(region, sgn, p)
                fx, fv = v, -g - cs * v * v + kxm * (w - x) - kvm * v
                kind_index = 2 * (region + 1) + (1 if sgn > 0.0 else 0)
                if warm and warm_h[kind_index] > 0.0:
                    h = warm_h[kind_index]
                else:
                    h = _initial_step(region, sgn, t, x, v, fx, fv, t1, rtol, atol, p)
                log_facold, rejected, first, start = math.log(1e-4), False, True, False
            if n_acc + n_rej >= MAX_STEPS:
                status = 1
                break
            last = h >= t1 - t
            if last:
                h = t1 - t
            if h <= 4e-16 * abs(t):
                status = 3
                break
            x_new, v_new, err = _step(x, v, fx, fv, h, g, cs, kxm, w, kvm, rtol, atol, kx, kv)
            if not err <= 1.0:  # also NaN
                h = h / (1.0 / FAC_MIN if err != err else min(1.0 / FAC_MIN, err**expo / SAFE))
                n_rej += 1
                rejected = True
                continue
            n_acc += 1
            # PI control [HNW93 §II.4, IV.2]: fac = err^(1/8 - 0.75β) / err_old^β.
            log_err = math.log(max(err, 1e-300))
            fac = max(1.0 / FAC_MAX, min(1.0 / FAC_MIN, math.exp(expo * log_err - BETA * log_facold) / SAFE))
            h_next = h / fac if not rejected else min(h / fac, h)
            log_facold, rejected = max(log_err, math.log(1e-4)), False
            if first:
                warm_h[2 * (region + 1) + (1 if sgn > 0.0 else 0)] = h
                first = False
            t_new = t1 if last else t + h
            crosses = _crosses(region, sgn, v, x_new, v_new, p)
            if crosses or (i_save < n_ts and ts[i_save] <= t_new):
                _extra(x, v, x_new, v_new, h, g, cs, kxm, w, kvm, kx, kv, fx_, fv_)
            theta, kind, wall = 2.0, 0, 0
            if crosses:
                theta, kind, wall = _next_event(region, sgn, x_new, v_new, t, h, x, v, fx_, fv_, p)
            if theta > 1.0:
                i_save = _save(out_x, ts, i_save, t_new, t, h, x, fx_)
                t, x, v, fx, fv, h = t_new, x_new, v_new, kx[12], kv[12], h_next
                continue
            t_end = t + theta * h
            i_save = _save(out_x, ts, i_save, t_end, t, h, x, fx_)
            if n_ev >= ev_t.shape[0]:
                status = 2
                break
            ev_t[n_ev], ev_kind[n_ev] = t_end, kind
            n_ev += 1
            xe, ve = _dense(theta, x, fx_), _dense(theta, v, fv_)
            region, sgn, x, v = _after_event(kind, wall, region, sgn, xe, ve, p)
            t, start = t_end, True
        return n_acc, n_rej, n_ev, status

    @_jit
    def _solve_batch_serial(ps, x0, v0, ts, rtol, atol, warm, out_x, stats):
        ev_t, ev_kind = np.empty(MAX_EVENTS), np.empty(MAX_EVENTS, np.int64)
        for i in range(ps.shape[0]):
            a, r, e, s = _solve(ps[i], x0, v0, ts, rtol, atol, warm, out_x[i], ev_t, ev_kind)
            stats[i, 0], stats[i, 1], stats[i, 2], stats[i, 3] = a, r, e, s

    @numba.njit(cache=False, parallel=True, fastmath={"contract"}, error_model="numpy")
    def _solve_batch_parallel(ps, x0, v0, ts, rtol, atol, warm, out_x, stats):
        for i in numba.prange(ps.shape[0]):
            ev_t, ev_kind = np.empty(MAX_EVENTS), np.empty(MAX_EVENTS, np.int64)
            a, r, e, s = _solve(ps[i], x0, v0, ts, rtol, atol, warm, out_x[i], ev_t, ev_kind)
            stats[i, 0], stats[i, 1], stats[i, 2], stats[i, 3] = a, r, e, s


def params_array(kappa, k_r, mass=2.37e-3, gravity=9.81, drag=0.122, lower=-0.4, upper=0.4) -> np.ndarray:
    """The solver's parameter vector (κ N/m, k_r N·s/m, m kg, g m/s², k²g 1/m, lower m,
    upper m); `None` removes the damping, the drag or a wall (±inf)."""
    return np.array(
        [
            kappa,
            0.0 if k_r is None else k_r,
            mass,
            gravity,
            0.0 if drag is None else drag * drag * gravity,
            -math.inf if lower is None else lower,
            math.inf if upper is None else upper,
        ],
        float,
    )


def _from_peer(p) -> np.ndarray:
    return params_array(p.kappa, p.k_r, p.mass, p.gravity, p.drag, p.lower, p.upper)


class Result:
    """One trajectory: x at the save times (m), the event times (s) and kinds
    (`ENTRY`, `EXIT`, `EXTREMUM`), accepted and rejected steps, and the status (0: ok)."""

    def __init__(self, x, ev_t, ev_kind, accepted, rejected, status):
        self.x, self.event_t, self.event_kind = x, ev_t, ev_kind
        self.accepted, self.rejected, self.status = accepted, rejected, status

    @property
    def entries(self) -> np.ndarray:
        """Contact entry times, s."""
        return self.event_t[self.event_kind == ENTRY]

    @property
    def crossings(self) -> int:
        """Wall crossings (entries and exits)."""
        return int(np.sum((self.event_kind == ENTRY) | (self.event_kind == EXIT)))


def solve(p, y0, ts, *, rtol: float, atol: float, warm: bool = True) -> Result:
    """One trajectory of the ball (`_peers.Params` p) from y0 = (x0 m, v0 m/s) saved at the
    sorted times `ts` (s, from t0 = ts[0]), at scipy's rtol/atol semantics."""
    ts = np.ascontiguousarray(ts, float)
    out = np.empty(ts.shape)
    ev_t, ev_kind = np.empty(MAX_EVENTS), np.zeros(MAX_EVENTS, np.int64)
    a, r, e, s = _solve(_from_peer(p), float(y0[0]), float(y0[1]), ts, rtol, atol, warm, out, ev_t, ev_kind)
    return Result(out, ev_t[:e].copy(), ev_kind[:e].copy(), a, r, s)


def solve_batch(kappa, k_r, y0, ts, *, rtol: float, atol: float, parallel: bool, warm: bool = True):
    """Trajectories for each (κ [N/m], k_r [N·s/m]) pair of Table 1 example 2's ball:
    x (n, len(ts)) in m, and per row (accepted, rejected, events, status). `parallel`:
    a `prange` loop over the rows on every core (Numba's threads), else one core."""
    ts = np.ascontiguousarray(ts, float)
    kappa, k_r = np.asarray(kappa, float), np.asarray(k_r, float)
    ps = np.stack([params_array(a, b) for a, b in zip(kappa, k_r, strict=True)])
    out = np.empty((len(ps), len(ts)))
    stats = np.zeros((len(ps), 4), np.int64)
    fn = _solve_batch_parallel if parallel else _solve_batch_serial
    fn(ps, float(y0[0]), float(y0[1]), ts, rtol, atol, warm, out, stats)
    return out, stats


def threads() -> int:
    """Numba's thread count for the `prange` rows (every core unless NUMBA_NUM_THREADS says)."""
    return int(numba.get_num_threads()) if numba is not None else os.cpu_count() or 1


def warm_up() -> float:
    """Compile every function (one short call each); returns the compile time, s."""
    from ._peers import Params

    start = time.perf_counter()
    ts = np.linspace(0.0, 0.05, 3)
    solve(Params(), (-0.4, -8.0), ts, rtol=1e-6, atol=1e-6)
    for parallel in (False, True):
        solve_batch([1e4], [0.2], (-0.4, -8.0), ts, rtol=1e-6, atol=1e-6, parallel=parallel)
    return time.perf_counter() - start


# -- the bench's rows ---------------------------------------------------------------------------

METHOD = "Numba DOP853 + events"


def _wp_rows(tols, ts, x_ref, timed, log, compile_s) -> list[dict]:
    from ._peers import Params
    from ._scale import Y0

    rows = []
    for tol in tols:
        timing = timed(lambda tol=tol: solve(Params(), Y0, ts, rtol=tol, atol=tol))
        run = timing.out
        d = np.abs(run.x - x_ref)
        rows.append(
            {
                "method": METHOD,
                "setting": f"tol {tol:g}",
                "error": float(np.max(d)) if np.all(np.isfinite(d)) else math.inf,
                "wall_s": timing.median,
                "wall_min_s": timing.min,
                "compile_s": compile_s if not rows else 0.0,
                "peer": True,
                "runs": timing.runs,
                "steps": int(run.accepted + run.rejected),
                "accepted": int(run.accepted),
                "rejected": int(run.rejected),
                "crossings": run.crossings,
                "status": int(run.status),
            }
        )
        r = rows[-1]
        log(
            f"  peer {METHOD:<26} {r['setting']:<22} error {r['error']:>8.2e} m  wall {1e6 * r['wall_s']:9.1f} us"
            f"  steps {r['steps']} ({r['rejected']} rej), {r['crossings']} wall crossings"
        )
    return rows


def _fastest(rows, max_error):
    if max_error is None or not math.isfinite(max_error):
        return None
    ok = [r for r in rows if r["error"] is not None and r["error"] <= max_error]
    return min(ok, key=lambda r: r["wall_s"]) if ok else None


def _fmt_ratio(value) -> str:
    return f"{value:9.3g}x" if value is not None else f"{'n/a':>10}"


def ratio_columns(wp_rows: list[dict], compiled_rows: list[dict], log) -> None:
    """Add to each project row of `wp_rows` its wall time over the fastest scipy-with-events
    run and over the fastest compiled-loop run at least as accurate (`vs_scipy`,
    `vs_compiled`; None where no such run), with that compiled run's step counts, and log them."""
    scipy_rows = [
        r for r in wp_rows if r["peer"] and r["method"].startswith("scipy") and "events" in r["method"]
    ]
    mine = [r for r in wp_rows if not r["peer"]]
    if mine:
        log("  ratios at each row's error (wall / fastest peer run at least as accurate):")
    for row in mine:
        sc, cl = _fastest(scipy_rows, row["error"]), _fastest(compiled_rows, row["error"])
        row["vs_scipy"] = None if sc is None else row["wall_s"] / sc["wall_s"]
        row["vs_compiled"] = None if cl is None else row["wall_s"] / cl["wall_s"]
        row["compiled_steps"] = None if cl is None else [cl["accepted"], cl["rejected"]]
        steps = (
            "" if cl is None else f"; compiled {cl['accepted']} acc / {cl['rejected']} rej at {cl['setting']}"
        )
        own = f"{row['accepted']} acc / {row['rejected']} rej" if "accepted" in row else ""
        log(
            f"       {row['method']:<26} {row['setting']:<22} vs scipy {_fmt_ratio(row['vs_scipy'])}  "
            f"vs compiled {_fmt_ratio(row['vs_compiled'])}  steps {own}{steps}"
        )


def contract_bound(tol: float, x, ts, contacts=None, lower: float = -0.4, upper: float = 0.4) -> np.ndarray:
    """The event mode's accuracy contract (README, "The accuracy contract") for each row of
    x (rows of samples at `ts`, m) at rtol = atol = `tol`: 1e3 · tol · X · (1 + N), X =
    max(1 m, max |x|, max |v| · 1 s), m. |v| is taken from the samples' differences and N,
    unless given (`contacts`, per row), counts the contacts the samples show: both can only
    come out low, so the bound is at most the contract's."""
    x = np.atleast_2d(np.asarray(x, float))
    v = np.max(np.abs(np.diff(x, axis=1)) / np.diff(ts), axis=1)
    scale = np.maximum(1.0, np.maximum(np.max(np.abs(x), axis=1), v * 1.0))
    if contacts is None:
        outside = (x < lower) | (x > upper)
        contacts = outside[:, 0] + np.sum(outside[:, 1:] & ~outside[:, :-1], axis=1)
    return 1e3 * tol * scale * (1.0 + np.asarray(contacts, float))


#: The most disagreeing rows `check_rows` judges against the scipy reference (each ~0.2 s).
MAX_REFERENCES = 64


def check_rows(x_peer, status, x_own, own_tol: float, kappa, k_r, ts, tol: float, references=None) -> dict:
    """The peer's rows (x_peer at `ts`, per-row `status`, at tolerance `tol`) against the
    project's rows of the same (κ, k_r) pairs (x_own, at `own_tol`).

    A row is right where both agree within the sum of their accuracy contracts
    (`contract_bound`): were both within their contracts they could differ by no more.
    A row beyond that, or with a failure status, is judged against the scipy reference
    (event-located DOP853 at rtol 1e-13; at most `MAX_REFERENCES` rows, cached in
    `references` by row): the peer is wrong there if it failed or is off the reference by
    more than its contract (the project likewise). Disagreeing rows beyond the references
    count as the peer's wrong rows, unjudged.

    **Returns:** `peer_wrong_rows`, `jaxunilat_wrong_rows`, `disagreeing_rows`,
    `judged_rows`, `unjudged_rows`, `max_abs_dx_m` (largest |x_peer − x_own|), and
    `wrong_examples`: up to 5 wrong rows' κ, k_r and errors against the reference.
    """
    from ._peers import Params, reference
    from ._scale import Y0

    references = {} if references is None else references
    x_peer, x_own, status = np.asarray(x_peer, float), np.asarray(x_own, float), np.asarray(status)
    with np.errstate(invalid="ignore"):
        diff = np.max(np.abs(x_peer - x_own), axis=1)
    diff = np.where(np.isfinite(diff), diff, np.inf)
    screen = contract_bound(tol, x_own, ts) + contract_bound(own_tol, x_own, ts)
    disagree = np.nonzero((diff > screen) | (status != 0))[0]
    judged, unjudged = disagree[:MAX_REFERENCES], disagree[MAX_REFERENCES:]
    peer_wrong, own_wrong, examples = [], [], []
    for i in judged:
        i = int(i)
        if i not in references:
            references[i] = reference(Params(kappa=float(kappa[i]), k_r=float(k_r[i])), Y0, ts)
        ref = references[i]
        contacts = [len(ref.entries)]
        with np.errstate(invalid="ignore"):
            err_peer, err_own = (float(np.max(np.abs(x[i] - ref.x))) for x in (x_peer, x_own))
        if status[i] != 0 or not err_peer <= contract_bound(tol, ref.x, ts, contacts)[0]:
            peer_wrong.append(i)
            if len(examples) < 5:
                examples.append(
                    {
                        "row": i,
                        "kappa": float(kappa[i]),
                        "k_r": float(k_r[i]),
                        "status": int(status[i]),
                        "peer_error_m": err_peer,
                        "jaxunilat_error_m": err_own,
                    }
                )
        if not err_own <= contract_bound(own_tol, ref.x, ts, contacts)[0]:
            own_wrong.append(i)
    return {
        "peer_wrong_rows": len(peer_wrong) + len(unjudged),
        "jaxunilat_wrong_rows": len(own_wrong),
        "disagreeing_rows": len(disagree),
        "judged_rows": len(judged),
        "unjudged_rows": len(unjudged),
        "max_abs_dx_m": float(np.max(diff)),
        "wrong_examples": examples,
    }


def _own_rows(n: int) -> dict:
    """The project's rows of the throughput scene's n pairs (`_scale.trajectory`, swept
    the platform's faster way), for `bench_section` when it is not given them."""
    from .._solver._sweep import sweep
    from ._scale import one_by_one_fastest, pairs, sweep_kwargs, trajectory

    kappa, k_r = pairs(n)
    x = sweep(trajectory, kappa, k_r, **sweep_kwargs(n, one_by_one=one_by_one_fastest()))[0]
    return {"x": np.asarray(x), "kappa": kappa, "k_r": k_r}


def _throughput_rows(n, tol, timed, log, own) -> tuple[list[dict], dict]:
    from ._scale import SAMPLES, T1, TOL, Y0, pairs

    kappa, k_r = pairs(n)
    ts = np.linspace(0.0, T1, SAMPLES)
    rows, checks, references = [], [], {}
    for parallel in (False, True):
        timing = timed(lambda p=parallel: solve_batch(kappa, k_r, Y0, ts, rtol=tol, atol=tol, parallel=p))
        x, stats = timing.out
        cores = threads() if parallel else 1
        # The process's CPU time for one more run: on a shared machine the wall time
        # also counts the other processes' share of the cores.
        cpu = time.process_time()
        solve_batch(kappa, k_r, Y0, ts, rtol=tol, atol=tol, parallel=parallel)
        cpu = time.process_time() - cpu
        # Every row against the project's: only the right rows count towards the throughput.
        check = check_rows(x, stats[:, 3], own["x"], TOL, kappa, k_r, ts, tol, references)
        checks.append(check)
        wrong = check["peer_wrong_rows"]
        rows.append(
            {
                "method": f"{METHOD}, tol {tol:g}, "
                + (f"prange on {cores} threads" if parallel else "serial"),
                "n": int(n),
                "threads": cores,
                "traj_per_s": (n - wrong) / timing.median,
                "traj_per_s_all_rows": n / timing.median,
                "peer_wrong_rows": wrong,
                "valid": wrong == 0,
                "wall_s": timing.median,
                "cpu_s": cpu,
                "peak_mem_mb": None,
                "all_ok": bool(np.all(stats[:, 3] == 0)),
                "steps_mean": float(np.mean(stats[:, 0] + stats[:, 1])),
                "steps_max": int(np.max(stats[:, 0] + stats[:, 1])),
                "peer": True,
            }
        )
        r = rows[-1]
        log(
            f"  compiled loop N = {n:>6}, {'prange' if parallel else 'serial'}, {cores} thread(s): "
            f"{r['traj_per_s']:10.1f} right traj/s  wall {r['wall_s']:.4f} s (CPU {cpu:.4f} s)  "
            f"steps mean {r['steps_mean']:.0f}; wrong rows {wrong} of {n} "
            f"(max |dx| vs jaxunilat {check['max_abs_dx_m']:.1e} m)"
        )
    worst = max(checks, key=lambda c: c["peer_wrong_rows"])
    check = {
        "how": "every row of the peer's throughput runs against jaxunilat.sweep's rows of the same pairs "
        f"(event mode, {TOL:g}): a row is right where the two agree within the sum of their accuracy "
        "contracts (1e3 tol X (1 + N)); the others are judged against the scipy reference (DOP853 + "
        "events, rtol 1e-13), wrong where off it by more than the contract or failed",
        "n": int(n),
        **worst,
    }
    return rows, check


def bench_section(
    tols, throughput_n: int, max_error: float, ts, x_ref, wp_rows, timed, log, own: dict | None = None
) -> dict:
    """The bench's compiled-loop section: work-precision rows at `tols` (rtol = atol),
    the ratio columns of the project's rows (`ratio_columns`), and the serial and
    `prange` throughput over `throughput_n` (κ, k_r) pairs at the loosest tolerance whose
    example-2 error is at most `max_error` m, every row checked against the project's
    rows of the same pairs (`own`: `x`, `kappa`, `k_r` of the throughput scene; swept
    here if not given or of other pairs): `peer_wrong_rows`, and a throughput of the
    right rows only. Without Numba: one line, no rows."""
    if not available():
        log("  " + why_missing())
        for row in (r for r in wp_rows if not r["peer"]):
            row["vs_compiled"] = None
        return {"status": why_missing(), "rows": [], "throughput": [], "peer_wrong_rows": None}
    from ._scale import pairs

    compile_s = warm_up()
    rows = _wp_rows(tols, ts, x_ref, timed, log, compile_s)
    ratio_columns(wp_rows, rows, log)
    ok = [r for r in rows if r["error"] <= max_error]
    tol = max(float(r["setting"].split()[1]) for r in ok) if ok else min(tols)
    kappa, k_r = pairs(throughput_n)
    if own is None or not (np.array_equal(own["kappa"], kappa) and np.array_equal(own["k_r"], k_r)):
        own = _own_rows(throughput_n)
    throughput, check = _throughput_rows(throughput_n, tol, timed, log, own)
    return {
        "status": "measured",
        "how": "event-located DOP853, unrolled scalar code in Numba; compile time excluded (warm-up call)",
        "numba": numba.__version__,
        "compile_s": compile_s,
        "rows": rows,
        "throughput": throughput,
        # Rows of the throughput runs whose result is off the accuracy contract (the worse run).
        "peer_wrong_rows": check["peer_wrong_rows"],
        "peer_check": check,
    }


def main() -> int:
    """`python -m jaxunilat._bench._compiled`: this peer's rows and throughput alone
    (the bench's scene, reference and timing: medians after a warm-up)."""
    import statistics

    from ._peers import Params, reference
    from ._scale import SAMPLES, T1, Y0

    if not available():
        print(why_missing())
        return 1

    class Timing:
        def __init__(self, fn, runs=21):
            fn()
            walls = []
            for _ in range(runs):
                start = time.perf_counter()
                self.out = fn()
                walls.append(time.perf_counter() - start)
            self.median, self.min, self.runs = statistics.median(walls), min(walls), runs

    ts = np.linspace(0.0, T1, SAMPLES)
    x_ref = reference(Params(), Y0, ts).x
    section = bench_section(tuple(10.0**-k for k in range(4, 13)), 1000, 1e-9, ts, x_ref, [], Timing, print)
    print(f"compile {section['compile_s']:.1f} s, numba {section['numba']}, {threads()} threads")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
