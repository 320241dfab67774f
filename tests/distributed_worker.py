"""One process of a `jaxunilat.sweep` spread over several processes with `jax.distributed`.

Every process runs this same script with the same grid; `sweep` shards the rows over
the devices of all processes (each device computes its own rows) and hands the whole
result to every process; process 0 saves it. Also the example of the top-level README:

    # one command per host (or several on one machine, each with its own --process-id):
    python tests/distributed_worker.py --coordinator HOST0:12355 --num-processes 2 --process-id 0 --out run
    python tests/distributed_worker.py --coordinator HOST0:12355 --num-processes 2 --process-id 1 --out run

    # under SLURM (`jax.distributed.initialize()` reads SLURM's variables):
    srun --ntasks 2 python tests/distributed_worker.py --out run

On CPUs add `XLA_FLAGS=--xla_force_host_platform_device_count=2` for two devices per
process (one per core); the CPU collectives that gather the result go through gloo.

Writes `OUT/rows_<process>.json` (the global rows this process computed, recorded as
they run) and, on process 0, `OUT/result.npz` (`x` [m] at the save times [s] `ts`,
`kappa` [N/m]). A watchdog ends a process that has no result `--watchdog` seconds after start-up
(a peer hangs) with exit status 3 and a message on stderr; `jax.distributed` itself
aborts the processes when one dies (no heartbeat for `--heartbeat` seconds).

Exit status 2 and one line on stderr: process 0 found the coordinator's port taken (it
tries to bind it before starting `jax.distributed`, whose service would crash on it; the
other processes cannot tell a stranger on that port from the coordinator and end after
`--init-timeout`), or `sweep` refused its input (`InputError`: e.g. a function or grid
that differs between processes).
"""

from __future__ import annotations

import argparse
import errno
import faulthandler
import functools
import hashlib
import json
import os
import socket
import sys
import threading
import time

import numpy as np

#: Table 1 example 2 dropped from 1 cm above the lower wall at -3 m/s [m, m/s].
Y0 = (-0.39, -3.0)
#: The exit status of a process that its watchdog ended.
WATCHDOG_EXIT = 3
#: The exit status of bad input: a taken coordinator port, or a sweep that refused its input.
INPUT_EXIT = 2

#: The global rows this process computed (appended from the running program).
ROWS: list[int] = []


def grid(n: int) -> np.ndarray:
    """n contact stiffnesses κ [N/m], log-spaced over Table 1's range [5e3, 2e4]."""
    return np.geomspace(5e3, 2e4, n)


def _record(rows) -> None:
    ROWS.extend(int(r) for r in np.atleast_1d(np.asarray(rows)))


def trajectory(row, kappa, t1=0.1):
    """One row of the sweep: x [m] at 11 points over [0, t1] s (Tsit5, tolerance 1e-8);
    `row` (the row's global index) is recorded on the process that computes it."""
    import jax

    import jaxunilat as ju

    jax.debug.callback(_record, row)
    sol = ju.simulate(
        ju.Ball.table1(2, kappa=kappa),
        np.asarray(Y0),
        t1,
        rtol=1e-8,
        atol=1e-8,
        samples=11,
        outputs=("x",),
        max_steps=1024,
    )
    return sol.ys["x"]


def _watchdog(seconds: float, process: int) -> None:
    """End this process `seconds` from now unless it finished: a message and exit status
    3 (a Python thread), or, should the interpreter be stuck, faulthandler's tracebacks
    and exit status 1 five seconds later. (`jax.distributed` ends a process by itself,
    with SIGABRT, when a peer stops sending heartbeats; a peer that hangs with its
    heartbeats going needs this.)"""

    def expire():
        sys.stderr.write(
            f"distributed_worker: process {process} has no result after {seconds:g} s "
            "(a peer process died or hangs); giving up\n"
        )
        sys.stderr.flush()
        os._exit(WATCHDOG_EXIT)

    timer = threading.Timer(seconds, expire)
    timer.daemon = True
    timer.start()
    faulthandler.dump_traceback_later(seconds + 5, exit=True)


def _port_taken(coordinator: str) -> str | None:
    """Why process 0 cannot serve `coordinator` (HOST:PORT): one line naming the address,
    or None when the port is free (or cannot be checked: then jax reports).

    jax.distributed's service binds every interface on the coordinator's port
    (`[::]:PORT`, or `JAX_COORDINATOR_BIND_ADDRESS`); this binds the same, as gRPC does
    (SO_REUSEADDR: a port whose last connection is in TIME_WAIT is free). A port that
    another program takes between this check and jax's bind still crashes the service."""
    bind = os.environ.get("JAX_COORDINATOR_BIND_ADDRESS") or "[::]:" + coordinator.rpartition(":")[2]
    host, _, port = bind.rpartition(":")
    try:
        family, kind, proto, _, address = socket.getaddrinfo(
            host.strip("[]") or None, int(port), type=socket.SOCK_STREAM, flags=socket.AI_PASSIVE
        )[0]
        probe = socket.socket(family, kind, proto)
    except (OSError, ValueError):
        return None  # not an address this machine can bind: jax says why
    with probe:
        probe.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)
        if family == socket.AF_INET6:
            probe.setsockopt(socket.IPPROTO_IPV6, socket.IPV6_V6ONLY, 0)  # IPv4 too, as gRPC
        try:
            probe.bind(address)
        except OSError as e:
            if e.errno not in (errno.EADDRINUSE, errno.EACCES):
                return None
            return (
                f"distributed_worker: cannot start the coordinator at {coordinator} (binding {bind}: "
                f"{e.strerror}); choose another port in --coordinator HOST:PORT"
            )
    return None


def _parse(argv):
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--coordinator", help="HOST:PORT of process 0 (default: SLURM's, via jax)")
    p.add_argument("--num-processes", type=int)
    p.add_argument("--process-id", type=int)
    p.add_argument("--rows", type=int, default=8, help="κ grid size")
    p.add_argument("--t1", type=float, default=0.1, help="end time [s]")
    p.add_argument("--out", required=True, help="output folder")
    p.add_argument("--init-timeout", type=int, default=300, help="wait this long for all processes [s]")
    p.add_argument("--watchdog", type=float, default=300.0, help="give up this long after start-up [s]")
    p.add_argument("--heartbeat", type=int, default=60, help="jax.distributed heartbeat timeout [s]")
    p.add_argument("--hang", action="store_true", help="(testing) hang after start-up")
    p.add_argument(
        "--mismatch", action="store_true", help="(testing) then sweep a different grid per process"
    )
    return p.parse_args(argv)


def main(argv=None) -> int:
    args = _parse(argv)
    taken = args.coordinator and args.process_id == 0 and _port_taken(args.coordinator)
    if taken:
        print(taken, file=sys.stderr)
        return INPUT_EXIT
    import jax

    import jaxunilat as ju
    from jaxunilat._internal import InputError

    jax.config.update("jax_cpu_collectives_implementation", "gloo")
    jax.distributed.initialize(
        args.coordinator,
        args.num_processes,
        args.process_id,
        # Given a coordinator, use the arguments alone (no SLURM/MPI detection).
        cluster_detection_method=None if args.coordinator is None else "deactivate",
        initialization_timeout=args.init_timeout,
        heartbeat_timeout_seconds=args.heartbeat,
    )
    me = jax.process_index()
    _watchdog(args.watchdog, me)
    print(
        f"process {me} of {jax.process_count()}: {jax.local_device_count()} of {jax.device_count()} devices",
        flush=True,
    )
    if args.hang:
        time.sleep(10 * args.watchdog)
    kappa = grid(args.rows)
    rows = np.arange(args.rows)
    try:
        x = np.asarray(ju.sweep(functools.partial(trajectory, t1=args.t1), rows, kappa))
    except InputError as e:  # refused on every process: nothing ran
        print(f"distributed_worker: process {me}: {e}", file=sys.stderr, flush=True)
        jax.distributed.shutdown()
        return INPUT_EXIT
    os.makedirs(args.out, exist_ok=True)
    record = {
        "process": me,
        "devices": jax.local_device_count(),
        "rows": sorted(ROWS),
        "result_sha256": hashlib.sha256(x.tobytes()).hexdigest(),  # every process gets all rows
    }
    if args.mismatch:  # sweep must refuse arguments that differ between processes
        try:
            ju.sweep(functools.partial(trajectory, t1=args.t1), rows, kappa * (1 + me))
        except ValueError as e:
            record["mismatch_error"] = str(e)
    with open(os.path.join(args.out, f"rows_{me}.json"), "w") as f:
        json.dump(record, f)
    if me == 0:
        np.savez(os.path.join(args.out, "result.npz"), x=x, kappa=kappa, ts=np.linspace(0.0, args.t1, 11))
    print(f"process {me}: done, {len(ROWS)} rows computed here", flush=True)
    jax.distributed.shutdown()
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
