"""Messages a user can act on: bad input refused with one line naming the key, the value
and the range; the flag and the file named on a failed write; numbers in bounded width;
control characters in file names escaped; temporary names that fit every output name;
and an unconverged fit refused by `jaxunilat qualify`.

Each test runs the command line in-process (`main`) and reads its exit code, stdout and
stderr.
"""

import errno
import json
import os
import re

import pytest

from jaxunilat._cli._main import main
from jaxunilat._internal import write_atomically

FIT = {
    "parameters": {
        "kappa": {"value": 26190.0, "stderr": 490.0, "ci95": [25250.0, 27170.0]},
        "k_r": {"value": 0.3597, "stderr": 0.0033, "ci95": [0.3533, 0.3663]},
    },
    "derived": {
        "restitution": {"value": 0.935, "stderr": 3.4e-6, "ci95": [0.93499, 0.93501]},
        "contact_time": {"value": 1.0e-3, "stderr": 9.4e-6, "ci95": [0.99e-3, 1.03e-3]},
    },
    "identifiable": {"kappa": True, "k_r": True, "restitution": True, "contact_time": True},
    "correlation": [[1.0, 0.99996], [0.99996, 1.0]],
    "converged": True,
    "mass": 0.0027,
    "law": "kelvin-voigt",
}
#: A run of digits longer than any number a message should print.
LONG_DIGITS = re.compile(r"\d{17,}")


def _cli(capsys, *argv):
    capsys.readouterr()
    code = main([str(a) for a in argv])
    out, err = capsys.readouterr()
    return code, out, err


def _one_error_line(err: str) -> str:
    lines = err.splitlines()
    assert len(lines) == 1 and lines[0].startswith("jaxunilat: error: "), err
    assert "internal error" not in err and "a bug in" not in err
    return lines[0]


DATA = """# jaxunilat-data: 1
# scene = drop
# observe = {observe}
# mass = 0.0027
# drag = 0.12
# x0 = 0.305
# v0 = 0
# noise = {noise}
{body}"""
BODIES = {
    "trace": "t,x\n0,0.305\n0.1,0.256\n0.2,0.109\n",
    "impacts": "t\n0.2494\n0.6958\n1.1131\n",
    "apex": "h\n0.2461\n0.2017\n",
}


@pytest.mark.parametrize(
    ("observe", "noise", "shown", "valid"),
    [
        ("trace", "1e-200", "1e-200", "[1e-09, 1] m"),
        ("apex", "2", "2", "[1e-09, 1] m"),
        ("impacts", "1e-200", "1e-200", "[1e-07, 1] s"),
        ("impacts", "5", "5", "[1e-07, 1] s"),
    ],
)
def test_noise_outside_its_physical_range_is_refused_naming_key_value_and_range(
    tmp_path, capsys, observe, noise, shown, valid
):
    """`# noise = 1e-200` gave `internal error: LinAlgError` after pages of overflow
    warnings; now exit 2 before any fit, one line with the key, the value and the range."""
    path = tmp_path / "drop.csv"
    path.write_text(DATA.format(observe=observe, noise=noise, body=BODIES[observe]))
    code, out, err = _cli(capsys, "identify", path)
    line = _one_error_line(err)
    assert code == 2 and out == ""
    assert f"line 8: noise = {shown} is out of range; valid range is {valid}" in line


def _fit_file(tmp_path, text: str):
    path = tmp_path / "fit.json"
    path.write_text(text)
    return path


@pytest.mark.parametrize("command", [("qualify",), ("export", "mujoco")])
@pytest.mark.parametrize(
    ("what", "text", "says"),
    [
        ("nested 100000 deep", "[" * 100_000 + "]" * 100_000, "nested more than 64 deep"),
        (
            "kappa of 5001 digits",
            json.dumps(FIT).replace("26190.0", "2" + "0" * 5000),
            "a number of 5001 digits",
        ),
        (
            "kappa beyond float64",
            json.dumps(FIT).replace("26190.0", "2" + "0" * 400),
            "parameters.kappa.value = 2e+400 is out of range",
        ),
        (
            "kappa of 1e300",
            json.dumps(FIT).replace("26190.0", "1e300"),
            "parameters.kappa.value = 1e+300 N/m is out of range; valid range is [0.001, 1e+15] N/m",
        ),
        (
            "mass of 5e-324",
            json.dumps(FIT).replace('"mass": 0.0027', '"mass": 5e-324'),
            "mass = 4.94066e-324 kg is out of range; valid range is [1e-06, 1000] kg",
        ),
    ],
)
def test_a_hostile_fit_json_is_bad_input_not_a_bug(tmp_path, capsys, command, what, text, says):
    """Recursion, Python's integer-conversion limit and float64 overflow inside the fit
    reader were `internal error ... a bug in jaxunilat`; now exit 2 with one line."""
    path = _fit_file(tmp_path, text)
    code, out, err = _cli(capsys, *command, path)
    line = _one_error_line(err)
    assert code == 2 and out == ""
    assert says in line and len(line) < 400 and not LONG_DIGITS.search(line)


def test_a_failed_write_names_the_flag_and_the_file_given(tmp_path, capsys, monkeypatch):
    """`--plot out/x.png: cannot write: [Errno 13] Permission denied`, not `cannot write
    output: ... '.x.png.1a2b3c4d.tmp'` (a file the user never named)."""
    denied = os.strerror(errno.EACCES)

    def refuse(src, dst):
        raise PermissionError(errno.EACCES, denied, src, dst)

    monkeypatch.setattr(os, "replace", refuse)
    plot = tmp_path / "x.png"
    code, out, err = _cli(capsys, "simulate", "ball", "--t1", "0.01", "--samples", "11", "--plot", plot)
    line = _one_error_line(err)
    assert code == 1
    assert line == f"jaxunilat: error: --plot {plot}: cannot write: [Errno {errno.EACCES}] {denied}"
    assert not list(tmp_path.iterdir())  # nothing left behind, no temporary file either


def test_every_valid_output_name_can_be_written(tmp_path):
    """A name of 250 bytes (any up to the file system's 255) is written: the temporary file
    beside it has a short name of its own (it added 14 bytes to the output's name)."""
    path = tmp_path / ("a" * 246 + ".csv")
    with write_atomically(path) as f:
        f.write("t,x\n")
    assert path.read_text() == "t,x\n"
    assert sorted(os.listdir(tmp_path)) == [path.name]


def test_a_write_error_names_the_output_not_the_temporary_file(tmp_path, monkeypatch):
    def refuse(src, dst):
        raise PermissionError(errno.EACCES, os.strerror(errno.EACCES), src, dst)

    monkeypatch.setattr(os, "replace", refuse)
    path = tmp_path / "out.csv"
    with pytest.raises(PermissionError) as info:
        with write_atomically(path) as f:
            f.write("x")
    assert info.value.filename == str(path) and ".tmp" not in str(info.value)


def test_a_contradiction_prints_numbers_in_bounded_width(capsys):
    """A wild fit's e (1e170) in a contradiction was printed with `.4f`, 171 digits; the
    line that reports it shortens every such number to 6 significant digits."""
    from types import SimpleNamespace

    from jaxunilat.identify._cli._identify import _verdict

    reason = f"drop.csv: the fit's e = {1e170:.4f} contradicts the e = {0.9349:.4f} of its flights"
    code = _verdict(SimpleNamespace(contradictions=[reason], converged=False, message=""))
    out = capsys.readouterr().out
    assert code == 3
    assert "the fit's e = 1e+170 contradicts the e = 0.9349" in out
    assert not LONG_DIGITS.search(out)


def test_qualify_refuses_an_unconverged_fit(tmp_path, capsys):
    """`"converged": false`: exit 3 with the reason, no verdict (it printed PASS, exit 0)."""
    path = _fit_file(tmp_path, json.dumps({**FIT, "converged": False}))
    code, out, err = _cli(capsys, "qualify", path)
    line = _one_error_line(err)
    assert code == 3 and out == ""
    assert "the fit did not converge (converged = false)" in line and "--kappa" in line


def test_control_characters_in_file_names_are_escaped(tmp_path, capsys, monkeypatch):
    """A file name's terminal escape (`\\x1b[2J` clears the screen) and newline reach the
    terminal escaped, in error lines and in `wrote` lines alike, each one line."""
    missing = tmp_path / "no\x1b[2Jsuch\nfile.csv"
    code, out, err = _cli(capsys, "identify", missing)
    line = _one_error_line(err)
    assert code == 2 and "\x1b" not in err
    assert "no\\x1b[2Jsuch\\nfile.csv: no such file" in line

    name = "fit\x1b[2J\n.json"
    monkeypatch.chdir(tmp_path)
    code, out, err = _cli(capsys, "qualify", "--kappa", "26190", "--k-r", "0.3597", "--json", name)
    assert code == 0 and err == "" and "\x1b" not in out
    assert "wrote       fit\\x1b[2J\\n.json" in out.splitlines()
    assert (tmp_path / name).exists()
