"""Restitution against impact speed: per-bounce points from data, one curve per contact law."""

from __future__ import annotations

from collections.abc import Mapping

import numpy as np

from jaxunilat._internal import InputError


def _data_sets(data) -> list[tuple[str | None, object]]:
    """(label, result) pairs from one result, a sequence of them or a mapping label → result."""
    if data is None:
        return []
    if isinstance(data, Mapping):
        return [(str(label), result) for label, result in data.items()]
    if hasattr(data, "restitution"):
        return [("data", data)]
    sets = list(data)
    if len(sets) == 1:
        return [("data", sets[0])]
    return [(f"data {i + 1}", result) for i, result in enumerate(sets)]


def plot_restitution(data=None, laws=None, *, ax=None, title: str | None = None):
    """Restitution e against impact speed v: the data's bounces as points, each law as a curve.

    **Arguments:**

    - `data`: per-bounce restitution from `bounce_restitution` (anything with
      `impact_speed`, m/s, and `restitution` arrays): one result, a sequence of them
      (labelled "data 1", "data 2", …) or a mapping label → result. Each data set gets
      its own marker colour.
    - `laws`: a mapping name → (speeds [m/s], e), e.g. from `law_restitution` for each
      fitted contact law; drawn as lines.
    - `ax`: a matplotlib `Axes` to draw on; default: a new figure.
    - `title`: the axes' title.

    **Returns:** the `matplotlib.figure.Figure` (save it with `jaxunilat.plot.save_figure`).
    """
    sets = _data_sets(data)
    curves = dict(laws or {})
    for label, result in sets:
        if not (hasattr(result, "impact_speed") and hasattr(result, "restitution")):
            raise InputError(
                f"data {label!r} is a {type(result).__name__}; valid: results of bounce_restitution "
                "(with impact_speed and restitution)"
            )
    for name, curve in curves.items():
        if len(curve) != 2 or np.shape(curve[0]) != np.shape(curve[1]):
            raise InputError(f"laws[{name!r}] must be a pair (speeds [m/s], e) of arrays of one shape")
    from matplotlib.figure import Figure

    if ax is None:
        fig = Figure(figsize=(6.4, 4.4), layout="constrained")
        ax = fig.add_subplot()
    else:
        fig = ax.figure
    markers = "osD^v<>p"
    for i, (label, result) in enumerate(sets):
        ax.plot(
            np.asarray(result.impact_speed, dtype=float),
            np.asarray(result.restitution, dtype=float),
            linestyle="none",
            marker=markers[i % len(markers)],
            ms=5,
            color=f"C{i}",
            label=label,
        )
    for j, (name, (speeds, e)) in enumerate(curves.items()):
        speeds, e = np.asarray(speeds, dtype=float), np.asarray(e, dtype=float)
        order = np.argsort(speeds)
        ax.plot(speeds[order], e[order], lw=1.5, color=f"C{len(sets) + j}", label=str(name))
    ax.set_xlabel("impact speed v [m/s]")
    ax.set_ylabel("restitution e = v_out / v_in [-]")
    ax.grid(True, alpha=0.3)
    if sets or curves:
        ax.legend(loc="best")
    if title is not None:
        ax.set_title(title, fontsize=10)
    return fig
