"""A hostile probe of the command line and the API: absurd numbers in imported tables,
broken JAX/XLA environment variables, values of the wrong kind, traced bad values under
`jax.jit`, hints that name API keywords on the command line. Each case failed (a
traceback, an abort, a bare error or a plain number without status) before its fix."""

import os
import subprocess
import sys
import warnings

import jax
import jax.numpy as jnp
import numpy as np
import pytest

import jaxunilat as ju
from jaxunilat._cli._main import main

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
WAV = os.path.join(ROOT, "data", "phone_drop.wav")
Y0 = [-0.4, -1 / 0.122]


def _run(argv, capsys):
    code = main(argv)
    out = capsys.readouterr()
    return code, out.out, out.err


def _one_error_line(err: str) -> str:
    lines = err.strip().splitlines()
    assert len(lines) == 1, err
    assert lines[0].startswith("jaxunilat: error:") and "Traceback" not in err
    return lines[0]


# -- absurd magnitudes in imported tables ----------------------------------------------


@pytest.mark.parametrize(
    ("kind", "text", "where"),
    [
        # Before: OverflowError traceback (x0 from a 1e308 s interval).
        (
            "phyphox",
            '"Event time (s)","Interval (s)"\n2.0,0.27\n1e308,0.26\n-1e300,0.25\n2.75,0.24\n',
            ("line 3", "'Event time (s)'", "'1e308'"),
        ),
        # Before: "Dataset: x (row 2) = inf is not finite", naming neither file nor column.
        ("video", "t (s),y (cm)\n0,5\n0.1,1e400\n0.2,4\n", ("line 3", "'y (cm)'", "'1e400'", "infinity")),
    ],
)
def test_absurd_table_values_are_one_line_naming_file_line_column(tmp_path, capsys, kind, text, where):
    src = tmp_path / f"{kind}.csv"
    src.write_text(text)
    with warnings.catch_warnings():
        warnings.simplefilter("error")  # no RuntimeWarning spill either
        argv = ["import", kind, str(src), "--ball", "pingpong", "--out", str(tmp_path / "o.csv")]
        code, out, err = _run(argv, capsys)
    assert code == 2
    line = _one_error_line(err)
    assert f"{kind}.csv" in line and "out of range" in line and "valid range" in line
    for part in where:
        assert part in line
    assert not (tmp_path / "o.csv").exists()


# -- environment variables that stop JAX -----------------------------------------------


@pytest.mark.parametrize(
    ("name", "value"),
    [
        ("JAX_PLATFORMS", "cuda"),  # before: a bare AssertionError traceback
        ("XLA_FLAGS", "--garbage"),  # before: XLA aborted the process (an F-log line, exit 134)
    ],
)
def test_broken_jax_environment_is_one_line_exit_2(name, value):
    env = dict(os.environ, **{name: value})
    env.pop("JAX_PLATFORMS" if name == "XLA_FLAGS" else "XLA_FLAGS", None)
    proc = subprocess.run(
        [sys.executable, "-m", "jaxunilat", "simulate", "ball", "--t1", "0.1", "--samples", "3"],
        capture_output=True,
        text=True,
        env=env,
        timeout=300,
    )
    assert proc.returncode == 2, proc.stderr
    line = _one_error_line(proc.stderr)
    assert f"{name}={value!r}" in line


# -- values of the wrong kind -----------------------------------------------------------


def test_list_valued_parameter_is_refused_naming_it():
    # Before: a Ball with kappa of shape (2,), then "Cannot stack arrays ..." from simulate.
    with pytest.raises(
        ValueError, match=r"kappa = \[1.0, 2.0\] has shape \(2,\); valid is one real number in N/m"
    ):
        ju.Ball.table1(2, kappa=[1.0, 2.0])
    with pytest.raises(ValueError, match="k_r = a traced array has shape"):
        jax.jit(lambda k: ju.Ball.table1(2, k_r=k).k_r)(jnp.ones(2))
    assert float(ju.Ball.table1(2, kappa=[1e4]).kappa) == 1e4  # one entry: taken
    rows = jax.vmap(lambda k: ju.Ball.table1(2, kappa=k).kappa)(jnp.array([1e4, 2e4]))
    np.testing.assert_array_equal(rows, [1e4, 2e4])  # a batch of models still works


def test_complex_data_is_refused_naming_it(tmp_path):
    # Before: write_csv dropped the imaginary part with a ComplexWarning; clearance_force returned 0j.
    with pytest.raises(TypeError, match="column 'x' is complex; valid columns hold real numbers"):
        ju.write_csv(tmp_path / "c.csv", ("t", "x"), (np.arange(3.0), np.arange(3) * 1j))
    assert not (tmp_path / "c.csv").exists()
    with pytest.raises(TypeError, match="x = 1j is complex; give a real number in m"):
        ju.clearance_force(1j, 0.0, 1e-3, 1.0, 0.1)


# -- throw=False: a failed status for every traced invalid input -------------------------


def _status(solver, **traced):
    def run(tr):
        kw = dict(solver=solver, throw=False, max_steps=40000, samples=5)
        if solver == "rk4":
            kw["dt"] = jnp.asarray(1e-5)
        kw.update(tr)
        return ju.simulate(ju.Ball.table1(2), jnp.asarray(Y0), kw.pop("t1", 0.1), **kw).status

    return int(jax.jit(run)(traced))


@pytest.mark.parametrize("solver", ["rk4", "tsit5"])
@pytest.mark.parametrize(
    "traced",
    [
        dict(ts=jnp.array([0.0, 0.05, 0.02])),  # before: JaxRuntimeError "saveat.ts must be increasing"
        dict(ts=jnp.array([0.0, 0.05, 0.2])),  # before: "saveat.ts must lie between t0 and t1"
        dict(dt=jnp.asarray(-1e-5)),  # before: JaxRuntimeError (a step of the wrong sign)
    ],
    ids=["ts-decreasing", "ts-beyond-t1", "dt-negative"],
)
def test_traced_invalid_input_without_throw_is_a_failed_status(solver, traced, capfd):
    assert _status(solver, **traced) == ju.Status.INVALID_INPUT
    assert "Traceback" not in capfd.readouterr().err


def test_traced_negative_rk4_step_with_throw_names_dt_and_its_range():
    run = jax.jit(
        lambda dt: ju.simulate(
            ju.Ball.table1(2), jnp.asarray(Y0), 0.1, solver="rk4", dt=dt, max_steps=20000, samples=5
        ).ys["x"]
    )
    with pytest.raises(
        Exception, match=r"dt is out of range \(a traced value\); valid range is \(0, inf\) s"
    ):
        run(-1e-5)


# -- helpers under jit: NaN for traced bad values, ValueError for concrete ones -----------


@pytest.mark.parametrize(
    ("name", "fn", "bad"),
    [
        ("kappa", lambda v: ju.contact_time(v, 0.2, 2.37e-3), -1e4),  # before: inf
        ("kappa", lambda v: ju.restitution(v, 0.2, 2.37e-3), -1e4),  # before: 0.0
        ("mass", lambda v: ju.damping_ratio(1e4, 0.2, v), -1.0),
        ("e", lambda v: ju.parameters_from_restitution(v, 1e-3, 2.37e-3)[0], 2.0),  # before: a number
        ("t_c", lambda v: ju.parameters_from_restitution(0.8, v, 2.37e-3)[1], -1e-3),
        ("kappa", lambda v: ju.hunt_crossley_contact_time(v, 1.0, 1.0), -1.0),  # before: complex
    ],
)
def test_helpers_refuse_or_give_nan(name, fn, bad):
    with pytest.raises(ValueError, match=rf"{name} = .* is out of range; valid range is"):
        fn(bad)
    assert np.isnan(float(jax.jit(fn)(bad)))


def test_impact_times_of_an_invalid_traced_run_are_nan():
    def first(kappa):
        sol = ju.simulate(ju.Ball.table1(2, kappa=kappa), jnp.asarray(Y0), 0.3, solver="event", throw=False)
        return sol.status, ju.impact_times(sol, 2), ju.apexes(sol, 1)[0]

    status, times, apex = jax.jit(first)(-1e4)  # before: plain numbers next to the failed status
    assert int(status) == ju.Status.INVALID_INPUT
    assert np.all(np.isnan(times)) and np.all(np.isnan(apex))
    status, times, _ = jax.jit(first)(1e4)
    assert int(status) == ju.Status.SUCCESS and np.all(np.isfinite(times))


# -- messages that lead somewhere ---------------------------------------------------------


def test_rk4_hint_names_flags_not_api_keywords(capsys):
    # Before: "... or solver='tsit5' or solver='event' (allow_coarse_dt=True runs it anyway ...)".
    code, _, err = _run(["simulate", "ball", "--solver", "rk4", "--dt", "1e-3"], capsys)
    line = _one_error_line(err)
    assert code == 2
    assert "allow_coarse_dt" not in line and "solver='" not in line
    assert "use --dt <= 0.000153 s, or --solver tsit5 or --solver event" in line


def test_event_mode_with_a_smooth_switch_names_the_flags(capsys):
    code, _, err = _run(
        ["simulate", "ball", "--heaviside", "logistic", "--eps", "1e-3", "--solver", "event"], capsys
    )
    line = _one_error_line(err)
    assert code == 2 and "--solver event" in line and "--heaviside exact" in line and "Exact()" not in line


def test_wav_threshold_below_the_default_onset_floor_works(tmp_path, capsys):
    # Before: "noise_level = 5 is out of range; valid range is (0, 3]" (an option the CLI lacks).
    out_csv = tmp_path / "o.csv"
    code, out, err = _run(
        ["import", "wav", WAV, "--ball", "pingpong", "--out", str(out_csv), "--threshold", "3"], capsys
    )
    assert code == 0, err
    assert out_csv.exists() and "noise_level" not in err


def test_contacts_shorter_than_the_sample_spacing_are_flagged(capsys):
    # Before: "contacts   0 on the output grid" for a ball that bounces (kappa 1e12: t_c ~ 1.5e-7 s).
    code, out, _ = _run(["simulate", "ball", "--kappa", "1e12", "--t1", "0.3", "--samples", "31"], capsys)
    assert code == 0
    line = next(x for x in out.splitlines() if x.startswith("contacts"))
    assert "a lower bound" in line and "--solver event" in line and "1.5e-07 s" in line
    code, out, _ = _run(["simulate", "ball", "--t1", "0.3", "--samples", "301"], capsys)
    line = next(x for x in out.splitlines() if x.startswith("contacts"))
    assert "lower bound" not in line  # example 2: contacts of ~1.5 ms against 1 ms between samples


def test_exact_heaviside_gradient_warning_once_per_call():
    def loss(kappa):
        return ju.simulate(ju.Ball.table1(2, kappa=kappa), jnp.asarray(Y0), 0.05, samples=3).ys["x"].sum()

    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        jax.grad(loss)(1.01e4)  # before: two warnings (both walls / two traces of the switch)
    found = [w for w in caught if issubclass(w.category, ju.ExactHeavisideGradientWarning)]
    assert len(found) == 1
    assert found[0].filename == __file__  # attributed to the user's code, not to JAX


def test_negative_seed_names_the_flag(capsys):
    # Before: "jaxunilat: error: expected non-negative integer" (NumPy's words, no flag).
    code, _, err = _run(["identify", os.path.join(ROOT, "data", "drop_impacts.csv"), "--seed", "-5"], capsys)
    assert code == 2
    assert "--seed -5 is out of range; valid range is integers >= 0" in _one_error_line(err)
