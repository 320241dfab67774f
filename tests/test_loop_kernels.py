"""`use_loop_kernels`: the XLA option it sets, that the event loop qualifies for it, and
that results match XLA's default configuration (checked in a fresh process opted out).

The suite runs with the option on, as `import jaxunilat` sets it (and conftest.py calls
`use_loop_kernels`); tests/test_default_fast.py checks the import's part.
"""

import json
import os
import re
import subprocess
import sys
import textwrap

import jax
import jax.numpy as jnp
import numpy as np
import pytest

import jaxunilat as ju
from jaxunilat._internal import _loop_kernels
from jaxunilat._solver._settings import make_settings
from jaxunilat._solver._simulate import _solve

OPTION = "xla_cpu_small_while_loop_byte_threshold"


@pytest.mark.parametrize("value", [0, -5, 1.5, "1024", True, None])
def test_byte_threshold_is_validated(value):
    with pytest.raises(ValueError, match="byte_threshold"):
        ju.use_loop_kernels(value)


def _flags_after(monkeypatch, before, started=False, **kw):
    if before is None:
        monkeypatch.delenv("XLA_FLAGS", raising=False)
    else:
        monkeypatch.setenv("XLA_FLAGS", before)
    monkeypatch.setattr(_loop_kernels, "_backend_started", lambda: started)
    monkeypatch.setattr(_loop_kernels, "_ADDED", [])
    active = ju.use_loop_kernels(**kw)
    return active, os.environ.get("XLA_FLAGS")


def test_option_is_added_to_xla_flags(monkeypatch):
    active, flags = _flags_after(monkeypatch, None, byte_threshold=4096)
    assert active and flags == f"--xla_backend_extra_options={OPTION}=4096"
    assert ju.loop_kernel_bytes(flags) == 4096
    active, flags = _flags_after(monkeypatch, "--xla_force_host_platform_device_count=2")
    assert (
        active
        and flags == f"--xla_force_host_platform_device_count=2 --xla_backend_extra_options={OPTION}=1048576"
    )


def test_option_joins_other_backend_options(monkeypatch):
    active, flags = _flags_after(monkeypatch, "--xla_backend_extra_options=xla_cpu_disable_loop_unrolling")
    assert active
    assert flags == f"--xla_backend_extra_options={OPTION}=1048576,xla_cpu_disable_loop_unrolling"


def test_an_option_already_set_is_left_alone(monkeypatch):
    before = f"--xla_backend_extra_options={OPTION}=777"
    active, flags = _flags_after(monkeypatch, before, started=True)
    assert active and flags == before
    assert ju.loop_kernel_bytes(flags) == 777
    assert ju.loop_kernel_bytes("--xla_cpu_enable_fast_math=false") is None


def test_too_late_warns_and_changes_nothing(monkeypatch):
    with pytest.warns(RuntimeWarning, match="before the first JAX computation"):
        active, flags = _flags_after(monkeypatch, "--xla_dump_to=/nowhere", started=True)
    assert not active and flags == "--xla_dump_to=/nowhere"


def _entry_ops(hlo: str) -> str:
    """The instructions of the compiled program's entry computation."""
    return hlo[hlo.index("\nENTRY") :].split("\n}\n", 1)[0]


@pytest.mark.parametrize(
    "options",
    [
        dict(piece_solver="tsit5"),
        dict(piece_solver="dopri8", flight="integrated"),
        dict(piece_solver="dopri8", autodiff="forward"),
    ],
)
def test_event_loop_compiles_into_one_kernel(options):
    """Nothing in the loop (a sort, a scatter, a host callback) keeps XLA from compiling
    it as one kernel: no `while` is left among the entry computation's thunks."""
    ball = ju.Ball.table1(2)
    settings = make_settings("event", 2.0, rtol=1e-10, atol=1e-10, **options)
    lowered = _solve.lower(
        ball,
        ball.paper_initial_state(),
        jnp.asarray(0.0),
        jnp.asarray(2.0),
        jnp.linspace(0, 2, 5),
        settings,
        ("x",),
        True,
        "rows",
    )
    hlo = lowered.compile().as_text()
    entry = _entry_ops(hlo)
    assert 'xla_cpu_small_call="true"' in entry
    assert not re.search(r"\swhile\(", entry)


@pytest.mark.parametrize("piece_solver", ["tsit5", "dopri8"])
def test_backward_loop_compiles_into_one_kernel(piece_solver):
    """Reverse mode: the checkpointed loop's backward pass holds no scatter (the
    transpose of a gather with a batched index, `_event_locate.pick`), so it is one
    kernel too, as is every other loop of `jax.grad`'s program."""

    def loss(theta):
        ball = ju.Ball.table1(2, kappa=theta[0], k_r=theta[1])
        sol = ju.simulate(
            ball,
            ball.paper_initial_state(),
            1.0,
            solver="event",
            rtol=1e-10,
            atol=1e-10,
            samples=11,
            piece_solver=piece_solver,
            outputs=("x",),
        )
        return jnp.sum(sol.ys["x"] ** 2) + jnp.sum(ju.impact_times(sol, 3))

    hlo = jax.jit(jax.grad(loss)).lower(jnp.asarray([1e4, 0.2])).compile().as_text()
    entry = _entry_ops(hlo)
    assert not re.search(r"\swhile\(", entry)


_RUN = textwrap.dedent(
    """
    import json, sys
    import numpy as np
    import jaxunilat as ju
    out = {}
    for piece in ("tsit5", "dopri8"):
        b = ju.Ball.table1(2)
        s = ju.simulate(b, b.paper_initial_state(), 2.0, samples=201, solver="event", rtol=1e-10,
                        atol=1e-10, piece_solver=piece, outputs=("x",))
        out[piece] = dict(x=np.asarray(s.ys["x"]).tolist(), steps=int(s.num_steps),
                          entries=np.asarray(s.events.t[s.events.kind == 1]).tolist())
    print(json.dumps(dict(runs=out, option=ju.loop_kernel_bytes())))
    """
)


def test_results_match_the_default_configuration():
    """A fresh process opted out of the option (XLA's default thunk-by-thunk loop) gives
    the same steps, and outputs and contact times equal to rounding."""
    env = dict(os.environ)
    env["XLA_FLAGS"] = _loop_kernels.without_option(env.get("XLA_FLAGS", ""))
    env[_loop_kernels.OPT_OUT] = "1"
    proc = subprocess.run([sys.executable, "-c", _RUN], env=env, capture_output=True, text=True, timeout=600)
    assert proc.returncode == 0, proc.stderr
    default = json.loads(proc.stdout.strip().splitlines()[-1])
    assert default["option"] is None  # the fresh process ran XLA's default
    assert ju.loop_kernel_bytes() is not None  # this process runs with the option (conftest)
    for piece, ref in default["runs"].items():
        b = ju.Ball.table1(2)
        s = ju.simulate(
            b,
            b.paper_initial_state(),
            2.0,
            samples=201,
            solver="event",
            rtol=1e-10,
            atol=1e-10,
            piece_solver=piece,
            outputs=("x",),
        )
        assert int(s.num_steps) == ref["steps"]
        np.testing.assert_allclose(np.asarray(s.ys["x"]), ref["x"], rtol=0, atol=1e-11)
        entries = np.asarray(s.events.t[s.events.kind == 1])
        np.testing.assert_allclose(entries, ref["entries"], rtol=0, atol=1e-12)
