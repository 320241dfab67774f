"""No command's output ever overwrites one of its inputs or another of its outputs.

The output flags are read from the argument parser itself (every command and
subcommand), so a new output flag fails `test_output_flag_refuses_a_collision` until
it has a row in `COMMANDS`. Each collision is refused with exit code 2 and one line
naming the flag, before any work starts, and the file it named keeps its bytes.
"""

import argparse
import hashlib
import os
import re
import shutil

import pytest

from jaxunilat._cli._main import build_parser, main

DATA_DIR = os.path.join(os.path.dirname(os.path.dirname(os.path.abspath(__file__))), "data")

#: Optional flags that read a file although their metavar looks like a path (none yet).
INPUT_FLAGS: set[tuple[tuple[str, ...], str]] = set()
#: Destinations that mark an output whatever their metavar.
OUTPUT_DESTS = {"out", "json", "plot", "events"}
_PATHLIKE = re.compile(r"^(DIR|[A-Z_]+\.[a-z0-9]+)$")

#: Per command: the arguments before the outputs ("{NAME}" stands for the input file
#: NAME; a required output may come here: the flag under test, given last, overrides it),
#: the inputs (NAME -> how to make it) and which output flags are directories.
COMMANDS = {
    ("simulate", "ball"): dict(argv=["--solver", "event"], inputs={}),
    ("simulate", "coupling"): dict(argv=[], inputs={}),
    ("identify",): dict(argv=["{DATA}"], inputs={"DATA": "drop_impacts.csv"}),
    ("qualify",): dict(argv=["{FIT}"], inputs={"FIT": "fit.json"}),
    ("reproduce",): dict(argv=["--quick"], inputs={}, dirs={"--out"}),
    ("bench",): dict(argv=["--size", "tiny"], inputs={}, dirs={"--out"}),
    ("import", "wav"): dict(
        argv=["{SOURCE}", "--ball", "pingpong", "--out", "imported.csv"], inputs={"SOURCE": "phone_drop.wav"}
    ),
    ("import", "phyphox"): dict(
        argv=["{SOURCE}", "--ball", "pingpong", "--out", "imported.csv"],
        inputs={"SOURCE": "phyphox_drop_10cm.csv"},
    ),
    ("import", "video"): dict(
        argv=["{SOURCE}", "--ball", "pingpong", "--out", "imported.csv"], inputs={"SOURCE": "drop_trace.csv"}
    ),
}


def _subparsers(parser):
    for action in parser._actions:
        if isinstance(action, argparse._SubParsersAction):
            seen = set()
            for name, sub in action.choices.items():
                if id(sub) not in seen:  # aliases share one parser
                    seen.add(id(sub))
                    yield name, sub


def _walk(parser, path=()):
    """(command path, parser) for every parser under `parser` (the root excluded)."""
    for name, sub in _subparsers(parser):
        yield (*path, name), sub
        yield from _walk(sub, (*path, name))


def _is_output(command, action) -> bool:
    if not action.option_strings or action.help == argparse.SUPPRESS:
        return False
    flag = max(action.option_strings, key=len)
    if (command, flag) in INPUT_FLAGS:
        return False
    metavar = action.metavar if isinstance(action.metavar, str) else ""
    return action.dest in OUTPUT_DESTS or bool(_PATHLIKE.match(metavar))


def output_flags() -> list[tuple[tuple[str, ...], str]]:
    """Every (command path, output flag) of the command line."""
    found = []
    for command, parser in _walk(build_parser()):
        for action in parser._actions:
            if _is_output(command, action):
                found.append((command, max(action.option_strings, key=len)))
    return found


FLAGS = output_flags()
SPELLINGS = ("same", "dotdot", "symlink")


def test_the_walk_finds_the_known_outputs():
    """The parser walk itself works: it sees the outputs every command is known to have."""
    for known in [
        (("simulate", "ball"), "--out"),
        (("simulate", "ball"), "--plot"),
        (("simulate", "ball"), "--events"),
        (("simulate", "coupling"), "--out"),
        (("simulate", "coupling"), "--plot"),
        (("identify",), "--json"),
        (("identify",), "--plot"),
        (("qualify",), "--json"),
        (("reproduce",), "--out"),
        (("bench",), "--out"),
        (("import", "wav"), "--out"),
        (("import", "wav"), "--plot"),
        (("import", "phyphox"), "--out"),
        (("import", "video"), "--out"),
    ]:
        assert known in FLAGS, known


def _make_input(kind: str, path) -> None:
    if kind.endswith(".json"):
        path.write_text('{"kappa": {"estimate": 26000.0}, "k_r": {"estimate": 0.3}}\n')
    else:
        shutil.copy(os.path.join(DATA_DIR, kind), path)


def _spell(target, spelling: str, tmp_path, suffix: str) -> str:
    """Another name for the file `target`: itself, a relative detour, or a new symlink."""
    if spelling == "same":
        return str(target)
    if spelling == "dotdot":
        (tmp_path / "sub").mkdir(exist_ok=True)
        return os.path.join(".", "sub", os.pardir, target.name)  # relative to tmp_path (cwd)
    link = tmp_path / f"link{suffix}"
    link.symlink_to(target)
    return str(link)


def _digest(path) -> str:
    with open(path, "rb") as fh:
        return hashlib.sha256(fh.read()).hexdigest()


def _command_line(command, tmp_path):
    """`command`'s arguments before its outputs, with its inputs made in `tmp_path`:
    (argv, {NAME: path})."""
    inputs = {}
    for name, kind in COMMANDS[command]["inputs"].items():
        inputs[name] = tmp_path / f"input_{name.lower()}{os.path.splitext(kind)[1]}"
        _make_input(kind, inputs[name])
    argv = [
        *command,
        *(a.format(**{k: str(v) for k, v in inputs.items()}) for a in COMMANDS[command]["argv"]),
    ]
    return argv, inputs


def _cases():
    for command, flag in FLAGS:
        row = COMMANDS.get(command, {})
        file_outputs = [f for c, f in FLAGS if c == command and f not in row.get("dirs", ())]
        if flag in row.get("dirs", ()):
            targets = ["an existing file"]
        else:
            targets = [f"input {name}" for name in row.get("inputs", {})]
            targets += [f"output {other}" for other in file_outputs if other != flag]
        for target in targets or ["(no row)"]:
            for spelling in SPELLINGS:
                yield pytest.param(
                    command, flag, target, spelling, id=f"{' '.join(command)} {flag} {target} {spelling}"
                )


@pytest.mark.parametrize("command, flag, target, spelling", list(_cases()))
def test_output_flag_refuses_a_collision(command, flag, target, spelling, tmp_path, monkeypatch, capsys):
    if command not in COMMANDS or target == "(no row)":
        pytest.fail(
            f"{' '.join(command)} {flag} is an output flag with no collision to test: add the command "
            "to COMMANDS (its inputs, its directory outputs), or the flag to INPUT_FLAGS if it is read"
        )
    monkeypatch.chdir(tmp_path)
    argv, inputs = _command_line(command, tmp_path)
    suffix = ".png" if "plot" in flag else ".csv"
    if target == "an existing file":
        victim = tmp_path / "existing.txt"
        victim.write_text("keep me\n")
        argv += [flag, _spell(victim, spelling, tmp_path, "")]
    elif target.startswith("input "):
        victim = inputs[target.split()[1]]
        argv += [flag, _spell(victim, spelling, tmp_path, suffix)]
    else:  # another output of the same command, named by its plain path
        victim = tmp_path / f"shared{suffix}"
        victim.write_text("an earlier result\n")
        other = target.split()[1]
        argv += [other, str(victim), flag, _spell(victim, spelling, tmp_path, suffix)]
    before = _digest(victim)
    code = main(argv)
    err = capsys.readouterr().err
    assert code == 2, (argv, err)
    lines = err.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith("jaxunilat: error:"), err
    assert flag in lines[0], lines[0]
    assert _digest(victim) == before, f"{victim} was modified"


@pytest.mark.parametrize("name", ["bench", "reproduce"])
def test_output_dir_refuses_a_directory_where_it_writes_a_file(name, tmp_path, capsys):
    """A directory in --out DIR with the name of a file the command writes: refused up front."""
    import jaxunilat._cli._bench as bench
    import jaxunilat.paper._reproduce as reproduce

    out = tmp_path / "out"
    blocker = bench.OUTPUT_FILES[0] if name == "bench" else reproduce.SUMMARY
    (out / blocker).mkdir(parents=True)
    extra = ["--size", "tiny"] if name == "bench" else ["--quick"]
    assert main([name, *extra, "--out", str(out)]) == 2
    err = capsys.readouterr().err
    assert len(err.strip().splitlines()) == 1 and "--out" in err and blocker in err, err


@pytest.mark.parametrize("command", sorted({c for c, f in FLAGS if f == "--plot"}), ids=" ".join)
def test_plot_in_a_format_matplotlib_cannot_write_is_refused_up_front(command, tmp_path, monkeypatch, capsys):
    """Every command with --plot refuses an unknown image suffix before any work (exit 2,
    one line), so a long run never ends in a figure it cannot write."""
    monkeypatch.chdir(tmp_path)
    argv, inputs = _command_line(command, tmp_path)
    code = main([*argv, "--plot", str(tmp_path / "figure.nosuchformat")])
    err = capsys.readouterr().err
    assert code == 2, err
    assert "unsupported image format 'nosuchformat'" in err and len(err.strip().splitlines()) == 1
    assert sorted(os.listdir(tmp_path)) == sorted(p.name for p in inputs.values())
