"""Malformed inputs: Python API, CLI flags and data files each give a clear error.

Every Python-API case raises `ValueError` whose message names the parameter and the
offending value (and, for a range, the valid range). Every CLI case exits with code 2
and prints exactly one line, with no traceback. No input file is ever modified.
"""

import hashlib
import math
import os

import jax
import numpy as np
import pytest

import jaxunilat as ju
from jaxunilat._cli._main import main

Y0 = np.array([-0.4, -1.0 / 0.122])


def _ball(**kw):
    return ju.Ball.table1(2, **kw)


def _sim(**kw):
    args = dict(samples=11, outputs=("x",))
    args.update(kw)
    model = args.pop("model", _ball())
    y0 = args.pop("y0", Y0)
    t1 = args.pop("t1", 0.1)
    return ju.simulate(model, y0, t1, **args)


# (label, callable, substrings the message must contain)
API = [
    ("negative mass", lambda: _ball(mass=-0.1), ["mass", "-0.1", "(0, inf)"]),
    ("zero mass", lambda: _ball(mass=0.0), ["mass", "0", "(0, inf)"]),
    ("negative kappa", lambda: ju.Ball(kappa=-1e4), ["kappa", "-10000", "(0, inf)"]),
    ("NaN kappa", lambda: ju.Ball(kappa=math.nan), ["kappa", "nan", "finite"]),
    ("inf k_r", lambda: _ball(k_r=math.inf), ["k_r", "inf", "finite"]),
    ("negative k_r", lambda: _ball(k_r=-0.2), ["k_r", "-0.2", "[0, inf)"]),
    ("negative drag", lambda: _ball(drag=-0.1), ["drag", "-0.1", "[0, inf)"]),
    ("negative gravity", lambda: _ball(gravity=-9.81), ["gravity", "-9.81", "[0, inf)"]),
    ("gap zero", lambda: _ball(lower=0.1, upper=0.1), ["gap", "0", "(0, inf)"]),
    ("gap negative", lambda: _ball(lower=0.4, upper=-0.4), ["gap", "-0.8", "(0, inf)"]),
    ("eps zero", lambda: ju.Logistic(0.0), ["eps", "0", "(0, inf)"]),
    ("eps negative", lambda: ju.Softplus(-1e-5), ["eps", "-1e-05", "(0, inf)"]),
    ("eps NaN", lambda: ju.Softplus(math.nan), ["eps", "nan"]),
    ("unknown heaviside", lambda: ju.heaviside("tanh", 1e-5), ["tanh"]),
    ("unknown example", lambda: ju.Ball.table1(9), ["example", "9", "1-5"]),
    ("unknown solver", lambda: _sim(solver="kvaerno5"), ["solver", "kvaerno5", "'event'"]),
    ("rk4 dt zero", lambda: _sim(solver="rk4", dt=0.0), ["dt", "0", "(0, inf)"]),
    ("rk4 dt negative", lambda: _sim(solver="rk4", dt=-1e-5), ["dt", "-1e-05", "(0, inf)"]),
    ("rk4 without dt", lambda: _sim(solver="rk4"), ["dt", "None"]),
    ("t1 zero", lambda: _sim(t1=0.0), ["t1", "0", "t1 > t0"]),
    ("t1 negative", lambda: _sim(t1=-1.0), ["t1", "-1", "t1 > t0"]),
    ("t1 NaN", lambda: _sim(t1=math.nan), ["t1", "nan"]),
    ("t_span triple", lambda: _sim(t1=(0.0, 1.0, 2.0)), ["t_span", "pair"]),
    ("rtol zero", lambda: _sim(rtol=0.0), ["rtol", "0", "(0, 1]"]),
    ("rtol above 1", lambda: _sim(rtol=2.0), ["rtol", "2", "(0, 1]"]),
    ("atol negative", lambda: _sim(atol=-1e-8), ["atol", "-1e-08", "(0, inf)"]),
    ("y0 NaN", lambda: _sim(y0=[math.nan, 0.0]), ["y0", "nan"]),
    ("y0 shape", lambda: _sim(y0=[0.0, 0.0, 0.0]), ["y0", "(3,)", "(2,)"]),
    ("samples one", lambda: _sim(samples=1), ["samples", "1", ">= 2"]),
    ("unknown output", lambda: _sim(outputs=("acceleration",)), ["output", "acceleration", "'x'"]),
    ("no outputs", lambda: _sim(outputs=()), ["outputs", "empty"]),
    ("max_steps zero", lambda: _sim(max_steps=0), ["max_steps", "0", ">= 1"]),
    ("max_events zero", lambda: _sim(solver="event", max_events=0), ["max_events", "0", ">= 1"]),
    ("dtmax zero", lambda: _sim(solver="event", dtmax=0.0), ["dtmax", "0", "(0, inf)"]),
    (
        "unknown piece solver",
        lambda: _sim(solver="event", piece_solver="kvaerno5"),
        ["piece_solver", "kvaerno5"],
    ),
    (
        "event with smooth H",
        lambda: _sim(model=_ball(heaviside=ju.Logistic(1e-5)), solver="event"),
        ["heaviside", "Logistic", "Exact()"],
    ),
    ("ts unsorted", lambda: _sim(ts=[0.05, 0.01]), ["ts", "sorted"]),
    ("ts beyond t1", lambda: _sim(ts=[0.0, 0.5]), ["ts", "[0, 0.1]"]),
    ("not a model", lambda: ju.simulate("ball", Y0, 1.0), ["model", "'ball'"]),
    (
        "x0 inside upper wall",
        lambda: _sim(y0=[1.0, 0.0]),
        ["x0 = 1 m", "[-0.4, 0.4] m", "0.6 m inside the upper"],
    ),
    ("x0 inside lower wall", lambda: _sim(y0=[-0.41, 0.0]), ["x0 = -0.41 m", "[-0.4, 0.4] m", "lower"]),
    # Work and memory estimated before compiling: hours of RK4 steps, outputs of many GiB.
    (
        "rk4 steps 2e11",
        lambda: _sim(solver="rk4", dt=1e-11, t1=2.0),
        ["dt = 1e-11", "2e+11", "dt >= 2e-08 s"],
    ),
    ("samples 1e10", lambda: _sim(samples=10**10), ["samples = 10000000000", "GiB", "2 to 268435456"]),
    ("max_events 1e9", lambda: _sim(solver="event", max_events=10**9), ["max_events = 1000000000", "GiB"]),
    ("max_steps 1e9", lambda: _sim(max_steps=10**9), ["max_steps = 1000000000", "<= 1e+08"]),
]


@pytest.mark.parametrize("label, call, parts", API, ids=[a[0] for a in API])
def test_api_bad_input_names_parameter_value_and_range(label, call, parts):
    with pytest.raises(ValueError) as info:
        call()
    message = str(info.value)
    for part in parts:
        assert part in message, (label, message)


# (label, callable, substrings): a wrong type raises TypeError (also a ValueError) naming the parameter
TYPES = [
    ("kappa text", lambda: ju.Ball(kappa="abc"), ["kappa = 'abc'", "string", "real number in N/m"]),
    ("kappa numeric text", lambda: ju.Ball(kappa="1e4"), ["kappa = '1e4'", "string"]),
    ("kappa complex", lambda: ju.Ball(kappa=1e4 + 1j), ["kappa = (10000+1j)", "complex"]),
    ("kappa None", lambda: ju.Ball(kappa=None), ["kappa = None"]),
    ("mass object", lambda: _ball(mass=object()), ["mass = <object", "not numeric"]),
    ("k_r boolean", lambda: _ball(k_r=True), ["k_r = True", "boolean"]),
    ("coupling alpha text", lambda: ju.Coupling.table2(6, alpha="x"), ["alpha = 'x'", "string"]),
    ("eps text", lambda: ju.Logistic("x"), ["eps = 'x'", "string"]),
    ("law text", lambda: _ball(law="kv"), ["law = 'kv'", "KelvinVoigt()"]),
    ("heaviside text", lambda: _ball(heaviside="exact"), ["heaviside = 'exact'", "Exact()"]),
    ("outputs text", lambda: _sim(outputs="xv"), ["outputs = 'xv'", "tuple of names", "outputs=('x',)"]),
    ("y0 text", lambda: _sim(y0="ab"), ["y0 = 'ab'", "string"]),
    ("y0 complex", lambda: _sim(y0=[-0.4 + 1j, 0.0]), ["y0 = [(-0.4+1j), 0.0]", "complex"]),
    ("t1 text", lambda: _sim(t1="1"), ["t1 = '1'", "string"]),
    ("t_span text", lambda: _sim(t1=(0.0, "1")), ["t1 = '1'", "string"]),
    ("dt text", lambda: _sim(solver="rk4", dt="1e-5"), ["dt = '1e-5'", "string"]),
    ("rtol complex", lambda: _sim(rtol=1e-8j), ["rtol = 1e-08j", "complex"]),
    ("ts text", lambda: _sim(ts="abc"), ["ts = 'abc'", "string"]),
    ("contact_time text", lambda: ju.contact_time("a", 0.2, 1.0), ["kappa = 'a'", "string"]),
    ("ball_state text", lambda: ju.ball_state("a", 0.0), ["x0 = 'a'", "string"]),
]


@pytest.mark.parametrize("label, call, parts", TYPES, ids=[a[0] for a in TYPES])
def test_api_wrong_type_names_parameter_and_value(label, call, parts):
    with pytest.raises(TypeError) as info:
        call()
    assert isinstance(info.value, ValueError)  # code that reports bad input as ValueError sees it
    message = str(info.value)
    for part in parts:
        assert part in message, (label, message)


def test_float32_is_refused_with_the_reason():
    """x64 off: simulate refuses before compiling, and says why and how to fix it."""
    jax.config.update("jax_enable_x64", False)
    try:
        with pytest.raises(ValueError) as info:
            ju.simulate(ju.Ball.table1(2), Y0, 0.2, solver="event")
    finally:
        jax.config.update("jax_enable_x64", True)
    message = str(info.value)
    for part in ("float32", "float64", "stalls", "jax_enable_x64', True"):
        assert part in message, message


def test_float32_inputs_are_cast_up_and_accurate():
    """float32 arrays in, float64 inside: the event mode meets its tolerance."""
    ball = ju.Ball(
        kappa=np.float32(1e4), k_r=np.float32(0.2), mass=np.float32(2.37e-3), drag=np.float32(0.122)
    )
    # The stress suite's structure (2001 samples of x, v): one compile for both.
    sol = ju.simulate(
        ball,
        Y0.astype(np.float32),
        0.5,
        solver="event",
        rtol=1e-10,
        atol=1e-10,
        samples=2001,
        outputs=("x", "v"),
    )
    assert sol.ys["x"].dtype == np.float64
    # The float32 casts change the parameters by < 6e-8 relative: compare with the reference
    # of exactly those float32 values, not the float64 ones.
    from reference import BallParams, scipy_reference

    p = BallParams(
        kappa=float(np.float32(1e4)),
        k_r=float(np.float32(0.2)),
        mass=float(np.float32(2.37e-3)),
        drag=float(np.float32(0.122)),
    )
    y0 = [float(v) for v in Y0.astype(np.float32)]
    rx, _ = scipy_reference(p, y0, 0.5)(np.asarray(sol.ts))
    assert np.max(np.abs(np.asarray(sol.ys["x"]) - rx)) < 1e-8


# -- the command line ----------------------------------------------------------------------------

CLI = [
    (["simulate", "ball", "--mass", "-1"], "mass = -1"),
    (["simulate", "ball", "--gap", "0"], "gap = 0"),
    (["simulate", "ball", "--gap", "-0.8"], "gap = -0.8"),
    (["simulate", "ball", "--heaviside", "logistic", "--eps", "-1e-5"], "eps = -1e-05"),
    (["simulate", "ball", "--solver", "rk4", "--dt", "-1e-5"], "dt = -1e-05"),
    (["simulate", "ball", "--t1", "-1"], "t1 = -1"),
    (["simulate", "ball", "--rtol", "0"], "rtol = 0"),
    (["simulate", "ball", "--atol", "nan"], "atol = nan"),
    (["simulate", "ball", "--drag", "-0.1"], "drag = -0.1"),
    (["simulate", "ball", "--k-r", "-0.2"], "k_r = -0.2"),
    (["simulate", "ball", "--v0", "inf"], "v0 = inf"),
    (["simulate", "ball", "--solver", "kvaerno5"], "kvaerno5"),
    (["simulate", "ball", "--x0", "1"], "x0 = 1 m is out of range; valid range is [-0.4, 0.4] m"),
    (["simulate", "ball", "--gap", "0.5", "--x0", "-0.3"], "valid range is [-0.25, 0.25] m"),
    (["simulate", "ball", "--solver", "rk4", "--dt", "1e-11", "--t1", "2"], "dt >= 2e-08 s"),
    (["simulate", "ball", "--samples", "10000000000"], "samples = 10000000000"),
    (["simulate", "ball", "--samples", "1e10"], "samples = 10000000000"),
    (["simulate", "ball", "--samples", "2.5"], "invalid count '2.5'"),
    (["simulate", "coupling", "--t1", "1e6"], "t1 = 1e+06 s is out of range for --solver event"),
    (["simulate", "coupling", "--solver", "rk4", "--dt", "1e-9", "--t1", "1000"], "dt >= 1e-05 s"),
    (["simulate", "coupling", "--samples", "1e10"], "samples = 10000000000"),
    (["simulate", "ball", "--events", "{tmp}/e.csv"], "--events needs --solver event"),
    (["simulate", "ball", "--out", "{tmp}/a.csv", "--plot", "{tmp}/a.csv"], "name the same file"),
    (["simulate", "ball", "--out", "{tmp}"], "directory"),
    (["simulate", "ball", "--out", "{tmp}/no/such/dir/x.csv"], "x.csv"),
    (["simulate", "ball", "--plot", "{tmp}/x.docx"], "docx"),
    (["identify", "{tmp}/missing.csv"], "missing.csv"),
    (["identify", "{tmp}"], "directory"),
    (["identify", "--starts", "0"], "starts"),
    (["identify", "--fit", "spin"], "spin"),
    (["qualify", "--kappa", "-1", "--k-r", "0.3"], "kappa = -1"),
    (["qualify", "--kappa", "2.6e4"], "--k-r"),
    (["qualify", "{tmp}/missing.json"], "missing.json"),
    (["export", "mujoco", "{tmp}/missing.json"], "missing.json"),
]


@pytest.mark.parametrize("argv, part", CLI, ids=[" ".join(a) for a, _ in CLI])
def test_cli_bad_input_exit_2_one_line(argv, part, tmp_path, capsys):
    argv = [a.replace("{tmp}", str(tmp_path)) for a in argv]
    code = main(argv)
    err = capsys.readouterr().err
    assert code == 2, err
    lines = err.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith("jaxunilat: error:"), err
    assert "Traceback" not in err
    assert part.replace("{tmp}", str(tmp_path)) in lines[0], lines[0]


# -- data files ----------------------------------------------------------------------------------

GOOD_HEAD = "# jaxunilat-data: 1\n# scene = drop\n# observe = trace\n# mass = 0.0027\n# drag = 0.12\n"
GOOD_ROWS = "# x0 = 0.305\n# v0 = 0\nt,x\n0,0.305\n0.001,0.30499\n0.002,0.30498\n"

DATA = [
    ("no magic line", GOOD_HEAD.replace("# jaxunilat-data: 1\n", "") + GOOD_ROWS, "jaxunilat-data"),
    ("negative mass", GOOD_HEAD.replace("0.0027", "-0.0027") + GOOD_ROWS, "mass = -0.0027"),
    ("NaN drag", GOOD_HEAD.replace("0.12", "nan") + GOOD_ROWS, "drag"),
    ("unknown scene", GOOD_HEAD.replace("drop", "trampoline") + GOOD_ROWS, "trampoline"),
    ("unknown observe", GOOD_HEAD.replace("trace", "video") + GOOD_ROWS, "video"),
    ("text in a column", GOOD_HEAD + GOOD_ROWS.replace("0.30499", "abc"), "abc"),
    ("NaN in a column", GOOD_HEAD + GOOD_ROWS.replace("0.30499", "nan"), "nan"),
    ("times not increasing", GOOD_HEAD + GOOD_ROWS.replace("0.002,", "0.0005,"), "t"),
    ("no rows", GOOD_HEAD + "# x0 = 0.305\n# v0 = 0\nt,x\n", "row"),
    ("rackets gap zero", GOOD_HEAD.replace("drop", "rackets") + "# gap = 0\n" + GOOD_ROWS, "gap = 0"),
    ("binary garbage", b"\x00\x01\x02\xff" * 20, "bad.csv"),
]


def _digest(path):
    with open(path, "rb") as fh:
        return hashlib.sha256(fh.read()).hexdigest(), os.stat(path).st_mtime_ns


@pytest.mark.parametrize("label, content, part", DATA, ids=[d[0] for d in DATA])
def test_bad_data_file_clear_error_and_unmodified(label, content, part, tmp_path, capsys):
    from jaxunilat import identify

    path = tmp_path / "bad.csv"
    path.write_bytes(content if isinstance(content, bytes) else content.encode())
    before = _digest(path)
    with pytest.raises(ValueError) as info:
        identify.load_dataset(str(path))
    assert str(path) in str(info.value) or "bad.csv" in str(info.value), str(info.value)
    assert part in str(info.value), (label, str(info.value))
    code = main(["identify", str(path)])
    err = capsys.readouterr().err
    assert code == 2, err
    assert len(err.strip().splitlines()) == 1 and "Traceback" not in err
    assert _digest(path) == before, f"{label}: the input file was modified"


def test_good_inputs_are_never_modified(tmp_path, capsys):
    """A bundled data file and a fit JSON read by the CLI keep their bytes and mtime."""
    import shutil

    root = os.path.join(os.path.dirname(os.path.dirname(os.path.abspath(__file__))), "data")
    data = tmp_path / "drop_apex.csv"
    shutil.copy(os.path.join(root, "drop_apex.csv"), data)
    before = _digest(data)
    from jaxunilat import identify

    identify.load_dataset(str(data))
    # A bad flag after a good file: the file is read-validated and left alone.
    assert main(["identify", str(data), "--starts", "0"]) == 2
    fit = tmp_path / "fit.json"
    fit.write_text('{"parameters": {"kappa": {"value": "x"}}}')
    fit_before = _digest(fit)
    assert main(["qualify", str(fit)]) == 2
    assert main(["export", "mujoco", str(fit)]) == 2
    capsys.readouterr()
    assert _digest(data) == before
    assert _digest(fit) == fit_before


def test_start_at_a_wall_or_resting_in_contact_is_allowed():
    """The paper's start (exactly at the lower wall) and a ball resting in contact (sunk by
    its static sag m g / kappa) pass; one sag-tolerance deeper does not."""
    ball = _ball()
    sag = 2.37e-3 * 9.81 / 1e4
    for x0 in (-0.4, 0.4, 0.0, -0.4 - sag, -0.4 - 9.9 * sag):
        ball.check_initial_state(np.array([x0, 0.0]))
    with pytest.raises(ValueError, match="x0 = -0.40023"):
        ball.check_initial_state(np.array([-0.4 - 100 * sag, 0.0]))
    # One wall only: anywhere above the floor.
    ju.Ball.table1(2, upper=None).check_initial_state(np.array([5.0, 0.0]))
