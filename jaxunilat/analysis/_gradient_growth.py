"""How reverse-mode gradients grow with the horizon in the coupling's chaotic regime.

A loss over a window [t_s, t_s + T] of the coupling at full speed (t_s past the spin-up,
ω ≈ b c) is differentiated by reverse mode through one `simulate` run with respect to
log κ and log k_r. In a chaotic regime a perturbation of the parameters grows like
e^(λT) with λ > 0 the largest Lyapunov exponent, and so do the gradients of any loss on
the trajectory: beyond a few Lyapunov times 1/λ they are huge, jump in sign from one
horizon (or one parameter value) to the next, and no longer point downhill on the
averaged loss. `gradient_growth` measures ‖∂ log L/∂ log θ‖ against T next to e^(λT)
from `ftle`.

The loss is the mean square of the elastic joint forces,

    L(T) = (1/n) Σ_k (T_ξ(t_k)² + T_η(t_k)²),   t_k uniform on [t_s, t_s + T]   [N²]

(T_ξ, T_η from [K90 Eq. 4.8]), started from the nominal model's state at t_s (fixed: the
gradient is that of a window fit that starts from a measured state).
"""

from __future__ import annotations

import dataclasses

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np

from .._internal._errors import InputError
from .._internal._validate import check_finite, check_range
from .._solver._simulate import _TRACES, one_failure_message

#: The differentiated parameters (log multipliers), in this order.
PARAMETERS = ("kappa", "k_r")
_FORCES = ("T_xi", "T_eta")
_STATE = ("psi_xi", "dpsi_xi", "psi_eta", "dpsi_eta")


@dataclasses.dataclass(frozen=True)
class GradientGrowth:
    """Gradient norms of a windowed loss against the horizon.

    **Fields:**

    - `horizons`: the window lengths T, s.
    - `loss`: L(T), N² (mean square elastic joint force over the window).
    - `gradient`: (len(horizons), 2) array of ∂ log L/∂ log θ for θ = (κ, k_r), by
      reverse-mode AD (dimensionless: a 1 % change of θ changes L by about that many %).
    - `norm`: the Euclidean norm of each row of `gradient`.
    - `ftle`: λ, 1/s, the finite-time Lyapunov exponent over [t_start, t_start + max T]
      (`ftle`); NaN if not computed.
    - `t_start`: the window start t_s, s.
    """

    horizons: np.ndarray
    loss: np.ndarray
    gradient: np.ndarray
    norm: np.ndarray
    ftle: float
    t_start: float

    @property
    def lyapunov_growth(self) -> np.ndarray:
        """e^(λT) for each horizon (the growth of a perturbation over the window)."""
        return np.exp(self.ftle * self.horizons)

    def useful_horizon(self, limit: float = 1e2) -> float:
        """The longest horizon, s, up to which every norm stays within `limit` × the shortest
        horizon's norm (beyond it the gradient is dominated by the chaotic growth)."""
        ok = self.norm <= limit * self.norm[0]
        bad = np.nonzero(~ok)[0]
        return float(self.horizons[-1] if len(bad) == 0 else self.horizons[max(bad[0] - 1, 0)])

    def table(self) -> str:
        """A Markdown table: T, L, ∂ log L/∂ log κ, ∂ log L/∂ log k_r, norm, e^(λT)."""
        rows = [
            "| T (s) | L (N²) | ∂logL/∂logκ | ∂logL/∂logk_r | norm | e^(λT) |",
            "|---|---|---|---|---|---|",
        ]
        for i, t in enumerate(self.horizons):
            g = self.gradient[i]
            rows.append(
                f"| {t:.3g} | {self.loss[i]:.3e} | {g[0]:.3g} | {g[1]:.3g} | {self.norm[i]:.3g} | "
                f"{self.lyapunov_growth[i]:.3g} |"
            )
        return "\n".join(rows)


def _scaled(model, s):
    return eqx.tree_at(
        lambda m: (m.kappa, m.k_r), model, (model.kappa * jnp.exp(s[0]), model.k_r * jnp.exp(s[1]))
    )


def _window(s, model, y0, t0, horizon, samples, settings):
    """(L, state at t0 + T) of one run over [t0, t0 + T] with θ = θ₀·e^s (all traced)."""
    from .._solver._simulate import simulate

    ts = t0 + horizon * jnp.linspace(0.0, 1.0, samples)
    sol = simulate(
        _scaled(model, s), y0, (t0, t0 + horizon), ts=ts, outputs=_FORCES + _STATE, **dict(settings)
    )
    loss = jnp.mean(sol.ys["T_xi"] ** 2 + sol.ys["T_eta"] ** 2)
    return loss, jnp.stack([sol.ys[n][-1] for n in _STATE])


@eqx.filter_jit
def _loss_and_gradient(model, y0, t0, horizon, samples, settings):
    """log L and ∂ log L/∂s at s = 0 (one compilation for every horizon and parameter value)."""
    _TRACES["gradient_growth"] += 1

    def log_loss(s):
        return jnp.log(_window(s, model, y0, t0, horizon, samples, settings)[0])

    return jax.value_and_grad(log_loss)(jnp.zeros(len(PARAMETERS)))


_DEFAULT_SETTINGS = dict(solver="event", rtol=1e-10, atol=1e-13, max_steps=65_536, max_events=8192)


def _frozen(settings):
    return tuple(sorted({**_DEFAULT_SETTINGS, **settings}.items()))


@one_failure_message
def window_loss(model, y0, t_start, horizon, *, samples: int = 201, **settings) -> float:
    """L(T) = the mean of T_ξ² + T_η² on `samples` uniform times over [t_start, t_start + T], N².

    **Arguments:** as `gradient_growth` (`y0`: the state at `t_start`, rad and rad/s).

    **Returns:** L, N². The forward function that `gradient_growth` differentiates; evaluated
    on its own (no AD) it is the finite-difference reference. It shares `simulate`'s compiled
    program with `state_at`.
    """
    args = (jnp.asarray(y0, float), jnp.asarray(float(t_start)), jnp.asarray(float(horizon)))
    return float(_window(jnp.zeros(len(PARAMETERS)), model, *args, samples, _frozen(settings))[0])


@one_failure_message
def state_at(model, t_start: float, *, samples: int = 201, **settings) -> np.ndarray:
    """The coupling's state (ψ_ξ, ψ̇_ξ, ψ_η, ψ̇_η) at `t_start`, s, from the paper's initial state."""
    y0 = jnp.asarray(model.paper_initial_state(), float)
    args = (y0, jnp.asarray(0.0), jnp.asarray(float(t_start)))
    return np.asarray(_window(jnp.zeros(len(PARAMETERS)), model, *args, samples, _frozen(settings))[1])


@one_failure_message
def gradient_growth(
    model=None,
    horizons=(0.05, 0.1, 0.2, 0.5, 1.0, 2.0, 5.0),
    *,
    t_start: float = 6.0,
    samples: int = 201,
    lyapunov: bool = True,
    **settings,
) -> GradientGrowth:
    """Reverse-mode gradient norms of a windowed force loss against the horizon.

    **Arguments:**

    - `model`: a `Coupling` with an exact Heaviside; default `Coupling.table2(2)`
      (stiff constants, reading A, b = 12 1/s).
    - `horizons`: window lengths T, s (each > 0).
    - `t_start`: the window start, s; the default 6 s is past the spin-up
      (ω = b(c − e^(−a t)) is within 1 % of b c for t ≥ 6 s, a = 0.768 1/s [K90 Eq. 4.6]).
    - `samples`: uniform samples of the force in each window (fixed: one compilation).
    - `lyapunov`: also compute λ = `ftle(model, t_start, t_start + max T)`.
    - `settings`: `simulate` settings (default: event mode, rtol 1e-10, atol 1e-13,
      max_steps 65 536, max_events 8192; raise the budgets for horizons beyond ~5 s).

    **Returns:** a `GradientGrowth` (∂ log L/∂ log κ and ∂ log L/∂ log k_r per horizon,
    their norms, λ and e^(λT)).
    """
    from .._models._coupling import Coupling
    from ._lyapunov import ftle

    if model is None:
        model = Coupling.table2(2)
    if not isinstance(model, Coupling):
        raise InputError(f"model = {model!r} is not supported; valid: a jaxunilat.Coupling")
    if model.k_r is None:
        raise InputError("model.k_r = None is not supported; valid: a damping k_r > 0 (N*s/rad)")
    horizons = np.asarray(horizons, float).ravel()
    if horizons.size == 0:
        raise InputError("horizons = () is not supported; valid: one or more window lengths > 0 s")
    for t in horizons:
        check_finite("horizons", float(t))
        check_range("horizons", float(t), lo=0.0, lo_open=True)
    check_finite("t_start", float(t_start))
    check_range("t_start", float(t_start), lo=0.0)
    check_range("samples", samples, lo=2)
    y0 = jnp.asarray(state_at(model, t_start, samples=samples, **settings))
    frozen = _frozen(settings)
    losses, grads = [], []
    for t in horizons:  # one window per horizon; the compiled function is shared
        value, grad = _loss_and_gradient(
            model, y0, jnp.asarray(float(t_start)), jnp.asarray(t), int(samples), frozen
        )
        losses.append(float(np.exp(value)))
        grads.append(np.asarray(grad))
    grads = np.stack(grads)
    lam = float(ftle(model, t_start, t_start + float(horizons.max()))) if lyapunov else float("nan")
    return GradientGrowth(
        horizons=horizons,
        loss=np.asarray(losses),
        gradient=grads,
        norm=np.linalg.norm(grads, axis=1),
        ftle=lam,
        t_start=float(t_start),
    )
