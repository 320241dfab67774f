"""Plots in the style of [K90] Figs 4–8: displacement, velocity and the phase diagram.

Figures are built with `matplotlib.figure.Figure` and saved with the Agg canvas, so
nothing here needs a display or changes pyplot's global backend; the returned
figures also render inline in notebooks.
"""

from __future__ import annotations

import os
from collections.abc import Sequence
from typing import TYPE_CHECKING

import numpy as np

from .._internal._io import write_atomically

if TYPE_CHECKING:  # matplotlib is imported when a plot is made, not with the package
    from matplotlib.axes import Axes
    from matplotlib.figure import Figure

_WALL_STYLE = dict(color="0.35", linestyle="--", linewidth=0.9)


def plot_ball(
    ts,
    x,
    v,
    *,
    walls: tuple[float | None, float | None] | None = None,
    title: str | None = None,
    axes: Sequence[Axes] | None = None,
    label: str | None = None,
) -> Figure:
    """Plot a ball trajectory: x(t), v(t) and the phase diagram v(x).

    **Arguments:**

    - `ts`: times, s.
    - `x`: displacement, m (upward positive).
    - `v`: velocity, m/s.
    - `walls`: the rackets' positions (lower, upper), m, drawn as dashed lines;
      either may be `None`.
    - `title`: the figure title, e.g. the run's name and parameters.
    - `axes`: three existing axes (x(t), v(t), v(x)) to draw into, e.g. to overlay
      runs; by default a new figure with that layout is made.
    - `label`: a legend label for this trajectory.

    **Returns:** the figure.
    """
    from matplotlib.figure import Figure

    ts, x, v = (np.asarray(a, dtype=float) for a in (ts, x, v))
    if axes is None:
        fig = Figure(figsize=(11.0, 6.0), layout="constrained")
        grid = fig.add_gridspec(2, 2, width_ratios=(1.6, 1.0))
        ax_x = fig.add_subplot(grid[0, 0])
        ax_v = fig.add_subplot(grid[1, 0], sharex=ax_x)
        ax_p = fig.add_subplot(grid[:, 1])
    else:
        ax_x, ax_v, ax_p = axes
        fig = ax_x.get_figure()

    ax_x.plot(ts, x, linewidth=1.0, label=label)
    ax_x.set_ylabel("displacement x [m]")
    ax_x.tick_params(labelbottom=False)
    ax_v.plot(ts, v, linewidth=1.0, label=label)
    ax_v.set_xlabel("time t [s]")
    ax_v.set_ylabel("velocity v [m/s]")
    ax_p.plot(x, v, linewidth=0.8, label=label)
    ax_p.plot(x[:1], v[:1], "o", markersize=4, color="C3", label="start" if axes is None else None)
    ax_p.set_xlabel("displacement x [m]")
    ax_p.set_ylabel("velocity v [m/s]")
    ax_p.set_title("phase diagram")

    drawn = [w for w in (walls or ()) if w is not None]
    for i, wall in enumerate(drawn):
        ax_x.axhline(wall, **_WALL_STYLE)
        ax_p.axvline(wall, **_WALL_STYLE, label="racket" if i == 0 and axes is None else None)
    for ax in (ax_x, ax_v, ax_p):
        ax.grid(True, linewidth=0.4, alpha=0.5)
    ax_v.axhline(0.0, color="0.6", linewidth=0.6)
    ax_p.axhline(0.0, color="0.6", linewidth=0.6)
    if label is not None or axes is None:
        ax_p.legend(loc="best", fontsize="small")
    if title:
        fig.suptitle(title)
    return fig


def save_figure(fig: Figure, path: str | os.PathLike, *, dpi: int = 120) -> None:
    """Save a figure with the Agg canvas (no display needed); the format follows the
    suffix. The file is written whole or not at all (`internal.write_atomically`)."""
    from matplotlib.backends.backend_agg import FigureCanvasAgg

    if not isinstance(fig.canvas, FigureCanvasAgg):
        FigureCanvasAgg(fig)
    suffix = os.path.splitext(os.fspath(path))[1].lstrip(".").lower()
    with write_atomically(path, "wb") as f:  # never a truncated image
        fig.savefig(f, format=suffix or None, dpi=dpi)
