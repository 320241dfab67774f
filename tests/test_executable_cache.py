"""`simulate`'s executable cache (the command line's): a kept program gives the same
results as a fresh compile, without tracing; a new structure, backend setting or
source gets a new entry; a damaged entry is recompiled; it is never used where it
cannot be (throw=True, inside a transformation)."""

import os
import shutil
import subprocess
import sys

import jax
import numpy as np
import pytest

import jaxunilat as ju
from jaxunilat._internal import _executables
from jaxunilat._internal._executables import (
    ExecutableCache,
    call_key,
    disable_executable_cache,
    enable_executable_cache,
)

T1 = 0.3


def _simulate(kappa=1e4, outputs=("x", "v"), throw=False):
    ball = ju.Ball.table1(2, kappa=kappa)
    return ju.simulate(
        ball, ball.paper_initial_state(), T1, solver="event", samples=31, outputs=outputs, throw=throw
    )


def _entries(path):
    return sorted(f for f in os.listdir(path) if f.endswith(".jaxexe")) if os.path.isdir(path) else []


def _same(a, b):
    for x, y in zip(jax.tree_util.tree_leaves(a), jax.tree_util.tree_leaves(b), strict=True):
        np.testing.assert_array_equal(np.asarray(x), np.asarray(y))


@pytest.fixture
def cache_dir(tmp_path):
    yield str(tmp_path / "executables")
    disable_executable_cache()


def test_a_kept_program_runs_without_tracing_and_matches_a_fresh_compile(cache_dir):
    plain = [_simulate(kappa) for kappa in (1e4, 3e4)]
    enable_executable_cache(cache_dir)
    first = _simulate(1e4)
    assert len(_entries(cache_dir)) == 1
    enable_executable_cache(cache_dir)  # a new process: nothing loaded yet
    before = ju.debug.trace_counts().get("simulate", 0)
    again = [_simulate(kappa) for kappa in (1e4, 3e4)]  # new values, same program
    assert ju.debug.trace_counts().get("simulate", 0) == before
    assert len(_entries(cache_dir)) == 1
    for kept, fresh in zip([first, *again], [plain[0], *plain], strict=True):
        _same(kept, fresh)
    assert float(np.max(np.abs(np.asarray(again[0]["x"]) - np.asarray(again[1]["x"])))) > 1e-4


def test_a_new_structure_gets_its_own_entry_and_old_ones_are_evicted(cache_dir):
    enable_executable_cache(cache_dir, max_entries=2)
    _simulate(outputs=("x",))
    _simulate(outputs=("x", "v"))
    assert len(_entries(cache_dir)) == 2
    _simulate(outputs=("v",))
    assert len(_entries(cache_dir)) == 2


def test_a_damaged_entry_is_recompiled(cache_dir):
    reference = _simulate()
    enable_executable_cache(cache_dir)
    _simulate()
    (name,) = _entries(cache_dir)
    with open(os.path.join(cache_dir, name), "r+b") as f:
        f.truncate(1000)
    enable_executable_cache(cache_dir)
    _same(_simulate(), reference)
    (again,) = _entries(cache_dir)
    assert again == name and os.path.getsize(os.path.join(cache_dir, name)) > 1000


def test_an_entry_that_loads_but_fails_when_called_is_recompiled(cache_dir, monkeypatch):
    """An executable can deserialize and still fail on its first call (a copy that lacks
    some of its code): the entry is deleted, the program compiled afresh and kept anew."""
    from jax.experimental import serialize_executable

    reference = _simulate()
    enable_executable_cache(cache_dir)
    _simulate()
    (name,) = _entries(cache_dir)
    os.utime(os.path.join(cache_dir, name), (0, 0))

    def broken(*args, **kwargs):
        def call(*args):
            raise RuntimeError("NOT_FOUND: Function fusion not found")

        return call

    monkeypatch.setattr(serialize_executable, "deserialize_and_load", broken)
    enable_executable_cache(cache_dir)
    _same(_simulate(), reference)
    assert _entries(cache_dir) == [name]
    assert os.path.getmtime(os.path.join(cache_dir, name)) > 0  # written anew


def test_an_xla_without_the_compile_option_keeps_nothing(cache_dir, monkeypatch):
    """The kept compile passes an XLA option to stay out of JAX's own cache; an XLA that
    refuses it still gives the plain call's results, and nothing is kept."""
    reference = _simulate()
    monkeypatch.setattr(_executables, "_OWN_KEY_OPTION", {"xla_no_such_option": False})
    enable_executable_cache(cache_dir)
    _same(_simulate(), reference)
    assert _entries(cache_dir) == []


def test_never_used_with_throw_or_inside_a_transformation(cache_dir):
    enable_executable_cache(cache_dir)
    _simulate(throw=True)
    jax.jit(lambda k: _simulate(k).ys["x"])(2e4)
    jax.grad(lambda k: _simulate(k)["x"][-1])(2e4)
    assert _entries(cache_dir) == []


def test_a_program_with_host_callbacks_is_called_plainly(cache_dir, monkeypatch):
    """A program with a host callback (a Python closure of the process) does not
    serialize: the cache calls it plainly, without a compile of its own or a try at
    serializing, and keeps nothing."""
    from jax.experimental import serialize_executable

    from jaxunilat._internal._executables import kept_call

    seen = []
    jitted = jax.jit(lambda x: (jax.debug.callback(lambda v: seen.append(float(v)), x.sum()), 2.0 * x)[1])
    tried = []
    monkeypatch.setattr(serialize_executable, "serialize", lambda *a: tried.append(a) or 1 / 0)
    enable_executable_cache(cache_dir)
    out = kept_call("test.callback", jitted, (np.arange(3.0),))
    np.testing.assert_array_equal(np.asarray(out), [0.0, 2.0, 4.0])
    jax.effects_barrier()
    assert seen == [3.0] and tried == [] and _entries(cache_dir) == []


def test_the_tsit5_and_rk4_programs_are_kept(cache_dir):
    """diffrax's own input checks (host callbacks, whatever `throw` says) are traced away
    for `simulate`, which makes them itself: the default solver's program is kept, and the
    kept one gives the same run."""
    ball = ju.Ball.table1(2)
    for solver, extra in (("tsit5", {}), ("rk4", {"dt": 1e-5})):
        reference = ju.simulate(ball, ball.paper_initial_state(), T1, solver=solver, samples=31, **extra)
        enable_executable_cache(cache_dir)
        try:
            kept = ju.simulate(
                ball, ball.paper_initial_state(), T1, solver=solver, samples=31, throw=False, **extra
            )
            again = ju.simulate(
                ball, ball.paper_initial_state(), T1, solver=solver, samples=31, throw=False, **extra
            )
        finally:
            disable_executable_cache()
        _same(kept, reference)
        _same(again, reference)
    assert len(_entries(cache_dir)) == 2


def test_the_key_covers_values_that_decide_the_program(monkeypatch):
    ball = ju.Ball.table1(2)
    args = (ball, np.zeros(2), np.asarray(1.0))
    key = call_key("simulate", args, ("x",))
    assert key is not None
    assert key == call_key("simulate", (ju.Ball.table1(2, kappa=5.0), np.ones(2), np.asarray(2.0)), ("x",))
    assert key != call_key("simulate", args, ("v",))
    assert key != call_key("simulate", (ball, np.zeros(3), np.asarray(1.0)), ("x",))
    assert key != call_key("simulate", (ball, np.zeros(2, np.float32), np.asarray(1.0)), ("x",))
    assert key != call_key("simulate", (ju.Ball.table1(2, heaviside=ju.Logistic(1e-6)), *args[1:]), ("x",))
    monkeypatch.setenv("XLA_FLAGS", "--xla_cpu_enable_fast_math=false")
    assert key != call_key("simulate", args, ("x",))
    monkeypatch.delenv("XLA_FLAGS")
    monkeypatch.setattr(_executables, "_SOURCE_DIGEST", {"jaxunilat": "edited"})
    assert key != call_key("simulate", args, ("x",))
    monkeypatch.undo()
    assert key == call_key("simulate", args, ("x",))
    monkeypatch.setattr(_executables, "_host_cpu", lambda: "another CPU")
    assert key != call_key("simulate", args, ("x",))
    assert call_key("simulate", (ball, [0.0, 1.0]), ("x",)) is None  # a leaf that is no array


def test_an_unwritable_directory_only_costs_the_cache(tmp_path):
    blocker = tmp_path / "file"
    blocker.write_text("not a directory")
    cache = ExecutableCache(str(blocker / "executables"))
    reference = _simulate()
    try:
        _executables._ACTIVE[:] = [cache]
        _same(_simulate(), reference)
    finally:
        disable_executable_cache()


DATA = os.path.join(os.path.dirname(os.path.dirname(os.path.abspath(__file__))), "data", "drop_trace.csv")


@pytest.mark.parametrize(
    ("argv", "program"),
    [
        (["simulate", "ball", "--solver", "event", "--t1", "0.3"], "_solve_batched"),
        (["identify", DATA, "--starts", "1"], "evaluate_rows"),
        (["simulate", "ball", "--t1", "0.3"], "_solve_batched"),
    ],
    ids=["simulate", "identify", "simulate-default-solver"],
)
def test_the_command_lines_second_run_traces_nothing(argv, program, tmp_path):
    """Fresh processes on one cache: a later run prints the same results, and JAX logs no
    tracing of the solve (`JAX_LOG_COMPILES`). That holds too when the executables were
    lost while JAX's own compilation cache kept its entries: a program JAX read back from
    there does not serialize whole on the CPU, so the kept one must be compiled afresh."""
    environ = {k: v for k, v in os.environ.items() if k != "JAXUNILAT_NO_CACHE"}
    environ.update(JAXUNILAT_CACHE_DIR=str(tmp_path / "cache"), JAX_LOG_COMPILES="1")
    executables = str(tmp_path / "cache" / "executables")
    command = [sys.executable, "-m", "jaxunilat", *argv]

    def run():
        done = subprocess.run(command, capture_output=True, text=True, env=environ, timeout=300)
        assert done.returncode == 0, done.stderr
        return done

    runs = [run(), run()]
    shutil.rmtree(executables)
    runs += [run(), run()]
    for first, second in (runs[:2], runs[2:]):
        assert program in first.stderr and program not in second.stderr
    printed = [[line for line in r.stdout.splitlines() if "wall time" not in line] for r in runs]
    assert all(p == printed[0] for p in printed)
    assert len(_entries(executables)) == 1
