"""Per-impact table and force statistics of a coupling run."""

from __future__ import annotations

import numpy as np

from .._internal._errors import InputError
from ._event import ENTRY, EXIT

IMPACT_COLUMNS = ("wall", "t_in", "t_out", "rate_in", "rate_out", "restitution", "peak_force")


def impact_table(sol, model) -> dict[str, np.ndarray]:
    """One row per joint impact of an event-mode coupling run, as NumPy columns.

    **Arguments:**

    - `sol`: a `Solution` of `simulate(coupling, ..., solver="event", outputs=(..., "T_xi", "T_eta"))`
      for one trajectory.
    - `model`: the `Coupling` that was simulated.

    **Returns:** columns `wall` (`xi-`, `xi+`, `eta-`, `eta+`: the coordinate ψ_ξ or ψ_η
    and the side of its clearance), `t_in`, `t_out` (s; NaN for a contact open at t1),
    `rate_in`, `rate_out` (the coordinate's rate, rad/s), `restitution` =
    |rate_out/rate_in| and `peak_force` (N): the largest elastic force κ·D of that
    contact on the saved samples (T_η for ψ_ξ walls, T_ξ for ψ_η walls), as in
    [K90 Figs 9–10].
    """
    ev = sol.events
    if ev is None:
        raise InputError("impact_table needs a run of solver='event'")
    count = int(ev.count)
    t = np.asarray(ev.t)[:count]
    y = np.asarray(ev.y)[:count]
    kind = np.asarray(ev.kind)[:count]
    wall = np.asarray(ev.wall)[:count]
    ts = np.asarray(sol.ts)
    force = {0: np.asarray(sol.ys["T_eta"]), 2: np.asarray(sol.ys["T_xi"])}
    names = model.wall_names
    rows = {name: [] for name in IMPACT_COLUMNS}
    open_ = {}
    for i in range(count):
        w = int(wall[i])
        coord = 0 if w < 2 else 2
        if kind[i] == ENTRY:
            open_[w] = (t[i], y[i, coord + 1])
        elif kind[i] == EXIT and w in open_:
            t_in, r_in = open_.pop(w)
            _append(rows, names[w], t_in, t[i], r_in, y[i, coord + 1], ts, force[coord])
    for w, (t_in, r_in) in open_.items():
        coord = 0 if w < 2 else 2
        _append(rows, names[w], t_in, np.nan, r_in, np.nan, ts, force[coord])
    order = np.argsort(np.asarray(rows["t_in"], dtype=float), kind="stable")
    return {
        k: np.asarray(v, dtype=object if k == "wall" else float)[order]
        if len(v)
        else np.asarray(v, dtype=float)
        for k, v in rows.items()
    }


def _append(rows, name, t_in, t_out, r_in, r_out, ts, force):
    end = ts[-1] if np.isnan(t_out) else t_out
    inside = (ts >= t_in) & (ts <= end)
    rows["wall"].append(name)
    rows["t_in"].append(t_in)
    rows["t_out"].append(t_out)
    rows["rate_in"].append(r_in)
    rows["rate_out"].append(r_out)
    rows["restitution"].append(abs(r_out / r_in) if r_in != 0 and not np.isnan(r_out) else np.nan)
    rows["peak_force"].append(float(np.max(np.abs(force[inside]))) if np.any(inside) else 0.0)
