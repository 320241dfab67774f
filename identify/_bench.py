"""identify's rows in `jaxunilat bench`: the fits of the bundled data sets, and a cold
joint fit of 30 throws from the command line.

The bench names them in its `ROWS` (`jaxunilat/_bench/_main.py`):
`identification` and `joint_fit` are each called with the bench's size settings (a
`jaxunilat.bench.Size`: `name`, `identify_sets`, `identify_runs`, `joint_files`) and a
`log` function (one printed line per call), and return their row of `bench.json`.
jaxunilat's engine never imports this package; this module uses identify's public names and
`jaxunilat.bench`.

The joint fit's workload (`write_throws`): `JOINT_FILES` synthetic drops of one ball (one
mass, one drag), released from rest at heights spread over 0.2–0.6 m, each recorded as
its first `JOINT_BOUNCES` impact onsets on its own clock, with N(0, (0.3 ms)²) timing
noise (stated in the file). The flights are closed-form quadratic-drag flights (no
jaxunilat run makes the data): falling from rest through h takes acosh(exp(g k² h))/(g k)
and lands at tanh(g k t)/k; launched upward at u, the ball rises for atan(k u)/(g k) to
ln(1 + k²u²)/(2 g k²); each bounce returns e times the landing speed after a contact of
t_c.

`joint_fit` times `jaxunilat identify f1.csv … f30.csv --law auto` in a fresh process
(`sys.executable -m jaxunilat`) with `JAXUNILAT_NO_CACHE=1`: cold, every program
compiled in that process, nothing read from an executable cache. The row holds the wall
time (`wall_s`, against the target `target_s`), the process's CPU time (`cpu_s`), the
exit status and the chosen law's κ, k_r.
"""

from __future__ import annotations

import json
import math
import os
import subprocess
import sys
import tempfile
import time

import numpy as np

from jaxunilat import identify

#: The workload: this many files, each with this many onsets.
JOINT_FILES = 30
JOINT_BOUNCES = 12
#: The ball: mass (kg), drag k (s/m), restitution, contact time (s), gravity (m/s²).
JOINT_BALL = dict(mass=0.0027, drag=0.12, e=0.9, contact_time=1e-3, gravity=9.81)
#: Release heights (m) and the onsets' timing noise (s, one sd).
JOINT_HEIGHTS = (0.2, 0.6)
JOINT_NOISE = 3e-4
JOINT_SEED = 20261125
#: The bench's target for the cold command (s).
JOINT_TARGET_S = 20.0


# -- the rows ---------------------------------------------------------------------------------


def identification(size, log) -> dict:
    """Wall time (s) of `identify.fit` on each of the first `size.identify_sets` bundled
    data sets (the drop trace first), `size.identify_runs` times each: the first call with
    compilation, the fastest later one warm."""
    if size.identify_sets == 0:
        return {"status": f"skipped at size {size.name}", "rows": []}
    from jaxunilat._internal import bundled_data

    paths = fit_sets(bundled_data("*.csv"))
    if not paths:
        return {"status": "skipped: the bundled data/ folder was not found", "rows": []}
    paths = sorted(paths, key=lambda p: not p.endswith("drop_trace.csv"))[: size.identify_sets]
    rows = [_fit_row(path, size.identify_runs) for path in paths]
    for row in rows:
        warm = "" if row["warm_s"] is None else f", warm {row['warm_s']:.1f} s"
        log(f"  identify.fit {row['data']}: first call {row['first_s']:.1f} s (with compile){warm}")
    return {"status": "measured", "rows": rows}


def fit_sets(paths: list[str]) -> list[str]:
    """The `jaxunilat-data` files among `paths` (`identify.fit` reads them as they are);
    raw tool exports, such as phyphox tables, need `jaxunilat import` first."""
    out = []
    for path in paths:
        with open(path, encoding="utf-8", errors="replace") as f:
            if f.readline().startswith("# jaxunilat-data"):
                out.append(path)
    return out


def _fit_row(path: str, runs: int) -> dict:
    """One data set fitted `runs` times: the walls (s) and the estimates."""
    data = identify.load_dataset(path)
    nuisance = ("offset",) if data.observe == "impacts" else ()
    walls, res = [], None
    for _ in range(runs):
        start = time.perf_counter()
        res = identify.fit(data, nuisance=nuisance)
        walls.append(time.perf_counter() - start)
    return {
        "data": os.path.basename(path),
        "observe": data.observe,
        "fit": "identify.fit(data" + (", nuisance=('offset',))" if nuisance else ")"),
        "first_s": walls[0],
        "warm_s": min(walls[1:]) if len(walls) > 1 else None,
        "kappa": res.params["kappa"].value,
        "k_r": res.params["k_r"].value,
        "converged": bool(res.converged),
    }


def joint_fit(size, log) -> dict:
    """The cold joint fit of `size.joint_files` throws (`joint_fit_files`); skipped where 0."""
    if not size.joint_files:
        return {"status": f"skipped at size {size.name}"}
    return joint_fit_files(size.joint_files, log)


def joint_fit_files(n: int = JOINT_FILES, log=print) -> dict:
    """Wall time (s) of the cold joint fit of n throws with `--law auto`, in a fresh process."""
    env = {**os.environ, "JAXUNILAT_NO_CACHE": "1"}
    with tempfile.TemporaryDirectory(prefix="jaxunilat-joint-") as folder:
        paths = write_throws(folder, n)
        out_json = os.path.join(folder, "fit.json")
        cpu = _children_cpu()
        start = time.perf_counter()
        proc = subprocess.run(
            command(paths, "--json", out_json), env=env, capture_output=True, text=True, check=False
        )
        wall = time.perf_counter() - start
        cpu = _children_cpu() - cpu
        fitted = _read_fit(out_json) if proc.returncode in (0, 3) else {}
    row = {
        "name": "joint_fit_30" if n == JOINT_FILES else f"joint_fit_{n}",
        "command": f"JAXUNILAT_NO_CACHE=1 jaxunilat identify throw_01.csv ... throw_{n:02d}.csv --law auto",
        "files": n,
        "wall_s": wall,
        "cpu_s": cpu,
        "target_s": JOINT_TARGET_S,
        "met": bool(proc.returncode == 0 and wall <= JOINT_TARGET_S),
        "exit_status": proc.returncode,
        **fitted,
    }
    if proc.returncode not in (0, 3):
        row["error"] = (proc.stderr or proc.stdout).strip().splitlines()[-1:] or [""]
    log(
        f"  joint fit of {n} throws, --law auto, cold: {wall:.1f} s (target {JOINT_TARGET_S:.0f} s; "
        f"{cpu:.1f} s of CPU)"
    )
    return row


# -- the joint fit's workload -------------------------------------------------------------------


def _fall(h: float, k: float, g: float) -> tuple[float, float]:
    """Time (s) and landing speed (m/s) of a fall from rest through h (m)."""
    t = math.acosh(math.exp(g * k * k * h)) / (g * k)
    return t, math.tanh(g * k * t) / k


def _rise(u: float, k: float, g: float) -> tuple[float, float]:
    """Time (s) to the apex and its height (m) after a launch at u (m/s)."""
    return math.atan(k * u) / (g * k), math.log1p((k * u) ** 2) / (2 * g * k * k)


def onsets(h0: float, *, bounces: int = JOINT_BOUNCES, **ball) -> np.ndarray:
    """Noise-free impact onset times (s since the release) of a drop from rest at h0 (m)."""
    b = {**JOINT_BALL, **ball}
    k, g = b["drag"], b["gravity"]
    t, w = _fall(h0, k, g)
    out = [t]
    for _ in range(bounces - 1):
        t_up, apex = _rise(b["e"] * w, k, g)
        t_down, w = _fall(apex, k, g)
        out.append(out[-1] + b["contact_time"] + t_up + t_down)
    return np.asarray(out)


def throws(n: int = JOINT_FILES, seed: int = JOINT_SEED, *, bounces: int = JOINT_BOUNCES) -> list:
    """n `identify.Dataset`s of impact onsets: one ball, heights spread over `JOINT_HEIGHTS`,
    a random clock offset (0.5–3 s) and N(0, `JOINT_NOISE`²) timing noise per file."""
    rng = np.random.default_rng(seed)
    heights = np.linspace(*JOINT_HEIGHTS, n) if n > 1 else np.array([JOINT_HEIGHTS[0]])
    out = []
    for h0 in heights:
        h0 = round(float(h0), 4)
        offset = rng.uniform(0.5, 3.0)
        t = onsets(h0, bounces=bounces) + offset + JOINT_NOISE * rng.standard_normal(bounces)
        out.append(
            identify.Dataset(
                scene="drop",
                observe="impacts",
                mass=JOINT_BALL["mass"],
                drag=JOINT_BALL["drag"],
                x0=h0,
                v0=0.0,
                noise=JOINT_NOISE,
                t=np.round(t, 7),
                source="SYNTHETIC: closed-form quadratic-drag drops (identify._bench)",
            )
        )
    return out


def write_throws(folder: str, n: int = JOINT_FILES, seed: int = JOINT_SEED) -> list[str]:
    """Write `throws(n, seed)` as data files throw_01.csv … into `folder`; returns their paths."""
    paths = []
    for i, d in enumerate(throws(n, seed)):
        path = os.path.join(folder, f"throw_{i + 1:02d}.csv")
        identify.write_dataset(path, d, overwrite=True)
        paths.append(path)
    return paths


def command(paths: list[str], *extra: str) -> list[str]:
    """The timed command line: `python -m jaxunilat identify PATHS --law auto`."""
    return [sys.executable, "-m", "jaxunilat", "identify", *paths, "--law", "auto", *extra]


def _children_cpu() -> float:
    """User + system CPU seconds of this process's finished children (NaN where unknown):
    on a shared machine the wall time follows the load, the CPU time much less."""
    try:
        import resource
    except ImportError:
        return math.nan
    usage = resource.getrusage(resource.RUSAGE_CHILDREN)
    return usage.ru_utime + usage.ru_stime


def _read_fit(path: str) -> dict:
    """κ, k_r, the chosen law and convergence from the command's JSON (empty when unreadable)."""
    try:
        with open(path, encoding="utf-8") as fh:
            d = json.load(fh)
    except (OSError, ValueError):
        return {}
    params = d.get("parameters", {})
    return {
        "law": d.get("law"),
        "kappa": params.get("kappa", {}).get("value"),
        "k_r": params.get("k_r", {}).get("value"),
        "converged": d.get("converged"),
    }
