"""The identification problem: a data set turned into a simulator-backed prediction.

The fitted vector z has a fixed layout, `PARAMETERS`:

    z = (log κ, log k_r, log k_drag, x0, v0, offset, scale, level)

in SI units (κ in N/m, k_r in N·s/m, drag k in s/m, x0 in m, v0 in m/s, offset in s,
scale dimensionless, level in m). Logs make κ, k_r and drag positive and put the problem
on a relative scale; which entries are fitted is the fit's (static) choice, the rest are
held at their values.

`scale` and `level` are a trace's length calibration (`TRACE_ONLY`): its position is
x_data = level + scale · x_model(t), with x_model the simulator's position (m, floor at
0; for two rackets, walls at ±gap/2) and x0, v0 physical. A video's scale (pixels to
metres, from a ruler that perspective puts 10–20% off) and its floor level (set by hand
to a pixel) are not measured; gravity fixes the scale through the flights' curvature,
and the bounces fix the level. Other observations hold them at (1, 0).

Each observation type predicts one vector from z with the event mode (exact contact,
every entry located), [K90 §6]:

- `trace`: the position level + scale · x at the sample times (minus the clock offset,
  when a video's time origin is unknown: frames before the release see the ball held
  at x0);
- `impacts`: the contact onset times, plus the recording's unknown time offset. Where
  the onsets' own ratio chain counts the bounces (a drop whose chain is not broken,
  missed bounces included: `bounce`), each observed onset is matched to *its own*
  predicted bounce, so no drift of the prediction can slip it onto a neighbour's;
  otherwise to the *nearest* predicted onset (the model predicts a few more onsets than
  observed), so a missed quiet bounce costs nothing and a spurious click is one large
  residual that the robust pass excludes, instead of shifting every later onset by one
  bounce;
- `apex`: the rebound apex heights (apexes after the first impact).

Two contact laws can be fitted (`LAWS`): the paper's Kelvin–Voigt law (κ in N/m, k_r in
N·s/m) and Hunt–Crossley with n = 3/2 (κ in N/m^1.5, k_r in N·s/m^2.5).
"""

from __future__ import annotations

import math

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
from jaxtyping import Array

import jaxunilat as ju
from jaxunilat._internal import check_choice

#: The fitted vector's entries, in order.
PARAMETERS = ("kappa", "k_r", "drag", "x0", "v0", "offset", "scale", "level")
#: Entries stored as logs in z.
LOG_PARAMETERS = ("kappa", "k_r", "drag")
#: The nuisance parameters a fit may free (`fit(..., nuisance=...)`).
NUISANCE = ("drag", "x0", "v0", "offset", "scale", "level")
#: Nuisance parameters of traces only (a trace's length scale and contact level); every
#: other observation holds them at their `NEUTRAL` values.
TRACE_ONLY = ("scale", "level")
#: The values that leave the data as they are: x_data = 0 + 1 · x_model.
NEUTRAL = {"scale": 1.0, "level": 0.0}
#: Units for reports.
UNITS = {
    "kappa": "N/m",
    "k_r": "N*s/m",
    "drag": "s/m",
    "x0": "m",
    "v0": "m/s",
    "offset": "s",
    "scale": "",
    "level": "m",
}
#: The contact laws a fit can use, by name: the one registry of laws. Each law's object owns
#: its closed forms, units and step limits; a new law is its class plus a line here.
LAW_MODELS = {"kelvin-voigt": ju.KelvinVoigt(), "hunt-crossley": ju.HuntCrossley(1.5)}
#: The laws that `law="auto"` compares (by the lowest BIC).
LAWS = ("kelvin-voigt", "hunt-crossley")


def law_name(law) -> str:
    """The registry name of `law`: a name of `LAW_MODELS` or "auto", or a law object equal
    to a registered one (`jaxunilat.HuntCrossley(1.5)` → "hunt-crossley"). Anything else:
    `ValueError` naming the registered laws."""
    if isinstance(law, ju.AbstractContactLaw):
        for name, model in LAW_MODELS.items():
            if type(model) is type(law) and model == law:
                return name
        raise ValueError(
            f"law: {law!r} is not a registered law; valid: "
            + ", ".join(f"{model!r} ({name!r})" for name, model in LAW_MODELS.items())
            + " (a new law is a line of identify's law table, LAW_MODELS)"
        )
    check_choice("law", law, (*LAW_MODELS, "auto"))
    return law


#: Predicted onsets beyond the observed ones (room for missed bounces in the matching).
EXTRA_ONSETS = 4


def units(law: str) -> dict[str, str]:
    """The report units of every parameter under `law`."""
    return {**UNITS, **LAW_MODELS[law].units}


def applies(name: str, observe: str) -> bool:
    """Whether the entry `name` of z can be fitted to observations of kind `observe`."""
    return name not in TRACE_ONLY or observe == "trace"


def to_z(values: dict[str, float]) -> np.ndarray:
    """Physical values (every name of `PARAMETERS`; scale and level default to `NEUTRAL`) → z."""
    values = {**NEUTRAL, **values}
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
    law: str = eqx.field(static=True)
    shift_trace: bool = eqx.field(static=True)
    autodiff: str = eqx.field(static=True)
    mass: Array
    gravity: Array
    half_gap: Array
    t_obs: Array
    y_obs: Array
    sigma: Array
    horizon: Array
    bounce: Array  # impacts: each row's predicted bounce (0 = the first impact), or -1: nearest

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
            law=LAW_MODELS[self.law],
        )

    def predict(self, z) -> tuple[Array, Array]:
        """The predicted observations and whether the run succeeded."""
        ball = self.ball(z)
        y0 = jnp.stack([z[3], z[4]])
        common = dict(
            solver="event",
            rtol=self.tol,
            atol=self.tol,
            max_steps=self.max_steps,
            throw=False,
            autodiff=self.autodiff,
        )
        if self.observe == "trace":
            ts = jnp.maximum(self.t_obs - z[5], 0.0) if self.shift_trace else self.t_obs
            sol = ju.simulate(ball, y0, ts[-1], ts=ts, outputs=("x",), **common)
            pred = z[7] + z[6] * sol.ys["x"]
        else:
            ts = jnp.stack([jnp.zeros(()), self.horizon])
            sol = ju.simulate(ball, y0, self.horizon, ts=ts, outputs=("x",), **common)
            if self.observe == "impacts":
                onsets = ju.impact_times(sol, self.n_events + EXTRA_ONSETS) + z[5]
                onsets = jnp.where(jnp.isfinite(onsets), onsets, jnp.inf)
                index = self.bounce.astype(jnp.int32)
                own = jnp.take(onsets, jnp.clip(index, 0, onsets.shape[0] - 1))
                # A bounce the run did not reach (a trial point whose ball runs late) is
                # predicted at the run's end: a large residual, not a failed point.
                own = jnp.where(jnp.isfinite(own), own, self.horizon + z[5])
                pred = jnp.where(index >= 0, own, _nearest(onsets, self.y_obs))
            else:
                onsets = ju.impact_times(sol, 1)
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


def _nearest(predicted: Array, observed: Array) -> Array:
    """For each observed time, the nearest predicted time (inf where none exists)."""
    gap = jnp.abs(predicted[None, :] - observed[:, None])
    return jnp.take(predicted, jnp.argmin(gap, axis=1))


@jax.jit
def evaluate_rows(problem: Problem, zs, skip) -> tuple[Array, Array]:
    """Residuals for each row of `zs`, in one compiled sequential loop.

    `problem` is a stack of data sets of one structure (`stack_problems`: every array
    leaf with a leading file axis) and `zs` has shape (files, rows, len(PARAMETERS)). This is the
    package's jitted entry point: the fit calls it with a fixed number of rows (each
    file's point and its finite-difference neighbours), so only the first call compiles.
    Every leaf of `problem` is an array (`stack_problems`), so a plain `jax.jit` suffices,
    and the command line can keep its executable on disk (`jaxunilat._internal.kept_call`).

    `skip` (a traced bool, so both settings share the program): every file's first row
    runs first, and when one of them fails the other rows are not run (residuals 1e6,
    not ok). A point whose own run fails is rejected whatever its neighbours give, and
    such runs (a trial step into a stiff corner) are the ones that run to `max_steps`.
    Rows that are independent points (`JointEvaluator.values`) pass False.
    """
    # One flat loop over (row, file) pairs, every file's first row first: a nested map
    # would keep the inner solves from compiling into one loop kernel each.
    files, rows = zs.shape[:2]
    flat = jax.tree.map(lambda leaf: jnp.tile(leaf, (rows,) + (1,) * (leaf.ndim - 1)), problem)
    first = jnp.arange(files * rows) < files
    n_obs = problem.y_obs.shape[-1]

    def body(all_ok, item):
        p, z, is_first = item
        run = is_first | all_ok | ~skip
        r, ok = jax.lax.cond(
            run, lambda: p.residuals(z), lambda: (jnp.full((n_obs,), 1e6), jnp.zeros((), bool))
        )
        return all_ok & (ok | ~is_first), (r, ok)

    pairs = jnp.swapaxes(zs, 0, 1).reshape(files * rows, -1)
    _, (r, ok) = jax.lax.scan(body, jnp.ones((), bool), (flat, pairs, first))
    return r.reshape(rows, files, -1).swapaxes(0, 1), ok.reshape(rows, files).T


def stack_problems(problems: list[Problem]) -> Problem:
    """One `Problem` whose array leaves stack those of `problems` (all of one structure:
    the same static fields and observation counts) along a leading file axis."""
    # NumPy stacking then one transfer: an eager jnp.stack would compile on first use.
    return jax.tree.map(lambda *leaves: _device(np.stack([np.asarray(x) for x in leaves])), *problems)


def _device(value) -> Array:
    """A float64 jax array of `value` (jax.device_put compiles nothing; jnp.asarray would)."""
    return jax.device_put(np.asarray(value, dtype=float))


def make_problem(
    data,
    *,
    tol: float = 1e-10,
    has_drag: bool,
    sigma: float = 1.0,
    horizon: float | None = None,
    law: str = "kelvin-voigt",
    shift_trace: bool = False,
    rows: int | None = None,
    max_steps: int | None = None,
    bounce=None,
):
    """A `Problem` for a loaded `identify.Dataset`.

    `rows` pads the observations to that many (repeating the last one; the fit gives
    padded rows no weight) so that data sets of one structure stack into one batch;
    `max_steps` overrides the step budget (a batch uses its largest). `bounce` (impact
    onsets): each onset's predicted bounce (0-based, below `len(t) + EXTRA_ONSETS`), or
    None: every onset is matched to the nearest predicted one.
    """
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
    if max_steps is None:
        max_steps = default_max_steps(n_events, horizon)
    bounce = np.full(len(y_obs), -1.0) if bounce is None else np.asarray(bounce, dtype=float)
    if rows is not None and rows > len(y_obs):
        pad = rows - len(y_obs)
        y_obs = np.concatenate([y_obs, np.repeat(y_obs[-1:], pad)])
        t_obs = np.concatenate([t_obs, np.repeat(t_obs[-1:], pad)])
        bounce = np.concatenate([bounce, np.repeat(bounce[-1:], pad)])
        n_events = rows if n_events else 0
    return Problem(
        scene=data.scene,
        observe=data.observe,
        has_drag=has_drag,
        n_events=n_events,
        tol=float(tol),
        max_steps=int(max_steps),
        law=law,
        shift_trace=bool(shift_trace),
        autodiff="reverse",
        mass=_device(data.mass),
        gravity=_device(data.gravity),
        half_gap=_device(0.0 if data.gap is None else data.gap / 2),
        t_obs=_device(t_obs),
        y_obs=_device(y_obs),
        sigma=_device(sigma),
        horizon=_device(horizon),
        bounce=_device(bounce),
    )


def default_max_steps(n_events: int, horizon: float) -> int:
    """The step budget of one run: room for every bounce and the flight between them,
    rounded up to a power of two (a static field: files whose needs differ a little share
    one compiled program instead of compiling one each)."""
    need = min(max(2048, 200 * (n_events + 4) + 600 * horizon), 16384)
    return int(2 ** math.ceil(math.log2(need)))
