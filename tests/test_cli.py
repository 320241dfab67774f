"""The command line: files written, summaries printed, one-line errors with exit code 2."""

import os
import subprocess
import sys

import numpy as np
import pytest
from reference import BallParams, scipy_reference

from jaxunilat._cli._main import main


def _run(args, capsys):
    code = main(args)
    out = capsys.readouterr()
    return code, out.out, out.err


def test_simulate_ball_writes_csv_and_png(tmp_path, capsys):
    csv, png = tmp_path / "run.csv", tmp_path / "run.png"
    code, out, err = _run(
        [
            "simulate",
            "ball",
            "--example",
            "2",
            "--t1",
            "0.5",
            "--samples",
            "501",
            "--out",
            str(csv),
            "--plot",
            str(png),
        ],
        capsys,
    )
    assert code == 0, err
    lines = csv.read_text().splitlines()
    assert lines[0] == "t,x,v"
    data = np.loadtxt(csv, delimiter=",", skiprows=1)
    assert data.shape == (501, 3)
    assert data[0, 0] == 0.0 and data[-1, 0] == pytest.approx(0.5, abs=0)
    assert np.allclose(np.diff(data[:, 0]), 0.001)
    # The trajectory in the file is the physical one (independent scipy reference).
    ref_x, _ = scipy_reference(BallParams.table1(2), (-0.4, -1 / 0.122), 0.5)(data[:, 0])
    assert np.max(np.abs(data[:, 1] - ref_x)) < 1e-5
    assert png.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    assert png.stat().st_size > 10_000
    assert "contacts" in out and "steps" in out and "final" in out


def test_event_solver_counts_located_contacts(capsys):
    code, out, err = _run(["simulate", "ball", "--solver", "event", "--t1", "2", "--samples", "11"], capsys)
    assert code == 0, err
    # The scipy reference (tests/reference.py, DOP853 with event location, rtol 1e-13): 8 contacts
    # over [0, 2] s, 3 of them upper.
    assert "8 located (5 lower, 3 upper)" in out


def test_flags_override_example(tmp_path, capsys):
    csv = tmp_path / "run.csv"
    code, _, err = _run(
        [
            "simulate",
            "ball",
            "--example",
            "1",
            "--kappa",
            "2e4",
            "--k-r",
            "0.05",
            "--drag",
            "0",
            "--gap",
            "0.6",
            "--x0",
            "0",
            "--v0",
            "3",
            "--t1",
            "0.4",
            "--samples",
            "41",
            "--out",
            str(csv),
        ],
        capsys,
    )
    assert code == 0, err
    data = np.loadtxt(csv, delimiter=",", skiprows=1)
    params = BallParams(kappa=2e4, k_r=0.05, drag=None, lower=-0.3, upper=0.3)
    ref_x, _ = scipy_reference(params, (0.0, 3.0), 0.4)(data[:, 0])
    assert np.max(np.abs(data[:, 1] - ref_x)) < 1e-5


BAD = [
    ["simulate", "ball", "--mass", "-1"],
    ["simulate", "ball", "--gap", "0"],
    ["simulate", "ball", "--heaviside", "logistic"],
    ["simulate", "ball", "--heaviside", "softplus", "--eps", "0"],
    ["simulate", "ball", "--solver", "rk4", "--dt", "0"],
    ["simulate", "ball", "--t1", "0"],
    ["simulate", "ball", "--kappa", "nan"],
    ["simulate", "ball", "--solver", "euler"],
    ["simulate", "ball", "--samples", "1"],
    ["simulate", "ball", "--example", "7"],
    ["simulate", "ball", "--no-such-flag"],
    ["simulate", "ball", "--kappa", "abc"],
    ["simulate"],
    [],
]


@pytest.mark.parametrize("argv", BAD, ids=lambda a: " ".join(a) or "<none>")
def test_bad_flags_exit_2_with_one_line(argv, capsys):
    code, out, err = _run(argv, capsys)
    assert code == 2
    lines = err.strip().splitlines()
    assert len(lines) == 1, err
    assert lines[0].startswith("jaxunilat: error:")
    assert "Traceback" not in err


def test_output_path_checks(tmp_path, capsys):
    code, _, err = _run(["simulate", "ball", "--out", str(tmp_path)], capsys)
    assert code == 2 and "directory" in err
    code, _, err = _run(["simulate", "ball", "--out", str(tmp_path / "missing" / "x.csv")], capsys)
    assert code == 2 and "does not exist" in err


@pytest.mark.parametrize("dt", ["5", "1e-3", "3e-3"])
def test_rk4_beyond_its_step_limit_is_refused(dt, tmp_path, capsys):
    """Before: exit 0 with x(t1) = -1.2e14 m (dt 5 s), or contacts silently lost (1e-3 s)."""
    csv = tmp_path / "x.csv"
    code, _, err = _run(["simulate", "ball", "--solver", "rk4", "--dt", dt, "--out", str(csv)], capsys)
    assert code == 2
    assert len(err.strip().splitlines()) == 1 and f"dt = {float(dt):g} s" in err and "0.000153" in err
    assert not csv.exists()


def test_console_script_module_entry_point():
    env = dict(os.environ, MPLBACKEND="Agg")
    proc = subprocess.run(
        [sys.executable, "-m", "jaxunilat", "simulate", "ball", "--mass", "0"],
        capture_output=True,
        text=True,
        env=env,
        timeout=300,
    )
    assert proc.returncode == 2
    assert proc.stderr.count("\n") == 1 and "mass" in proc.stderr


def test_events_writes_contact_table(tmp_path, capsys):
    events = tmp_path / "contacts.csv"
    code, out, err = _run(
        ["simulate", "ball", "--solver", "event", "--t1", "2", "--samples", "11", "--events", str(events)],
        capsys,
    )
    assert code == 0, err
    lines = events.read_text().splitlines()
    assert lines[0] == "wall,t_in,t_out,v_in,v_out,restitution,peak_force,max_penetration"
    rows = [line.split(",") for line in lines[1:]]
    # The scipy reference (checked against it below): 8 contacts over [0, 2] s, 3 of them upper.
    assert len(rows) == 8
    assert [r[0] for r in rows].count("upper") == 3
    ref = scipy_reference(BallParams.table1(2), (-0.4, -1 / 0.122), 2.0).contacts
    t_in = np.array([float(r[1]) for r in rows])
    assert np.max(np.abs(t_in - [c.t_in for c in ref])) < 1e-8
    assert f"wrote      {events} (contact table: 8 contacts)" in out


def test_events_contact_open_at_t1_has_empty_fields(tmp_path, capsys):
    events = tmp_path / "contacts.csv"
    # The first upper contact lasts from 0.121668 s to about 0.1232 s (the scipy reference).
    argv = ["simulate", "ball", "--solver", "event", "--t1", "0.1225", "--samples", "11"]
    code, _, err = _run([*argv, "--events", str(events)], capsys)
    assert code == 0, err
    last = events.read_text().splitlines()[-1].split(",")
    assert last[0] == "upper" and last[2] == last[4] == last[5] == ""
    assert float(last[6]) > 0 and float(last[7]) > 0


def test_events_needs_event_solver(tmp_path, capsys):
    events = tmp_path / "contacts.csv"
    code, _, err = _run(["simulate", "ball", "--events", str(events)], capsys)
    assert code == 2
    lines = err.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith("jaxunilat: error:")
    assert "--events needs --solver event" in lines[0]
    assert not events.exists()


def test_events_output_path_checks(tmp_path, capsys):
    base = ["simulate", "ball", "--solver", "event"]
    code, _, err = _run([*base, "--events", str(tmp_path)], capsys)
    assert code == 2 and "directory" in err
    code, _, err = _run([*base, "--events", str(tmp_path / "missing" / "x.csv")], capsys)
    assert code == 2 and "does not exist" in err
    same = str(tmp_path / "same.csv")
    code, _, err = _run([*base, "--out", same, "--events", same], capsys)
    assert code == 2 and "same file" in err and len(err.strip().splitlines()) == 1


_FOREVER = """
import sys
import jax, jax.numpy as jnp
import jaxunilat._solver._simulate as engine
from jaxunilat._cli._main import main

def forever(*args, **kwargs):  # a compiled solve that never returns
    print("solving", flush=True)
    loop = jax.jit(lambda x: jax.lax.while_loop(lambda c: c >= 0, lambda c: c + 1.0, x))
    return loop(jnp.float64(0.0)).block_until_ready()

engine.simulate = forever
sys.exit(main(["simulate", "ball", "--samples", "11"]))
"""


def test_ctrl_c_interrupts_a_compiled_solve():
    """Ctrl-C inside a compiled computation: one line and exit 130 at once, not a hang
    until the computation ends (here: never)."""
    import signal
    import time

    env = dict(os.environ, MPLBACKEND="Agg")
    proc = subprocess.Popen(
        [sys.executable, "-c", _FOREVER], stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, env=env
    )
    try:
        assert proc.stdout.readline() == "solving\n"
        time.sleep(0.5)  # into the compiled loop (an earlier signal ends it the same way)
        proc.send_signal(signal.SIGINT)
        _, err = proc.communicate(timeout=120)
    finally:
        proc.kill()
    assert proc.returncode == 130, err
    ours = [line for line in err.splitlines() if line.startswith("jaxunilat:")]
    assert ours == ["jaxunilat: error: interrupted"], err


# -- solver knobs and failure hints ----------------------------------------------------------


class _Recorder:
    """Stands in for `simulate`: records its keywords, returns a failed run."""

    def __init__(self, status):
        self.kwargs, self.status = None, status

    def __call__(self, model, y0, t1, **kwargs):
        import types

        self.kwargs = kwargs
        return types.SimpleNamespace(status=self.status)


@pytest.mark.parametrize("model", ["ball", "coupling"])
def test_solver_knob_flags_reach_simulate(model, monkeypatch, capsys):
    import jaxunilat._solver._simulate as engine
    from jaxunilat import Status

    record = _Recorder(Status.MAX_STEPS)
    monkeypatch.setattr(engine, "simulate", record)
    argv = ["simulate", model, "--solver", "event", "--t1", "1", "--max-steps", "1e3", "--max-events", "64"]
    code, _, err = _run([*argv, "--piece-solver", "dopri8", "--flight", "integrated"], capsys)
    assert code == 1
    kw = record.kwargs
    assert (kw["max_steps"], kw["max_events"], kw["piece_solver"], kw["flight"]) == (
        1000,
        64,
        "dopri8",
        "integrated",
    )
    # The hint names this run's budget and only the event mode's knobs, as flags.
    line = err.strip()
    assert "--max-steps = 1000" in line and "--rtol/--atol" in line and "--flight closed" in line
    assert "--piece-solver dopri8" not in line and "--dt" not in line  # already dopri8; no rk4 advice


@pytest.mark.parametrize(
    "solver, status, present, absent",
    [
        (
            "event",
            "MAX_STEPS",
            ["--max-steps = 16384", "--piece-solver dopri8", "--t1"],
            ["--flight", "--dt"],
        ),
        ("tsit5", "MAX_STEPS", ["--max-steps = 200000", "--rtol/--atol"], ["--piece-solver", "--flight"]),
        ("rk4", "MAX_STEPS", ["--max-steps = 200016", "--dt"], ["--rtol", "--piece-solver"]),
        ("event", "EVENT_OVERFLOW", ["--max-events = 2048", "increase --max-events"], ["--max-steps"]),
        ("tsit5", "NONFINITE", ["tighten --rtol/--atol"], ["--piece-solver", "--dt"]),
    ],
)
def test_ball_failure_hint_lists_the_knobs_of_the_solver_used(
    solver, status, present, absent, monkeypatch, capsys
):
    import jaxunilat._solver._simulate as engine
    from jaxunilat import Status

    monkeypatch.setattr(engine, "simulate", _Recorder(Status[status]))
    code, _, err = _run(["simulate", "ball", "--solver", solver, "--t1", "2"], capsys)
    assert code == 1 and len(err.strip().splitlines()) == 1
    for part in present:
        assert part in err, err
    for part in absent:
        assert part not in err, err


@pytest.mark.parametrize(
    "argv, flag",
    [
        (["simulate", "ball", "--solver", "tsit5", "--flight", "closed"], "--flight"),
        (
            ["simulate", "ball", "--solver", "rk4", "--dt", "1e-5", "--piece-solver", "dopri8"],
            "--piece-solver",
        ),
        (["simulate", "coupling", "--solver", "tsit5", "--max-events", "10"], "--max-events"),
    ],
)
def test_event_knobs_need_the_event_solver(argv, flag, capsys):
    code, _, err = _run(argv, capsys)
    assert code == 2 and f"{flag} applies to --solver event only" in err


def test_api_failure_hints_follow_the_solver():
    from jaxunilat._solver._settings import make_settings
    from jaxunilat._solver._simulate import _messages

    event = _messages(make_settings("event", 1.0, flight="integrated", dtmax=0.01))[0]
    for part in ("max_steps = 16384", "piece_solver='dopri8'", "flight='closed'", "a larger dtmax"):
        assert part in event, event
    dopri = _messages(make_settings("event", 1.0, piece_solver="dopri8"))[0]
    assert "piece_solver" not in dopri and "flight" not in dopri and "dtmax" not in dopri
    rk4 = _messages(make_settings("rk4", 1.0, dt=1e-5))
    assert "rtol" not in rk4[0] and "increase max_steps" in rk4[0] and "decrease dt" in rk4[1]
    tsit5 = _messages(make_settings("tsit5", 1.0))[0]
    assert "loosen rtol/atol" in tsit5 and "piece_solver" not in tsit5


def test_a_solver_failure_inside_a_transformation_prints_its_own_message(capsys, monkeypatch):
    """A run that fails inside jit/jacrev reaches the command line wrapped (equinox's class
    name first, JAX's traced stack with file paths before it): the one line printed is
    the solver's message, never a traceback's file path."""
    import jaxunilat.analysis._sensitivity as sensitivity
    from jaxunilat._cli._main import main

    wrapped = (
        "Above is the stack outside of JIT. Below is the stack inside of JIT:\n"
        '  File "/somewhere/jaxunilat/_sensitivity.py", line 320, in _ball_jacobian\n'
        "equinox.EquinoxRuntimeError: jaxunilat.simulate: the solver used all max_steps = 16384 steps "
        "before t1 (event); increase max_steps\n\nAn error occurred during the runtime of your JAX program."
    )

    def fail(*args, **kwargs):
        raise RuntimeError(wrapped)

    monkeypatch.setattr(sensitivity, "ball_sensitivity", fail)
    code = main(["sensitivity", "ball", "--t1", "30"])
    err = capsys.readouterr().err.strip().splitlines()
    assert code != 0 and len(err) == 1
    assert err[0] == (
        "jaxunilat: error: jaxunilat.simulate: the solver used all max_steps = 16384 steps before t1 "
        "(event); increase max_steps"
    )


def test_bundled_data_is_found_from_any_working_folder(tmp_path, monkeypatch):
    """`jaxunilat identify` without DATA, and the bench, find the source tree's data/
    beside the package, not only in the working folder."""
    import os

    from jaxunilat.identify._cli._identify import default_data_path

    from jaxunilat._internal import bundled_data

    def data_sets():
        return bundled_data("*.csv")

    monkeypatch.chdir(tmp_path)
    path = default_data_path()
    assert os.path.isfile(path) and path.endswith(os.path.join("data", "drop_trace.csv"))
    assert path in data_sets() and len(data_sets()) >= 5
