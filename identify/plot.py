"""Figures of identify (matplotlib; each returns a `matplotlib.figure.Figure`).

- `plot_fit(result)`: a fit's data, prediction and residuals.
- `plot_restitution_of_fit(result)`: per-bounce e against impact speed with the law's curve.
- `plot_restitution(data, laws)`: per-bounce restitution and contact-law curves.
- `plot_detection(result)`: a WAV import's envelope, onsets and intervals.
- `plot_table_import(result)`: a phyphox or video import.
"""

from ._report._plot import plot_fit, plot_restitution_of_fit
from ._report._plot_import import plot_detection, plot_table_import
from ._report._plot_restitution import plot_restitution

__all__ = ["plot_detection", "plot_fit", "plot_restitution", "plot_restitution_of_fit", "plot_table_import"]
