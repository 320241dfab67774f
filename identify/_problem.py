"""The identification problem: a data set turned into a simulator-backed prediction.

The fitted vector z has a fixed layout, `PARAMETERS`:

    z = (log κ, log k_r, log k_drag, x0, v0, offset)

in SI units (κ in N/m, k_r in N·s/m, drag k in s/m, x0 in m, v0 in m/s, offset in s).
Logs make κ, k_r and drag positive and put the problem on a relative scale; which of
the six entries are fitted is the fit's (static) choice, the rest are held at their
values.

Each observation type predicts one vector from z with the event mode (exact contact,
every entry located), [K90 §6]:

- `trace`: the position x at the sample times;
- `impacts`: the contact onset times, plus the recording's unknown time offset;
- `apex`: the rebound apex heights (apexes after the first impact).
"""

from __future__ import annotations

import math

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
from jaxtyping import Array

import jaxunilat as ju

#: The fitted vector's entries, in order.
PARAMETERS = ("kappa", "k_r", "drag", "x0", "v0", "offset")
#: Entries stored as logs in z.
LOG_PARAMETERS = ("kappa", "k_r", "drag")
#: The nuisance parameters a fit may free (`fit(..., nuisance=...)`).
NUISANCE = ("drag", "x0", "v0", "offset")
#: Units for reports.
UNITS = {"kappa": "N/m", "k_r": "N*s/m", "drag": "s/m", "x0": "m", "v0": "m/s", "offset": "s"}


def to_z(values: dict[str, float]) -> np.ndarray:
    """Physical values (all six names) → z."""
    return np.array(
        [math.log(values[n]) if n in LOG_PARAMETERS else float(values[n]) for n in PARAMETERS], dtype=float
    )


def from_z(z) -> dict[str, float]:
    """z → physical values."""
    z = np.asarray(z, dtype=float)
    return {
        n: float(np.exp(v)) if n in LOG_PARAMETERS else float(v) for n, v in zip(PARAMETERS, z, strict=True)
    }


class Problem(eqx.Module):
    """One data set as a prediction problem (final).

    Structure (scene, observation type, drag on/off, sizes, tolerances) is static;
    data and constants are traced, so a new data set of the same shape does not
    retrace.
    """

    scene: str = eqx.field(static=True)
    observe: str = eqx.field(static=True)
    has_drag: bool = eqx.field(static=True)
    n_events: int = eqx.field(static=True)
    tol: float = eqx.field(static=True)
    max_steps: int = eqx.field(static=True)
    mass: Array
    gravity: Array
    half_gap: Array
    t_obs: Array
    y_obs: Array
    sigma: Array
    horizon: Array

    def ball(self, z) -> ju.Ball:
        walls = (0.0, None) if self.scene == "drop" else (-self.half_gap, self.half_gap)
        return ju.Ball(
            kappa=jnp.exp(z[0]),
            k_r=jnp.exp(z[1]),
            mass=self.mass,
            gravity=self.gravity,
            drag=jnp.exp(z[2]) if self.has_drag else None,
            lower=walls[0],
            upper=walls[1],
        )

    def predict(self, z) -> tuple[Array, Array]:
        """The predicted observations and whether the run succeeded."""
        ball = self.ball(z)
        y0 = jnp.stack([z[3], z[4]])
        common = dict(solver="event", rtol=self.tol, atol=self.tol, max_steps=self.max_steps, throw=False)
        if self.observe == "trace":
            sol = ju.simulate(ball, y0, self.t_obs[-1], ts=self.t_obs, outputs=("x",), **common)
            pred = sol.ys["x"]
        else:
            ts = jnp.stack([jnp.zeros(()), self.horizon])
            sol = ju.simulate(ball, y0, self.horizon, ts=ts, outputs=("x",), **common)
            onsets = ju.impact_times(sol, self.n_events + 1)
            if self.observe == "impacts":
                pred = onsets[: self.n_events] + z[5]
            else:
                times, heights = ju.apexes(sol, self.n_events + 2)
                # Rebound apexes only: skip a release apex at or before the first impact.
                skip = jnp.sum(times <= onsets[0])
                pred = jnp.take(heights, jnp.arange(self.n_events) + skip)
        ok = (sol.status == ju.Status.SUCCESS) & jnp.all(jnp.isfinite(pred))
        return pred, ok

    def residuals(self, z) -> tuple[Array, Array]:
        """(prediction − data)/σ, and whether the run succeeded (NaN rows become 1e6)."""
        pred, ok = self.predict(z)
        r = (pred - self.y_obs) / self.sigma
        return jnp.where(jnp.isfinite(r), r, 1e6), ok


@eqx.filter_jit
def evaluate_rows(problem: Problem, zs) -> tuple[Array, Array]:
    """Residuals for each row of `zs` (rows, 6), in one compiled sequential map.

    This is the package's jitted entry point: the fit calls it with a fixed number of
    rows (the current point and its finite-difference neighbours), so only the
    first call compiles.
    """
    return jax.lax.map(problem.residuals, zs)


def _device(value) -> Array:
    """A float64 jax array of `value` (jax.device_put compiles nothing; jnp.asarray would)."""
    return jax.device_put(np.asarray(value, dtype=float))


def make_problem(
    data, *, tol: float = 1e-10, has_drag: bool, sigma: float = 1.0, horizon: float | None = None
):
    """A `Problem` for a loaded `identify.Dataset`."""
    if data.observe == "trace":
        y_obs, t_obs, n_events = data.x, data.t, 0
    elif data.observe == "impacts":
        y_obs, t_obs, n_events = data.t, data.t, len(data.t)
    else:
        y_obs = data.h
        t_obs = data.h if data.t is None else data.t
        n_events = len(data.h)
    if horizon is None:
        horizon = float(t_obs[-1]) if data.observe == "trace" else 1.0
    max_steps = int(min(max(2048, 200 * (n_events + 4) + 600 * horizon), 16384))
    return Problem(
        scene=data.scene,
        observe=data.observe,
        has_drag=has_drag,
        n_events=n_events,
        tol=float(tol),
        max_steps=max_steps,
        mass=_device(data.mass),
        gravity=_device(data.gravity),
        half_gap=_device(0.0 if data.gap is None else data.gap / 2),
        t_obs=_device(t_obs),
        y_obs=_device(y_obs),
        sigma=_device(sigma),
        horizon=_device(horizon),
    )
