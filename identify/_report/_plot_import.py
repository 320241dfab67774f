"""Figures of an import: the WAV detection and the phyphox/video tables (matplotlib)."""

from __future__ import annotations

import os

import numpy as np

from .._data._import import ImportResult, fit_intervals
from .._data._import_audio import envelope, read_wav


def plot_intervals(ax, times: np.ndarray, *, smooth_label: str, outlier_label: str) -> None:
    """Onset intervals (ms) against their start (s), the smooth decay fitted to them, and
    the intervals that break it (squares) on a matplotlib `ax`."""
    ax.plot(times[:-1], np.diff(times) * 1e3, "o", ms=4, color="C0", label="intervals")
    fit = fit_intervals(times)
    if fit is not None:
        ax.plot(fit.start, fit.expected * 1e3, "-", color="C1", lw=1, label=smooth_label)
        out = ~fit.inlier
        if out.any():
            ax.plot(
                fit.start[out],
                fit.interval[out] * 1e3,
                "s",
                mfc="none",
                color="C3",
                ms=9,
                label=outlier_label,
            )
    ax.legend(loc="upper right", fontsize=8)
    ax.set_ylabel("interval [ms]")


def plot_detection(result: ImportResult, *, samples=None, title: str | None = None):
    """A figure of a WAV import: the envelope with accepted onsets (green) and rejected
    clicks (red crosses), and the interval sequence with its smooth fit.

    `samples`: the recording's mono samples (default: read again from `result.source`).
    **Returns:** a `matplotlib.figure.Figure`.
    """
    from matplotlib.figure import Figure

    det = result.detection
    if samples is None:
        samples = read_wav(result.source).samples
    env = envelope(samples, det.rate)
    fig = Figure(figsize=(10.0, 6.0), layout="constrained")
    top, bottom = fig.subplots(2, 1, height_ratios=(3, 2))
    bins = max(1, len(env) // 4000)
    m = len(env) // bins * bins
    peaks = env[:m].reshape(-1, bins).max(axis=1)
    t = (np.arange(len(peaks)) * bins + bins / 2) / det.rate
    top.plot(t, peaks, lw=0.6, color="0.4", label="envelope (high-passed magnitude)")
    top.axhline(det.settings["threshold"] * det.noise_floor, color="C1", lw=0.8, ls="--", label="threshold")
    ok = det.accepted
    top.plot(det.onset[ok], det.peak[ok], "v", color="C2", ms=6, label=f"accepted onsets ({ok.sum()})")
    for when in det.onset[ok]:
        top.axvline(when, color="C2", lw=0.5, alpha=0.5)
    if (~ok).any():
        top.plot(
            det.onset[~ok], det.peak[~ok], "x", color="C3", ms=9, mew=2, label=f"rejected ({(~ok).sum()})"
        )
    top.set_yscale("log")
    top.set_ylim(max(det.noise_floor * 0.5, 1e-6), None)
    top.set_xlabel("t [s] (recording clock)")
    top.set_ylabel("envelope [full scale]")
    top.legend(loc="upper right", fontsize=8)
    onsets = det.onsets
    if len(onsets) >= 2:
        plot_intervals(bottom, onsets, smooth_label="smooth fit", outlier_label="breaks the decay")
    bottom.set_xlabel("interval start [s]")
    top.set_title(title or f"{os.path.basename(result.source)}: {len(onsets)} onsets", fontsize=10)
    for ax in (top, bottom):
        ax.grid(True, alpha=0.3)
    return fig


def plot_table_import(result: ImportResult, *, title: str | None = None):
    """A figure of a phyphox import (intervals against onset time, with the smooth decay
    and the suspicious intervals) or a video import (x against t).

    **Returns:** a `matplotlib.figure.Figure`.
    """
    from matplotlib.figure import Figure

    ds = result.dataset
    fig = Figure(figsize=(9.0, 5.0), layout="constrained")
    ax = fig.subplots()
    if ds.observe == "trace":
        ax.plot(ds.t, ds.x * 1e3, ".", ms=3, color="C0")
        ax.set_xlabel("t [s] (0 = first tracked frame)")
        ax.set_ylabel("x [mm]")
    else:
        plot_intervals(
            ax, np.asarray(ds.t), smooth_label="smooth decay", outlier_label="breaks the decay (kept)"
        )
        ax.set_xlabel("interval start [s] (recording clock)")
    ax.grid(True, alpha=0.3)
    ax.set_title(title or f"{os.path.basename(result.source)}: {ds.num_rows} rows", fontsize=10)
    return fig
