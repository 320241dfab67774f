"""Plots of the rolling-mill coupling in the style of [K90] Figs 9–14."""

from __future__ import annotations

from typing import TYPE_CHECKING

import numpy as np

if TYPE_CHECKING:
    from matplotlib.figure import Figure

_WALL_STYLE = dict(color="0.35", linestyle="--", linewidth=0.9)


def plot_coupling(ts, ys: dict, *, delta: float | None = None, title: str | None = None) -> Figure:
    """Figs 11–14 of [K90] for one run.

    **Arguments:**

    - `ts`: times, s.
    - `ys`: outputs of the run: `psi_xi`, `dpsi_xi`, `psi_eta`, `dpsi_eta` (rad, rad/s)
      and `X`, `Y` (m, the joint's path on fixed axes).
    - `delta`: the angular clearance δ, rad, drawn (axes in mrad) as dashed lines.
    - `title`: the figure title.

    **Returns:** a figure with four panels: ψ_ξ(t) and ψ_η(t) (Fig. 11), the phase
    diagrams ψ̇_ξ(ψ_ξ) (Fig. 12) and ψ̇_η(ψ_η) (Fig. 13), and Y(X) (Fig. 14).
    """
    from matplotlib.figure import Figure

    ts = np.asarray(ts, dtype=float)
    g = {k: np.asarray(v, dtype=float) for k, v in ys.items()}
    fig = Figure(figsize=(11.0, 8.5), layout="constrained")
    axes = fig.subplots(2, 2)
    ax = axes[0, 0]
    ax.plot(ts, 1e3 * g["psi_xi"], "-", linewidth=0.9, label=r"$\psi_\xi$")
    ax.plot(ts, 1e3 * g["psi_eta"], "--", linewidth=0.9, label=r"$\psi_\eta$")
    ax.set_xlabel("time t [s]")
    ax.set_ylabel("rotation [mrad]")
    ax.set_title("Fig. 11: displacements")
    for i, (name, rate, axp, fig_no) in enumerate(
        (("psi_xi", "dpsi_xi", axes[0, 1], 12), ("psi_eta", "dpsi_eta", axes[1, 0], 13))
    ):
        sym = r"\xi" if i == 0 else r"\eta"
        axp.plot(1e3 * g[name], 1e3 * g[rate], linewidth=0.6)
        axp.set_xlabel(rf"$\psi_{sym}$ [mrad]")
        axp.set_ylabel(rf"$\dot\psi_{sym}$ [mrad/s]")
        axp.set_title(f"Fig. {fig_no}: phase diagram, plane ${sym} = 0$")
        if delta is not None:
            for s in (-1, 1):
                axp.axvline(1e3 * s * delta, **_WALL_STYLE)
    if delta is not None:
        for s in (-1, 1):
            ax.axhline(1e3 * s * delta, **_WALL_STYLE, label="clearance $\\pm\\delta$" if s == 1 else None)
    ax.legend(loc="best", fontsize="small")
    ax = axes[1, 1]
    ax.plot(1e3 * g["X"], 1e3 * g["Y"], linewidth=0.6)
    ax.set_xlabel("X [mm]")
    ax.set_ylabel("Y [mm]")
    ax.set_aspect("equal", adjustable="datalim")
    ax.set_title("Fig. 14: joint path on fixed axes")
    for a in axes.ravel():
        a.grid(True, linewidth=0.4, alpha=0.5)
    if title:
        fig.suptitle(title)
    return fig


def plot_impact_forces(runs, *, title: str | None = None) -> Figure:
    """Figs 9–10 of [K90]: the elastic joint forces T_ξ(t) and T_η(t).

    **Arguments:**

    - `runs`: a sequence of `(label, ts [s], T_xi [N], T_eta [N])`.
    - `title`: the figure title.

    **Returns:** a figure with two panels (T_ξ above, T_η below), forces in kN.
    """
    from matplotlib.figure import Figure

    fig = Figure(figsize=(10.0, 7.0), layout="constrained")
    ax_x, ax_e = fig.subplots(2, 1, sharex=True)
    for label, ts, t_xi, t_eta in runs:
        ax_x.plot(np.asarray(ts), 1e-3 * np.asarray(t_xi), linewidth=0.7, label=label)
        ax_e.plot(np.asarray(ts), 1e-3 * np.asarray(t_eta), linewidth=0.7, label=label)
    ax_x.set_ylabel(r"$T_\xi = \kappa D(\psi_\eta)$ [kN]")
    ax_e.set_ylabel(r"$T_\eta = \kappa D(\psi_\xi)$ [kN]")
    ax_e.set_xlabel("time t [s]")
    ax_x.set_title("Fig. 9: impact force component T_xi")
    ax_e.set_title("Fig. 10: impact force component T_eta")
    for a in (ax_x, ax_e):
        a.grid(True, linewidth=0.4, alpha=0.5)
        a.legend(loc="best", fontsize="small")
    if title:
        fig.suptitle(title)
    return fig


def line_figure(curves, *, xlabel: str, ylabel: str, title: str, walls=(), figsize=(9.0, 4.8)) -> Figure:
    """One panel of labelled curves, as the paper's single-panel figures.

    **Arguments:**

    - `curves`: a sequence of `(label, x, y)` or `(label, x, y, style)`.
    - `xlabel`, `ylabel`: axis labels with units.
    - `title`: the panel title.
    - `walls`: y values drawn as dashed horizontal lines (e.g. the rackets).

    **Returns:** the figure.
    """
    from matplotlib.figure import Figure

    fig = Figure(figsize=figsize, layout="constrained")
    ax = fig.add_subplot()
    for curve in curves:
        label, x, y = curve[:3]
        style = curve[3] if len(curve) > 3 else "-"
        ax.plot(np.asarray(x), np.asarray(y), style, linewidth=0.8, label=label)
    for w in walls:
        ax.axhline(w, **_WALL_STYLE)
    ax.set_xlabel(xlabel)
    ax.set_ylabel(ylabel)
    ax.set_title(title)
    ax.grid(True, linewidth=0.4, alpha=0.5)
    if any(c[0] for c in curves):
        ax.legend(loc="best", fontsize="small")
    return fig
