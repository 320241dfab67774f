"""A GPU check of `sweep`'s batch sizing, as one script that prints one JSON object.

Not collected by pytest (no `test_` prefix): run it by hand on a machine with a GPU,

    python tests/gpu_check.py                # N = 100 000 and 1 000 000, ~3-5 min on one H100

On the bench's throughput scene (Table 1 example 2, event mode, Dopri8 pieces at tol
1e-10, [0, 2] s, 2001 save times) it measures

- `simulate`: one call's compile time and warm latency (median of `--latency-runs` calls);
- `sweep` at N = `--n` rows: the default batch sizing (`batch_size=None`) against all rows
  at once (`batch_size=N`; the same program when the sizing takes them all), their results
  compared bit for bit, and (last, one warm run, skipped when the time is up) the former
  bench default, chunks of 1000 rows;
- `sweep` at N = `--n-big` rows with the default sizing (all at once would ask for ~135 GiB);
- `outputs`: the N = `--n` rows with 2 save times instead of 2001, default sizing, and the
  throughput ratio 2001 / 2 (what the outputs cost under `vmap`; the goal is >= 0.7).

Each sweep row: rows a device vmaps at once, first call (compile, sizing and run) and warm
medians [s], trajectories/s, the compiled program's bytes against the budget, and whether
every row succeeded (checked on the device: the outputs stay there). Without a GPU it prints
one line, `{"skipped": ...}`, and exits 0; `--cpu` runs it anyway (at small `--n`, e.g. to
check the script: `python tests/gpu_check.py --cpu --n 200 --n-big 400 --budget-bytes 4e7`,
where `--budget-bytes` stands in for the free memory and `--cpu` forces lockstep batching,
`JAXUNILAT_VMAP=batch`, so that the sizing applies).
"""

from __future__ import annotations

import argparse
import json
import os
import statistics
import sys
import time


def _parse(argv):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--n", type=int, default=100_000, help="rows of the default-against-all-at-once sweep")
    ap.add_argument("--n-big", type=int, default=1_000_000, help="rows of the large sweep (0: skip)")
    ap.add_argument("--repeats", type=int, default=3, help="warm runs per sweep (median)")
    ap.add_argument("--latency-runs", type=int, default=21, help="warm simulate calls (median)")
    ap.add_argument(
        "--time-limit", type=float, default=270.0, help="s; optional sections after it are skipped"
    )
    ap.add_argument("--cpu", action="store_true", help="run without a GPU (lockstep batching forced)")
    ap.add_argument(
        "--budget-bytes", type=float, default=None, help="(testing) free memory per device, bytes"
    )
    return ap.parse_args(argv)


def trajectory_two_samples(kappa, k_r):
    """The bench's throughput row with 2 save times instead of 2001 (module level, so that
    `sweep` compiles it once)."""
    from jaxunilat._bench._scale import solve

    sol = solve(kappa, k_r, samples=2)
    return sol.ys["x"], sol.status, sol.num_steps


def main(argv=None) -> int:
    args = _parse(sys.argv[1:] if argv is None else argv)
    if args.cpu:
        os.environ["JAXUNILAT_VMAP"] = "batch"  # GPUs' lockstep batching, so that sizing applies
    import jax

    import jaxunilat  # noqa: F401  (float64; on a CPU its loop-kernel option before JAX starts)

    backend = jax.default_backend()
    if backend == "cpu" and not args.cpu:
        print(json.dumps({"skipped": f"no GPU (JAX backend {backend!r}); --cpu runs it anyway"}))
        return 0

    import jax.numpy as jnp

    from jaxunilat._bench._scale import pairs, trajectory
    from jaxunilat._solver import _sweep
    from jaxunilat._solver._sweep import batch_rows, sweep, sweep_compiled

    if args.budget_bytes is not None:
        _sweep._free_bytes = lambda devices: int(args.budget_bytes)
    started = time.perf_counter()
    device = jax.devices()[0]
    out = {
        "device": str(device),
        "device_kind": getattr(device, "device_kind", None),
        "devices": jax.device_count(),
        "backend": backend,
        "jax": jax.__version__,
        "scene": "Table 1 example 2, event mode, dopri8 tol 1e-10, [0, 2] s, 2001 save times",
        "free_bytes": _sweep._free_bytes(jax.devices()),
        "budget_bytes": _sweep._budget(jax.devices()),
        "headroom": _sweep.HEADROOM,
    }

    # simulate: compile and warm latency.
    start = time.perf_counter()
    jax.block_until_ready(trajectory(1.0e4, 0.2))
    first = time.perf_counter() - start
    walls = []
    for i in range(args.latency_runs):
        start = time.perf_counter()
        jax.block_until_ready(trajectory(1.0e4 + i, 0.2))
        walls.append(time.perf_counter() - start)
    out["simulate"] = {"first_call_s": first, "latency_s": statistics.median(walls), "runs": len(walls)}
    print(f"simulate: first {first:.1f} s, warm {1e3 * statistics.median(walls):.2f} ms", file=sys.stderr)

    def timed_sweep(label, n, batch_size, keep=False, repeats=args.repeats):
        kappa, k_r = pairs(n)
        kw = {} if batch_size is None else {"batch_size": batch_size}
        start = time.perf_counter()
        res = jax.block_until_ready(sweep(trajectory, kappa, k_r, **kw))
        first = time.perf_counter() - start
        walls = []
        for _ in range(repeats):
            del res
            start = time.perf_counter()
            res = jax.block_until_ready(sweep(trajectory, kappa, k_r, **kw))
            walls.append(time.perf_counter() - start)
        x, status, steps = res
        mem = sweep_compiled(trajectory, kappa, k_r, **kw).memory_analysis()
        wall = statistics.median(walls)
        row = {
            "label": label,
            "n": n,
            "batch_size": batch_size,
            "rows_at_once": batch_rows(trajectory, kappa, k_r) if batch_size is None else min(batch_size, n),
            "first_call_s": first,
            "wall_s": wall,
            "runs": len(walls),
            "traj_per_s": n / wall,
            "program_bytes": None if mem is None else _sweep._total(mem),
            "all_ok": bool(jnp.all(status == 0)),
            "finite": bool(jnp.all(jnp.isfinite(x))),
            "steps_mean": float(jnp.mean(steps)),
        }
        print(
            f"sweep {label}: N = {n}, {row['rows_at_once']} rows at once, {row['traj_per_s']:.0f} traj/s "
            f"(first call {first:.1f} s), all ok {row['all_ok']}",
            file=sys.stderr,
        )
        return row, (x if keep else None)

    rows = []
    row, x_default = timed_sweep("default sizing", args.n, None, keep=True)
    rows.append(row)
    row, x_all = timed_sweep("all at once", args.n, args.n, keep=True)
    row["max_abs_dx_vs_default_m"] = float(jnp.max(jnp.abs(x_all - x_default)))
    row["bitwise_equal_to_default"] = bool(jnp.array_equal(x_all, x_default))
    rows.append(row)
    del x_default, x_all
    if args.n_big:
        row, _ = timed_sweep("default sizing", args.n_big, None)
        key = next((k for k in _sweep._SIZING if k[0] is trajectory), None)
        if key is not None:
            per_row, fixed = _sweep._SIZING[key]
            row["per_row_bytes"] = {"temp": per_row[0], "output": per_row[1], "argument": per_row[2]}
            row["all_at_once_bytes"] = fixed + args.n_big * sum(per_row)
        rows.append(row)
    # The outputs' cost under vmap: the same rows with 2 save times instead of 2001.
    kappa, k_r = pairs(args.n)
    jax.block_until_ready(sweep(trajectory_two_samples, kappa, k_r))
    walls = []
    for _ in range(args.repeats):
        start = time.perf_counter()
        jax.block_until_ready(sweep(trajectory_two_samples, kappa, k_r))
        walls.append(time.perf_counter() - start)
    two = args.n / statistics.median(walls)
    out["outputs"] = {
        "n": args.n,
        "traj_per_s_2_save_times": two,
        "traj_per_s_2001_save_times": rows[0]["traj_per_s"],
        "ratio_2001_vs_2": rows[0]["traj_per_s"] / two,
    }
    print(
        f"outputs: 2 save times {two:.0f} traj/s, ratio 2001/2 {out['outputs']['ratio_2001_vs_2']:.2f}",
        file=sys.stderr,
    )
    label = "chunks of 1000 (the former bench default)"
    if args.n <= 1000:
        rows.append({"label": label, "skipped": f"N = {args.n}: one chunk"})
    elif time.perf_counter() - started > args.time_limit:
        rows.append({"label": label, "skipped": f"over the time limit ({args.time_limit:g} s)"})
    else:
        rows.append(timed_sweep(label, args.n, 1000, repeats=1)[0])
    out["sweep"] = rows
    out["total_s"] = time.perf_counter() - started
    print(json.dumps(out))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
