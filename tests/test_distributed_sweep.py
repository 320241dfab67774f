"""`jaxunilat.sweep` across processes: `jax.distributed` on a loopback coordinator.

Processes of `tests/distributed_worker.py` on this machine (CPU devices, gloo
collectives) sweep a κ grid of the ball model together. Their result must be bitwise
equal to the same sweep in this one process, reach process 0 (and every other
process), and each row must be computed exactly once: every process records the global
rows its devices ran (a `jax.debug.callback` inside the row function), and their union
is the grid, without overlap (the padding rows, copies of the last row, aside).

Processes whose function differs (another end time closed over) must all refuse the
sweep, with exit status 2 and the reason; a coordinator port that is already taken must
end process 0 with exit status 2 and one line on stderr (not a crash of jax's service).

A killed worker and a hung one must end their peers with an error within a time limit:
the killed one through `jax.distributed`'s heartbeat, the hung one through the worker's
watchdog. All groups start at once (the hung group mostly waits), and every process
is killed at `DEADLINE` at the latest, so the file can never hang.
"""

from __future__ import annotations

import functools
import os
import signal
import socket
import subprocess
import sys
import time
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
import pytest

import jaxunilat

pytestmark = pytest.mark.slow

WORKER = Path(__file__).with_name("distributed_worker.py")
#: The longest the whole file's processes may run before they are killed [s].
DEADLINE = 240.0
#: The jax.distributed heartbeat timeout of the kill scenario, and the time its surviving
#: process gets to end after the kill [s].
HEARTBEAT = 10
AFTER_KILL = 45.0
#: The hung scenario's watchdog [s] (from the end of start-up).
HANG_WATCHDOG = 15.0
#: The success scenarios: name -> (processes, CPU devices each, rows).
SCENARIOS = {"2x2": (2, 2, 7), "4x1": (4, 1, 8)}  # 2x2: 4 devices, one padding row
#: The end times [s] of the processes of the scenario whose function differs.
DIFFERENT_T1 = ("0.1", "0.3")


def _free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def _env(devices: int) -> dict:
    """This environment (the suite's XLA options included) with `devices` CPU devices per
    process and no cluster variables that jax.distributed could pick up."""
    env = {k: v for k, v in os.environ.items() if not k.startswith(("SLURM_", "OMPI_", "JAX_COORDINATOR"))}
    flags = [f for f in env.get("XLA_FLAGS", "").split() if "xla_force_host_platform_device_count" not in f]
    env["XLA_FLAGS"] = " ".join([*flags, f"--xla_force_host_platform_device_count={devices}"])
    env["JAX_PLATFORMS"] = "cpu"
    return env


@dataclass
class Group:
    """Processes of one `jax.distributed` run, their logs and exit statuses."""

    out: Path
    procs: list = field(default_factory=list)
    logs: list = field(default_factory=list)
    ended: dict = field(default_factory=dict)  # process id -> (exit status, time.monotonic())

    def log(self, i: int) -> str:
        return self.logs[i].read_text(errors="replace")

    def poll(self) -> bool:
        """Record the processes that ended; True when all have."""
        for i, p in enumerate(self.procs):
            if i not in self.ended and p.poll() is not None:
                self.ended[i] = (p.returncode, time.monotonic())
        return len(self.ended) == len(self.procs)

    def kill(self) -> None:
        for i, p in enumerate(self.procs):
            if p.poll() is None:
                p.kill()
                p.wait()
            self.ended.setdefault(i, (p.returncode, time.monotonic()))


def _start(
    tmp: Path,
    name: str,
    n_proc: int,
    devices: int,
    *extra: str,
    hang: int | None = None,
    each: list | None = None,
) -> Group:
    """`n_proc` workers with the arguments `extra`, process `hang` hanging, and `each[i]`
    (if given) appended to process i's arguments."""
    port, group = _free_port(), Group(tmp / name)
    group.out.mkdir(parents=True)
    try:
        for i in range(n_proc):
            cmd = [sys.executable, "-u", str(WORKER), "--coordinator", f"127.0.0.1:{port}"]
            cmd += ["--num-processes", str(n_proc), "--process-id", str(i), "--out", str(group.out), *extra]
            cmd += ["--hang"] if i == hang else []
            cmd += list(each[i]) if each else []
            group.logs.append(group.out / f"log_{i}.txt")
            with open(group.logs[-1], "w") as f:
                group.procs.append(
                    subprocess.Popen(cmd, env=_env(devices), stdout=f, stderr=subprocess.STDOUT)
                )
    except BaseException:
        group.kill()
        raise
    return group


def _run_all(tmp: Path) -> dict:
    """Start every scenario, kill the kill scenario's process 1 once it is up, wait for all
    (at most `DEADLINE` s), kill what is left."""
    groups, start, killed_at = {}, time.monotonic(), None
    try:
        for name, (p, d, n) in SCENARIOS.items():
            groups[name] = _start(tmp, name, p, d, "--rows", str(n), "--mismatch")
        groups["killed"] = _start(tmp, "killed", 2, 1, "--heartbeat", str(HEARTBEAT), hang=1)
        groups["hung"] = _start(tmp, "hung", 2, 1, "--watchdog", str(HANG_WATCHDOG), hang=1)
        each = [("--t1", t1) for t1 in DIFFERENT_T1]
        groups["fn_differs"] = _start(tmp, "fn_differs", 2, 1, "--rows", "2", each=each)
        expected = _single_process([n for _, _, n in SCENARIOS.values()])  # meanwhile
        while time.monotonic() - start < DEADLINE:
            victim = groups["killed"].procs[1]
            if killed_at is None and "process 1 of 2" in groups["killed"].log(1):
                time.sleep(1.0)  # process 0 is inside sweep, waiting for process 1
                victim.send_signal(signal.SIGKILL)
                killed_at = time.monotonic()
            if all([g.poll() for g in groups.values()]):  # a list: poll every group
                break
            time.sleep(0.2)
    finally:
        for g in groups.values():
            g.kill()
    return {"groups": groups, "killed_at": killed_at, "expected": expected}


@pytest.fixture(scope="module")
def runs(tmp_path_factory):
    return _run_all(tmp_path_factory.mktemp("distributed"))


def _single_process(ns: list[int]) -> list[np.ndarray]:
    """The workers' sweeps over grids of `ns` rows, as one sweep in this process (one
    device, one compile: the rows are independent)."""
    import distributed_worker as worker

    fn = functools.partial(worker.trajectory, t1=0.1)
    rows = np.concatenate([np.arange(n) for n in ns])
    x = np.asarray(jaxunilat.sweep(fn, rows, np.concatenate([worker.grid(n) for n in ns])))
    return np.split(x, np.cumsum(ns)[:-1])


def _records(group: Group) -> list[dict]:
    import json

    return [json.loads((group.out / f"rows_{i}.json").read_text()) for i in range(len(group.procs))]


@pytest.mark.parametrize("name", list(SCENARIOS))
def test_sweep_over_processes_matches_one_process_bitwise(runs, name):
    (n_proc, devices, n), group = SCENARIOS[name], runs["groups"][name]
    for i in range(n_proc):
        assert group.ended[i][0] == 0, f"process {i} failed:\n{group.log(i)[-3000:]}"
    result = np.load(group.out / "result.npz")
    expected = runs["expected"][list(SCENARIOS).index(name)]
    assert result["x"].shape == expected.shape == (n, 11)
    np.testing.assert_array_equal(result["x"], expected)  # bitwise
    assert np.all(np.ptp(result["x"], axis=0)[1:] > 0)  # the rows differ: κ reached them
    records = _records(group)
    assert {r["result_sha256"] for r in records} == {records[0]["result_sha256"]}  # all got it
    # Each process ran its own contiguous block of rows; together each row once.
    n_pad = -n % (n_proc * devices)
    per = (n + n_pad) // n_proc
    rows = []
    for i, r in enumerate(records):
        assert r["devices"] == devices
        assert r["rows"] == sorted(min(k, n - 1) for k in range(i * per, (i + 1) * per))
        rows += r["rows"]
    counts = np.bincount(rows, minlength=n)
    assert counts[: n - 1].tolist() == [1] * (n - 1)
    assert counts[n - 1] == 1 + n_pad  # the padding rows repeat the last one
    for r in records:  # a grid that differs between processes is refused, on each
        assert "args differ between processes" in r.get("mismatch_error", ""), r


def test_a_killed_worker_ends_the_others_with_an_error(runs):
    group, killed_at = runs["groups"]["killed"], runs["killed_at"]
    assert killed_at is not None, "process 1 never came up:\n" + group.log(1)[-3000:]
    status, ended = group.ended[0]
    log = group.log(0)
    assert status != 0, log[-3000:]
    assert ended - killed_at < AFTER_KILL, f"process 0 ended {ended - killed_at:.0f} s after the kill"
    assert "another task died" in log or "stopped sending heartbeats" in log, log[-3000:]
    assert not (group.out / "result.npz").exists()


def test_a_hung_worker_ends_by_the_watchdog(runs):
    group = runs["groups"]["hung"]
    for i in range(2):
        status, _ = group.ended[i]
        log = group.log(i)
        assert status == 3, f"process {i}: exit status {status}\n{log[-3000:]}"
        assert f"process {i} has no result after {HANG_WATCHDOG:g} s" in log
    assert "process 0 of 2" in group.log(0)  # it got as far as the sweep
    assert not (group.out / "result.npz").exists()


def test_a_function_that_differs_between_processes_is_refused_on_each(runs):
    group = runs["groups"]["fn_differs"]
    for i in range(2):
        status, _ = group.ended[i]
        log = group.log(i)
        assert status == 2, f"process {i}: exit status {status}\n{log[-3000:]}"
        assert f"process {i}: fn differs between processes (program fingerprints [" in log, log[-3000:]
        assert "pass every process the same function" in log
    assert not (group.out / "result.npz").exists()
    for name in SCENARIOS:  # the same function on every process still sweeps
        assert {status for status, _ in runs["groups"][name].ended.values()} == {0}


def test_a_taken_coordinator_port_is_one_line_and_exit_2(tmp_path):
    with socket.socket() as squatter:
        squatter.bind(("127.0.0.1", 0))
        squatter.listen()
        address = f"127.0.0.1:{squatter.getsockname()[1]}"
        cmd = [sys.executable, str(WORKER), "--coordinator", address, "--num-processes", "2"]
        cmd += ["--process-id", "0", "--out", str(tmp_path)]
        done = subprocess.run(cmd, env=_env(1), capture_output=True, text=True, timeout=60)
    assert done.returncode == 2, done.stderr[-3000:]
    (line,) = done.stderr.splitlines()
    assert address in line and "choose another port" in line, line
