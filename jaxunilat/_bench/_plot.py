"""The benchmark's figures: work-precision and throughput (from a `bench.json` dictionary;
the figures read no goal, so old files draw alike)."""

from __future__ import annotations

import math

from ._goals import GOALS, LOOSE_ERROR, TIGHT_ERROR


def _series(rows):
    """Rows grouped by method, in the order of their settings: {method: (errors, walls, peer)}."""
    groups: dict[str, list] = {}
    for row in rows:
        if row["error"] is None or row["wall_s"] is None or not math.isfinite(row["error"]):
            continue
        groups.setdefault(row["method"], []).append(row)
    out = {}
    for method, group in groups.items():
        out[method] = ([r["error"] for r in group], [r["wall_s"] for r in group], group[0]["peer"])
    return out


def work_precision_figure(result: dict):
    """Error (m, log x) against wall time (s, log y), one line per method; peers dashed
    (scipy, NumPy, and the compiled loop when Numba ran).

    **Returns:** a matplotlib `Figure`.
    """
    import matplotlib
    from matplotlib.figure import Figure

    fig = Figure(figsize=(9, 6), constrained_layout=True)
    ax = fig.add_subplot()
    colors = iter(matplotlib.colormaps["tab20"].colors)
    compiled = result.get("compiled_loop", {}).get("rows", [])
    for method, (errors, walls, peer) in _series(result["work_precision"] + compiled).items():
        style = dict(ls="--", marker="o") if peer else dict(ls="-", marker="s", lw=2)
        ax.plot(errors, walls, ms=4, color=next(colors), label=method, **style)
    for key, bound in (("time_ratio_1e9", TIGHT_ERROR), ("time_ratio_1e6", LOOSE_ERROR)):
        ax.axvline(bound, color="0.7", lw=0.8, zorder=0)
        ax.text(bound, 1.0, f" {key}", transform=ax.get_xaxis_transform(), va="top", color="0.4")
    ax.set(
        xscale="log",
        yscale="log",
        xlabel="error: max |x - x_ref| at 2001 points [m]",
        ylabel="wall time per solve (median) [s]",
        title="Work-precision, Table 1 example 2 over [0, 2] s (peers dashed; lines follow the settings)",
    )
    ax.grid(True, which="both", alpha=0.3)
    ax.legend(fontsize=7, ncol=2)
    return fig


def throughput_figure(result: dict):
    """Trajectories per second against batch size N (log-log): sweep, scipy loop,
    compiled loop (serial and prange), scale-out.

    **Returns:** a matplotlib `Figure`.
    """
    from matplotlib.figure import Figure

    fig = Figure(figsize=(8, 5.5), constrained_layout=True)
    ax = fig.add_subplot()
    mine = sorted((r for r in result["throughput"] if not r["peer"]), key=lambda r: r["n"])
    for method in dict.fromkeys(r["method"] for r in mine):  # one line per sweep strategy
        rows = [r for r in mine if r["method"] == method]
        devices = rows[-1].get("devices")
        label = method if devices is None else f"{method}, {devices} device(s)"
        ax.plot([r["n"] for r in rows], [r["traj_per_s"] for r in rows], "-s", label=label)
    for r in (r for r in result["throughput"] if r["peer"]):
        ax.axhline(r["traj_per_s"], ls="--", color="C1", label=f"{r['method']} ({r['n']} pairs)")
    for r in result.get("compiled_loop", {}).get("throughput", []):
        ax.plot([r["n"]], [r["traj_per_s"]], "D", ms=7, label=r["method"])
    for r in result.get("scale_out", {}).get("rows", []):
        ax.plot(
            [r["n"]], [r["traj_per_s"]], "^", ms=8, label=f"sweep on {r['devices']} device(s), N = {r['n']}"
        )
    target = GOALS["throughput"]["target"]
    ax.axhline(target, color="0.6", lw=0.8, ls=":", label=f"throughput goal, {target:g} traj/s")
    ax.set(
        xscale="log",
        yscale="log",
        xlabel="batch size N ((kappa, k_r) pairs)",
        ylabel="trajectories per second",
        title="Throughput, example 2 over [0, 2] s, error <= 1e-8 m",
    )
    ax.grid(True, which="both", alpha=0.3)
    ax.legend(fontsize=7)
    return fig
