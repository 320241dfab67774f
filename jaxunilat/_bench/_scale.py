"""The benchmark's throughput scene and its 1-device against N-device measurement.

Two ways to sweep: vmapped rows, as many at once as the device's free memory holds
(`sweep`'s default `batch_size=None`: all of them, or equal chunks), and rows one by one
(`batch_size=1`), which on a CPU whose loops compile into single kernels
(`use_loop_kernels`) runs each row at its own pace instead of in lockstep.
`jaxunilat bench` gives its process one CPU device per core (`host_devices`) so that
`sweep` shards the rows over every core. `python -m jaxunilat._bench._scale N REPEATS
[--one-by-one]` prints one JSON object with the sharded sweep's throughput on the first
device alone and on all visible devices, for a process that could not get them itself.

`process_rows` times the same sweep spread over 1, 2, 4 processes on this machine
(`jax.distributed` on a loopback coordinator, one CPU device each, gloo collectives):
`python -m jaxunilat._bench._scale --processes 1,2,4 N REPEATS [--one-by-one]` prints
their rows as one JSON object.
"""

from __future__ import annotations

import json
import statistics
import sys
import time

import numpy as np

#: Table 1 example 2 over [0, 2] s, x saved at 2001 points [K90 §5.1].
T1 = 2.0
SAMPLES = 2001
Y0 = (-0.4, -1.0 / 0.122)
#: The throughput scene's event mode: Dopri8 pieces at this tolerance (error ≤ 1e-8 m on
#: example 2, about 125 steps) and buffers.
TOL = 1e-10
PIECE = "dopri8"
MAX_STEPS = 512
MAX_EVENTS = 256


def pairs(n: int, seed: int = 0) -> tuple[np.ndarray, np.ndarray]:
    """n (κ [N/m], k_r [N·s/m]) pairs, log-uniform over Table 1's ranges [5e3, 2e4] × [0.1, 0.4]."""
    rng = np.random.default_rng(seed)
    kappa = 10 ** rng.uniform(np.log10(5e3), np.log10(2e4), n)
    k_r = 10 ** rng.uniform(np.log10(0.1), np.log10(0.4), n)
    return kappa, k_r


def solve(kappa, k_r, samples: int = SAMPLES):
    """The throughput scene at (κ [N/m], k_r [N·s/m]) with `samples` save times of x: the
    event mode's `Solution` (`throw=False`: the status says how it went)."""
    from .._models._ball import Ball
    from .._solver._simulate import simulate

    return simulate(
        Ball.table1(2, kappa=kappa, k_r=k_r),
        np.asarray(Y0),
        T1,
        solver="event",
        piece_solver=PIECE,
        rtol=TOL,
        atol=TOL,
        samples=samples,
        outputs=("x",),
        max_steps=MAX_STEPS,
        max_events=MAX_EVENTS,
        throw=False,
    )


def trajectory(kappa, k_r):
    """One row of the sweep: (x at the save times [m], status, steps) in the event mode."""
    sol = solve(kappa, k_r)
    return sol.ys["x"], sol.status, sol.num_steps


#: The option `host_devices` added to `XLA_FLAGS`, if any (the bench's child commands
#: run without it, as users do).
ADDED_XLA_FLAG: str | None = None


def host_devices() -> int | None:
    """Give this process one CPU device per core, if JAX has not started yet (the
    benchmark command calls it first): `sweep` then shards rows over every core.

    **Returns:** the device count asked for, or None if it was too late or already set.
    """
    import os

    from .._internal._loop_kernels import add_xla_flags

    flags = os.environ.get("XLA_FLAGS", "")
    count = os.cpu_count() or 1
    if "xla_force_host_platform_device_count" in flags:
        return None
    option = f"--xla_force_host_platform_device_count={count}"
    if not add_xla_flags(f"{flags} {option}".strip()):
        return None
    global ADDED_XLA_FLAG
    ADDED_XLA_FLAG = option
    return count


def one_by_one_fastest() -> bool:
    """Whether sweeping rows one by one beats vmapped rows here: on a CPU whose loops
    compile into single kernels (`use_loop_kernels`). On a GPU, vmap."""
    import jax

    from .._internal._loop_kernels import loop_kernel_bytes

    return jax.default_backend() == "cpu" and loop_kernel_bytes() is not None


def strategy(one_by_one: bool) -> str:
    """The sweep strategy's name in the benchmark's rows."""
    return "rows one by one (batch_size=1)" if one_by_one else "vmapped (batch sized to free memory)"


def sweep_kwargs(n: int, devices=None, one_by_one: bool = False) -> dict:
    """`sweep`'s options for a batch of n rows: one by one, or vmapped with `sweep`'s own
    sizing (all rows at once where the compiled program fits the free memory, else equal
    chunks of the most that fit)."""
    del n  # sweep sizes the batch itself
    if one_by_one:
        return dict(devices=devices, batch_size=1)
    return dict(devices=devices)


def run_sweep(n: int, repeats: int, devices=None, one_by_one: bool = False) -> dict:
    """Time `sweep(trajectory, ...)` over n pairs: compile, median wall, memory, steps."""
    import jax

    from .._solver._sweep import batch_rows, sweep, sweep_compiled

    kappa, k_r = pairs(n)
    kw = sweep_kwargs(n, devices, one_by_one)
    start = time.perf_counter()
    compiled = sweep_compiled(trajectory, kappa, k_r, **kw)
    compile_s = time.perf_counter() - start
    out = jax.block_until_ready(sweep(trajectory, kappa, k_r, **kw))
    walls = []
    for _ in range(repeats):
        start = time.perf_counter()
        out = jax.block_until_ready(sweep(trajectory, kappa, k_r, **kw))
        walls.append(time.perf_counter() - start)
    wall = statistics.median(walls)
    n_dev = len(jax.devices() if devices is None else devices)
    mem = compiled.memory_analysis()
    per_device = None
    if mem is not None:
        per_device = mem.argument_size_in_bytes + mem.output_size_in_bytes + mem.temp_size_in_bytes
        per_device -= mem.alias_size_in_bytes
    x, status, steps = (np.asarray(a) for a in out)
    batch = kw.get("batch_size") or batch_rows(trajectory, kappa, k_r, devices=devices)
    return {
        "n": int(n),
        "strategy": strategy(one_by_one),
        "devices": n_dev,
        # Rows a device vmaps at once (the chunk of `lax.map`, or all of its rows).
        "rows_at_once": int(min(batch, -(-n // n_dev))),
        "wall_s": wall,
        "runs": len(walls),
        "compile_s": compile_s,
        "traj_per_s": n / wall,
        "peak_mem_mb": None if per_device is None else per_device * n_dev / 2**20,
        "all_ok": bool(np.all(status == 0)),
        "steps_mean": float(np.mean(steps)),
        "steps_max": int(np.max(steps)),
        "x": x,
        "kappa": kappa,
        "k_r": k_r,
    }


def scale_rows(n: int, repeats: int, one_by_one: bool = False) -> list[dict]:
    """Throughput on the first device alone, then on all visible devices."""
    import jax

    rows = []
    for devices in (jax.devices()[:1], jax.devices()):
        row = run_sweep(n, repeats, devices=devices, one_by_one=one_by_one)
        rows.append({k: v for k, v in row.items() if k not in ("x", "kappa", "k_r")})
    return rows


#: The longest one process count's run may take before its processes are killed [s].
PROCESS_TIMEOUT = 600.0


def _free_port() -> int:
    import socket

    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def _process_env() -> dict:
    """This environment with one CPU device per process (loop-kernel options kept)."""
    import os

    env = {k: v for k, v in os.environ.items() if not k.startswith(("SLURM_", "OMPI_", "JAX_COORDINATOR"))}
    flags = [f for f in env.get("XLA_FLAGS", "").split() if "xla_force_host_platform_device_count" not in f]
    env["XLA_FLAGS"] = " ".join([*flags, "--xla_force_host_platform_device_count=1"])
    env["JAX_PLATFORMS"] = "cpu"
    return env


#: A child process's command (`-c`: `-m` would import this module twice).
_CHILD = "import sys; from jaxunilat._bench._scale import main; sys.exit(main(sys.argv[1:]))"


def _run_processes(count: int, n: int, repeats: int, one_by_one: bool) -> dict:
    """One `run_sweep` spread over `count` processes; process 0's row (or the failure)."""
    import subprocess
    import tempfile

    port = _free_port()
    with tempfile.TemporaryDirectory() as tmp:
        cmd = [sys.executable, "-c", _CHILD, "--process", str(count), "PID", str(port)]
        cmd += [str(n), str(repeats), f"{tmp}/x.npy"] + (["--one-by-one"] if one_by_one else [])
        logs = [open(f"{tmp}/log_{i}", "w+") for i in range(count)]  # noqa: SIM115
        procs = [
            subprocess.Popen(
                [str(i) if a == "PID" else a for a in cmd],
                env=_process_env(),
                stdout=logs[i],
                stderr=subprocess.STDOUT,
            )
            for i in range(count)
        ]
        try:
            codes = [p.wait(timeout=PROCESS_TIMEOUT) for p in procs]
        except subprocess.TimeoutExpired:
            codes = None
        finally:
            for p in procs:
                if p.poll() is None:
                    p.kill()
                    p.wait()
        texts = []
        for f in logs:
            f.seek(0)
            texts.append(f.read())
            f.close()
        if codes is None or any(codes):
            why = "timed out" if codes is None else f"exit statuses {codes}"
            tail = (texts[0].strip().splitlines() or ["no output"])[-1]
            return {"processes": count, "failed": f"{why}: {tail}"}
        return json.loads(texts[0].strip().splitlines()[-1]) | {"x": np.load(f"{tmp}/x.npy")}


def process_rows(n: int, repeats: int, counts=(1, 2, 4), one_by_one: bool = False) -> list[dict]:
    """Throughput of `sweep(trajectory, ...)` over n pairs spread over each of `counts`
    processes on this machine (one CPU device each; `jax.distributed`, gloo collectives).

    **Returns:** one row per count: `processes`, `traj_per_s`, `wall_s` (median of
    `repeats` runs after a warm-up, gather to every process included), `compile_s`,
    `all_ok`, `max_dx_vs_first_m` (max |x - x of the first count| [m]; 0.0: bitwise
    equal), or `failed` with the reason.
    """
    rows, first = [], None
    for count in counts:
        row = _run_processes(count, n, repeats, one_by_one)
        x = row.pop("x", None)
        if x is not None:
            first = x if first is None else first
            row["max_dx_vs_first_m"] = float(np.max(np.abs(x - first)))
        rows.append(row)
    return rows


def _process_main(argv: list[str]) -> int:
    """One process of `process_rows`: COUNT ID PORT N REPEATS X_PATH [--one-by-one]."""
    import jax

    import jaxunilat  # noqa: F401  (float64)

    count, me, port, n, repeats = (int(a) for a in argv[:5])
    jax.config.update("jax_cpu_collectives_implementation", "gloo")
    jax.distributed.initialize(
        f"127.0.0.1:{port}",
        count,
        me,
        cluster_detection_method="deactivate",
        initialization_timeout=int(PROCESS_TIMEOUT),
        heartbeat_timeout_seconds=30,
    )
    row = run_sweep(n, repeats, one_by_one="--one-by-one" in argv[6:])
    if me == 0:
        np.save(argv[5], row["x"])
        print(
            json.dumps(
                {"processes": count} | {k: v for k, v in row.items() if k not in ("x", "kappa", "k_r")}
            )
        )
    jax.distributed.shutdown()
    return 0


def main(argv: list[str] | None = None) -> int:
    argv = sys.argv[1:] if argv is None else argv
    if argv[:1] == ["--process"]:
        return _process_main(argv[1:])
    if argv[:1] == ["--processes"]:
        import jaxunilat  # noqa: F401  (float64)

        counts = tuple(int(c) for c in argv[1].split(","))
        n, repeats = int(argv[2]), int(argv[3])
        print(json.dumps({"rows": process_rows(n, repeats, counts, one_by_one="--one-by-one" in argv[4:])}))
        return 0
    import jax

    import jaxunilat  # noqa: F401  (float64)

    n, repeats = int(argv[0]), int(argv[1])
    rows = scale_rows(n, repeats, one_by_one="--one-by-one" in argv[2:])
    print(json.dumps({"platform": jax.default_backend(), "device_count": jax.device_count(), "rows": rows}))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())


def process_section(n: int, repeats: int, counts: tuple[int, ...], log) -> dict:
    """The benchmark's `scale_processes` section: `process_rows` (skipped for no counts),
    each row logged."""
    if not counts:
        return {"how": "skipped at this size", "rows": []}
    one_by_one = one_by_one_fastest()
    rows = process_rows(n, repeats, counts, one_by_one)
    for row in rows:
        if "failed" in row:
            log(f"  {row['processes']} process(es): failed ({row['failed']})")
        else:
            log(
                f"  {row['processes']} process(es) x 1 CPU device, N = {row['n']}, {row['strategy']}: "
                f"{row['traj_per_s']:.1f} traj/s (max |dx| vs {counts[0]}: {row['max_dx_vs_first_m']:.1e} m)"
            )
    how = "jax.distributed on 127.0.0.1, one CPU device per process, gloo collectives"
    return {"how": how, "rows": rows}
