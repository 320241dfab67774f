"""The package's face: its version comes from the installed metadata, and importing it
loads neither matplotlib nor scipy (plots import matplotlib when drawn; scipy is a test
and benchmark dependency only). The rules on the source (function length, the packages'
and the layers' imports, the README's size) are in `test_rules.py`."""

import pathlib
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


_ROOT = pathlib.Path(__file__).resolve().parent.parent


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
