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
