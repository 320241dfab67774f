"""Where latency-bound work runs when JAX's default backend is an accelerator
(`jaxunilat._internal._placement`): a concrete single `simulate`, `identify.fit`,
`identify.qualify_fit` and the command line on the host CPU; traced (vmapped, jitted)
solves where JAX puts them; the user's placement first.

No accelerator is needed: a child process with two CPU devices stands in, the default
backend reported as "gpu" and the host's CPU device being the second one, so that where a
result lives says which rule placed it.
"""

from __future__ import annotations

import json
import os
import subprocess
import sys

import jax
import pytest

from jaxunilat._internal import _placement

CHILD = r"""
import json, jax, numpy as np
import jaxunilat as ju
from jaxunilat._internal import _placement, keep_placement, on_host
import concurrent.futures

default, host = jax.devices()
jax.default_backend = lambda: "gpu"           # the machine's default backend: an accelerator
_placement.jax.local_devices = lambda backend=None: [host]   # its host CPU device

def where(a):
    return str(next(iter(a.devices())))

def run(kappa=1e4):
    return ju.simulate(ju.Ball.table1(2, kappa=kappa), (-0.4, -1 / 0.122), 0.05, solver="event", samples=5).ys["x"]

out = {}
out["single"] = where(run())                                   # concrete: the host
out["jit_vmap"] = where(jax.jit(jax.vmap(run))(np.array([1e4, 2e4])))   # traced: JAX's default
with jax.default_device(default):
    out["user_default_device"] = where(run())                  # the user's placement wins
with on_host():
    with concurrent.futures.ThreadPoolExecutor(1) as pool:
        out["thread_kept"] = pool.submit(keep_placement(lambda: where(jax.numpy.zeros(1) + 1))).result()
        out["thread_plain"] = pool.submit(lambda: where(jax.numpy.zeros(1) + 1)).result()
print(json.dumps(out))
"""


def test_latency_bound_work_goes_to_the_host_and_the_users_placement_wins():
    env = dict(os.environ, XLA_FLAGS="--xla_force_host_platform_device_count=2", JAXUNILAT_DEVICE="")
    done = subprocess.run([sys.executable, "-c", CHILD], capture_output=True, text=True, env=env, timeout=600)
    assert done.returncode == 0, done.stderr[-3000:]
    out = json.loads(done.stdout.strip().splitlines()[-1])
    assert out["single"] == "cpu:1"
    assert out["jit_vmap"] == "cpu:0"
    assert out["user_default_device"] == "cpu:0"
    assert out["thread_kept"] == "cpu:1" and out["thread_plain"] == "cpu:0"


def test_the_rule(monkeypatch):
    # On a CPU backend nothing moves.
    monkeypatch.delenv(_placement.ENV, raising=False)
    assert jax.default_backend() == "cpu" and _placement.host_device() is None
    # An accelerator as the default backend: the host's CPU device...
    monkeypatch.setattr(jax, "default_backend", lambda: "gpu")
    cpu = jax.local_devices(backend="cpu")[0]
    assert _placement.host_device() == cpu
    with _placement.on_host():
        assert jax.config.jax_default_device == cpu
    # ...unless the user placed the work, or asked for JAX's default device.
    with jax.default_device(cpu):
        assert _placement.host_device() is None
    monkeypatch.setenv(_placement.ENV, "default")
    assert _placement.host_device() is None
    monkeypatch.setenv(_placement.ENV, "gpu0")
    with pytest.raises(ValueError, match="JAXUNILAT_DEVICE = 'gpu0' is not supported; valid: host, default"):
        _placement.host_device()


def test_fit_and_qualify_are_placed():
    from jaxunilat import identify

    assert identify.fit.__wrapped__ is not None and identify.qualify_fit.__wrapped__ is not None
