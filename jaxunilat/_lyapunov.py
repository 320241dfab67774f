"""A chaos indicator: the finite-time Lyapunov exponent (FTLE) of the coupling.

The tangent dynamics δẏ = (∂f/∂y)·δy are integrated alongside the trajectory, with the
Jacobian–vector product computed by `jax.jvp` of the model's vector field at every
stage. The FTLE over a window [t0, t1] is

    λ = (ln‖δy(t1)‖ − ln‖δy(t0)‖) / (t1 − t0)      [1/s]

in the scaled norm ‖(ψ/δ, ψ̇/(δ ω_c))‖, ω_c = √(κ l / J_t); the transient before t0
aligns δy with the most expanding direction. λ > 0 means nearby trajectories diverge
exponentially (chaos); λ < 0 means they converge.

The exact Heaviside's vector field jumps at contact entry (the damping force k_r ψ̇
switches on), and its Jacobian misses that jump, so the tangent dynamics use a smooth
Heaviside of width ε = `eps_fraction`·δ (default 0.02 δ): the FTLE is that of the
smoothed model. Its bias is small against the contact depth (≈ 0.1–0.4 δ under the
stiff constants).
"""

from __future__ import annotations

from typing import ClassVar

import equinox as eqx
import jax
import jax.numpy as jnp
from jaxtyping import Array

from ._coupling import Coupling
from ._heaviside import Logistic
from ._model import AbstractModel


class TangentCoupling(AbstractModel):
    """The coupling with its tangent dynamics: state (y, δy), 8 components.

    **Arguments:**

    - `model`: the `Coupling` (use a smooth Heaviside for a meaningful linearization).
    """

    model: Coupling

    state_names: ClassVar[tuple[str, ...]] = (
        "psi_xi",
        "dpsi_xi",
        "psi_eta",
        "dpsi_eta",
        "d_psi_xi",
        "d_dpsi_xi",
        "d_psi_eta",
        "d_dpsi_eta",
    )
    output_names: ClassVar[tuple[str, ...]] = ("log_norm",)

    def _scale(self):
        m = self.model
        delta = m.delta_xi
        w_c = jnp.sqrt(m.kappa * m.length / m.j_t)
        return jnp.stack([delta, delta * w_c, delta, delta * w_c])

    def vector_field(self, t, z, args=None):
        y, dy = z[:4], z[4:]
        fy, jv = jax.jvp(lambda s: self.model.vector_field(t, s), (y,), (dy,))
        return jnp.concatenate([fy, jv])

    def output(self, name, t, z):
        if name == "log_norm":
            return jnp.log(jnp.linalg.norm(z[4:] / self._scale()))
        raise ValueError(f"output = {name!r} is not supported; choose from {self.output_names}")


def ftle(
    model: Coupling,
    t0: float,
    t1: float,
    *,
    eps_fraction: float = 0.02,
    rtol: float = 1e-8,
    atol: float = 1e-12,
    max_steps: int = 400_000,
) -> Array:
    """The finite-time Lyapunov exponent of a coupling run over [t0, t1], 1/s.

    **Arguments:**

    - `model`: a `Coupling` (its Heaviside option is replaced by `Logistic(eps_fraction·δ)`).
    - `t0`, `t1`: the window, s; the run starts at 0 from the paper's initial state.
    - `eps_fraction`: the smoothing width as a fraction of the clearance δ.
    - `rtol`, `atol`: Tsit5's tolerances (atol applies to the trajectory; the tangent,
      started at a scaled norm of 1e100, is controlled by rtol). Keep λ·(t1 − t0)
      within about ±400.
    - `max_steps`: the step budget.

    **Returns:** λ, 1/s (a scalar; `jax.vmap` over models batches it, one compilation).
    """
    from ._simulate import simulate

    smooth = eqx.tree_at(lambda m: m.heaviside, model, Logistic(eps_fraction * model.delta_xi))
    tangent = TangentCoupling(smooth)
    scale = tangent._scale()
    # The tangent equation is linear: start it at 1e100 (scaled norm) so that it can
    # contract by e^-900 or grow by e^470 without leaving float64's range.
    dy0 = 1e100 * jnp.stack([1.0, 1.0, 1.0, 1.0]) * scale / 2.0
    z0 = jnp.concatenate([smooth.paper_initial_state(), dy0])
    ts = jnp.stack([jnp.asarray(t0, float), jnp.asarray(t1, float)])
    sol = simulate(
        tangent,
        z0,
        t1,
        solver="tsit5",
        rtol=rtol,
        atol=atol,
        ts=ts,
        outputs=("log_norm",),
        max_steps=max_steps,
        throw=False,
    )
    log_norm = sol.ys["log_norm"]
    return jnp.where(sol.status == 0, (log_norm[1] - log_norm[0]) / (ts[1] - ts[0]), jnp.nan)
