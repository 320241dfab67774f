"""Long recordings of one drop as impact onsets: 50-100 bounces, the way a phone hears them.

Made with the independent scipy reference (`bounce_reference.scipy_bounces`: flights with
quadratic drag integrated by DOP853, each bounce's (e, t_c) from a callable), then the
recorder's faults: an unknown clock offset, timing jitter, a release height estimated by
the importer (`estimated = x0`, a few per cent off). Two balls:

- `pingpong`: a 40 mm, 2.7 g ball on a floor, 52 onsets from 0.2 m. e = 0.945 above an
  impact speed of 0.15 m/s falls smoothly to 0.89 below 0.07 m/s (a real ping-pong ball's
  e falls at LOW speed), t_c = 1 ms, drag 0.12 s/m, 0.3% bounce-to-bounce scatter of e,
  timing jitter growing from 0.3 ms (loud first clicks) to 0.5 ms (quiet last ones).
- `steel`: a 20 mm steel ball (32.9 g, drag 0.017 s/m), 81 onsets from 0.3 m, e = 0.987,
  t_c = 0.1 ms, 0.1% scatter, 0.1 ms jitter.

Nothing here imports `jaxunilat` or `identify` but `identify.Dataset`, to hold the result.
"""

from __future__ import annotations

import functools

import numpy as np
from bounce_reference import scipy_bounces

#: Ping-pong: e above `PINGPONG_KNEE` m/s, falling smoothly over `PINGPONG_WIDTH` below it.
PINGPONG_E, PINGPONG_LOW_E, PINGPONG_KNEE, PINGPONG_WIDTH = 0.945, 0.89, 0.15, 0.08
STEEL_E = 0.987


def pingpong_e(speed):
    """The ping-pong ball's mean e at an impact speed (m/s): 0.945 above 0.15 m/s, a smooth
    step (3x² − 2x³) down to 0.89 at 0.07 m/s and below."""
    x = np.clip((PINGPONG_KNEE - np.asarray(speed, dtype=float)) / PINGPONG_WIDTH, 0.0, 1.0)
    return PINGPONG_E - (PINGPONG_E - PINGPONG_LOW_E) * (3 * x * x - 2 * x**3)


@functools.cache
def _onsets(ball: str, seed: int, scatter: float | None = None) -> tuple[tuple, tuple, tuple]:
    """(true onsets since the release [s], impact speeds [m/s], per-bounce e), cached."""
    spec = BALLS[ball]
    rng = np.random.default_rng(seed)
    scatter = 1.0 + (spec["scatter"] if scatter is None else scatter) * rng.standard_normal(spec["n"])
    used = []

    def bounce(i, w):
        e = float(spec["e"](w) * scatter[i])
        used.append(e)
        return e, spec["contact_time"]

    t, w = scipy_bounces(spec["h0"], bounce, spec["drag"], spec["n"])
    return tuple(t), tuple(w), tuple(used)


BALLS = {
    "pingpong": dict(
        n=52, h0=0.2, drag=0.12, mass=2.7e-3, contact_time=1e-3, scatter=0.003,
        e=pingpong_e, jitter=(3e-4, 5e-4), noise=4e-4,
    ),
    "steel": dict(
        n=81, h0=0.3, drag=0.017, mass=7850.0 * np.pi / 6 * 0.02**3, contact_time=1e-4, scatter=0.001,
        e=lambda w: STEEL_E, jitter=(1e-4, 1e-4), noise=1e-4,
    ),
}  # fmt: skip


def truth(ball: str, seed: int = 0, scatter: float | None = None) -> dict:
    """The true onsets (since the release), impact speeds and per-bounce e of a recording
    (`scatter`: the relative bounce-to-bounce scatter of e, default the ball's)."""
    t, w, e = _onsets(ball, seed, scatter)
    return {"t": np.asarray(t), "impact_speed": np.asarray(w), "e": np.asarray(e)}


def recording(
    ball: str, seed: int = 0, *, offset: float = 0.8123, x0_error: float = 0.04, scatter=None, path=None
):
    """An `identify.Dataset` of impact onsets as a phone's importer writes it: on the
    recording's clock (`offset` s after its start is the release), jittered, the release
    height estimated `x0_error` (relative) high and marked `estimated`, the noise stated."""
    from jaxunilat import identify

    spec = BALLS[ball]
    t = truth(ball, seed, scatter)["t"]
    rng = np.random.default_rng(10_000 + seed)
    sd = np.linspace(*spec["jitter"], len(t))
    recorded = t + offset + sd * rng.standard_normal(len(t))
    return identify.Dataset(
        scene="drop", observe="impacts", mass=float(spec["mass"]), drag=float(spec["drag"]),
        x0=round(spec["h0"] * (1.0 + x0_error), 4), v0=0.0, noise=float(spec["noise"]),
        t=np.round(recorded, 7), estimated=("x0",), path=path,
        source=f"synthetic long recording ({ball}, seed {seed}): tests/long_sequences.py",
    )  # fmt: skip
