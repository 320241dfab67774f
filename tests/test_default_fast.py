"""The loop-kernel option is on by default: `import jaxunilat` adds it to `XLA_FLAGS`,
`JAXUNILAT_NO_LOOP_KERNELS=1` opts out, and a backend started without it makes the first
`simulate` warn once. Fresh interpreters (subprocesses) for what happens at import; the
warning's rules in this process with the backend state monkeypatched."""

import json
import os
import subprocess
import sys
import textwrap
import warnings

import jax
import pytest

import jaxunilat as ju
from jaxunilat._bench import _goals as bench_goals
from jaxunilat._cli import _environment
from jaxunilat._internal import _loop_kernels

OPTION = "xla_cpu_small_while_loop_byte_threshold"
SETTING = f"--xla_backend_extra_options={OPTION}=1048576"


def _fresh(code: str, xla_flags: str | None = None, opt_out: str | None = None) -> dict:
    """Run `code` in a fresh interpreter with `XLA_FLAGS` and the opt-out as given (not
    this process's); its last line of output is JSON."""
    env = dict(os.environ)
    env.pop("XLA_FLAGS", None)
    env.pop(_loop_kernels.OPT_OUT, None)
    if xla_flags is not None:
        env["XLA_FLAGS"] = xla_flags
    if opt_out is not None:
        env[_loop_kernels.OPT_OUT] = opt_out
    proc = subprocess.run(
        [sys.executable, "-c", textwrap.dedent(code)], env=env, capture_output=True, text=True, timeout=300
    )
    assert proc.returncode == 0, proc.stderr
    return json.loads(proc.stdout.strip().splitlines()[-1])


_IMPORT = """
import json, os
import jaxunilat
import jax
jax.numpy.zeros(1).block_until_ready()  # the backend starts with what XLA_FLAGS holds now
print(json.dumps(dict(flags=os.environ.get("XLA_FLAGS"), bytes=jaxunilat.debug.loop_kernel_bytes())))
"""


def test_import_adds_the_option():
    out = _fresh(_IMPORT)
    assert out == {"flags": SETTING, "bytes": 1 << 20}
    # Other flags are kept; another option list is joined, not duplicated.
    out = _fresh(_IMPORT, xla_flags="--xla_cpu_enable_fast_math=false")
    assert out["flags"] == f"--xla_cpu_enable_fast_math=false {SETTING}"
    out = _fresh(_IMPORT, xla_flags="--xla_backend_extra_options=xla_cpu_disable_loop_unrolling")
    assert out["flags"] == f"--xla_backend_extra_options={OPTION}=1048576,xla_cpu_disable_loop_unrolling"


def test_a_threshold_already_set_is_kept():
    out = _fresh(_IMPORT, xla_flags=f"--xla_backend_extra_options={OPTION}=4096")
    assert out == {"flags": f"--xla_backend_extra_options={OPTION}=4096", "bytes": 4096}


@pytest.mark.parametrize("before", [None, "--xla_cpu_enable_fast_math=false"])
def test_opt_out_leaves_xla_flags_alone(before):
    out = _fresh(_IMPORT, xla_flags=before, opt_out="1")
    assert out == {"flags": before, "bytes": None}
    # "0" (and "", "false", "no") is no opt-out.
    assert _fresh(_IMPORT, xla_flags=before, opt_out="0")["bytes"] == 1 << 20


_CLI = """
import contextlib, io, json, os
from jaxunilat._cli import main
with contextlib.redirect_stdout(io.StringIO()):
    status = main(["--no-cache", "simulate", "ball", "--t1", "0.01", "--samples", "3"])
print(json.dumps(dict(status=status, flags=os.environ.get("XLA_FLAGS"))))
"""


@pytest.mark.parametrize("opt_out", [None, "1"])
def test_the_command_line_follows_the_opt_out(opt_out):
    """The command line runs with the option, and without it when the user opted out."""
    out = _fresh(_CLI, opt_out=opt_out)
    assert out == {"status": 0, "flags": None if opt_out else SETTING}


_LATE = """
import json, warnings
import jax, jax.numpy as jnp
jnp.zeros(1).block_until_ready()  # the user computes first: the backend starts without the option
import jaxunilat as ju
b = ju.Ball.table1(2)
with warnings.catch_warnings(record=True) as caught:
    warnings.simplefilter("always")
    for _ in range(3):  # traced only (no compile): the check runs when simulate is called
        jax.eval_shape(lambda k: ju.simulate(ju.Ball.table1(2, kappa=k), b.paper_initial_state(), 0.1,
                                             samples=3, outputs=("x",)).ys["x"], 1e4)
print(json.dumps(dict(messages=[str(w.message) for w in caught], bytes=ju.debug.loop_kernel_bytes())))
"""


def test_computing_before_the_import_warns_once_with_the_fix():
    out = _fresh(_LATE)
    assert out["bytes"] is None
    assert len(out["messages"]) == 1
    message = out["messages"][0]
    assert f"XLA_FLAGS='{SETTING}'" in message
    assert "Import jaxunilat before the first JAX computation" in message
    assert _loop_kernels.OPT_OUT in message
    # Opted out: no warning.
    assert _fresh(_LATE, opt_out="1")["messages"] == []


@pytest.fixture
def first_call(monkeypatch):
    """This process as if `simulate` had not run yet, with XLA_FLAGS without the option."""
    monkeypatch.setattr(_loop_kernels, "_CHECKED", [])
    monkeypatch.setattr(_loop_kernels, "_ADDED", [])
    monkeypatch.setenv("XLA_FLAGS", "--xla_cpu_enable_fast_math=false")
    monkeypatch.delenv(_loop_kernels.OPT_OUT, raising=False)
    monkeypatch.setattr(_loop_kernels, "_backend_started", lambda: True)
    return monkeypatch


def _warnings_of(calls: int) -> list[str]:
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        for _ in range(calls):
            _loop_kernels.warn_if_missing()
    return [str(w.message) for w in caught]


def test_the_warning_rules(first_call):
    assert len(_warnings_of(3)) == 1  # once per process


def test_no_warning_on_other_backends(first_call):
    first_call.setattr(jax, "default_backend", lambda: "gpu")
    assert _warnings_of(2) == []


def test_no_warning_when_opted_out(first_call):
    first_call.setenv(_loop_kernels.OPT_OUT, "1")
    assert _warnings_of(2) == []


def test_before_the_backend_starts_the_first_call_adds_the_option(first_call):
    """The option removed from XLA_FLAGS after the import: the first call puts it back."""
    first_call.setattr(_loop_kernels, "_backend_started", lambda: False)
    assert _warnings_of(1) == []
    assert os.environ["XLA_FLAGS"] == f"--xla_cpu_enable_fast_math=false {SETTING}"


def test_user_flags_and_without_option(first_call):
    first_call.setattr(_loop_kernels, "_backend_started", lambda: False)
    assert ju.use_loop_kernels()
    added = os.environ["XLA_FLAGS"]
    assert _loop_kernels.user_flags(added) == "--xla_cpu_enable_fast_math=false"
    assert _loop_kernels.user_flags("--other") == "--other"
    assert _loop_kernels.without_option(added) == "--xla_cpu_enable_fast_math=false"
    assert _loop_kernels.without_option(SETTING) == ""
    assert (
        _loop_kernels.without_option(f"--xla_backend_extra_options=a,{OPTION}=5 --b")
        == "--xla_backend_extra_options=a --b"
    )


def test_the_command_line_does_not_probe_its_own_option(monkeypatch):
    """`check_xla_flags` starts a probe process for flags the user set, not for the
    loop-kernel option alone (inherited from a parent that imported jaxunilat)."""
    monkeypatch.setattr(_environment, "_backend_started", lambda: False)

    def no_probe(*args, **kwargs):
        raise AssertionError("probe started")

    monkeypatch.setattr(_environment.subprocess, "run", no_probe)
    _environment.check_xla_flags(SETTING)
    _environment.check_xla_flags(None)
    with pytest.raises(AssertionError, match="probe started"):
        _environment.check_xla_flags(f"--garbage {SETTING}")


def _default_user_section(default_one=2.2e-4, default_vmap=0.07, kernels=1 << 20):
    return {
        "scene": "scene",
        "how": "how",
        "n": 400,
        "default": {
            "one_s": default_one,
            "vmap_s": default_vmap,
            "loop_kernel_bytes": kernels,
            "warnings": [],
        },
        "tuned": {"one_s": 2.0e-4, "vmap_s": 0.07, "loop_kernel_bytes": 1 << 20, "warnings": []},
        "one_ratio": default_one / 2.0e-4,
        "vmap_ratio": default_vmap / 0.07,
        "ratio": max(default_one / 2.0e-4, default_vmap / 0.07),
    }


def test_default_user_goal_is_the_worse_ratio():
    section = {
        "vmap_against_rows": {
            **{"ratio": 1.0, "n": 4, "kappa_range": [1, 2], "device": "cpu", "scene": "s"},
            **{"vmap_per_row_s": 1e-4, "sequential_per_row_s": 1e-4},
        },
        "reverse_against_forward": {"ratio": 3.0, "loss": "l", "scene": "s", "forward_s": 1, "reverse_s": 3},
        "command_line": {"commands": {}, "import_s": 1.0},
    }
    section["reverse_against_forward"]["forward_mode_ratio"] = 2.0
    section["default_user"] = _default_user_section()
    goal = bench_goals.user_goals(section)["default_user_ratio"]
    assert goal["value"] == pytest.approx(1.1) and goal["met"] and goal["target"] == 1.2
    assert goal["default_traj_per_s"] == pytest.approx(400 / 0.07)
    section["default_user"] = _default_user_section(default_one=2e-3, kernels=None)
    goal = bench_goals.user_goals(section)["default_user_ratio"]
    assert goal["value"] == pytest.approx(10.0) and not goal["met"]
    note = bench_goals._default_user_note(goal, missed=True)
    assert note.startswith("missed") and "without the loop-kernel option" in note
