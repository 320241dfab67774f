"""`jaxunilat bench`: run time against error, throughput, gradient cost and compile time.

Every figure is measured in one process against peers timed in the same run (scipy
`solve_ivp` with and without event location, a plain NumPy RK4 loop), on Table 1
example 2 over [0, 2] s [K90 §5.1]. The error is max |Δx| at 2001 points against the
benchmark's own reference (`_peers.reference`: event-located DOP853 at rtol
1e-13), itself checked against the drag-free closed form. Wall times are medians of
repeated runs after a warm-up call (at least `Size.repeats`, more for fast calls until
`Size.min_time_s` is spent); the warm-up's extra time is the compile time.

`run_bench(size)` returns the `bench.json` dictionary; the `jaxunilat bench` command
(`_cli/_bench.py`) writes it with the figures (`_plot.py`). The peers and the
reference are in `_peers.py`, the throughput scene and the sharded sweep's timing in
`_scale.py`, the goals measured on the users' own code (plain vmap, jax.grad, the
command line's second run, a default user's script) in `_user.py`, and the goals with
their notes in `_goals.py`.

The rows that time identification are listed in `ROWS`: each name is its key in
`bench.json`, and its target ("module:function") a callable `row(size, log) -> dict`
(`size`: this module's `Size`; `log`: called with each printed line), imported only when
the bench runs: `identification` and `joint_fit` (`jaxunilat/identify/_bench.py`).
"""

from __future__ import annotations

import dataclasses
import datetime
import functools
import json
import math
import os
import platform
import statistics
import subprocess
import sys
import time
import warnings
from collections.abc import Callable

import numpy as np

from . import _peers as peers, _user as user
from ._accelerator import accelerator_section
from ._goals import THROUGHPUT_ERROR, TIGHT_ERROR, goal_table as goal_table, goals
from ._scale import SAMPLES, T1, Y0, process_section


@dataclasses.dataclass(frozen=True)
class Size:
    """What one benchmark size runs."""

    name: str
    repeats: int  # the fewest timed runs after the warm-up
    slow_s: float  # a run slower than this is repeated only twice
    rk4_dts: tuple[float, ...]
    tsit5_tols: tuple[float, ...]
    smooth: tuple[tuple[str, float], ...]
    event_tols: tuple[float, ...]
    dopri8_tols: tuple[float, ...]
    peer_event_tols: dict
    peer_plain_tols: dict
    numpy_dts: tuple[float, ...]
    throughput_ns: tuple[int, ...]
    peer_loop_n: int
    scale_n: int
    skip_scenes: tuple[str, ...]
    error_checks: int
    gradient: bool = True  # the gradient section (its reverse-mode compile is the slowest)
    gradient_pieces: tuple[str, ...] = ("tsit5",)  # gradient_ratio is on the first (the default pieces)
    scale_out: bool = True  # the 1-device against 2-device subprocess
    scale_processes: tuple[int, ...] = (1, 2, 4)  # the sweep over this many processes; (): skip
    identify_sets: int = 0  # bundled data sets to fit (the default one first)
    identify_runs: int = 1  # fits per data set (the first includes compilation)
    joint_files: int = 0  # joint_fit: a cold `identify --law auto` of this many throws (0: skipped)
    # The users' code (`_user.py`): user_vmap_ratio's rows, cli_second_run's commands (each
    # run twice in fresh processes), and whether user_grad_ratio (its reverse-mode compile
    # is the slowest of the section) and default_user_ratio (two fresh processes) run.
    user_n: int = 1000
    # The accelerator section's sweep sizes (on a CPU backend it is skipped).
    accelerator_ns: tuple[int, ...] = (1_000, 10_000, 100_000, 1_000_000)
    user_cli: tuple[str, ...] = ("simulate", "identify", "reproduce")
    user_grad: bool = True
    default_user: bool = True
    # The batch sizes of the throughput's second strategy (vmapped beside one by one);
    # None: every one of `throughput_ns`; (): none (user_vmap_ratio still times plain vmap against
    # rows one by one, on the users' scene).
    compare_ns: tuple[int, ...] | None = None
    # Fast calls are repeated beyond `repeats` until this much time is spent (at most
    # `max_repeats` runs): on a shared VM single millisecond calls swing by 2x, and a
    # median of 5 can land on either mode.
    min_time_s: float = 0.25
    max_repeats: int = 51
    # The compiled-loop peer's tolerances (`_compiled.py`, Numba; rtol = atol).
    compiled_tols: tuple[float, ...] = tuple(10.0**-k for k in range(4, 13))


_ALL_SCENES = ("drag on", "drag = 0", "drag None", "upper far", "upper None")
SIZES = {
    "full": Size(
        name="full",
        repeats=5,
        slow_s=5.0,
        rk4_dts=(1e-4, 1e-5, 1e-6),
        tsit5_tols=(1e-4, 1e-6, 1e-8, 1e-10, 1e-12),
        smooth=(("logistic", 1e-4), ("logistic", 1e-5), ("softplus", 1e-4), ("softplus", 1e-5)),
        event_tols=(1e-4, 1e-6, 1e-8, 1e-10, 1e-12),
        dopri8_tols=(1e-6, 1e-8, 1e-9, 1e-10, 1e-11, 1e-12),
        peer_event_tols={
            "RK45": (1e-4, 1e-6, 1e-8, 1e-10),
            "DOP853": (1e-4, 1e-6, 1e-8, 1e-10, 1e-12),
            "LSODA": (1e-4, 1e-6, 1e-8, 1e-10, 1e-12),
        },
        peer_plain_tols={
            "RK45": (1e-4, 1e-6, 1e-8),
            "DOP853": (1e-4, 1e-6, 1e-8, 1e-10),
            "LSODA": (1e-4, 1e-6, 1e-8, 1e-10),
        },
        numpy_dts=(1e-4, 1e-5, 1e-6),
        throughput_ns=(1, 100, 1000, 10000),
        peer_loop_n=20,
        scale_n=1000,
        skip_scenes=_ALL_SCENES,
        error_checks=3,
        identify_sets=10,
        joint_files=30,
        identify_runs=2,
        gradient_pieces=("tsit5", "dopri8"),
    ),
    "quick": Size(
        name="quick",
        repeats=5,
        slow_s=1.0,
        rk4_dts=(1e-4, 1e-5),
        tsit5_tols=(1e-6, 1e-8, 1e-10),
        smooth=(("logistic", 1e-5),),
        event_tols=(1e-6, 1e-8, 1e-10, 1e-12),
        dopri8_tols=(1e-8, 1e-9, 1e-11),
        peer_event_tols={"RK45": (1e-6, 1e-8), "DOP853": (1e-6, 1e-8, 1e-10, 1e-12), "LSODA": (1e-8,)},
        peer_plain_tols={"DOP853": (1e-8,), "LSODA": (1e-8,)},
        numpy_dts=(1e-4, 1e-5),
        throughput_ns=(1, 1000),
        peer_loop_n=5,
        scale_n=200,
        skip_scenes=("drag = 0", "drag None"),
        error_checks=2,
        min_time_s=0.1,
        max_repeats=21,
        user_n=100,
        accelerator_ns=(1_000, 10_000),
        user_cli=("simulate", "identify"),  # reproduce --quick adds ~15 s: the full size runs it
        compare_ns=(),  # ~20 s of compiles; user_vmap_ratio times plain vmap against rows one by one
        scale_processes=(),  # a process start-up and compile per count (tests/test_distributed_sweep.py)
    ),
    # Only for the test suite (hidden flag `--size tiny`): every section, smallest settings;
    # what other tests cover at their own cost is skipped (each says so in bench.json).
    "tiny": Size(
        name="tiny",
        repeats=2,
        slow_s=0.5,
        rk4_dts=(1e-4,),
        tsit5_tols=(),
        smooth=(),
        event_tols=(1e-6, 1e-10, 1e-12),
        dopri8_tols=(),
        peer_event_tols={"DOP853": (1e-8, 1e-12)},
        peer_plain_tols={"LSODA": (1e-8,)},
        numpy_dts=(1e-4,),
        throughput_ns=(4,),
        peer_loop_n=2,
        scale_n=4,
        skip_scenes=("drag = 0", "drag None"),
        error_checks=1,
        gradient=False,  # tests/test_event_mode.py checks event-mode gradients against FD
        scale_out=False,  # tests/test_sweep.py runs the 2-device sweep
        scale_processes=(),  # tests/test_distributed_sweep.py runs 2 and 4 processes
        min_time_s=0.0,
        compare_ns=(),  # the vmapped sweep beside rows one by one: tests/test_sweep.py
        user_n=4,
        accelerator_ns=(4, 8),
        # The users' code in fresh processes and its reverse-mode compile (~90 s on 2 cores):
        # tests/test_bench.py runs the command-line pair on a fast command.
        user_cli=(),
        user_grad=False,
        default_user=False,
        compiled_tols=(1e-8, 1e-10, 1e-12),
    ),
}


def _clean(value):
    """JSON-safe: non-finite floats become None, NumPy scalars become Python numbers."""
    if isinstance(value, dict):
        return {k: _clean(v) for k, v in value.items()}
    if isinstance(value, (list, tuple)):
        return [_clean(v) for v in value]
    if isinstance(value, (np.integer,)):
        return int(value)
    if isinstance(value, (float, np.floating)):
        return float(value) if math.isfinite(value) else None
    if isinstance(value, np.bool_):
        return bool(value)
    return value


@dataclasses.dataclass
class Timing:
    """A timed call: its result, the first call's time (with compilation), the median and
    the fastest of the repeated runs (s), and how many runs."""

    out: object
    first: float
    median: float
    min: float
    runs: int


def _timed(fn: Callable, size: Size) -> Timing:
    """A warm-up call, then at least `size.repeats` runs, more until `size.min_time_s`
    is spent (at most `size.max_repeats`); 2 runs when the warm-up took over `size.slow_s`."""
    return _timed_together([fn], size)[0]


def _timed_together(fns: list[Callable], size: Size, warm_ups: int = 1) -> list[Timing]:
    """`_timed` for calls that are compared with each other (a gradient against its
    forward): `warm_ups` rounds of warm-up calls (the first with compilation; the last
    decides whether the calls are slow), then the runs alternate between them, so that a
    slow spell of the machine falls on all of them alike."""
    outs, rounds = [None] * len(fns), []
    for _ in range(warm_ups):
        rounds.append([])
        for i, fn in enumerate(fns):
            start = time.perf_counter()
            outs[i] = fn()
            rounds[-1].append(time.perf_counter() - start)
    firsts, lasts = rounds[0], rounds[-1]
    slow = max(lasts) >= size.slow_s
    walls = [[] for _ in fns]
    spent = 0.0
    while True:
        n = len(walls[0])
        if n >= (2 if slow else size.max_repeats):
            break
        if n >= (2 if slow else size.repeats) and spent >= size.min_time_s:
            break
        for i, fn in enumerate(fns):
            start = time.perf_counter()
            outs[i] = fn()
            wall = time.perf_counter() - start
            walls[i].append(wall)
            spent += wall
    return [
        Timing(out, first, statistics.median(w), min(w), len(w))
        for out, first, w in zip(outs, firsts, walls, strict=True)
    ]


def _error(x, x_ref) -> float:
    d = np.abs(np.asarray(x, float) - x_ref)
    return float(np.max(d)) if np.all(np.isfinite(d)) else math.inf


def machine() -> dict:
    """The machine and software the figures were taken on."""
    import jax

    from .._internal._loop_kernels import loop_kernel_bytes

    return {
        "date_utc": datetime.datetime.now(datetime.UTC).strftime("%Y-%m-%d %H:%M"),
        "platform": platform.platform(),
        "processor": platform.processor() or platform.machine(),
        "cpu_count": os.cpu_count(),
        "python": platform.python_version(),
        "jax": jax.__version__,
        "backend": jax.default_backend(),
        "devices": [str(d) for d in jax.devices()],
        # XLA:CPU compiles loops touching fewer bytes per iteration into one kernel
        # (`use_loop_kernels`, which the command line calls); None: XLA's default (1 KiB).
        "loop_kernel_bytes": loop_kernel_bytes(),
        # JAX's persistent compilation cache in this process (the command turns it off: the
        # bench measures compile times; cli_second_run measures the cache in child processes).
        "compilation_cache_dir": (
            jax.config.jax_compilation_cache_dir if jax.config.jax_enable_compilation_cache else None
        ),
    }


# -- the reference ----------------------------------------------------------------------------


def reference_check(ts: np.ndarray) -> dict:
    """The reference against the drag-free closed form (example 2 with drag=None), m."""
    p = peers.Params(drag=None)
    ref = peers.reference(p, Y0, ts)
    cf = peers.closed_form_drag_free(p, Y0, ts)
    n = min(len(ref.entries), len(cf.entries))
    return {
        "scene": "example 2, drag None, [0, 2] s",
        "max_dx_m": _error(ref.x, cf.x),
        "max_dt_entry_s": float(np.max(np.abs(np.subtract(ref.entries[:n], cf.entries[:n])))),
        "entries": n,
    }


# -- work-precision ---------------------------------------------------------------------------


def _project_rows(size: Size, ts, x_ref, log) -> tuple[list[dict], dict]:
    import jax

    from .._models._ball import Ball
    from .._models._heaviside import Logistic, Softplus
    from .._solver._simulate import simulate

    y0 = np.asarray(Y0)
    rk4_max_steps = int(math.ceil(T1 / min(size.rk4_dts))) + 16  # one compile for every dt
    common = dict(samples=SAMPLES, outputs=("x",), throw=False)
    configs = []  # (method, setting, compile key, callable)
    ball = Ball.table1(2)
    for dt in size.rk4_dts:
        kw = dict(solver="rk4", dt=dt, max_steps=rk4_max_steps, **common)
        configs.append(("rk4, exact H", f"dt {dt:g}", "rk4", ball, kw))
    for tol in size.tsit5_tols:
        configs.append(("tsit5, exact H", f"tol {tol:g}", "tsit5", ball, dict(rtol=tol, atol=tol, **common)))
    for kind, eps in size.smooth:
        hs = Logistic(eps) if kind == "logistic" else Softplus(eps)
        configs.append(
            (
                f"tsit5, {kind}",
                f"eps {eps:g} m, tol 1e-10",
                f"tsit5 {kind}",
                Ball.table1(2, heaviside=hs),
                dict(rtol=1e-10, atol=1e-10, **common),
            )
        )
    for piece, tols in (("tsit5", size.event_tols), ("dopri8", size.dopri8_tols)):
        for tol in tols:
            kw = dict(solver="event", piece_solver=piece, rtol=tol, atol=tol, **common)
            configs.append((f"event ({piece})", f"tol {tol:g}", f"event {piece}", ball, kw))
    rows, compiled = [], {}
    for method, setting, key, model, kw in configs:

        def run(model=model, kw=kw):
            sol = simulate(model, y0, T1, **kw)
            return jax.block_until_ready(sol)

        timing = _timed(run, size)
        sol, first, wall, runs = timing.out, timing.first, timing.median, timing.runs
        compile_s = max(first - wall, 0.0) if key not in compiled else None
        compiled.setdefault(key, compile_s)
        rows.append(
            {
                "method": method,
                "setting": setting,
                "error": _error(sol.ys["x"], x_ref),
                "wall_s": wall,
                "wall_min_s": timing.min,
                "compile_s": compile_s if compile_s is not None else 0.0,
                "peer": False,
                "runs": runs,
                "steps": int(sol.num_steps),
                "accepted": int(sol.num_accepted_steps),
                "rejected": int(sol.num_rejected_steps),
                "status": int(sol.status),
            }
        )
        log(_row_line(rows[-1]))
    return rows, compiled


def _peer_rows(size: Size, ts, x_ref, log) -> list[dict]:
    p = peers.Params()
    configs = []
    for method, tols in size.peer_event_tols.items():
        for tol in tols:
            configs.append(
                (
                    f"scipy {method} + events",
                    f"tol {tol:g}",
                    lambda m=method, t=tol: peers.solve_events(p, Y0, ts, method=m, rtol=t, atol=t),
                )
            )
    for method, tols in size.peer_plain_tols.items():
        for tol in tols:
            configs.append(
                (
                    f"scipy {method}, no events",
                    f"tol {tol:g}",
                    lambda m=method, t=tol: peers.solve_no_events(p, Y0, ts, method=m, rtol=t, atol=t),
                )
            )
    for dt in size.numpy_dts:
        configs.append(("NumPy RK4 loop", f"dt {dt:g}", lambda dt=dt: peers.numpy_rk4(p, Y0, ts, dt)))
    rows = []
    for method, setting, fn in configs:
        # Trial steps of the discontinuous right-hand side may overflow: that is the peer's own business.
        with warnings.catch_warnings(), np.errstate(all="ignore"):
            warnings.simplefilter("ignore", RuntimeWarning)
            timing = _timed(fn, size)
        run, wall, runs = timing.out, timing.median, timing.runs
        rows.append(
            {
                "method": method,
                "setting": setting,
                "error": _error(run.x, x_ref),
                "wall_s": wall,
                "wall_min_s": timing.min,
                "compile_s": 0.0,
                "peer": True,
                "runs": runs,
            }
        )
        log(_row_line(rows[-1]))
    return rows


def work_precision(size: Size, log: Callable[[str], None] = print) -> tuple[list[dict], dict]:
    """The work-precision section alone: (rows, compile times by configuration).

    **Arguments:**

    - `size`: a `Size` (e.g. `SIZES["quick"]`, or `dataclasses.replace` of one).
    - `log`: called with one line per row.

    **Returns:** the project's rows followed by the peers' rows (as in `bench.json`),
    and the compile time of each project configuration, s.
    """
    ts = np.linspace(0.0, T1, SAMPLES)
    ref = peers.reference(peers.Params(), Y0, ts)
    project, compiled = _project_rows(size, ts, ref.x, log)
    return project + _peer_rows(size, ts, ref.x, log), compiled


def _row_line(row: dict) -> str:
    err = "inf" if not math.isfinite(row["error"]) else f"{row['error']:.2e}"
    steps = f"  steps {row['steps']} ({row['rejected']} rej)" if "steps" in row else ""
    tag = "peer" if row["peer"] else "    "
    return f"  {tag} {row['method']:<26} {row['setting']:<22} error {err:>8} m  wall {1e3 * row['wall_s']:9.2f} ms{steps}"


def per_step_fit(rows: list[dict], method: str = "event (tsit5)") -> dict | None:
    """Least squares wall = fixed + per_step · steps over one method's rows (a profile)."""
    pts = [(r["steps"], r["wall_s"]) for r in rows if r["method"] == method and r.get("status") == 0]
    if len(pts) < 2:
        return None
    steps, walls = (np.array(a, float) for a in zip(*pts, strict=True))
    slope, intercept = np.polyfit(steps, walls, 1)
    return {"method": method, "fixed_s": float(intercept), "per_step_s": float(slope), "points": len(pts)}


# -- throughput and scale-out ----------------------------------------------------------------


def _throughput(size: Size, wp_rows, log) -> tuple[list[dict], dict, dict]:
    """The throughput rows, the accuracy checks of the largest batch, and that batch's
    rows (`x`, `kappa`, `k_r`: the compiled-loop peer's rows are checked against them)."""
    from ._scale import PIECE, TOL, one_by_one_fastest, run_sweep, strategy

    rows, checks = [], {}
    # The platform's fastest strategy first (its largest batch is checked against the
    # reference); on a CPU with loop kernels the vmapped one beside it, for comparison.
    fastest = one_by_one_fastest()
    last = None
    for one_by_one in (True, False) if fastest else (False,):
        compare = one_by_one != fastest and size.compare_ns is not None
        for n in size.compare_ns if compare else size.throughput_ns:
            row = run_sweep(
                n,
                size.repeats if n < 1000 or (size.name == "full" and n < 10000) else 2,
                one_by_one=one_by_one,
            )
            if one_by_one == fastest:
                last = row
            rows.append(
                {
                    "method": f"jaxunilat.sweep, event mode ({PIECE}) tol {TOL:g}, {strategy(one_by_one)}",
                    "n": n,
                    "traj_per_s": row["traj_per_s"],
                    "peak_mem_mb": row["peak_mem_mb"],
                    "wall_s": row["wall_s"],
                    "compile_s": row["compile_s"],
                    "devices": row["devices"],
                    "strategy": row["strategy"],
                    "rows_at_once": row["rows_at_once"],
                    "all_ok": row["all_ok"],
                    "steps_mean": row["steps_mean"],
                    "steps_max": row["steps_max"],
                    "peer": False,
                }
            )
            log(
                f"  sweep N = {n:>6}, {row['strategy']}, {row['devices']} device(s): "
                f"{row['traj_per_s']:10.1f} traj/s  wall {row['wall_s']:.3f} s  compile {row['compile_s']:.1f} s  "
                f"steps mean {row['steps_mean']:.0f}, max {row['steps_max']}"
            )
    # Accuracy of the largest batch: a few rows against the reference.
    ts = np.linspace(0.0, T1, SAMPLES)
    idx = np.unique(np.linspace(0, last["n"] - 1, size.error_checks).astype(int))
    errors = []
    for i in idx:
        ref = peers.reference(peers.Params(kappa=float(last["kappa"][i]), k_r=float(last["k_r"][i])), Y0, ts)
        errors.append(_error(last["x"][i], ref.x))
    checks["max_error_m"] = max(errors)
    checks["rows_checked"] = len(idx)
    if fastest and size.compare_ns == ():
        checks["vmapped"] = (
            f"left out at size {size.name} (user_vmap_ratio times plain vmap against rows one by one)"
        )
    # The scipy loop: the fastest peer whose example-2 error is <= 1e-8 m, over several pairs.
    ok = [r for r in wp_rows if r["peer"] and r["error"] <= THROUGHPUT_ERROR and "events" in r["method"]]
    if ok:
        best = min(ok, key=lambda r: r["wall_s"])
        method = best["method"].split()[1]
        tol = float(best["setting"].split()[1])
        kappa, k_r = last["kappa"][: size.peer_loop_n], last["k_r"][: size.peer_loop_n]
        start = time.perf_counter()
        for a, b in zip(kappa, k_r, strict=True):
            peers.solve_events(
                peers.Params(kappa=float(a), k_r=float(b)), Y0, ts, method=method, rtol=tol, atol=tol
            )
        wall = time.perf_counter() - start
        rows.append(
            {
                "method": f"scipy {method} + events loop, tol {tol:g}",
                "n": len(kappa),
                "traj_per_s": len(kappa) / wall,
                "peak_mem_mb": None,
                "wall_s": wall,
                "peer": True,
            }
        )
        log(f"  scipy loop ({method}, tol {tol:g}), {len(kappa)} pairs: {len(kappa) / wall:.1f} traj/s")
    return rows, checks, {k: last[k] for k in ("x", "kappa", "k_r")}


def _scale_out(size: Size, log) -> dict:
    """1-device against all-device throughput of the sharded sweep (N = size.scale_n)."""
    import jax

    from ._scale import one_by_one_fastest, scale_rows

    repeats = max(2, size.repeats)
    one_by_one = one_by_one_fastest()
    if jax.device_count() >= 2:
        result = {"how": "in process", "rows": scale_rows(size.scale_n, repeats, one_by_one)}
    elif jax.default_backend() != "cpu":
        return {"how": "skipped: a single accelerator is visible", "rows": []}
    else:
        env = dict(os.environ)
        env["XLA_FLAGS"] = (env.get("XLA_FLAGS", "") + " --xla_force_host_platform_device_count=2").strip()
        env["JAX_PLATFORMS"] = "cpu"
        cmd = [sys.executable, "-m", "jaxunilat._bench._scale", str(size.scale_n), str(repeats)]
        proc = subprocess.run(
            cmd + (["--one-by-one"] if one_by_one else []),
            env=env,
            capture_output=True,
            text=True,
            check=False,
        )
        if proc.returncode != 0:
            tail = (proc.stderr.strip().splitlines() or ["no output"])[-1]
            return {"how": "subprocess failed: " + tail, "rows": []}
        result = json.loads(proc.stdout.strip().splitlines()[-1])
        result["how"] = "subprocess with XLA_FLAGS=--xla_force_host_platform_device_count=2"
    for row in result["rows"]:
        log(
            f"  scale-out N = {row['n']}, {row['strategy']}: {row['devices']} device(s) "
            f"{row['traj_per_s']:.1f} traj/s"
        )
    return result


# -- gradient cost ----------------------------------------------------------------------------

GRAD_IMPACTS = 5


def _loss(theta, weights, piece="tsit5", autodiff="reverse"):
    """weights · (trace loss mean x² [m²], sum of the first 5 impact times [s]) at θ = (κ, k_r),
    event mode with `piece` ("tsit5" or "dopri8") pieces, differentiable in `autodiff` mode."""
    import jax.numpy as jnp

    from .._models._ball import Ball
    from .._solver._observe import impact_times
    from .._solver._simulate import simulate
    from ._scale import MAX_EVENTS, TOL

    sol = simulate(
        Ball.table1(2, kappa=theta[0], k_r=theta[1]),
        jnp.asarray(Y0),
        T1,
        solver="event",
        piece_solver=piece,
        autodiff=autodiff,
        rtol=TOL,
        atol=TOL,
        samples=SAMPLES,
        outputs=("x",),
        max_steps=2048,
        max_events=MAX_EVENTS,
    )
    trace = jnp.mean(sol.ys["x"] ** 2)
    impacts = jnp.sum(impact_times(sol, GRAD_IMPACTS + 1))  # the first onset is t0 = 0
    return weights[0] * trace + weights[1] * impacts


def _reference_losses(theta, ts) -> np.ndarray:
    run = peers.reference(peers.Params(kappa=float(theta[0]), k_r=float(theta[1])), Y0, ts)
    return np.array([np.mean(run.x**2), np.sum(run.entries[:GRAD_IMPACTS])])


def _gradient(size: Size, log) -> dict:
    import jax
    import jax.numpy as jnp

    theta = jnp.array([1.0e4, 0.2])
    ts = np.linspace(0.0, T1, SAMPLES)
    out = {
        "scene": "example 2, [0, 2] s, event mode tol 1e-10, theta = (kappa, k_r)",
        # gradient_ratio is taken on the default pieces (Tsit5); other pieces' rows are beside them.
        # Each loss has a row per mode: jax.grad on the default (checkpointed) loop, and
        # jax.jacfwd with autodiff="forward" (a plain loop: one tangent per parameter).
        "losses": [],
    }
    for piece in size.gradient_pieces:
        key = "losses" if piece == size.gradient_pieces[0] else f"losses_{piece}"
        out.setdefault(key, [])
        loss = functools.partial(_loss, piece=piece)
        fwd = jax.jit(loss)
        grads = {
            "reverse": jax.jit(jax.grad(loss)),
            "forward": jax.jit(jax.jacfwd(functools.partial(_loss, piece=piece, autodiff="forward"))),
        }
        for name, w in (("trace", (1.0, 0.0)), ("impact_times", (0.0, 1.0))):
            w = jnp.asarray(w)
            timings = _timed_together(
                [lambda w=w, fwd=fwd: jax.block_until_ready(fwd(theta, w))]
                + [lambda w=w, g=g: jax.block_until_ready(g(theta, w)) for g in grads.values()],
                size,
            )
            for mode, gt in zip(grads, timings[1:], strict=True):
                out[key].append(_gradient_row(name, piece, timings[0], gt, mode))
    # Finite differences of the reference (central, relative step 1e-6).
    fd = np.zeros((2, 2))
    for i in range(2):
        h = 1e-6 * float(theta[i])
        tp, tm = np.array(theta), np.array(theta)
        tp[i] += h
        tm[i] -= h
        fd[:, i] = (_reference_losses(tp, ts) - _reference_losses(tm, ts)) / (2 * h)
    for row in [row for key, rows in out.items() if key.startswith("losses") for row in rows]:
        j = 0 if row["loss"] == "trace" else 1
        row["fd_reference"] = [float(v) for v in fd[j]]
        row["max_rel_error"] = float(np.max(np.abs(np.array(row["ad"]) - fd[j]) / np.abs(fd[j])))
        log(
            f"  gradient of the {row['loss']} loss ({row['piece_solver']} pieces, {row['mode']} mode): "
            f"{row['ratio']:.1f}x forward "
            f"(forward {1e3 * row['forward_s']:.1f} ms, compile {row['gradient_compile_s']:.1f} s); "
            f"AD vs FD of the reference: max rel. error {row['max_rel_error']:.1e}"
        )
    return out


def _gradient_row(name: str, piece: str, forward: Timing, gradient: Timing, mode: str) -> dict:
    return {
        "loss": name,
        "piece_solver": piece,
        "mode": mode,  # "reverse": jax.grad; "forward": jax.jacfwd with autodiff="forward"
        "forward_s": forward.median,
        "gradient_s": gradient.median,
        "ratio": gradient.median / forward.median,
        "ratio_of_fastest_runs": gradient.min / forward.min,
        "forward_compile_s": max(forward.first - forward.median, 0.0),
        "gradient_compile_s": max(gradient.first - gradient.median, 0.0),
        "ad": [float(v) for v in np.asarray(gradient.out)],
    }


# -- compile, no retrace, static structure ------------------------------------------------


def count_equations(jaxpr) -> int:
    """Equations in a jaxpr and, recursively, in every sub-jaxpr (loops, conds, calls)."""
    from jax.extend import core

    def sub(value):
        if isinstance(value, core.ClosedJaxpr):
            return count(value.jaxpr)
        if isinstance(value, core.Jaxpr):
            return count(value)
        if isinstance(value, (tuple, list)):
            return sum(sub(v) for v in value)
        return 0

    def count(jx):
        return sum(1 + sum(sub(v) for v in eqn.params.values()) for eqn in jx.eqns)

    return count(jaxpr.jaxpr if isinstance(jaxpr, core.ClosedJaxpr) else jaxpr)


def _no_retrace(size: Size) -> dict:
    """New parameter values (κ, k_r, y0, tolerance) after the compiles: trace counts must not move."""
    import jax

    from .._models._ball import Ball
    from .._solver._simulate import simulate, trace_counts
    from .._solver._sweep import sweep
    from ._scale import one_by_one_fastest, pairs, sweep_kwargs, trajectory

    before = trace_counts()
    common = dict(samples=SAMPLES, outputs=("x",), throw=False, solver="event")
    jax.block_until_ready(
        simulate(
            Ball.table1(2, kappa=1.7e4, k_r=0.31), np.array([-0.2, 3.0]), T1, rtol=3e-9, atol=3e-9, **common
        )
    )
    jax.block_until_ready(simulate(Ball.table1(5), np.asarray(Y0), 1.5, rtol=1e-7, atol=1e-7, **common))
    n = size.throughput_ns[0]
    kappa, k_r = pairs(n, seed=1)  # new pairs, the batch size of a compiled run
    jax.block_until_ready(sweep(trajectory, kappa, k_r, **sweep_kwargs(n, one_by_one=one_by_one_fastest())))
    after = trace_counts()
    return {
        "calls": "event mode with new kappa, k_r, y0, t1, rtol/atol; sweep with new pairs",
        "before": before,
        "after": after,
        "ok": all(after.get(k, 0) == before.get(k, 0) for k in ("simulate", "sweep")),
    }


def _scene_ball(name: str):
    from .._models._ball import Ball

    return {
        "drag on": lambda: Ball.table1(2),
        "drag = 0": lambda: Ball.table1(2, drag=0.0),
        "drag None": lambda: Ball.table1(2, drag=None),
        "upper far": lambda: Ball.table1(2, upper=1.0e3),
        "upper None": lambda: Ball.table1(2, upper=None),
    }[name]()


def _skip_scenes(size: Size, log) -> list[dict]:
    """Static switches: the same physics with a term present (value 0 / out of reach) or absent."""
    import equinox as eqx
    import jax

    from .._solver._simulate import simulate

    rows = []
    kw = dict(solver="event", rtol=1e-10, atol=1e-10, samples=SAMPLES, outputs=("x",), throw=False)
    for name in size.skip_scenes:
        ball = _scene_ball(name)
        jaxpr = eqx.filter_make_jaxpr(lambda b: simulate(b, np.asarray(Y0), T1, **kw))(ball)[0]
        timing = _timed(lambda b=ball: jax.block_until_ready(simulate(b, np.asarray(Y0), T1, **kw)), size)
        sol, first, wall, runs = timing.out, timing.first, timing.median, timing.runs
        rows.append(
            {
                "scene": name,
                "equations": count_equations(jaxpr),
                "wall_s": wall,
                "wall_min_s": timing.min,
                "compile_s": max(first - wall, 0.0),
                "steps": int(sol.num_steps),
                "x_end_m": float(sol.ys["x"][-1]),
                "runs": runs,
            }
        )
        log(
            f"  scene {name:<11} {rows[-1]['equations']:6d} equations  wall {1e3 * wall:7.2f} ms  "
            f"compile {rows[-1]['compile_s']:.1f} s  steps {rows[-1]['steps']}"
        )
    return rows


def _profile(log) -> dict:
    """One event-mode call of the same compiled scene over a 1 µs span, and the loop's size.

    Set-up in Python (validation, settings), dispatch, the loop's start and end, and the
    outputs at the 2001 save times, all of them inside one step (each costs ~5x one in a
    long run, so this is an upper bound of the fixed cost; `per_step_fit`'s intercept is
    the fixed cost of the real runs).
    """
    import jax

    from .._models._ball import Ball
    from .._solver._simulate import simulate

    ball, y0 = Ball.table1(2), np.asarray(Y0)
    kw = dict(solver="event", rtol=1e-10, atol=1e-10, samples=SAMPLES, outputs=("x",), throw=False)
    walls = []
    for _ in range(9):
        start = time.perf_counter()
        jax.block_until_ready(simulate(ball, y0, 1e-6, **kw))
        walls.append(time.perf_counter() - start)
    out = {"fixed_call_s": statistics.median(walls)}
    log(
        f"  profile: one event-mode call over 1 us (all 2001 save times in one step): "
        f"{1e3 * out['fixed_call_s']:.2f} ms"
    )
    out.update(loop_structure(lambda b: simulate(b, y0, T1, **kw), ball))
    log(
        f"  profile: the step loop's body has {out['loop_body_equations']} equations; its conds' branches "
        f"{out['cond_branches']} (under vmap a cond runs all its branches)"
    )
    return out


def _loop_floor(size: Size, log) -> dict:
    """The floor under a step attempt (`_floor.loop_floor`), left out at size tiny."""
    if size.name == "tiny":
        return {"how": "skipped at size tiny"}
    from ._floor import loop_floor

    out = loop_floor()
    log(
        f"  floor: an empty while-loop iteration {out['empty_iteration_ns']:.1f} ns "
        f"({out['empty_row_iteration_vmap_ns']:.2f} ns a row vmapped); an event-mode step attempt "
        f"{out['event_attempt_ns']:.0f} ns ({out['event_row_attempt_vmap_ns']:.0f} ns a row-attempt vmapped)"
    )
    return out


def loop_structure(fn, *args) -> dict:
    """Equation counts of the largest while loop's body in `fn`'s jaxpr, and of its conds' branches."""
    import equinox as eqx
    from jax.extend import core

    jaxpr = eqx.filter_make_jaxpr(fn)(*args)[0]
    loops = []

    def walk(jx):
        for eqn in jx.eqns:
            if eqn.primitive.name == "while":
                loops.append(eqn.params["body_jaxpr"])
            for value in eqn.params.values():
                for v in value if isinstance(value, (tuple, list)) else (value,):
                    if isinstance(v, core.ClosedJaxpr):
                        walk(v.jaxpr)
                    elif isinstance(v, core.Jaxpr):
                        walk(v)

    walk(jaxpr.jaxpr)
    body = max(loops, key=count_equations)
    branches = []

    def conds(jx):
        for eqn in jx.eqns:
            if eqn.primitive.name == "cond":
                branches.append([count_equations(b) for b in eqn.params["branches"]])
            elif eqn.primitive.name in ("pjit", "jit", "closed_call", "custom_jvp_call", "custom_vjp_call"):
                for value in eqn.params.values():
                    if isinstance(value, core.ClosedJaxpr):
                        conds(value.jaxpr)

    conds(body.jaxpr if isinstance(body, core.ClosedJaxpr) else body)
    return {"loop_body_equations": count_equations(body), "cond_branches": branches}


# -- identify's rows ------------------------------------------------------------------------

#: The rows that time identification (see the module's docstring): name → "module:function".
ROWS = {
    "identification": "jaxunilat.identify._bench:identification",
    "joint_fit": "jaxunilat.identify._bench:joint_fit",
}


def _identify_rows(size: Size, log) -> dict:
    """Every row of `ROWS`, by name: what its function returns."""
    import pkgutil

    return {name: pkgutil.resolve_name(target)(size, log) for name, target in ROWS.items()}


# -- driver ---------------------------------------------------------------------------------


def run_bench(size_name: str = "full", log: Callable[[str], None] = print) -> dict:
    """Run every section at `size_name` ("full", "quick" or "tiny") and return `bench.json`'s dict.

    **Returns:** a dictionary with `machine`, `goals` (keyed as in `_goals.GOALS`), `work_precision`,
    `throughput` and further sections (`scale_out`, `scale_processes`, `gradient`, `compile_s`,
    `no_retrace`, `static_structure`, `profile`, `reference_check`, the registered rows
    (`identification`, `joint_fit`), `user`: the users' code's measurements and the code
    they time).
    """
    size = SIZES[size_name]
    ts = np.linspace(0.0, T1, SAMPLES)
    started = time.perf_counter()
    result: dict = {"machine": machine(), "size": size.name}
    log(f"jaxunilat bench ({size.name}) on {result['machine']['backend']}: {result['machine']['devices']}")
    log("reference: DOP853 + events, rtol 1e-13, atol 1e-15")
    ref = peers.reference(peers.Params(), Y0, ts)
    result["reference_check"] = reference_check(ts)
    log(f"  against the drag-free closed form: max |dx| = {result['reference_check']['max_dx_m']:.1e} m")
    log("work-precision (Table 1 example 2, [0, 2] s, 2001 points):")
    project, compiled = _project_rows(size, ts, ref.x, log)
    result["work_precision"] = project + _peer_rows(size, ts, ref.x, log)
    result["compile_s"] = compiled
    log("throughput:")
    result["throughput"], result["throughput_checks"], own = _throughput(size, result["work_precision"], log)
    from . import _compiled

    log("compiled loop (event-located DOP853 in Numba), a peer beside scipy:")
    result["compiled_loop"] = _compiled.bench_section(
        size.compiled_tols,
        max(size.throughput_ns),
        TIGHT_ERROR,
        ts,
        ref.x,
        result["work_precision"],
        lambda fn: _timed(fn, size),
        log,
        own=own,
    )
    result["accelerator"] = accelerator_section(
        log,
        ns=size.accelerator_ns,
        repeats=max(2, size.repeats),
        fit=size.name == "full",
        compiled=result["compiled_loop"],
    )
    result["scale_out"] = _scale_out(size, log) if size.scale_out else {"how": f"skipped at size {size.name}"}
    result["scale_out"].setdefault("rows", [])
    log("sweep over processes (jax.distributed, this machine):")
    result["scale_processes"] = process_section(size.scale_n, max(2, size.repeats), size.scale_processes, log)
    if size.gradient:
        log("gradient cost:")
        result["gradient"] = _gradient(size, log)
    else:
        result["gradient"] = {"scene": f"skipped at size {size.name}", "losses": []}
    result["no_retrace"] = _no_retrace(size)
    log(f"  no retrace on new parameter values: {result['no_retrace']['ok']}")
    log("static structure (event mode, tol 1e-10):")
    result["static_structure"] = _skip_scenes(size, log)
    result["profile"] = _profile(log)
    result["profile"]["per_step_fit"] = per_step_fit(project)
    result["profile"]["loop_floor"] = _loop_floor(size, log)
    result.update(_identify_rows(size, log))
    log("the way users write code:")
    result["user"] = {
        "code": user.USER_CODE,
        "vmap_against_rows": user.vmap_against_rows(size, _timed_together, log),
        "vmap_outputs": user.vmap_outputs(size, _timed_together, log),
        "reverse_against_forward": user.reverse_against_forward(size, _timed_together, log),
        "command_line": user.command_line(size, log),
        "default_user": user.default_user(size, log),
    }
    result["goals"] = goals(result)
    result["total_s"] = time.perf_counter() - started
    return _clean(result)
