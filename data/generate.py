"""Generate the bundled SYNTHETIC data sets of data/ (see data/README.md).

    python data/generate.py            # (re)write the four files
    python data/generate.py --check    # regenerate in memory and compare; write nothing

Every file is simulated with jaxunilat's event mode (`solver="event"`, rtol = atol =
1e-12: every contact entry and exit located) from the true parameters below, then
Gaussian noise from NumPy's `default_rng` with a fixed seed is added and the values are
rounded to the stated print precision. No measured or third-party data is involved.
"""

from __future__ import annotations

import argparse
import os
import sys

import numpy as np

HERE = os.path.dirname(os.path.abspath(__file__))
sys.path.insert(0, os.path.dirname(HERE))  # the repository root: `identify` and `jaxunilat`

import jax  # noqa: E402

import jaxunilat  # noqa: E402
from identify._data import Dataset, format_dataset, load_dataset, write_dataset  # noqa: E402

#: The seed; each file draws from its own child stream `SeedSequence(SEED).spawn(4)[i]`.
SEED = 20261122
TOL = 1e-12
GRAVITY = 9.81

#: The drop test: an ITTF-like ball (40 mm, 2.7 g) released from rest with its lowest
#: point 305 mm above a rigid surface at x = 0. The truth is given as (e, t_c); κ and k_r
#: follow from `jaxunilat.parameters_from_restitution` (Kelvin–Voigt, SPEC §5). e = 0.935
#: (with drag 0.12 s/m) gives a first rebound of about 247 mm: ITTF-compliant (240–260 mm).
DROP = dict(mass=2.7e-3, drag=0.12, x0=0.305, v0=0.0, restitution=0.935, contact_time=1.0e-3)
#: The drop trace: 1 kHz over [0, 2.5] s, noise 0.5 mm; positions printed to 1 µm.
DROP_TRACE = dict(rate=1000.0, duration=2.5, noise=0.5e-3, decimals=6)
#: The drop's impact onsets over [0, 4] s (an acoustic recording), noise 20 µs, clock
#: offset: recorded time = time since release + 0.0731 s; printed to 0.1 µs.
DROP_IMPACTS = dict(duration=4.0, noise=20e-6, offset=0.0731, decimals=7)
#: The drop's rebound apex heights over [0, 4] s, noise 1 mm, printed to 1 µm; apex
#: times rounded to 1 ms (no noise added to them).
DROP_APEX = dict(duration=4.0, noise=1.0e-3, decimals=6, time_decimals=3)
#: Two rackets 0.8 m apart (walls at ±0.4 m), the paper's ball mass and drag, and a
#: lining that is not one of the paper's: e = 0.92, t_c = 1.2 ms. 1 kHz over [0, 1.5] s.
RACKETS = dict(mass=2.37e-3, drag=0.122, gap=0.8, x0=-0.4, v0=-8.0, restitution=0.92, contact_time=1.2e-3)
RACKETS_TRACE = dict(rate=1000.0, duration=1.5, noise=0.5e-3, decimals=6)

FILES = ("drop_trace.csv", "drop_impacts.csv", "drop_apex.csv", "rackets_trace.csv")
SOURCE = (
    "SYNTHETIC: data/generate.py, jaxunilat event mode (rtol=atol=1e-12), seed {seed}; see data/README.md"
)


def true_parameters(spec: dict) -> tuple[float, float]:
    """(κ [N/m], k_r [N·s/m]) of a scene's stated (e, t_c) and mass."""
    kappa, k_r = jaxunilat.parameters_from_restitution(
        spec["restitution"], spec["contact_time"], spec["mass"]
    )
    return float(kappa), float(k_r)


def _ball(spec: dict) -> jaxunilat.Ball:
    kappa, k_r = true_parameters(spec)
    if "gap" in spec:
        lower, upper = -spec["gap"] / 2, spec["gap"] / 2
    else:
        lower, upper = 0.0, None
    return jaxunilat.Ball(
        kappa=kappa, k_r=k_r, mass=spec["mass"], gravity=GRAVITY, drag=spec["drag"], lower=lower, upper=upper
    )


def _grid(rate: float, duration: float) -> np.ndarray:
    n = round(duration * rate)
    return np.round(np.arange(n + 1) / rate, 9)


def _simulate(spec: dict, ts: np.ndarray):
    return jaxunilat.simulate(
        _ball(spec),
        [spec["x0"], spec["v0"]],
        float(ts[-1]),
        solver="event",
        rtol=TOL,
        atol=TOL,
        ts=ts,
        outputs=("x",),
    )


#: The most bounces one run may hold (a static size for the jitted event extraction).
MAX_BOUNCES = 64


@jax.jit
def _observe(events):
    return jaxunilat.impact_times(events, MAX_BOUNCES), jaxunilat.apexes(events, MAX_BOUNCES)


def _events(sol) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(impact onset times, rebound apex times, rebound apex heights) of a drop run."""
    if int(sol.events.count) >= 4 * MAX_BOUNCES:
        raise RuntimeError(f"more than {MAX_BOUNCES} bounces: raise MAX_BOUNCES")
    impacts, (t_apex, h_apex) = _observe(sol.events)
    impacts = np.asarray(impacts)[np.isfinite(impacts)]
    t_apex, h_apex = np.asarray(t_apex), np.asarray(h_apex)
    rebound = np.isfinite(t_apex) & (t_apex > impacts[0])  # not the release itself
    return impacts, t_apex[rebound], h_apex[rebound]


def generate() -> dict[str, Dataset]:
    """The four data sets, in memory."""
    rngs = [np.random.default_rng(s) for s in np.random.SeedSequence(SEED).spawn(4)]
    source = SOURCE.format(seed=SEED)
    common = dict(scene="drop", mass=DROP["mass"], drag=DROP["drag"], x0=DROP["x0"], v0=DROP["v0"])
    out = {}

    # One drop run covers the trace (first 2.5 s of samples), the impacts and the apexes.
    ts = _grid(DROP_TRACE["rate"], max(DROP_TRACE["duration"], DROP_IMPACTS["duration"]))
    sol = _simulate(DROP, ts)
    x = np.asarray(sol["x"])
    keep = ts <= DROP_TRACE["duration"] + 1e-12
    noisy = x[keep] + DROP_TRACE["noise"] * rngs[0].standard_normal(int(keep.sum()))
    out["drop_trace.csv"] = Dataset(
        observe="trace",
        **common,
        noise=DROP_TRACE["noise"],
        t=ts[keep],
        x=np.round(noisy, DROP_TRACE["decimals"]),
        source=source,
    )
    impacts, t_apex, h_apex = _events(sol)
    impacts = impacts[impacts <= DROP_IMPACTS["duration"]]
    recorded = (
        impacts + DROP_IMPACTS["offset"] + DROP_IMPACTS["noise"] * rngs[1].standard_normal(len(impacts))
    )
    out["drop_impacts.csv"] = Dataset(
        observe="impacts",
        **common,
        noise=DROP_IMPACTS["noise"],
        t=np.round(recorded, DROP_IMPACTS["decimals"]),
        source=source,
    )
    heights = h_apex + DROP_APEX["noise"] * rngs[2].standard_normal(len(h_apex))
    out["drop_apex.csv"] = Dataset(
        observe="apex",
        **common,
        noise=DROP_APEX["noise"],
        t=np.round(t_apex, DROP_APEX["time_decimals"]),
        h=np.round(heights, DROP_APEX["decimals"]),
        source=source,
    )

    ts = _grid(RACKETS_TRACE["rate"], RACKETS_TRACE["duration"])
    x = np.asarray(_simulate(RACKETS, ts)["x"])
    noisy = x + RACKETS_TRACE["noise"] * rngs[3].standard_normal(len(ts))
    out["rackets_trace.csv"] = Dataset(
        scene="rackets",
        observe="trace",
        mass=RACKETS["mass"],
        drag=RACKETS["drag"],
        x0=RACKETS["x0"],
        v0=RACKETS["v0"],
        gap=RACKETS["gap"],
        noise=RACKETS_TRACE["noise"],
        t=ts,
        x=np.round(noisy, RACKETS_TRACE["decimals"]),
        source=source,
    )
    return out


def _resolution(name: str, column: str) -> float:
    if name == "drop_impacts.csv":
        return 10.0 ** -DROP_IMPACTS["decimals"]
    if name == "drop_apex.csv" and column == "t":
        return 10.0 ** -DROP_APEX["time_decimals"]
    return 1e-6


def check(datasets: dict[str, Dataset], directory: str = HERE) -> list[str]:
    """Compare regenerated data sets with the files; return the problems (empty: reproduced).

    Text identical is "bit-for-bit"; otherwise every metadata value and column must be
    equal and every number within one unit of its last printed digit (a rounding flip
    from ~1e-12 solver differences between machines).
    """
    problems = []
    for name, fresh in datasets.items():
        path = os.path.join(directory, name)
        if not os.path.isfile(path):
            problems.append(f"{name}: missing")
            continue
        with open(path, encoding="utf-8") as f:
            if f.read() == format_dataset(fresh):
                continue
        stored = load_dataset(path)
        for key in ("scene", "observe", "mass", "drag", "x0", "v0", "gap", "noise", "gravity", "source"):
            if getattr(stored, key) != getattr(fresh, key):
                problems.append(
                    f"{name}: {key} = {getattr(stored, key)!r}, regenerated {getattr(fresh, key)!r}"
                )
        if stored.columns != fresh.columns or stored.num_rows != fresh.num_rows:
            problems.append(f"{name}: columns/rows {stored.columns}x{stored.num_rows} != regenerated")
            continue
        for column in fresh.columns:
            diff = np.max(np.abs(getattr(stored, column) - getattr(fresh, column)))
            if not diff <= 1.01 * _resolution(name, column):
                problems.append(f"{name}: column {column} differs by up to {diff:.3g}")
    return problems


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument(
        "--check", action="store_true", help="regenerate in memory and compare with the files; write nothing"
    )
    args = parser.parse_args(argv)
    datasets = generate()
    if args.check:
        problems = check(datasets)
        for p in problems:
            print(f"MISMATCH {p}")
        print("data/: " + ("all files reproduced" if not problems else f"{len(problems)} mismatches"))
        return 1 if problems else 0
    for name, ds in datasets.items():
        path = os.path.join(HERE, name)
        write_dataset(path, ds, overwrite=True)
        print(f"wrote {path}: {ds.observe}, {ds.num_rows} rows, {os.path.getsize(path)} bytes")
    for label, spec in (("drop", DROP), ("rackets", RACKETS)):
        kappa, k_r = true_parameters(spec)
        print(
            f"{label}: e = {spec['restitution']}, t_c = {spec['contact_time']} s -> kappa = {kappa!r} N/m, k_r = {k_r!r} N*s/m"
        )
    return 0


if __name__ == "__main__":
    sys.exit(main())
