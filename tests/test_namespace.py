"""One namespace: the repository's top-level identify/ folder installs as
`jaxunilat.identify`, so nothing named `identify` lands in site-packages, and PyPI's
`identify` (a pre-commit dependency, in the test extras) shares an environment with
jaxunilat.

The wheel is built here from a copy of the source tree without build isolation (the test extras
bring a setuptools recent enough), unpacked into a folder put first on `PYTHONPATH`, and
run from a folder outside the repository, beside the PyPI `identify` of this environment.
"""

from __future__ import annotations

import json
import os
import pathlib
import shutil
import subprocess
import sys
import zipfile

import pytest

_ROOT = pathlib.Path(__file__).resolve().parent.parent


#: What the wheel is built from (copied, so that the build leaves nothing in the checkout).
_SOURCES = ("pyproject.toml", "README.md", "LICENSE", "jaxunilat", "identify", "data")


@pytest.fixture(scope="module")
def wheel(tmp_path_factory) -> pathlib.Path:
    out, source = tmp_path_factory.mktemp("wheel"), tmp_path_factory.mktemp("source")
    for name in _SOURCES:
        if (_ROOT / name).is_dir():
            shutil.copytree(_ROOT / name, source / name, ignore=shutil.ignore_patterns("__pycache__"))
        else:
            shutil.copy2(_ROOT / name, source / name)
    build = subprocess.run(
        [
            sys.executable,
            "-m",
            "pip",
            "wheel",
            "--no-deps",
            "--no-build-isolation",
            "-q",
            "-w",
            str(out),
            str(source),
        ],
        capture_output=True,
        text=True,
        timeout=300,
    )
    if build.returncode != 0:
        pytest.fail(
            f"the wheel does not build without isolation (pip install '.[test]' first):\n{build.stderr}"
        )
    (found,) = out.glob("jaxunilat-*.whl")
    return found


def test_the_wheel_installs_identify_inside_jaxunilat_only(wheel):
    names = zipfile.ZipFile(wheel).namelist()
    tops = {name.split("/")[0] for name in names}
    assert tops == {"jaxunilat", f"{wheel.name.split('-')[0]}-{wheel.name.split('-')[1]}.dist-info"}, tops
    assert "jaxunilat/identify/__init__.py" in names
    assert "jaxunilat/identify/_fit/_problem.py" in names
    assert "jaxunilat/_data/drop_trace.csv" in names
    entry_points = next(n for n in names if n.endswith("entry_points.txt"))
    text = zipfile.ZipFile(wheel).read(entry_points).decode()
    assert "[console_scripts]" in text and "jaxunilat.commands" not in text and "jaxunilat.bench" not in text


def _child_env(site: pathlib.Path) -> dict:
    env = {k: v for k, v in os.environ.items() if k != "PYTHONPATH"}
    return {**env, "PYTHONPATH": str(site), "MPLBACKEND": "Agg"}


@pytest.mark.slow
def test_jaxunilat_identify_runs_beside_pypis_identify(wheel, tmp_path):
    """`jaxunilat identify` on the bundled data, from an unpacked wheel, in an environment
    where `import identify` is PyPI's package (its `identify.tags_from_path`)."""
    site, work = tmp_path / "site", tmp_path / "work"
    work.mkdir()
    zipfile.ZipFile(wheel).extractall(site)
    probe = (
        "import identify, jaxunilat\n"
        "from identify import identify as pypi\n"
        "from jaxunilat import identify as ours\n"
        "print(callable(pypi.tags_from_path), jaxunilat.__file__, ours.__file__, identify.__file__)\n"
    )
    run = subprocess.run(
        [sys.executable, "-c", probe],
        cwd=work,
        env=_child_env(site),
        capture_output=True,
        text=True,
        timeout=300,
    )
    if "No module named 'identify'" in run.stderr:
        pytest.skip("PyPI's identify is not installed (pip install '.[test]')")
    assert run.returncode == 0, run.stderr
    pypi_ok, ours_top, ours, pypi = run.stdout.split()
    assert pypi_ok == "True"
    assert pathlib.Path(ours_top).is_relative_to(site) and pathlib.Path(ours).is_relative_to(
        site / "jaxunilat"
    )
    assert not pathlib.Path(pypi).is_relative_to(site) and not pathlib.Path(pypi).is_relative_to(_ROOT)

    fit = subprocess.run(
        [sys.executable, "-m", "jaxunilat", "identify", "--json", "fit.json"],
        cwd=work,
        env=_child_env(site),
        capture_output=True,
        text=True,
        timeout=600,
    )
    assert fit.returncode == 0, fit.stderr
    result = json.loads((work / "fit.json").read_text())
    assert result["converged"] is True
    assert "kappa" in fit.stdout and "internal error" not in fit.stderr
