"""Gradient-based sensitivity studies [K90 §6]: ∂log(output)/∂log(parameter) by AD.

The outputs are scalar features of one event-mode run (`solver="event"`: the exact
model with every contact located, whose reverse-mode gradients include the
implicit-function derivatives of the contact times):

- coupling: the peak elastic impact force max κ·D (N), differentiated at the located
  peak (ψ̇ = 0, where the envelope theorem makes the peak time's own derivative
  vanish), and the RMS elastic force √(∫(T_ξ² + T_η²) dt / t1) (N, trapezoidal rule
  on the uniform samples, which is a smooth functional since D² is C¹);
- ball: apex heights above the lower racket (m) and contact onset times (s).

Parameters are perturbed multiplicatively, θ = θ₀·e^s, so a negative parameter (α)
has the normalized sensitivity (θ/out)·∂out/∂θ of its magnitude.

A normalized sensitivity S means: a 1 % increase of the parameter changes the output
by about S %. Near chaotic regimes the gradients of a long horizon are not
meaningful (they grow like e^(λt) with the horizon): `meaningful` is False when the
normalized gradient of the final state, ‖∂(y(t1)/y_scale)/∂log θ‖ (y_scale = δ for
the coupling, a for the ball), exceeds `growth_limit` (default 1e3; it is O(1–10)
in the regular run-up and grows without bound with the horizon in a chaotic regime).
"""

from __future__ import annotations

import dataclasses
import math

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np

from .._internal._errors import InputError
from .._solver._simulate import _TRACES, one_failure_message

#: The coupling's parameters `coupling_sensitivity` differentiates in, in its table's order.
COUPLING_PARAMETERS = ("clearance", "alpha", "b", "kappa", "k_r", "h")
COUPLING_SYMBOLS = {
    "clearance": "Delta",
    "alpha": "alpha",
    "b": "b",
    "kappa": "kappa",
    "k_r": "k_r",
    "h": "h",
}
COUPLING_OUTPUTS = ("peak_force", "rms_force")
BALL_PARAMETERS = ("kappa", "k_r", "drag", "gap")
_OUTPUTS = ("psi_xi", "dpsi_xi", "psi_eta", "dpsi_eta", "T_xi", "T_eta")


@dataclasses.dataclass(frozen=True)
class SensitivityResult:
    """Normalized sensitivities of a run's scalar outputs.

    **Fields:**

    - `model`: a one-line description of the run.
    - `outputs`, `parameters`: names (rows, columns).
    - `values`: the outputs' values at the nominal parameters (units per output).
    - `units`: each output's unit.
    - `table`: (outputs × parameters) array of ∂log(output)/∂log(parameter), by AD.
    - `meaningful`: False near chaotic regimes (the final state's normalized gradient
      above the limit), where `format_table` prints n/a instead of noise.
    - `growth`: ‖∂(y(t1)/y_scale)/∂log θ‖, the final state's normalized gradient norm.
    - `fd`: the central finite-difference table, when computed (`check=True`).
    """

    model: str
    outputs: tuple[str, ...]
    parameters: tuple[str, ...]
    values: np.ndarray
    units: tuple[str, ...]
    table: np.ndarray
    meaningful: bool
    growth: float
    fd: np.ndarray | None = None


# -- coupling -----------------------------------------------------------------------


def _scaled_coupling(base, s):
    """`base` with parameter i multiplied by exp(s[i]) (order: COUPLING_PARAMETERS)."""
    import equinox as eqx

    leaves = [getattr(base, name) for name in COUPLING_PARAMETERS]
    scaled = [v * jnp.exp(s[i]) for i, v in enumerate(leaves)]
    return eqx.tree_at(lambda m: [getattr(m, n) for n in COUPLING_PARAMETERS], base, scaled)


def _coupling_run(model, t1, ts, settings):
    from .._solver._simulate import simulate

    return simulate(model, model.paper_initial_state(), t1, ts=ts, outputs=_OUTPUTS, **dict(settings))


@one_failure_message
def locate_peak(model, t1, *, samples: int = 10001, **settings) -> tuple[float, str]:
    """The time (s) and force component ('T_xi' or 'T_eta') of the peak elastic force.

    The peak is found on `samples` uniform samples, refined on a local grid of the
    same size between the neighbouring samples, then by one Newton step on the
    coordinate's rate (ψ̇ = 0 at the peak). Not differentiable (a plain location).
    """
    ts = np.linspace(0.0, t1, samples)
    sol = _coupling_run(model, t1, ts, settings)
    t_xi, t_eta = np.abs(np.asarray(sol.ys["T_xi"])), np.abs(np.asarray(sol.ys["T_eta"]))
    name = "T_xi" if t_xi.max() >= t_eta.max() else "T_eta"
    force = t_xi if name == "T_xi" else t_eta
    i = int(np.argmax(force))
    lo, hi = ts[max(i - 1, 0)], ts[min(i + 1, samples - 1)]
    local = np.linspace(lo, hi, samples)
    sol = _coupling_run(model, t1, local, settings)
    k = int(np.argmax(np.abs(np.asarray(sol.ys[name]))))
    y = np.stack([np.asarray(sol.ys[n])[k] for n in _OUTPUTS[:4]])
    rate, coord = (3, 2) if name == "T_xi" else (1, 0)
    acc = float(np.asarray(model.vector_field(local[k], jnp.asarray(y)))[rate])
    del coord
    t_star = local[k] - (y[rate] / acc if acc != 0 else 0.0)
    return float(np.clip(t_star, lo, hi)), name


def _coupling_features(model, t1, grid, settings):
    """(peak, rms) and ψ(t1)/δ from one run on the grid's times (uniform samples + t*).

    `grid` = (ts, weights, k_star, which): the save times, the trapezoidal weights of the
    uniform samples (0 at the inserted peak time), the peak time's index and the force
    component (0: T_xi, 1: T_eta). All traced: a new peak time does not recompile.
    """
    ts, weights, k_star, which = grid
    sol = _coupling_run(model, t1, ts, settings)
    t_xi, t_eta = sol.ys["T_xi"], sol.ys["T_eta"]
    peak = jnp.abs(jnp.where(which == 0, t_xi[k_star], t_eta[k_star]))
    rms = jnp.sqrt(jnp.sum(weights * (t_xi**2 + t_eta**2)) / t1)
    state = jnp.stack([sol.ys["psi_xi"][-1], sol.ys["psi_eta"][-1]]) / model.delta_xi
    return jnp.stack([peak, rms]), state


def _coupling_grid(t1, samples, t_star, name):
    uniform = np.linspace(0.0, t1, samples - 1)
    k_star = int(np.searchsorted(uniform, t_star, side="right"))
    ts = np.insert(uniform, k_star, t_star)
    weights = np.zeros(samples)
    w = np.zeros(samples - 1)
    dt = np.diff(uniform)
    w[:-1] += 0.5 * dt
    w[1:] += 0.5 * dt
    weights[np.arange(samples) != k_star] = w
    return ts, weights, np.asarray(k_star), np.asarray(0 if name == "T_xi" else 1)


@eqx.filter_jit
def _coupling_jacobian(model, t1, grid, settings):
    """Outputs, final state, and their Jacobians w.r.t. the log-multipliers s (one compile)."""
    _TRACES["coupling_jacobian"] += 1

    def f(s):
        out = _coupling_features(_scaled_coupling(model, s), t1, grid, settings)
        return out, out

    jac, out = jax.jacrev(f, has_aux=True)(jnp.zeros(len(COUPLING_PARAMETERS)))
    return out, jac


@one_failure_message
def coupling_features(model, t1, *, samples: int = 10001, **settings) -> np.ndarray:
    """(peak elastic force [N], RMS elastic force [N]) of a coupling run, with the peak located.

    This is the forward function that `coupling_sensitivity` differentiates; evaluated
    on its own (no AD) it is the finite-difference reference.
    """
    settings = {**_DEFAULT_SETTINGS, **settings}
    t_star, name = locate_peak(model, t1, samples=samples, **settings)
    grid = _coupling_grid(t1, samples, t_star, name)
    # Not jitted as a whole: the run is `simulate`'s compiled program, the rest is cheap.
    feats, _ = _coupling_features(model, float(t1), grid, settings)
    return np.asarray(feats)


def _hashable(settings):
    return tuple(sorted(settings.items()))


_DEFAULT_SETTINGS = dict(solver="event", rtol=1e-11, atol=1e-14, max_steps=32_768, max_events=4096)


@one_failure_message
def coupling_sensitivity(
    example: int = 2,
    *,
    t1: float = 1.0,
    reading: str = "paper",
    params: str = "stiff",
    h: float | None = None,
    samples: int = 10001,
    check: bool = False,
    fd_step: float = 1e-4,
    growth_limit: float = 1e3,
    model=None,
    **settings,
) -> SensitivityResult:
    """Normalized sensitivities of the coupling's peak and RMS elastic impact forces.

    **Arguments:**

    - `example`: the Table 2 example (ignored when `model` is given).
    - `t1`: the horizon, s. The run-up (t1 ≲ 5 s) is not chaotic in the stiff model.
    - `reading`, `params`: as in `Coupling.table2`.
    - `h`: the viscous damping, N·s/rad; default 0.02·J_t so that its sensitivity is
      defined (at h = 0 a normalized sensitivity is 0 by definition).
    - `samples`: uniform samples for the RMS and the peak search.
    - `check`: also compute central finite differences (step `fd_step` in log θ).
    - `growth_limit`: the final state's normalized gradient norm above which
      `meaningful` is False.
    - `model`: a `Coupling` to use instead of the Table 2 preset.
    - `settings`: `simulate` settings (default: event mode, rtol 1e-11, atol 1e-14).

    **Returns:** a `SensitivityResult` over Δ, α, b, κ, k_r and h.
    """
    from .._models._coupling import Coupling

    if model is None:
        model = Coupling.table2(example, params, reading, warn=False)
        desc = f"coupling, Table 2 example {example}, {params}, reading {reading}, t1 = {t1:g} s"
    else:
        desc = f"coupling ({model.reading} reading), t1 = {t1:g} s"
    if h is None:
        h = 0.02 * float(model.j_t)
    model = _with(
        model, h=jnp.asarray(float(h)), k_r=model.k_r if model.k_r is not None else jnp.asarray(0.0)
    )
    # The step and event budgets grow with the horizon (static sizes: up to 2 s one compilation).
    blocks = max(1, math.ceil(t1 / 2.0))
    budget = dict(max_steps=32_768 * blocks, max_events=4096 * blocks)
    settings = {**_DEFAULT_SETTINGS, **budget, **settings}
    t_star, name = locate_peak(model, t1, samples=samples, **settings)
    grid = _coupling_grid(t1, samples, t_star, name)
    (values, _), (jac, jac_state) = _coupling_jacobian(
        model, np.asarray(float(t1)), grid, _hashable(settings)
    )
    s0 = jnp.zeros(len(COUPLING_PARAMETERS))
    values = np.asarray(values)
    table = np.asarray(jac) / values[:, None]
    growth = float(np.linalg.norm(jac_state))
    fd = None
    if check:
        fd = _central_differences(
            lambda s: coupling_features(_scaled_coupling(model, s), t1, samples=samples, **settings),
            s0,
            fd_step,
            values,
        )
    return SensitivityResult(
        model=desc + f", h = {float(h):.4g} N*s/rad",
        outputs=COUPLING_OUTPUTS,
        parameters=tuple(COUPLING_SYMBOLS[p] for p in COUPLING_PARAMETERS),
        values=values,
        units=("N", "N"),
        table=table,
        meaningful=bool(growth <= growth_limit),
        growth=growth,
        fd=fd,
    )


def _with(model, **fields):
    import equinox as eqx

    names = list(fields)
    return eqx.tree_at(
        lambda m: [getattr(m, n) for n in names],
        model,
        [fields[n] for n in names],
        is_leaf=lambda x: x is None,
    )


# -- ball ---------------------------------------------------------------------------


def _ball_model(s, base):
    from .._models._ball import Ball

    kappa = base["kappa"] * jnp.exp(s[0])
    k_r = base["k_r"] * jnp.exp(s[1])
    drag = base["drag"] * jnp.exp(s[2])
    gap = base["gap"] * jnp.exp(s[3])
    return Ball(kappa=kappa, k_r=k_r, drag=drag, lower=-gap / 2, upper=gap / 2), gap


def ball_features(s, base, t1, n, settings):
    """(apex heights above the lower racket [m] (n), contact onset times [s] (n)) and x(t1)/a.

    The initial state is the paper's: the lower racket, moving down at 1/0.122 m/s.
    """
    from .._models._ball import PAPER_DRAG
    from .._solver._observe import apexes, impact_times
    from .._solver._simulate import simulate

    ball, gap = _ball_model(s, base)
    y0 = jnp.stack([-gap / 2, jnp.asarray(-1.0 / PAPER_DRAG)])
    sol = simulate(ball, y0, t1, samples=3, outputs=("x", "v"), **settings)
    _, heights = apexes(sol, n)
    # Skip the contact open at t0 (the start at the lower racket).
    times = impact_times(sol, n + 1)[1:]
    state = jnp.stack([sol.ys["x"][-1], sol.ys["v"][-1] * 0.0]) / (gap / 2)
    return jnp.concatenate([heights + gap / 2, times]), state


@eqx.filter_jit
def _ball_features_jit(s, base, t1, n, settings):
    _TRACES["ball_features"] += 1
    return ball_features(s, base, t1, n, dict(settings))


@eqx.filter_jit
def _ball_jacobian(base, t1, n, settings):
    _TRACES["ball_jacobian"] += 1

    def f(s):
        out = ball_features(s, base, t1, n, dict(settings))
        return out, out

    jac, out = jax.jacrev(f, has_aux=True)(jnp.zeros(4))
    return out[0], jac[0], jac[1]


@one_failure_message
def ball_sensitivity(
    example: int = 2,
    *,
    t1: float = 3.0,
    n: int = 3,
    check: bool = False,
    fd_step: float = 1e-4,
    growth_limit: float = 1e3,
    **settings,
) -> SensitivityResult:
    """Normalized sensitivities of the ball's apex heights and impact times.

    **Arguments:**

    - `example`: the Table 1 example; the paper's initial state.
    - `t1`: the horizon, s (default 3: example 2's first three apexes are at 1.61, 2.27
      and 2.85 s; an output that does not happen by t1 is NaN and not meaningful).
    - `n`: how many apexes and impacts (the first `n` of each after t = 0).
    - `check`: also compute central finite differences (step `fd_step` in log θ).
    - `settings`: `simulate` settings (default: event mode, rtol = atol = 1e-12).

    **Returns:** a `SensitivityResult` over κ, k_r, drag k and the gap 2a (the walls at
    ±a move with it, and so does the start at the lower racket).
    """
    from .._models._ball import PAPER_DRAG, PAPER_GAP, TABLE1

    settings = {**dict(solver="event", rtol=1e-12, atol=1e-12), **settings}
    kappa, k_r = TABLE1[example] if example in TABLE1 else (None, None)
    if kappa is None:
        raise InputError(f"example = {example!r} is out of range; valid Table 1 examples are 1-5")
    base = {k: np.asarray(v) for k, v in dict(kappa=kappa, k_r=k_r, drag=PAPER_DRAG, gap=PAPER_GAP).items()}

    settings = _hashable(settings)
    t1a = np.asarray(float(t1))
    values, jac, jac_state = _ball_jacobian(base, t1a, n, settings)
    s0 = np.zeros(4)

    def f(s):
        return _ball_features_jit(s, base, t1a, n, settings)

    values = np.asarray(values)
    table = np.asarray(jac) / values[:, None]
    growth = float(np.linalg.norm(jac_state))
    fd = None
    if check:
        fd = _central_differences(lambda s: f(s)[0], s0, fd_step, values)
    outputs = tuple(f"apex_{i + 1}" for i in range(n)) + tuple(f"impact_{i + 1}" for i in range(n))
    return SensitivityResult(
        model=f"ball, Table 1 example {example}, t1 = {t1:g} s",
        outputs=outputs,
        parameters=("kappa", "k_r", "drag", "gap"),
        values=values,
        units=("m",) * n + ("s",) * n,
        table=table,
        meaningful=bool(growth <= growth_limit) and bool(np.all(np.isfinite(values))),
        growth=growth,
        fd=fd,
    )


def _central_differences(features, s0, fd_step, values) -> np.ndarray:
    """The finite-difference check of a sensitivity table: central differences of
    `features(s)` in each log-scale entry of s, divided by the outputs' values."""
    fd = np.zeros((len(values), len(s0)))
    for j in range(len(s0)):
        step = np.eye(len(s0))[j] * fd_step
        plus, minus = np.asarray(features(s0 + step)), np.asarray(features(s0 - step))
        fd[:, j] = (plus - minus) / (2 * fd_step) / values
    return fd


def format_table(result: SensitivityResult) -> str:
    """The result as a plain-text table, one row per output."""
    lines = [f"sensitivities d log(output) / d log(parameter): {result.model}"]
    head = f"{'output':<12} {'value':>14}  " + " ".join(f"{p:>9}" for p in result.parameters)
    lines.append(head)
    for i, name in enumerate(result.outputs):
        value = f"{result.values[i]:.6g} {result.units[i]}"
        if result.meaningful:
            cells = " ".join(f"{v:>9.4f}" for v in result.table[i])
        else:
            cells = " ".join(f"{'n/a':>9}" for _ in result.parameters)
        lines.append(f"{name:<12} {value:>14}  {cells}")
        if result.fd is not None:
            lines.append(f"{'  (FD)':<12} {'':>14}  " + " ".join(f"{v:>9.4f}" for v in result.fd[i]))
    missing = [name for name, v in zip(result.outputs, result.values, strict=True) if not np.isfinite(v)]
    if missing:
        lines.append(
            f"not meaningful: {', '.join(missing)} did not happen within the horizon (a missing event is "
            "not a sensitivity); lengthen the horizon (--t1)"
        )
    elif not result.meaningful:
        lines.append(
            f"not meaningful: the final state's normalized gradient norm is {result.growth:.3g} (it grows "
            "with the horizon, as in a chaotic regime); shorten the horizon (--t1) or use windowed outputs"
        )
    else:
        lines.append(f"final state's normalized gradient norm: {result.growth:.3g} (regular)")
    return "\n".join(lines)
