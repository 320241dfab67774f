"""The command line's light paths, its global flags, and the bundled data of an install.

`jaxunilat --help`, `--version` and the help of jaxunilat's own commands import no other
package and nothing of `jaxunilat.identify`: the identify commands are listed with the
help line their source gives and imported only when the command line names one. (Importing `jaxunilat` itself imports JAX
and the solver, so the checks are on the packages imported, not on JAX and not on time.)
The global flags are accepted before the command and after it. The repository's data/
is installed as `jaxunilat._data`, where `bundled_data` looks first.
"""

import os
import pathlib
import shutil
import subprocess
import sys
import tomllib

import pytest

from jaxunilat._cli import _compilation_cache, _main, _sensitivity
from jaxunilat._cli._main import build_parser, main

_ROOT = pathlib.Path(__file__).resolve().parent.parent
IDENTIFY_COMMANDS = ("identify", "import", "qualify", "export")

_CHILD = """\
import sys
from jaxunilat._cli._main import main
code = main({argv!r})
top = sorted({{"identify" if m.startswith("jaxunilat.identify") else m.split(".")[0] for m in sys.modules}})
print("MODULES", code, " ".join(top))
"""


def _run_child(argv: list[str]) -> tuple[int, set[str], str]:
    """Run `main(argv)` in a fresh interpreter: (exit code, top-level packages imported, with
    `jaxunilat.identify` counted as "identify", stdout)."""
    out = subprocess.run(
        [sys.executable, "-c", _CHILD.format(argv=argv)],
        capture_output=True,
        text=True,
        timeout=180,
        check=True,
    ).stdout
    line = next(line for line in out.splitlines() if line.startswith("MODULES "))
    _, code, *top = line.split()
    return int(code), set(top), out


@pytest.mark.parametrize(
    "argv", [["--help"], ["--version"], ["simulate", "--help"], ["simulate", "ball", "--help"]], ids=" ".join
)
def test_help_and_version_import_no_other_package(argv):
    code, top, out = _run_child(argv)
    assert code == 0, out
    assert not {"identify", "optax", "matplotlib", "scipy"} & top, sorted(top)
    if argv[0] != "simulate":  # the light path: not even JAX or NumPy (simulate's parser imports the models)
        assert not {"jax", "jaxlib", "numpy"} & top, sorted(top)
    if argv == ["--help"]:
        listed = {line.split()[0] for line in out.splitlines() if line.startswith("    ") and line.split()}
        assert set(IDENTIFY_COMMANDS) <= listed, out


def test_a_command_of_another_package_is_imported_when_named():
    code, top, out = _run_child(["identify", "--help"])
    assert code == 0 and "identify" in top, out
    assert "usage: jaxunilat identify" in out and "--no-cache" in out, out
    assert not {"jax", "optax", "matplotlib", "scipy"} & top, sorted(top)  # the identify package is lazy


def test_the_help_lines_read_from_the_source_are_the_registered_ones():
    """What `jaxunilat --help` lists for identify's commands without importing them is what
    their parsers say once loaded (else `written_summary` must give None)."""
    targets = dict(_main.COMMANDS)
    full = build_parser()
    registered = {a.dest: a.help for a in _subcommands(full)._choices_actions}
    lazy = build_parser(lazy=True)
    listed = {a.dest: a.help for a in _subcommands(lazy)._choices_actions}
    for name in IDENTIFY_COMMANDS:
        assert _main.written_summary(name, targets[name]) == registered[name], name
        assert name in _subcommands(lazy).waiting, name
    assert listed == registered
    assert list(listed) == list(registered)  # the same order


def test_a_waiting_command_loads_in_its_place():
    parser = build_parser(lazy=True)
    commands = _subcommands(parser)
    before = [a.dest for a in commands._choices_actions]
    args = parser.parse_args(["qualify"])
    assert args.command == "qualify" and callable(args.func)
    assert "qualify" not in commands.waiting
    assert [a.dest for a in commands._choices_actions] == before


def test_a_source_without_a_plain_help_line_gives_none(tmp_path, monkeypatch):
    (tmp_path / "plug_a.py").write_text(
        "HELP = 'x'\n"
        "def register(commands):\n"
        "    commands.add_parser('a', help=HELP)\n"
        "def other(commands):\n"
        "    commands.add_parser('a', aliases=['b'], help='a and b')\n"
        "def plain(commands):\n"
        "    p = commands.add_parser('a', help='the plain line', description='more')\n"
    )
    monkeypatch.syspath_prepend(str(tmp_path))
    assert _main.written_summary("a", "plug_a:register") is None
    assert _main.written_summary("a", "plug_a:other") is None
    assert _main.written_summary("a", "plug_a:plain") == "the plain line"
    assert _main.written_summary("a", "plug_a:missing") is None
    assert _main.written_summary("a", "no_such_module_here:register") is None
    assert "plug_a" not in sys.modules


def _subcommands(parser):
    return next(a for a in parser._actions if isinstance(a, _main._Commands))


# -- the global flags, before and after the command ------------------------------------


@pytest.mark.parametrize("lazy", [False, True], ids=["full", "lazy"])
@pytest.mark.parametrize(
    "argv, no_cache, debug",
    [
        (["identify", "x.csv"], False, False),
        (["--no-cache", "identify", "x.csv"], True, False),
        (["identify", "--no-cache", "x.csv"], True, False),
        (["identify", "x.csv", "--no-cache", "--debug"], True, True),
        (["--debug", "simulate", "ball"], False, True),
        (["simulate", "ball", "--debug"], False, True),
        (["simulate", "--no-cache", "ball"], True, False),
        (["--debug", "simulate", "ball", "--no-cache"], True, True),
        (["import", "audio", "a.wav", "--ball", "pingpong", "--out", "o.csv", "--no-cache"], True, False),
    ],
)
def test_global_flags_are_accepted_before_and_after_the_command(lazy, argv, no_cache, debug):
    args = build_parser(lazy=lazy).parse_args(argv)
    assert (args.no_cache, args.debug) == (no_cache, debug)


def test_version_after_the_command(capsys):
    from jaxunilat import __version__

    assert main(["simulate", "ball", "--version"]) == 0
    assert capsys.readouterr().out.strip() == f"jaxunilat {__version__}"


@pytest.mark.parametrize("where", ["before", "after"])
def test_no_cache_after_the_command_turns_the_cache_off(where, tmp_path, monkeypatch, capsys):
    enabled = []
    monkeypatch.setattr(_compilation_cache, "enable_compilation_cache", lambda: enabled.append(True))
    missing = str(tmp_path / "missing.csv")
    argv = ["--no-cache", "identify", missing] if where == "before" else ["identify", missing, "--no-cache"]
    assert main(argv) == 2
    assert main(["identify", missing]) == 2
    assert enabled == [True], "only the run without --no-cache enables the cache"
    assert "missing.csv" in capsys.readouterr().err


@pytest.mark.parametrize("where", ["before", "after"])
def test_debug_after_the_command_prints_the_traceback(where, monkeypatch, capsys):
    def boom(args):
        raise KeyError("boom")

    monkeypatch.setattr(_sensitivity, "_run_sensitivity", boom)
    argv = ["--debug", "sensitivity", "ball"] if where == "before" else ["sensitivity", "ball", "--debug"]
    assert main(argv) == 1
    err = capsys.readouterr().err
    assert "Traceback" in err and "internal error: KeyError" in err, err
    assert main(["sensitivity", "ball"]) == 1
    assert "Traceback" not in capsys.readouterr().err


# -- the bundled data in the wheel ------------------------------------------------------


def test_the_wheel_lists_every_package_and_installs_the_data():
    from setuptools import find_namespace_packages

    config = tomllib.loads((_ROOT / "pyproject.toml").read_text(encoding="utf-8"))["tool"]["setuptools"]
    found = find_namespace_packages(where=str(_ROOT), include=["jaxunilat*", "identify*"])
    found = [
        f"jaxunilat.{p}" if p.startswith("identify") else p for p in found if not p.endswith("__pycache__")
    ]
    assert sorted(config["packages"]) == sorted([*found, "jaxunilat._data"])
    assert config["package-dir"] == {"jaxunilat._data": "data", "jaxunilat.identify": "identify"}
    patterns = config["package-data"]["jaxunilat._data"]
    assert "*.csv" in patterns and "README.md" in patterns
    assert (_ROOT / "data" / "drop_trace.csv").is_file()


def _fake_install(root: pathlib.Path, with_data: bool) -> None:
    """`root/jaxunilat/`: the real `_internal` package beside an (optional) `_data/`, as
    an installed wheel lays them out, and no source tree's data/ beside it."""
    package = root / "jaxunilat"
    shutil.copytree(
        _ROOT / "jaxunilat" / "_internal", package / "_internal", ignore=shutil.ignore_patterns("__pycache__")
    )
    (package / "__init__.py").write_text("")
    if with_data:
        (package / "_data").mkdir()
        (package / "_data" / "drop_trace.csv").write_text("installed\n")


@pytest.mark.parametrize("with_data", [True, False], ids=["installed", "working-folder"])
def test_bundled_data_looks_in_the_installed_package_first(with_data, tmp_path):
    site, work = tmp_path / "site", tmp_path / "work"
    _fake_install(site, with_data)
    (work / "data").mkdir(parents=True)
    (work / "data" / "drop_trace.csv").write_text("working folder\n")
    code = "from jaxunilat._internal._io import bundled_data; print(bundled_data('drop_trace.csv'))"
    env = {**os.environ, "PYTHONPATH": str(site)}
    out = subprocess.run(
        [sys.executable, "-c", code],
        cwd=work,
        env=env,
        capture_output=True,
        text=True,
        timeout=120,
        check=True,
    ).stdout
    expected = site / "jaxunilat" / "_data" if with_data else work / "data"
    assert out.strip() == repr([str(expected / "drop_trace.csv")])
