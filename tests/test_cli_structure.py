"""The command line's structure: jaxunilat's `_cli` never imports identify, identify's
commands arrive through the `jaxunilat.commands` entry points, and the exit code follows
the exception's type: bad input 2, a bug (also a `ValueError` from deep inside) an
internal error, never "bad input"."""

import ast
import os
import pathlib
import subprocess
import sys

import pytest

from jaxunilat._cli._main import main

_ROOT = pathlib.Path(__file__).resolve().parent.parent
IDENTIFY_COMMANDS = {"identify", "import", "qualify", "export"}


def _imported_modules(path: pathlib.Path) -> list[tuple[int, str]]:
    found = []
    for node in ast.walk(ast.parse(path.read_text(), filename=str(path))):
        if isinstance(node, ast.Import):
            found += [(node.lineno, alias.name) for alias in node.names]
        elif isinstance(node, ast.ImportFrom) and node.level == 0 and node.module:
            found.append((node.lineno, node.module))
    return found


def test_the_command_line_of_jaxunilat_never_imports_identify():
    offenders = [
        f"{path.relative_to(_ROOT)}:{line}: {name}"
        for path in sorted((_ROOT / "jaxunilat" / "_cli").rglob("*.py"))
        for line, name in _imported_modules(path)
        if name.split(".")[0] == "identify" or name.startswith("jaxunilat.identify")
    ]
    assert offenders == []


def test_identify_commands_import_no_private_jaxunilat_module():
    offenders = [
        f"{path.relative_to(_ROOT)}:{line}: {name}"
        for path in sorted((_ROOT / "identify" / "_cli").rglob("*.py"))
        for line, name in _imported_modules(path)
        if name.startswith("jaxunilat.")
        and name != "jaxunilat._internal"
        and not name.startswith("jaxunilat.identify")
        and any(p.startswith("_") for p in name.split(".")[1:])
    ]
    assert offenders == []


def test_identify_commands_are_in_the_command_table():
    """identify's commands are lines of the one command table, in the subpackage
    `jaxunilat.identify`; no entry-point group connects them."""
    from jaxunilat._cli._main import COMMANDS, _loaded

    targets = dict(COMMANDS)
    assert IDENTIFY_COMMANDS <= set(targets)
    for name in IDENTIFY_COMMANDS:
        assert targets[name].startswith("jaxunilat.identify._cli."), targets[name]
        assert callable(_loaded(targets[name]))


def test_a_fresh_help_lists_every_command():
    out = subprocess.run(
        [sys.executable, "-m", "jaxunilat", "--help"], capture_output=True, text=True, timeout=120, check=True
    ).stdout
    listed = {line.split()[0] for line in out.splitlines() if line.startswith("    ") and line.split()}
    assert IDENTIFY_COMMANDS | {"simulate", "sensitivity", "reproduce", "bench"} <= listed, out


# -- exit codes by type -----------------------------------------------------------------


def _boom_value_error(*args, **kwargs):
    raise ValueError("boom")


def _boom_key_error(*args, **kwargs):
    raise KeyError("boom")


@pytest.mark.parametrize(
    "fail, kind", [(_boom_value_error, "ValueError"), (_boom_key_error, "KeyError")], ids=["value", "key"]
)
def test_a_bug_deep_in_a_command_is_an_internal_error_not_bad_input(fail, kind, monkeypatch, capsys):
    """A deep function of `simulate ball` (the contact table of the event mode, after the
    solve) raises: exit 1 with one line naming the type, never 2."""
    import jaxunilat._solver._observe as observe

    monkeypatch.setattr(observe, "contact_table", fail)
    argv = ["simulate", "ball", "--solver", "event", "--t1", "0.2", "--samples", "11"]
    code = main(argv)
    err = capsys.readouterr().err
    lines = err.strip().splitlines()
    assert code == 1 and len(lines) == 1, err
    assert lines[0].startswith(f"jaxunilat: error: internal error: {kind}: ") and "--debug" in err
    assert "Traceback" not in err

    assert main(["--debug", *argv]) == 1
    err = capsys.readouterr().err
    assert "Traceback" in err and "_boom_" in err, err


def test_a_value_error_raised_inside_the_traced_solve_is_an_internal_error(monkeypatch, capsys):
    """A `ValueError` while JAX traces the solve (not the API rejecting its arguments)."""
    import jaxunilat._solver._simulate as engine

    monkeypatch.setattr(engine, "_input_checks", _boom_value_error)
    monkeypatch.setattr(engine, "kept_call", lambda name, fn, args, static: fn(*args, *static))
    code = main(["simulate", "ball", "--t1", "0.123", "--samples", "7"])
    err = capsys.readouterr().err
    assert code == 1 and "internal error: ValueError: boom" in err, err


def test_a_value_error_raised_on_the_host_before_the_solve_is_an_internal_error(monkeypatch, capsys):
    """A plain `ValueError` from the host side of `simulate` (building the solver settings,
    before any tracing) is a bug: only the API's `InputError` is bad input."""
    import jaxunilat._solver._simulate as engine

    monkeypatch.setattr(engine, "make_settings", _boom_value_error)
    code = main(["simulate", "ball", "--t1", "0.123", "--samples", "7"])
    err = capsys.readouterr().err
    assert code == 1 and "internal error: ValueError: boom" in err, err


@pytest.mark.parametrize(
    "argv, words",
    [
        (["simulate", "ball", "--kappa", "-1"], "kappa"),
        (["simulate", "ball", "--t1", "0"], "t1"),
        (["simulate", "ball", "--example", "9"], "example"),
        (["simulate", "ball", "--samples", "1"], "samples"),
    ],
)
def test_bad_input_from_deep_validation_stays_exit_2(argv, words, capsys):
    code = main(argv)
    err = capsys.readouterr().err
    assert code == 2 and words in err and len(err.strip().splitlines()) == 1, err


def test_the_exit_codes_are_documented_in_the_shell():
    from jaxunilat._cli import _main

    for code in ("0 success", "1 a run-time failure", "2 bad usage or input", "3 a fit", "130"):
        assert code in " ".join(_main.__doc__.split()), code
    assert os.path.basename(_main.__file__) == "_main.py"
