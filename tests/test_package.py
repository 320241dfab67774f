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
