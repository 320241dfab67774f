"""The data against the fit, with residuals."""

from __future__ import annotations

import os

import numpy as np


def plot_fit(result, *, title: str | None = None):
    """A figure of the data against the fitted model (top) and the residuals (bottom).

    - trace: x(t) data points and the fitted run, m against s;
    - impacts: observed onset times against the fitted ones, per impact;
    - apex: observed rebound heights against the fitted ones, per rebound.

    **Returns:** a `matplotlib.figure.Figure` (save it with `jaxunilat.save_figure`).
    """
    from matplotlib.figure import Figure

    data = result.data
    fig = Figure(figsize=(9.0, 6.0), layout="constrained")
    top, bottom = fig.subplots(2, 1, sharex=True, height_ratios=(3, 1))
    residuals = np.asarray(result.residuals)
    if data.observe == "trace":
        # The fit at the sample times (what the fit compared; no new compilation).
        t = np.asarray(data.t)
        top.plot(t, data.x, ".", ms=2, color="0.5", label="data")
        top.plot(t, np.asarray(data.x) + residuals, lw=1.0, color="C0", label="fit")
        top.set_ylabel("x [m]")
        bottom.plot(t, residuals * 1e3, ".", ms=2, color="C3")
        bottom.set_ylabel("fit - data [mm]")
        bottom.set_xlabel("t [s]")
    else:
        k = np.arange(1, len(residuals) + 1)
        observed = np.asarray(data.t if data.observe == "impacts" else data.h)
        label, unit, scale = (
            ("onset time t [s]", "ms", 1e3) if data.observe == "impacts" else ("apex height h [m]", "mm", 1e3)
        )
        top.plot(k, observed, "o", color="0.5", label="data")
        top.plot(k, observed + residuals, "x", color="C0", label="fit")
        top.set_ylabel(label)
        bottom.stem(k, residuals * scale)
        bottom.set_ylabel(f"fit - data [{unit}]")
        bottom.set_xlabel("impact" if data.observe == "impacts" else "rebound")
    top.legend(loc="upper right")
    kappa, k_r = result.parameters["kappa"], result.parameters["k_r"]
    e = result.derived["restitution"]
    name = os.path.basename(data.path) if data.path else "data"
    default = (
        f"{name}: kappa = {kappa['value']:.4g} N/m, k_r = {k_r['value']:.4g} N*s/m, e = {e['value']:.4f}"
    )
    top.set_title(title or default, fontsize=10)
    for ax in (top, bottom):
        ax.grid(True, alpha=0.3)
    return fig
