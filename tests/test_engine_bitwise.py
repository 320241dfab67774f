"""The event engine's outputs against a stored reference, bit for bit.

`tests/data/engine_reference.npz` holds every output of a set of event-mode runs (Table 1
examples 1–5, Dopri8 pieces, integrated flight, a resting drop, Hunt–Crossley, forward
mode through `jax.jacfwd`, reverse mode through `jax.grad`, a `jax.vmap` batch over κ and
the rolling-mill coupling), computed once by the engine it guards. A restructuring of the
engine that is meant to change no arithmetic must reproduce them exactly.

The comparison is bitwise (`np.testing.assert_array_equal`) only where the stored jax and
jaxlib versions, the machine (`platform.machine()`) and the loop-kernel setting match the
running ones: XLA's code generation (fusion, vectorization, fused multiply–adds) changes
between versions and CPUs, and with it the last bits of a float64 result, which the event
location then carries into every later piece. Elsewhere the check is a tolerance of
rtol 1e-12-ish (scaled by each array's magnitude), which still catches a changed formula.

Regenerate (with the engine whose outputs are the reference, before a refactoring):

    python tests/test_engine_bitwise.py --regenerate
"""

from __future__ import annotations

import os
import platform
import sys

import jax
import jax.numpy as jnp
import numpy as np
import pytest

import jaxunilat

PATH = os.path.join(os.path.dirname(os.path.abspath(__file__)), "data", "engine_reference.npz")
SAMPLES = 201
PAPER_Y0 = (-0.4, -1.0 / 0.122)
#: The shared run settings of the ball cases (one compile per model structure).
BALL = dict(solver="event", rtol=1e-10, atol=1e-10, samples=SAMPLES, outputs=("x", "v"))
BUFFERS = dict(max_steps=8192, max_events=256)


def _solution(sol):
    """A Solution's arrays by name (ys, y1, status, step counts, EventRecord fields)."""
    out = {f"ys.{k}": v for k, v in sol.ys.items()}
    out.update(y1=sol.y1, status=sol.status, num_steps=sol.num_steps)
    out.update(num_accepted_steps=sol.num_accepted_steps, num_rejected_steps=sol.num_rejected_steps)
    ev = sol.events
    for name in ("t", "y", "kind", "wall", "peak_force", "count", "open_peak_force", "rest_time"):
        out[f"events.{name}"] = getattr(ev, name)
    return out


def _ball(model, y0, t1, **kw):
    return _solution(jaxunilat.simulate(model, jnp.asarray(y0, float), t1, **{**BALL, **BUFFERS, **kw}))


def _table1(n):
    def run():
        ball = jaxunilat.Ball.table1(n)
        return _solution(jaxunilat.simulate(ball, ball.paper_initial_state(), 2.0, **BALL, **BUFFERS))

    return run


def _rest_drop():
    # Table 1 example 2 without the upper wall, dropped from 5 cm above the lower one.
    return _ball(jaxunilat.Ball.table1(2, upper=None), (-0.35, 0.0), 3.0, max_steps=50_000, max_events=1024)


def _rest_drop_damped():
    # The same with k_r = 0.5 N·s/m: it comes to rest (from 1.24 s) and ends in one closed-form piece.
    ball = jaxunilat.Ball.table1(2, upper=None, k_r=0.5)
    return _ball(ball, (-0.35, 0.0), 3.0, max_steps=50_000, max_events=1024)


def _hunt_crossley():
    ball = jaxunilat.Ball.table1(2, law=jaxunilat.HuntCrossley(1.5), kappa=1e6, k_r=2e6)
    return _ball(ball, PAPER_Y0, 1.0)


def _forward_kappa():
    def x_of(kappa):
        sol = jaxunilat.simulate(
            jaxunilat.Ball.table1(2, kappa=kappa),
            jnp.asarray(PAPER_Y0),
            0.5,
            autodiff="forward",
            **BALL,
            **BUFFERS,
        )
        return {"x": sol.ys["x"], "events.t": sol.events.t[:8]}

    value = x_of(jnp.asarray(1e4))
    jac = jax.jacfwd(x_of)(jnp.asarray(1e4))
    return {**{f"value.{k}": v for k, v in value.items()}, **{f"d_dkappa.{k}": v for k, v in jac.items()}}


def _reverse_grad():
    def loss(theta):
        kappa, k_r, x0, v0 = theta
        sol = jaxunilat.simulate(
            jaxunilat.Ball.table1(2, kappa=kappa, k_r=k_r), jnp.stack([x0, v0]), 0.5, **BALL, **BUFFERS
        )
        ev = sol.events
        entries = (ev.kind == 1) & (jnp.arange(ev.t.shape[0]) < ev.count)
        idx = jnp.nonzero(entries, size=3, fill_value=0)[0]
        return jnp.sum(sol.ys["x"]) + jnp.sum(ev.t[idx])

    theta = jnp.asarray([1.0e4, 0.2, -0.39, PAPER_Y0[1]])
    value, grad = jax.value_and_grad(loss)(theta)
    return {"loss": value, "grad": grad}


def _vmap_kappa():
    def run(kappa):
        sol = jaxunilat.simulate(
            jaxunilat.Ball.table1(2, kappa=kappa),
            jnp.asarray(PAPER_Y0),
            0.5,
            **BALL,
            max_steps=1024,
            max_events=64,
        )
        return _solution(sol)

    return jax.vmap(run)(jnp.asarray([5e3, 1e4, 1.5e4, 2e4]))


def _coupling():
    model = jaxunilat.Coupling.table2(6, "stiff", "paper")
    outputs = ("psi_xi", "dpsi_xi", "psi_eta", "dpsi_eta", "T_xi", "T_eta")
    sol = jaxunilat.simulate(
        model,
        model.paper_initial_state(),
        0.5,
        solver="event",
        rtol=1e-9,
        atol=1e-12,
        samples=SAMPLES,
        outputs=outputs,
        max_steps=32_768,
        max_events=1024,
    )
    return _solution(sol)


CASES = {
    **{f"table1_{n}": _table1(n) for n in range(1, 6)},
    "dopri8": lambda: _ball(
        jaxunilat.Ball.table1(2), PAPER_Y0, 2.0, piece_solver="dopri8", rtol=1e-12, atol=1e-12
    ),
    "integrated_flight": lambda: _ball(jaxunilat.Ball.table1(2), PAPER_Y0, 2.0, flight="integrated"),
    "rest_drop": _rest_drop,
    "rest_drop_damped": _rest_drop_damped,
    "hunt_crossley": _hunt_crossley,
    "forward_kappa": _forward_kappa,
    "reverse_grad": _reverse_grad,
    "vmap_kappa": _vmap_kappa,
    "coupling": _coupling,
}


def _environment():
    import jaxlib

    return dict(
        jax=jax.__version__,
        jaxlib=jaxlib.__version__,
        machine=platform.machine(),
        loop_kernels=str("small_while_loop_byte_threshold" in os.environ.get("XLA_FLAGS", "")),
    )


def _compute(name):
    return {f"{name}/{k}": np.asarray(v) for k, v in CASES[name]().items()}


def regenerate():
    arrays = {}
    for name in CASES:
        arrays.update(_compute(name))
        print(f"{name}: done")
    env = {f"env/{k}": np.asarray(v) for k, v in _environment().items()}
    np.savez_compressed(PATH, **arrays, **env)
    print(f"wrote {PATH} ({os.path.getsize(PATH) / 1024:.0f} KiB)")


@pytest.fixture(autouse=True)
def _lockstep_vmap(monkeypatch):
    """The reference predates `simulate`'s row-by-row `jax.vmap` rule on a CPU, whose
    last bits differ from lockstep batching (`jax.jacfwd` maps the tangents with vmap);
    the engine is compared under the lockstep rule it was recorded with
    (`tests/test_vmap_rows.py` checks the row rule against per-row runs)."""
    monkeypatch.setenv("JAXUNILAT_VMAP", "batch")


@pytest.fixture(scope="module")
def reference():
    with np.load(PATH) as data:
        return {k: data[k] for k in data.files}


def _bitwise(reference) -> bool:
    return all(str(reference[f"env/{k}"]) == v for k, v in _environment().items())


@pytest.mark.parametrize("name", list(CASES))
def test_engine_outputs_match_reference(name, reference):
    got = _compute(name)
    assert sorted(got) == sorted(k for k in reference if k.startswith(f"{name}/"))
    exact = _bitwise(reference)
    for key, value in got.items():
        want = reference[key]
        assert value.dtype == want.dtype and value.shape == want.shape, key
        if exact:
            np.testing.assert_array_equal(value, want, err_msg=key)
        elif np.issubdtype(want.dtype, np.floating):
            finite = np.isfinite(want)
            np.testing.assert_array_equal(np.isfinite(value), finite, err_msg=key)
            scale = np.max(np.abs(want[finite]), initial=0.0)
            np.testing.assert_allclose(
                value[finite], want[finite], rtol=1e-11, atol=1e-11 * scale, err_msg=key
            )
        else:
            np.testing.assert_array_equal(value, want, err_msg=key)


if __name__ == "__main__":
    if sys.argv[1:] != ["--regenerate"]:
        sys.exit("usage: python tests/test_engine_bitwise.py --regenerate")
    os.environ["JAXUNILAT_NO_CACHE"] = "1"
    os.environ["JAXUNILAT_VMAP"] = "batch"  # the rule the reference was recorded with
    jax.config.update("jax_enable_x64", True)
    jaxunilat.use_loop_kernels()  # as tests/conftest.py does: the configuration the suite runs
    regenerate()
