"""The numerical stress suite's configurations, runner and accuracy contract.

Configurations are drawn from a fixed seed (`make_configs`), each run with `simulate`
and compared with the independent scipy event-located reference (`reference.py`).
Each run ends in one of three outcomes:

- **pass**: the run succeeded and its error is within the mode's contract (`bound`);
- **clear error**: `simulate` refused the input (`ValueError`) or reported a failure
  status (max_steps, non-finite, ...), which `throw=True` raises with a message;
- **silent failure**: the run reported success but its error exceeds the contract, or
  its outputs are not finite. The suite requires zero of these.

The accuracy contract (`bound`), with err = max |x − x_ref| over the saved samples, m:

- event mode (Tsit5 or Dopri8 pieces) at rtol = atol = τ:
  err ≤ 1e3 · τ · X · (1 + N), X = max(1 m, the largest |x|, |v|·1 s of the reference)
  and N the number of contacts in the reference;
- Tsit5 with the exact Heaviside at τ: err ≤ 3e2 · √τ · X · (1 + N);
- Tsit5 with a smooth Heaviside of width ε = f · δ, δ the reference's largest penetration:
  err ≤ 10 · f · X · (1 + N) (the smoothing bias);
- RK4 with the exact Heaviside at dt = t_c / n (t_c = π√(m/κ)): err ≤ 30 · (dt/t_c) · X · (1 + N).

Configurations share a compiled function when they share a structure (walls, drag on
or off, mode, Heaviside kind): outputs, sample count and step budgets are fixed here,
and parameter values, y0, t1 and tolerances are traced.
"""

from __future__ import annotations

import dataclasses
import math
import time

import jax
import numpy as np
from reference import BallParams, scipy_reference

import jaxunilat

#: Paper mass, kg, and gravity, m/s².
MASS = 2.37e-3
GRAVITY = 9.81
#: Saved samples per run and the outputs: fixed so that a structure compiles once.
SAMPLES = 2001
OUTPUTS = ("x", "v")
#: A reference that takes longer than this (s) leaves its run unjudged (reported, never a pass).
REFERENCE_SECONDS = 60
#: RK4's static step budget (horizons are clipped to it).
RK4_MAX_STEPS = 100_016

MODES = ("event", "event-dopri8", "tsit5", "logistic", "softplus", "rk4", "float32-inputs", "float32")


@dataclasses.dataclass(frozen=True)
class Config:
    """One stress configuration (SI units)."""

    index: int
    kappa: float
    k_r: float
    drag: float | None
    lower: float | None
    upper: float | None
    x0: float
    v0: float
    t1: float
    mode: str
    tol: float = 1e-8
    dt_fraction: float = 0.0  # rk4: dt = t_c * dt_fraction
    eps_fraction: float = 0.0  # smooth: eps = delta_max * eps_fraction
    family: str = "random"

    @property
    def structure(self) -> tuple:
        return (self.lower is None, self.upper is None, self.drag is None, self.mode)

    @property
    def physical(self) -> dict:
        """The physical parameters (SI), as keyword arguments of `BallParams` and `Ball`."""
        return dict(
            kappa=self.kappa,
            k_r=self.k_r,
            mass=MASS,
            gravity=GRAVITY,
            drag=self.drag,
            lower=self.lower,
            upper=self.upper,
        )

    @property
    def params(self) -> BallParams:
        return BallParams(**self.physical)

    @property
    def contact_time(self) -> float:
        return math.pi * math.sqrt(MASS / self.kappa)


def _apex_speed(height: float, drag: float | None) -> float:
    """Launch speed whose free-flight apex is `height` above the start: h = ln(1 + k²v²)/(2gk²)."""
    if drag is None or drag == 0:
        return math.sqrt(2 * GRAVITY * height)
    return math.sqrt(math.expm1(2 * GRAVITY * drag**2 * height)) / drag


def make_configs(n: int = 500, seed: int = 20261122) -> list[Config]:
    """`n` configurations from a fixed seed, covering the ranges of README.md, "Reliability and limits".

    κ log-uniform in [1e2, 1e9] N/m; k_r = ζ·2√(κm) with ζ in [0, 1] (ends included);
    drag off or uniform in [0, 0.2] s/m; horizons log-uniform up to 30 s; one- and
    two-sided walls; families: random start, paper-like arrival at a wall, grazing
    (apex exactly at the upper wall) and a ball dropped onto one wall to come to rest;
    every mode in `MODES`.
    """
    rng = np.random.default_rng(seed)
    configs = []
    for i in range(n):
        kappa = float(10 ** rng.uniform(2, 9))
        zeta = float(rng.choice([0.0, 1.0])) if rng.random() < 0.15 else float(rng.uniform(0, 1))
        k_r = zeta * 2 * math.sqrt(kappa * MASS)
        drag = None if rng.random() < 0.3 else float(rng.uniform(0, 0.2))
        family = str(rng.choice(["random", "paper", "grazing", "rest"], p=[0.4, 0.2, 0.2, 0.2]))
        a = float(rng.uniform(0.05, 0.5))
        two_sided = family == "grazing" or (family != "rest" and rng.random() < 0.7)
        lower, upper = -a, (a if two_sided else None)
        if family == "random":
            x0 = float(rng.uniform(-a, a))
            v0 = float(rng.uniform(-10, 10))
        elif family == "paper":
            x0, v0 = -a, -float(rng.uniform(0.5, 10))
        elif family == "grazing":
            x0 = float(rng.uniform(-a, 0.5 * a))
            v0 = _apex_speed(a - x0, drag)
        else:
            x0, v0 = -a + float(rng.uniform(0.001, 0.05)), 0.0
        t1 = float(10 ** rng.uniform(-1.3, math.log10(30.0)))
        mode = MODES[i % len(MODES)]
        tol = float(rng.choice([1e-6, 1e-8, 1e-10]))
        if mode == "event-dopri8":
            tol = float(rng.choice([1e-10, 1e-12]))
        dt_fraction = float(10 ** rng.uniform(-2.3, -1.3))  # dt = t_c/200 ... t_c/20
        eps_fraction = float(10 ** rng.uniform(-4, -2))
        if mode == "rk4":
            t1 = min(t1, 0.9 * (RK4_MAX_STEPS - 16) * dt_fraction * math.pi * math.sqrt(MASS / kappa))
        configs.append(
            Config(
                i, kappa, k_r, drag, lower, upper, x0, v0, t1, mode, tol, dt_fraction, eps_fraction, family
            )
        )
    return configs


def group_by_structure(configs):
    """Configurations grouped by compiled structure, structures in first-seen order."""
    groups: dict = {}
    for c in configs:
        groups.setdefault(c.structure, []).append(c)
    return groups


@dataclasses.dataclass
class Outcome:
    config: Config
    kind: str  # "pass", "clear", "silent", "unjudged" (the reference was too slow)
    error: float = math.nan
    bound: float = math.nan
    detail: str = ""
    seconds: float = 0.0


def _ball(c: Config, eps: float | None = None):
    heaviside = jaxunilat.Exact()
    if c.mode == "logistic":
        heaviside = jaxunilat.Logistic(eps)
    elif c.mode == "softplus":
        heaviside = jaxunilat.Softplus(eps)
    return jaxunilat.Ball(**c.physical, heaviside=heaviside)


def bound(c: Config, ref_x, ref_v, ts, n_contacts: int) -> float:
    """The mode's accuracy contract for this run, m (see the module docstring)."""
    scale = max(1.0, float(np.max(np.abs(ref_x))), float(np.max(np.abs(ref_v))) * 1.0)
    growth = scale * (1 + n_contacts)
    if c.mode in ("event", "event-dopri8", "float32-inputs"):
        return 1e3 * c.tol * growth
    if c.mode == "tsit5":
        return 3e2 * math.sqrt(c.tol) * growth
    if c.mode in ("logistic", "softplus"):
        return 10 * c.eps_fraction * growth
    if c.mode == "rk4":
        return 30 * c.dt_fraction * growth
    raise ValueError(c.mode)


def _simulate(c: Config, eps: float | None):
    ball = _ball(c, eps)
    y0 = np.array([c.x0, c.v0])
    kwargs = dict(samples=SAMPLES, outputs=OUTPUTS, throw=False)
    if c.mode in ("event", "event-dopri8", "float32-inputs"):
        piece = "dopri8" if c.mode == "event-dopri8" else "tsit5"
        if c.mode == "float32-inputs":
            # float32 arrays in: simulate computes in float64 (inputs are cast up).
            ball = jaxunilat.Ball(
                **{k: (None if v is None else np.float32(v)) for k, v in c.physical.items()}
            )
            y0 = y0.astype(np.float32)
        return jaxunilat.simulate(
            ball, y0, c.t1, solver="event", piece_solver=piece, rtol=c.tol, atol=c.tol, **kwargs
        )
    if c.mode == "rk4":
        dt = c.contact_time * c.dt_fraction
        return jaxunilat.simulate(ball, y0, c.t1, solver="rk4", dt=dt, max_steps=RK4_MAX_STEPS, **kwargs)
    return jaxunilat.simulate(ball, y0, c.t1, solver="tsit5", rtol=c.tol, atol=c.tol, **kwargs)


def _float32_refused(c: Config) -> Outcome:
    """With x64 off, `simulate` must refuse the run with a message that says why."""
    previous = jax.config.jax_enable_x64
    jax.config.update("jax_enable_x64", False)
    try:
        ball = _ball(c)
        jaxunilat.simulate(ball, [c.x0, c.v0], c.t1, solver="event", samples=SAMPLES, outputs=OUTPUTS)
    except ValueError as err:
        ok = "float64" in str(err) and "jax_enable_x64" in str(err)
        return Outcome(c, "clear" if ok else "silent", detail=str(err)[:120])
    finally:
        jax.config.update("jax_enable_x64", previous)
    return Outcome(c, "silent", detail="float32 run was not refused")


def _reference(c: Config):
    """The scipy reference, or None if it takes longer than `REFERENCE_SECONDS` or fails."""
    try:
        return scipy_reference(
            c.params, (c.x0, c.v0), c.t1, max_segments=50_000, max_seconds=REFERENCE_SECONDS
        )
    except RuntimeError:  # ReferenceTimeout: too slow or too many pieces; or solve_ivp failed
        return None


def run_config(c: Config) -> Outcome:
    """Run one configuration and classify it against the reference."""
    start = time.perf_counter()
    if c.mode == "float32":
        out = _float32_refused(c)
        out.seconds = time.perf_counter() - start
        return out
    ref = None
    eps = None
    if c.mode in ("logistic", "softplus"):
        ref = _reference(c)
        if ref is None:
            return Outcome(
                c, "unjudged", detail="reference too slow or failed", seconds=time.perf_counter() - start
            )
        ts = np.linspace(0.0, c.t1, 4001)
        rx, _ = ref(ts)
        pen = 0.0
        if c.lower is not None:
            pen = max(pen, float(np.max(c.lower - rx)))
        if c.upper is not None:
            pen = max(pen, float(np.max(rx - c.upper)))
        eps = max(pen, 1e-12) * c.eps_fraction
    try:
        sol = _simulate(c, eps)
        status = int(sol.status)
    except ValueError as err:
        return Outcome(c, "clear", detail=f"ValueError: {err}"[:160], seconds=time.perf_counter() - start)
    if status != jaxunilat.Status.SUCCESS:
        return Outcome(
            c, "clear", detail=f"status {jaxunilat.Status(status).name}", seconds=time.perf_counter() - start
        )
    ts, x, v = (np.asarray(a) for a in (sol.ts, sol.ys["x"], sol.ys["v"]))
    if not (np.all(np.isfinite(x)) and np.all(np.isfinite(v))):
        return Outcome(c, "silent", detail="non-finite output with status SUCCESS")
    if ref is None:
        ref = _reference(c)
        if ref is None:
            return Outcome(
                c, "unjudged", detail="reference too slow or failed", seconds=time.perf_counter() - start
            )
    rx, rv = ref(ts)
    err = float(np.max(np.abs(x - rx)))
    b = bound(c, rx, rv, ts, len(ref.contacts))
    detail = f"{len(ref.contacts)} contacts"
    kind = "pass" if err <= b else "silent"
    return Outcome(c, kind, err, b, detail, time.perf_counter() - start)


def run_all(configs) -> list[Outcome]:
    """Run every configuration, one structure (one compile) after another."""
    outcomes = []
    for group in group_by_structure(configs).values():
        outcomes.extend(run_config(c) for c in group)
    return sorted(outcomes, key=lambda o: o.config.index)


def summary_table(outcomes) -> str:
    """A Markdown table: per mode and in total, configurations, passes, clear errors, silent failures."""
    rows = []
    for mode in (*MODES, "total"):
        sel = [o for o in outcomes if mode == "total" or o.config.mode == mode]
        if not sel:
            continue
        ratios = [o.error / o.bound for o in sel if o.kind == "pass" and o.bound > 0]
        worst = f"{max(ratios):.2g}" if ratios else "-"
        rows.append(
            f"| {mode} | {len(sel)} | {sum(o.kind == 'pass' for o in sel)} | "
            f"{sum(o.kind == 'clear' for o in sel)} | {sum(o.kind == 'silent' for o in sel)} | "
            f"{sum(o.kind == 'unjudged' for o in sel)} | {worst} |"
        )
    head = (
        "| mode | configurations | passes | clear errors | silent failures | unjudged | worst err/bound |\n"
        "|---|---|---|---|---|---|---|"
    )
    return head + "\n" + "\n".join(rows)
