"""One failure, one error: the same clean error on every call, nothing else on stderr, and
the standard output's own failures (a full disk, a reader that went away) told apart from
bugs.

- A failed `simulate(throw=True)` raises `equinox.EquinoxRuntimeError` carrying only the
  solver's message, on the first call and on later calls too (JAX raises a later call's
  failure from its C++ fast path as a plain `ValueError` with a callback traceback).
- The Python API prints nothing on stderr for such a failure (JAX logs the callback's
  traceback by default); the command line prints one line.
- `jaxunilat ... > /dev/full` is one line naming stdout, exit 1; `jaxunilat ... | head`
  whose reader went away ends quietly with 141 (128 + SIGPIPE).
"""

import errno
import json
import os
import subprocess
import sys
import textwrap

import equinox as eqx
import pytest

import jaxunilat
from jaxunilat._cli._main import main

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
BALL = jaxunilat.Ball.table1(2)
Y0 = (0.1, 0.0)
EQUINOX_ADVICE = ("filter_jit", "EQX_ON_ERROR", "CpuCallback", "Traceback", "--------")


def _run(code: str, *args, **kwargs) -> subprocess.CompletedProcess:
    env = {**os.environ, "JAXUNILAT_NO_CACHE": "1"}
    return subprocess.run(
        [sys.executable, *args] if args else [sys.executable, "-c", code],
        capture_output=True,
        text=True,
        cwd=ROOT,
        env=env,
        timeout=300,
        **kwargs,
    )


def test_a_failure_after_a_success_raises_the_documented_error():
    """The second call of a compiled program fails through JAX's fast path (a ValueError,
    `INTERNAL: CpuCallback error` with an embedded traceback, before the fix): it raises
    the same EquinoxRuntimeError, with the same message, as the first."""
    jaxunilat.simulate(BALL, Y0, 0.01, max_steps=100)  # succeeds: the program is compiled
    messages = []
    for _ in range(2):
        with pytest.raises(eqx.EquinoxRuntimeError) as info:
            jaxunilat.simulate(BALL, Y0, 1.0, max_steps=100)
        messages.append(str(info.value))
    assert messages[0] == messages[1]
    assert messages[0].startswith("jaxunilat.simulate: the solver used all max_steps = 100 steps")
    assert "\n" not in messages[0] and not any(word in messages[0] for word in EQUINOX_ADVICE)


def test_a_python_api_failure_prints_nothing_on_stderr():
    """JAX logs a failed host callback (`jax.pure_callback failed`, its traceback and
    equinox's banner) on stderr; the error that `simulate` raises already says it all, so
    the log is dropped: stderr stays empty, the first and the cached call alike."""
    script = textwrap.dedent(
        """
        import jaxunilat
        ball = jaxunilat.Ball.table1(2)
        jaxunilat.simulate(ball, (0.1, 0.0), 0.01, max_steps=100)
        for _ in range(2):
            try:
                jaxunilat.simulate(ball, (0.1, 0.0), 1.0, max_steps=100)
            except Exception as err:
                print(type(err).__name__, "|", err)
        """
    )
    done = _run(script)
    assert done.returncode == 0, done.stderr
    assert done.stderr == ""
    lines = done.stdout.strip().splitlines()
    assert len(lines) == 2 and lines[0] == lines[1]
    assert lines[0].startswith("EquinoxRuntimeError | jaxunilat.simulate: the solver used all max_steps")


@pytest.mark.skipif(not os.path.exists("/dev/full"), reason="needs /dev/full")
@pytest.mark.parametrize("unbuffered", ["1", ""])
def test_a_full_stdout_is_one_line_naming_stdout(unbuffered):
    """`> /dev/full`: one line naming stdout, exit 1 (before: exit 0 with nothing said for
    --version, whose write argparse swallows; `a bug in jaxunilat` for a command)."""
    env = {**os.environ, "PYTHONUNBUFFERED": unbuffered}
    with open("/dev/full", "w") as full:
        done = subprocess.run(
            [sys.executable, "-m", "jaxunilat", "--version"],
            stdout=full,
            stderr=subprocess.PIPE,
            text=True,
            cwd=ROOT,
            env=env,
            timeout=120,
        )
    assert done.returncode == 1
    assert done.stderr == "jaxunilat: error: stdout: cannot write: [Errno 28] No space left on device\n"


def test_a_reader_that_went_away_ends_quietly_with_sigpipes_status():
    """`jaxunilat --help | head -0`: the reader is gone before anything is written; the
    command ends as Unix tools do, 128 + SIGPIPE and nothing on stderr."""
    child = subprocess.Popen(
        [sys.executable, "-m", "jaxunilat", "--help"],
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        cwd=ROOT,
    )
    child.stdout.close()  # before the child (still importing) writes anything
    err = child.stderr.read().decode()
    assert child.wait(timeout=120) == 141
    assert err == ""


class _FullStream:
    """A standard output on a full disk: every write fails with ENOSPC."""

    def write(self, text):
        raise OSError(errno.ENOSPC, os.strerror(errno.ENOSPC))

    def flush(self):
        pass


def test_a_command_whose_print_fails_names_stdout_not_a_bug(tmp_path, monkeypatch, capsys):
    """A command's own print failing (export prints its snippet) is stdout's failure: one
    line, exit 1, never `internal error ... a bug in jaxunilat`."""
    fit = {
        "parameters": {"kappa": {"value": 26000.0, "stderr": 400.0}, "k_r": {"value": 0.36, "stderr": 0.003}},
        "identifiable": {"kappa": True, "k_r": True, "restitution": True},
        "converged": True,
        "mass": 0.0027,
    }
    path = tmp_path / "fit.json"
    path.write_text(json.dumps(fit))
    capsys.readouterr()
    monkeypatch.setattr(sys, "stdout", _FullStream())
    code = main(["export", "mujoco", str(path)])
    err = capsys.readouterr().err
    assert code == 1
    assert err == "jaxunilat: error: stdout: cannot write: [Errno 28] No space left on device\n"


def test_a_failed_sweep_or_study_raises_the_solvers_message_alone():
    """`sweep` and the `analysis` studies give a solver failure as `simulate` does: one
    EquinoxRuntimeError with the solver's message, not JAX's callback traceback."""
    import jax.numpy as jnp

    def row(kappa):
        return jaxunilat.simulate(jaxunilat.Ball.table1(2, kappa=kappa), Y0, 1.0, max_steps=100).ys["x"]

    with pytest.raises(eqx.EquinoxRuntimeError) as info:
        jaxunilat.sweep(row, jnp.array([1e4, 2e4]))
    message = str(info.value)
    assert message.startswith("jaxunilat.simulate: the solver used all max_steps = 100 steps")
    assert "\n" not in message and not any(word in message for word in EQUINOX_ADVICE)

    coupling = jaxunilat.Coupling.table2(1)
    with pytest.raises(eqx.EquinoxRuntimeError) as info:
        jaxunilat.analysis.coupling_features(coupling, 0.5, samples=101, max_steps=20)
    assert str(info.value).startswith("jaxunilat.simulate: ")
    assert "\n" not in str(info.value) and not any(word in str(info.value) for word in EQUINOX_ADVICE)
