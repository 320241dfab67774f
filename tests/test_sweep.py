"""`jaxunilat.sweep`: the vmap path, sharded across devices.

The 2-device case runs in a subprocess with `XLA_FLAGS=--xla_force_host_platform_device_count=2`
(the flag must be set before JAX starts): the sharded event-mode result is compared with the
drag-free closed form (tests/reference.py), the output is checked to span both devices, and
new values must not retrace.
"""

from __future__ import annotations

import json
import os
import subprocess
import sys
import textwrap

import jax
import jax.numpy as jnp
import numpy as np
import pytest

import jaxunilat

_SCRIPT = textwrap.dedent(
    """
    import json
    import sys

    import jax
    import numpy as np

    import jaxunilat as ju

    sys.path.insert(0, TESTS_DIR)
    from reference import BallParams, closed_form_reference

    Y0 = np.array([-0.39, -3.0])
    TS = np.linspace(0.0, 0.3, 31)


    def drop(kappa, k_r):
        ball = ju.Ball.table1(2, kappa=kappa, k_r=k_r, drag=None)
        sol = ju.simulate(
            ball, Y0, 0.3, solver="event", rtol=1e-10, atol=1e-10, ts=TS, outputs=("x",),
            max_steps=512, max_events=32,
        )
        return sol.ys["x"], ju.impact_times(sol, 1)


    kappa = np.geomspace(5e3, 2e4, 5)  # odd: one padded row
    k_r = np.linspace(0.1, 0.4, 5)
    x, t_imp = ju.sweep(drop, kappa, k_r)
    traces = ju.trace_counts()["sweep"]
    x2, _ = ju.sweep(drop, kappa * 1.01, k_r)  # new values, same shapes
    retraced = ju.trace_counts()["sweep"] - traces
    exact = [
        closed_form_reference(BallParams.table1(2, kappa=kappa[i], k_r=k_r[i], drag=None), Y0, 0.3)(TS)[0]
        for i in range(5)
    ]
    print(json.dumps({
        "devices": jax.device_count(),
        "shard_devices": len(x.sharding.device_set),
        "shape": list(x.shape),
        "max_dx_closed_form": float(max(np.max(np.abs(np.asarray(x[i]) - exact[i])) for i in range(5))),
        "changed": float(np.max(np.abs(np.asarray(x2) - np.asarray(x)))),
        "t_imp": [float(t) for t in np.asarray(t_imp)[:, 0]],
        "retraced": retraced,
    }))
    """
)


@pytest.mark.slow
def test_sweep_shards_over_two_host_devices():
    env = dict(os.environ)
    env["XLA_FLAGS"] = (env.get("XLA_FLAGS", "") + " --xla_force_host_platform_device_count=2").strip()
    env["JAX_PLATFORMS"] = "cpu"
    script = f"TESTS_DIR = {os.path.dirname(os.path.abspath(__file__))!r}\n" + _SCRIPT
    proc = subprocess.run(
        [sys.executable, "-c", script], env=env, capture_output=True, text=True, timeout=600, check=False
    )
    assert proc.returncode == 0, proc.stderr[-3000:]
    out = json.loads(proc.stdout.strip().splitlines()[-1])
    assert out["devices"] == 2
    assert out["shard_devices"] == 2, "the sweep's output does not span both devices"
    assert out["shape"] == [5, 31]
    # Every row against the drag-free closed form (parabola + damped oscillator).
    assert out["max_dx_closed_form"] <= 1e-8
    assert out["changed"] > 1e-6  # the second call really used the new values ...
    assert out["retraced"] == 0  # ... without a new trace
    # First impact of a drag-free fall from 1 cm above the wall at -3 m/s, for every row.
    t_free = (np.sqrt(3.0**2 + 2 * 9.81 * 0.01) - 3.0) / 9.81
    np.testing.assert_allclose(out["t_imp"], t_free, rtol=0, atol=1e-12)


def _affine(a, b, c):
    return a * c + b, jnp.sin(a)


def test_sweep_matches_vmap_on_the_default_devices():
    a, b = np.linspace(0.0, 1.0, 7), np.linspace(2.0, 3.0, 7)
    got, sin_a = jaxunilat.sweep(_affine, a, b, 3.0, in_axes=(0, 0, None))
    np.testing.assert_allclose(np.asarray(got), 3.0 * a + b, rtol=0, atol=1e-15)
    np.testing.assert_allclose(np.asarray(sin_a), np.sin(a), rtol=1e-15)
    got2, _ = jaxunilat.sweep(_affine, a, b, 3.0, in_axes=(0, 0, None), batch_size=3)
    np.testing.assert_allclose(np.asarray(got2), 3.0 * a + b, rtol=0, atol=1e-15)
    assert len(jax.devices()) >= 1


def test_sweep_of_a_batched_model_pytree():
    kappas = jnp.array([5e3, 1e4, 2e4])

    def contact_time(ball):
        return jaxunilat.contact_time(ball.kappa, ball.k_r, ball.mass)

    balls = jax.vmap(lambda k: jaxunilat.Ball(kappa=k, k_r=0.2))(kappas)  # every leaf batched
    got = np.asarray(jaxunilat.sweep(contact_time, balls))
    zeta = 0.2 / (2 * np.sqrt(np.asarray(kappas) * jaxunilat.PAPER_MASS))
    expected = np.pi / (np.sqrt(np.asarray(kappas) / jaxunilat.PAPER_MASS) * np.sqrt(1 - zeta**2))
    np.testing.assert_allclose(got, expected, rtol=1e-12)


@pytest.mark.parametrize(
    "kwargs, match",
    [
        (dict(in_axes=(0, 1, None)), "in_axes entry 1"),
        (dict(in_axes=(0, 0)), "one per argument"),
        (dict(in_axes=None), "no argument as batched"),
        (dict(batch_size=0), "batch_size = 0"),
        (dict(devices=()), "devices is empty"),
    ],
)
def test_sweep_refuses_bad_arguments(kwargs, match):
    with pytest.raises(ValueError, match=match):
        jaxunilat.sweep(_affine, np.ones(3), np.ones(3), 2.0, **kwargs)


def test_sweep_refuses_mismatched_batches():
    with pytest.raises(ValueError, match="leading axes disagree"):
        jaxunilat.sweep(_affine, np.ones(3), np.ones(4), 2.0, in_axes=(0, 0, None))


# -- batch sizing (`batch_size=None`) ---------------------------------------------------------

GIB = 2**30


def test_chunk_rows_takes_the_whole_batch_when_it_fits():
    """The sizing rule with the bench's GPU figures: ~119 KB of work, 16 KB of output and
    16 B of arguments per row, 60% of an 80 GB device's free memory."""
    from jaxunilat._solver._sweep import HEADROOM, chunk_rows

    per_row, fixed, budget = (119e3, 16e3, 16.0), 1e6, HEADROOM * 80 * GIB
    assert chunk_rows(100_000, per_row, fixed, budget) is None  # 13.5 GB: all at once
    chunk = chunk_rows(1_000_000, per_row, fixed, budget)  # 135 GB: chunks
    assert chunk is not None and chunk % 8 == 0 and 100_000 < chunk < 1_000_000
    k = -(-1_000_000 // chunk)
    assert fixed + 1_000_000 * (16e3 + 16) + chunk * sum(per_row) <= budget  # it fits ...
    assert chunk * k - 1_000_000 < 8 * k  # ... in equal chunks, little padding
    assert chunk_rows(1_000_000, per_row, fixed, budget * 10) is None
    assert chunk_rows(10, (1.0, 0.0, 0.0), 0.0, 4.0) == 4  # fewer than 8 rows fit: not rounded
    with pytest.raises(ValueError, match="arguments and outputs alone"):
        chunk_rows(1_000_000, per_row, fixed, 8 * GIB)  # 16 GB of outputs in 8 GB


def _drop(kappa, k_r):
    sol = jaxunilat.simulate(
        jaxunilat.Ball.table1(2, kappa=kappa, k_r=k_r),
        np.array([-0.4, -1 / 0.122]),
        0.3,
        solver="event",
        rtol=1e-8,
        atol=1e-8,
        samples=11,
        throw=False,
    )
    return sol.ys["x"], sol.status


def test_sweep_sizes_a_lockstep_batch_to_the_free_memory(monkeypatch):
    """With lockstep batching (GPUs; forced here) and a small memory budget `sweep` runs
    the rows in smaller vmapped chunks, whose program fits the budget, with the same
    results bit for bit as all rows at once; with plenty of memory, all at once."""
    from jaxunilat._solver import _sweep

    monkeypatch.setenv("JAXUNILAT_VMAP", "batch")
    for cache in ("_SIZING", "_CHOSEN", "_POINTS"):
        monkeypatch.setattr(_sweep, cache, {})
    n = 160
    kappa, k_r = np.geomspace(5e3, 2e4, n), np.linspace(0.1, 0.4, n)
    devices = jax.devices()[:1]
    whole = _sweep.sweep_compiled(_drop, kappa, k_r, devices=devices)  # plenty of memory
    assert _sweep._sized(_drop, (kappa, k_r), (0, 0), devices, n) == (None, 0)
    full = _sweep._total(whole.memory_analysis())
    x_all, status = (np.asarray(a) for a in jaxunilat.sweep(_drop, kappa, k_r, devices=devices))
    assert np.all(status == 0)

    monkeypatch.setattr(_sweep, "_CHOSEN", {})
    monkeypatch.setattr(_sweep, "_free_bytes", lambda devices: int(full / _sweep.HEADROOM / 3))
    chunk, n_pad = _sweep._sized(_drop, (kappa, k_r), (0, 0), devices, n)
    assert chunk is not None and chunk < n and chunk % _sweep.ALIGN == 0 and (n + n_pad) % chunk == 0
    chunked = _sweep.sweep_compiled(_drop, kappa, k_r, devices=devices)
    assert _sweep._total(chunked.memory_analysis()) <= _sweep._budget(devices) < full
    x, status = (np.asarray(a) for a in jaxunilat.sweep(_drop, kappa, k_r, devices=devices))
    assert x.shape == (n, 11) and np.all(status == 0)
    np.testing.assert_array_equal(x, x_all)
    traces = jaxunilat.trace_counts()["sweep"]
    jaxunilat.sweep(_drop, kappa * 1.01, k_r, devices=devices)  # new values: the same chunks
    assert jaxunilat.trace_counts()["sweep"] == traces
    # batch_size overrides the sizing; on rows one by one (a CPU's default) nothing is measured.
    assert _sweep._sized(_drop, (kappa, k_r), (0, 0), devices, n)[0] == chunk
    monkeypatch.setenv("JAXUNILAT_VMAP", "rows")
    assert _sweep._sized(_drop, (kappa, k_r), (0, 0), devices, n) == (None, 0)
