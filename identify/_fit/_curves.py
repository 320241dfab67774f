"""What a fit's restitution figure draws, computed in the fit layer: each impact file's
per-bounce e from its kept onsets, and each fitted law's e against the impact speed.

The figures (`identify.plot`) take a `RestitutionCurves` and only draw it.
"""

from __future__ import annotations

import dataclasses
import math
import os
from collections.abc import Mapping

import numpy as np

from ._outcome import FitOutcome
from ._restitution import BounceRestitution, bounce_restitution, law_restitution


@dataclasses.dataclass(frozen=True)
class RestitutionCurves:
    """A fit's restitution against impact speed, ready to draw.

    - `points`: `(file, label, BounceRestitution)` per segment of ≥ 3 kept onsets of an
      impact file (drag-corrected per-bounce e and impact speeds, m/s; a missed bounce
      splits a file, whose segments are labelled "name (k)").
    - `curves`: `{label: (speeds m/s, e)}`: the fitted law ("<law> (fit)") and, after
      `law="auto"`, the other law, over the bounces' speed range.
    """

    points: tuple[tuple[int, str, BounceRestitution], ...]
    curves: Mapping[str, tuple[np.ndarray, np.ndarray]]


def restitution_curves(result: FitOutcome) -> RestitutionCurves:
    """The per-bounce e of `result`'s impact files and its laws' e(v) (`RestitutionCurves`)."""
    points = tuple(bounce_points(result))
    return RestitutionCurves(points=points, curves=law_curves(result, _speed_grid(points)))


def bounce_points(result: FitOutcome) -> list[tuple[int, str, BounceRestitution]]:
    """Each impact file's per-bounce restitution from its kept onsets (drag-corrected).

    Uses the fitted drag and contact time; a missed bounce splits the sequence (an
    interval spanning two flights says nothing about either), and the first segment
    of a drop from rest also gets its first bounce from the fitted release height.
    **Returns:** `(file, label, BounceRestitution)`, one per segment of ≥ 3 onsets.
    """
    drag = result.params["drag"].value if result.data.drag > 0 or "drag" in result.free else 0.0
    t_c = result.derived["contact_time"].value
    t_c = t_c if math.isfinite(t_c) else 0.0
    out = []
    for f, entry in enumerate(result.datasets):
        d = result.datasets_data[f]
        if d.observe != "impacts":
            continue
        keep = np.ones(d.num_rows, bool)
        keep[[o.row for o in entry.outliers]] = False
        cuts = [m.before_row for m in entry.missed]
        kept = np.flatnonzero(keep)
        segments = np.split(kept, [int(np.searchsorted(kept, c)) for c in cuts])
        label = os.path.basename(d.path) if d.path else f"data {f + 1}"
        x0 = entry.params["x0"].value if "x0" in entry.params else d.x0
        offset = entry.params["offset"].value if "offset" in entry.params else None
        for k, seg in enumerate(segments):
            if seg.size < 3:
                continue
            from_rest = k == 0 and d.v0 == 0 and offset is not None and seg[0] == 0
            try:
                points = bounce_restitution(
                    np.asarray(d.t)[seg],
                    drag=drag,
                    gravity=d.gravity,
                    contact_time=min(t_c, 0.5 * float(np.min(np.diff(np.asarray(d.t)[seg])))),
                    drop_height=x0 if from_rest and x0 > 0 else None,
                )
            except ValueError:
                continue
            out.append((f, label if len(segments) == 1 else f"{label} ({k + 1})", points))
    return out


def law_curves(result: FitOutcome, speeds) -> dict[str, tuple[np.ndarray, np.ndarray]]:
    """e(v) of the fitted law (and, after `law="auto"`, of the other law) at `speeds` (m/s)."""
    d = result.data
    laws = (
        result.laws
        if result.laws
        else {result.law: {"parameters": {"kappa": result.kappa, "k_r": result.k_r}}}
    )
    curves = {}
    for name, entry in laws.items():
        p = entry["parameters"]
        e = law_restitution(name, p["kappa"], p["k_r"], d.mass, speeds, gravity=d.gravity)
        curves[f"{name} (fit)" if name == result.law else name] = (np.asarray(speeds), np.asarray(e))
    return curves


def _speed_grid(points) -> np.ndarray:
    """24 impact speeds (m/s) over the bounces' range, a little beyond it."""
    speeds = np.concatenate([np.asarray(p.impact_speed) for *_, p in points]) if points else np.array([1.0])
    speeds = speeds[np.isfinite(speeds)]
    lo, hi = (float(np.min(speeds)), float(np.max(speeds))) if speeds.size else (0.3, 3.0)
    return np.linspace(max(0.8 * lo, 0.05), 1.1 * hi, 24)
