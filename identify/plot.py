"""Figures of identify (matplotlib; each returns a `matplotlib.figure.Figure`).

- `plot_fit(result)`: a fit's data, prediction and residuals.
- `plot_restitution_of_fit(result)`: per-bounce e against impact speed with the law's curve.
- `plot_restitution(data, laws)`: per-bounce restitution and contact-law curves.
- `plot_detection(result)`: a WAV import's envelope, onsets and intervals.
- `plot_table_import(result)`: a phyphox or video import.

A fit's figures draw what the fit layer computes for them (the per-bounce e of the kept
onsets and the laws' e(v): `identify._fit._curves`); the drawing is `identify._report`'s.
"""

from ._fit._curves import restitution_curves
from ._report import _plot
from ._report._plot_import import plot_detection, plot_table_import
from ._report._plot_restitution import plot_restitution

__all__ = ["plot_detection", "plot_fit", "plot_restitution", "plot_restitution_of_fit", "plot_table_import"]


def plot_fit(result, *, title: str | None = None):
    """A figure of the data against the fitted model and the residuals.

    - impact onsets: restitution against impact speed (left: each bounce from the data's
      drag-corrected flight times, each fitted law as a black curve) and the onset
      residuals of every file (right, ms, against the onset time in s);
    - trace: x(t) data and the fitted run of the first file (top, m), the residuals of
      every file (bottom, mm);
    - apex: observed rebound heights against the fitted ones (top, m), residuals (bottom, mm).

    Fitted rows are dots, held-out rows open circles, outliers red crosses (a red
    triangle at the axis' edge when beyond the kept rows' range, which sets the axis).
    Each file has its own colour; the key sits right of the axes (a legend of file
    names up to `MANY_FILES` files, a colour bar of the release height x0 in mm beyond)
    and the markers' legend below them, never over the data. The figure grows a little
    with the number of files named in the legend.

    **Returns:** a `matplotlib.figure.Figure` (save it with `jaxunilat.save_figure`).
    """
    view = restitution_curves(result) if result.data.observe == "impacts" else None
    return _plot.plot_fit(result, view, title=title)


def plot_restitution_of_fit(result, *, ax=None):
    """Per-bounce restitution against impact speed: the data (drag-corrected flights of
    the kept onsets, each file in its colour) and each fitted law's curve (black).

    On a new figure (`ax` None) the files' key and the legend sit outside the axes as in
    `plot_fit`; on a given `ax`, one legend (the laws, and the files up to `MANY_FILES`)
    goes just right of it. **Returns:** the figure.
    """
    return _plot.plot_restitution_of_fit(result, restitution_curves(result), ax=ax)
