"""The bench on an accelerator: what a user with a GPU gets, beside the host's cores.

Where JAX's default backend is not the CPU, `jaxunilat bench` adds the `accelerator`
section (`bench.json`; the other sections keep their keys):

- `sweep`: `jaxunilat.sweep` throughput of the throughput scene (Table 1 example 2, event
  mode, Dopri8 pieces at 1e-10, [0, 2] s, 2001 save times) at N = 1e3, 1e4, 1e5 and 1e6 on
  the accelerator, the batch sized by `sweep` from the device's free memory;
- `latency`: one `simulate` call of that scene, warm, on the accelerator (placed there
  with `jax.default_device`) and as a user gets it by default (on the host: see
  `jaxunilat._internal.on_host`);
- `fit`: wall time of `jaxunilat identify` on the bundled drop trace in a fresh process
  (what a user runs; compile included, no cache);
- `compiled_loop`: the compiled loop's throughput on the same machine's cores (`prange`
  and serial), from the bench's `compiled_loop` section of the same run, beside the sweep.

On a CPU backend the section says it was skipped.
"""

from __future__ import annotations

import os
import statistics
import subprocess
import sys
import tempfile
import time

#: The sweep sizes of the accelerator section.
ACCELERATOR_NS = (1_000, 10_000, 100_000, 1_000_000)


def accelerator_section(log, ns=ACCELERATOR_NS, repeats: int = 3, fit: bool = True, compiled=None) -> dict:
    """The `accelerator` section (see the module docstring); `compiled`: the run's
    `compiled_loop` section, whose throughput rows go beside the sweep's."""
    import jax

    backend = jax.default_backend()
    if backend == "cpu":
        return {"status": "skipped: JAX's default backend is the CPU"}
    device = jax.devices()[0]
    log(f"accelerator ({device.device_kind}):")
    out = {
        "status": "measured",
        "backend": backend,
        "device": str(device),
        "device_kind": device.device_kind,
        "sweep": [_sweep_row(n, repeats, log) for n in ns],
        "latency": _latency(device, repeats, log),
    }
    out["fit"] = _fit_wall(log) if fit else {"status": "skipped at this size"}
    rows = (compiled or {}).get("throughput", [])
    out["compiled_loop"] = [
        {k: r.get(k) for k in ("method", "n", "traj_per_s", "wrong_rows")} for r in rows
    ] or {"status": (compiled or {}).get("status", "not measured")}
    return out


def _sweep_row(n: int, repeats: int, log) -> dict:
    """One sweep size: throughput, compile, the rows vmapped at once, all rows ok."""
    from ._scale import run_sweep

    try:
        row = run_sweep(n, repeats)
    except Exception as err:  # out of memory at the largest N, say: recorded, not fatal
        log(f"  sweep N = {n}: failed: {type(err).__name__}: {str(err).splitlines()[0][:200]}")
        return {"n": n, "error": f"{type(err).__name__}: {str(err).splitlines()[0][:200]}"}
    keep = ("n", "traj_per_s", "wall_s", "compile_s", "rows_at_once", "peak_mem_mb", "all_ok", "steps_mean")
    log(
        f"  sweep N = {n:>8}: {row['traj_per_s']:12.0f} traj/s, {row['rows_at_once']} rows at once, "
        f"compile {row['compile_s']:.1f} s, all ok {row['all_ok']}"
    )
    return {k: row[k] for k in keep}


def _latency(device, repeats: int, log) -> dict:
    """One warm `simulate` call on the accelerator and where the default puts it (s)."""
    import jax

    from ._scale import pairs, trajectory

    kappa, k_r = (float(v[0]) for v in pairs(1))

    def timed() -> float:
        jax.block_until_ready(trajectory(kappa, k_r))  # compile
        walls = []
        for _ in range(max(repeats, 5)):
            start = time.perf_counter()
            jax.block_until_ready(trajectory(kappa, k_r))
            walls.append(time.perf_counter() - start)
        return statistics.median(walls)

    with jax.default_device(device):
        on_device = timed()
    default = timed()
    log(
        f"  one simulate call: {1e3 * on_device:.2f} ms on the accelerator, {1e3 * default:.2f} ms by default"
    )
    return {"accelerator_s": on_device, "default_s": default}


def _fit_wall(log) -> dict:
    """`jaxunilat identify` of the bundled drop trace in a fresh process, no cache (s)."""
    from .._internal._io import bundled_data

    found = bundled_data("drop_trace.csv")
    if not found:
        return {"status": "no bundled data"}
    with tempfile.TemporaryDirectory(prefix="jaxunilat-bench-fit-") as work:
        env = dict(os.environ, JAXUNILAT_CACHE_DIR=os.path.join(work, "cache"), MPLBACKEND="Agg")
        start = time.perf_counter()
        proc = subprocess.run(
            [sys.executable, "-m", "jaxunilat", "--no-cache", "identify", found[0]],
            env=env,
            cwd=work,
            capture_output=True,
            text=True,
            check=False,
        )
        wall = time.perf_counter() - start
    row = {
        "command": "jaxunilat --no-cache identify data/drop_trace.csv",
        "wall_s": wall,
        "returncode": proc.returncode,
    }
    log(f"  jaxunilat identify (fresh process): {wall:.1f} s, exit {proc.returncode}")
    return row
