"""The package's face: its version comes from the installed metadata, and importing it
loads neither matplotlib nor scipy (plots import matplotlib when drawn; scipy is a test
and benchmark dependency only)."""

import subprocess
import sys
from importlib.metadata import version

import jaxunilat


def test_version_is_the_installed_one():
    assert jaxunilat.__version__ == version("jaxunilat")


def test_importing_loads_neither_matplotlib_nor_scipy():
    code = (
        "import sys, jaxunilat, identify\n"
        "print(sorted(m for m in sys.modules if m.split('.')[0] in ('matplotlib', 'scipy')))"
    )
    out = subprocess.run(
        [sys.executable, "-c", code], capture_output=True, text=True, check=True, timeout=120
    )
    assert out.stdout.strip() == "[]"


def test_identify_uses_only_the_public_api_and_jaxunilat_internal():
    """The two packages depend one way: identify imports jaxunilat's public names and
    `jaxunilat.internal`, never a private module (parsed, so strings and comments do not
    count)."""
    import ast
    import pathlib

    root = pathlib.Path(__file__).resolve().parent.parent / "identify"
    private = []
    for path in sorted(root.glob("*.py")):
        for node in ast.walk(ast.parse(path.read_text(encoding="utf-8"))):
            names = []
            if isinstance(node, ast.ImportFrom) and node.module:
                names = [node.module] + [f"{node.module}.{a.name}" for a in node.names]
            elif isinstance(node, ast.Import):
                names = [a.name for a in node.names]
            for name in names:
                parts = name.split(".")
                if parts[0] == "jaxunilat" and any(p.startswith("_") for p in parts[1:]):
                    private.append(f"{path.name}:{node.lineno}: {name}")
    assert private == []


def _imports(path):
    """(line, module) of every import in a source file (parsed: strings and comments do
    not count); relative imports resolved against the file's package."""
    import ast

    package = ".".join(path.relative_to(_ROOT).with_suffix("").parts)
    if path.name == "__init__.py":
        package += ".__init__"
    found = []
    for node in ast.walk(ast.parse(path.read_text(encoding="utf-8"))):
        if isinstance(node, ast.ImportFrom):
            base = node.module or ""
            if node.level:
                parent = package.split(".")[: -node.level]
                base = ".".join(parent + ([base] if base else []))
            found += [(node.lineno, base)] + [(node.lineno, f"{base}.{a.name}") for a in node.names]
        elif isinstance(node, ast.Import):
            found += [(node.lineno, a.name) for a in node.names]
    return found


_ROOT = __import__("pathlib").Path(__file__).resolve().parent.parent


def test_only_the_command_line_and_the_bench_import_identify():
    """jaxunilat's core, studies and figures never import `identify` (the packages
    depend one way: identify on jaxunilat)."""
    offenders = []
    for path in sorted((_ROOT / "jaxunilat").rglob("*.py")):
        part = path.relative_to(_ROOT / "jaxunilat").parts[0]
        if part in ("_cli", "_bench"):
            continue
        offenders += [
            f"{path.relative_to(_ROOT)}:{line}: {name}"
            for line, name in _imports(path)
            if name.split(".")[0] == "identify"
        ]
    assert offenders == []


def test_identify_reads_only_public_names_of_jaxunilat():
    """`ju.NAME` in identify names the curated public API (not a private attribute, and
    not one of the top-level aliases kept for the namespaces)."""
    import ast

    public = {name for name in dir(jaxunilat) if not name.startswith("_")}
    offenders = []
    for path in sorted((_ROOT / "identify").glob("*.py")):
        tree = ast.parse(path.read_text(encoding="utf-8"))
        aliases = {
            a.asname or a.name
            for node in ast.walk(tree)
            if isinstance(node, ast.Import)
            for a in node.names
            if a.name == "jaxunilat"
        }
        for node in ast.walk(tree):
            if isinstance(node, ast.Attribute) and isinstance(node.value, ast.Name):
                if node.value.id in aliases and node.attr not in public:
                    offenders.append(f"{path.name}:{node.lineno}: {node.value.id}.{node.attr}")
    assert offenders == []


def test_namespaces_and_the_aliases_of_their_old_top_level_names():
    assert jaxunilat.analysis.ftle is jaxunilat.ftle
    assert jaxunilat.plot.plot_ball is jaxunilat.plot_ball
    assert jaxunilat.paper.reproduce is jaxunilat.reproduce
    assert jaxunilat.debug.trace_counts is jaxunilat.trace_counts
    assert isinstance(jaxunilat.debug.trace_counts(), dict)
    try:
        jaxunilat.no_such_name  # noqa: B018
    except AttributeError as err:
        assert "no_such_name" in str(err)
    else:
        raise AssertionError("an unknown attribute must raise AttributeError")


def test_no_function_is_over_150_lines():
    """Functions short enough to read, in both packages (docstrings included)."""
    import ast

    long = []
    for package in ("jaxunilat", "identify"):
        for path in sorted((_ROOT / package).rglob("*.py")):
            for node in ast.walk(ast.parse(path.read_text(encoding="utf-8"))):
                if isinstance(node, (ast.FunctionDef, ast.AsyncFunctionDef)):
                    lines = node.end_lineno - node.lineno + 1
                    if lines > 150:
                        long.append(f"{path.relative_to(_ROOT)}:{node.lineno}: {node.name} ({lines} lines)")
    assert long == []


def test_the_core_does_not_depend_on_its_studies_figures_or_command_line():
    """Dependencies run downwards: `_models` and `internal` import no other part of
    jaxunilat but `internal`; `_solver` imports only `_models` and `internal`."""
    allowed = {
        "_models": {"_models", "internal"},
        "internal": {"internal"},
        "_solver": {"_solver", "_models", "internal"},
    }
    offenders = []
    for part, ok in allowed.items():
        for path in sorted((_ROOT / "jaxunilat" / part).rglob("*.py")):
            for line, name in _imports(path):
                parts = name.split(".")
                if parts[0] == "jaxunilat" and (len(parts) < 2 or parts[1] not in ok):
                    offenders.append(f"{path.relative_to(_ROOT)}:{line}: {name}")
    assert offenders == []


def test_notebooks_use_only_public_modules():
    """The notebooks teach the public API: no `jaxunilat._...` or `identify._...` import
    in any code cell (parsed), and `jaxunilat.bench` importable without scipy."""
    import ast
    import json

    offenders = []
    for path in sorted((_ROOT / "notebooks").glob("*.ipynb")):
        for cell in json.loads(path.read_text(encoding="utf-8"))["cells"]:
            if cell["cell_type"] != "code":
                continue
            code = "".join(line for line in cell["source"] if not line.lstrip().startswith(("%", "!")))
            for node in ast.walk(ast.parse(code)):
                names = []
                if isinstance(node, ast.Import):
                    names = [a.name for a in node.names]
                elif isinstance(node, ast.ImportFrom) and node.module:
                    names = [node.module] + [f"{node.module}.{a.name}" for a in node.names]
                offenders += [
                    f"{path.name}: {n}" for n in names if any(p.startswith("_") for p in n.split(".")[1:])
                ]
    assert offenders == []
    code = "import sys, jaxunilat.bench; print(sorted(m for m in sys.modules if m.split('.')[0] == 'scipy'))"
    out = subprocess.run(
        [sys.executable, "-c", code], capture_output=True, text=True, check=True, timeout=120
    )
    assert out.stdout.strip() == "[]"
