"""Observations of an event-mode run: contact table, impact times, apexes.

`impact_times` and `apexes` are pure JAX (jit, vmap and grad): they are what the
identification differentiates. `contact_table` is for people: it returns NumPy
columns, one row per contact.
"""

from __future__ import annotations

import jax.numpy as jnp
import numpy as np
from jaxtyping import Array

from .._internal._errors import InputError
from .._models._model import AbstractSwitchedModel
from ._event import ENTRY, EXIT, EXTREMUM, EventRecord

CONTACT_COLUMNS = (
    "wall",
    "t_in",
    "t_out",
    "v_in",
    "v_out",
    "restitution",
    "peak_force",
    "max_penetration",
)


def _events(sol_or_events) -> EventRecord:
    events = getattr(sol_or_events, "events", sol_or_events)
    if not isinstance(events, EventRecord):
        raise InputError("this needs a run of solver='event' (its Solution carries the events)")
    return events


def _meaningful(sol_or_events) -> Array | bool:
    """False when `sol_or_events` is a `Solution` whose inputs failed the checks
    (`Status.INVALID_INPUT`, e.g. a traced negative stiffness under `jax.jit` with
    `throw=False`): its events are then meaningless, and the observations are NaN."""
    status = getattr(sol_or_events, "status", None)
    if status is None:
        return True
    from ._simulate import Status

    return jnp.asarray(status) != Status.INVALID_INPUT


def _check_count(n) -> None:
    if isinstance(n, bool) or not isinstance(n, (int, np.integer)) or n < 0:
        raise InputError(f"n = {n!r} is out of range; valid range is integers >= 0 (a static count)")


def _select(events: EventRecord, keep: Array, n: int) -> tuple[Array, Array]:
    """Indices of the first `n` events where `keep`, and which of them exist."""
    _check_count(n)
    keep = keep & (jnp.arange(events.t.shape[-1]) < events.count)
    (idx,) = jnp.nonzero(keep, size=n, fill_value=0)
    valid = jnp.arange(n) < jnp.sum(keep)
    return idx, valid


def impact_times(sol_or_events, n: int, *, wall: int | None = None) -> Array:
    """The first `n` contact onset times, s; NaN where fewer happened.

    A contact open at t0 (the ball starts at a wall moving in) counts as an onset
    at t0. Event times carry implicit-function gradients, so this is
    differentiable with respect to the model's parameters and y0.

    **Arguments:**

    - `sol_or_events`: a `Solution` of `solver="event"` (or its `EventRecord`).
    - `n`: how many (static).
    - `wall`: only contacts with this wall index (lower first), or all.

    All NaN for a `Solution` with `Status.INVALID_INPUT` (inputs that failed the
    run-time checks under `jax.jit`/`jax.vmap` with `throw=False`): such a run's
    events mean nothing. Check `sol.status` for the reason.
    """
    ev = _events(sol_or_events)
    keep = ev.kind == ENTRY
    if wall is not None:
        keep = keep & (ev.wall == wall)
    idx, valid = _select(ev, keep, n)
    valid = valid & _meaningful(sol_or_events)
    return jnp.where(valid, ev.t[idx], jnp.nan)


def apexes(sol_or_events, n: int, *, coordinate: int = 0) -> tuple[Array, Array]:
    """The first `n` apexes of free flight (roots of the observable, v for the ball).

    **Returns:** `(times [s], heights)`, where heights are state component
    `coordinate` (x, m, for the ball) at the apex; NaN where fewer happened, and all
    NaN for a `Solution` with `Status.INVALID_INPUT` (as `impact_times`).
    """
    ev = _events(sol_or_events)
    idx, valid = _select(ev, (ev.kind == EXTREMUM) & (ev.wall == -1), n)
    valid = valid & _meaningful(sol_or_events)
    return jnp.where(valid, ev.t[idx], jnp.nan), jnp.where(valid, ev.y[idx, coordinate], jnp.nan)


def contact_table(sol, model=None, *, wall_names: tuple[str, ...] | None = None) -> dict[str, np.ndarray]:
    """One row per contact of an event-mode run, as NumPy columns.

    **Columns:** `wall` (name), `t_in`, `t_out` (s; NaN for a contact still open at
    t1), `v_in`, `v_out` (m/s, NaN if open), `restitution` = |v_out/v_in|,
    `peak_force` (N, the largest |contact force| on the step sub-grid) and
    `max_penetration` (m, at the located deepest point).

    **Arguments:**

    - `sol`: a `Solution` of `solver="event"` for one trajectory (not batched).
    - `model`: the model that was simulated; used for the wall names and the
      penetration depth. For the ball, pass the `Ball`.
    - `wall_names`: override the names (lower first).
    """
    ev = _events(sol)
    if np.ndim(ev.count) != 0:
        raise InputError("contact_table takes one trajectory; index a batched Solution first")
    count = int(ev.count)
    t = np.asarray(ev.t)[:count]
    y = np.asarray(ev.y)[:count]
    kind = np.asarray(ev.kind)[:count]
    wall = np.asarray(ev.wall)[:count]
    peak = np.asarray(ev.peak_force)[:count]
    if wall_names is None:
        named = isinstance(model, AbstractSwitchedModel)
        wall_names = (tuple(model.wall_names) if named else ()) or tuple(f"wall{i}" for i in range(8))
    rows = []
    current = None
    for i in range(count):
        if kind[i] == ENTRY:
            current = dict(wall=int(wall[i]), t_in=t[i], v_in=y[i, -1], depth=np.nan)
        elif kind[i] == EXTREMUM and current is not None and wall[i] == current["wall"]:
            if model is not None and np.isnan(current["depth"]):
                current["depth"] = float(np.asarray(model.switches(y[i]))[current["wall"]])
        elif kind[i] == EXIT and current is not None:
            rows.append((current, t[i], y[i, -1], peak[i]))
            current = None
    if current is not None:
        rows.append((current, np.nan, np.nan, float(np.asarray(ev.open_peak_force))))
    table = {name: [] for name in CONTACT_COLUMNS}
    for start, t_out, v_out, f_peak in rows:
        table["wall"].append(wall_names[start["wall"]])
        table["t_in"].append(start["t_in"])
        table["t_out"].append(t_out)
        table["v_in"].append(start["v_in"])
        table["v_out"].append(v_out)
        table["restitution"].append(abs(v_out / start["v_in"]) if start["v_in"] != 0 else np.nan)
        table["peak_force"].append(f_peak)
        table["max_penetration"].append(start["depth"])
    return {k: np.asarray(v, dtype=object if k == "wall" else float) for k, v in table.items()}


__all__ = ["CONTACT_COLUMNS", "apexes", "contact_table", "impact_times", "ENTRY", "EXIT", "EXTREMUM"]
