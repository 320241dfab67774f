"""Execute every notebook in `notebooks/` at its small size (JAXUNILAT_NOTEBOOK_QUICK=1).

Each notebook runs in a fresh `python3` kernel with `notebooks/` as its working
directory. jupyter_client starts a kernelspec whose command is `python` with this
interpreter (`sys.executable`); a cell prepended in memory checks that the kernel
runs in the same environment as the tests. The executed notebook is kept in memory
only: nothing is written back to the repository.
"""

from __future__ import annotations

import pathlib
import sys

import pytest

nbformat = pytest.importorskip("nbformat")
nbclient = pytest.importorskip("nbclient")
pytest.importorskip("ipykernel")

from nbclient.exceptions import CellExecutionError  # noqa: E402

NOTEBOOK_DIR = pathlib.Path(__file__).resolve().parent.parent / "notebooks"
NOTEBOOKS = sorted(NOTEBOOK_DIR.glob("*.ipynb"))
CELL_TIMEOUT_S = 600

_SAME_ENV_CHECK = (
    "import sys as _sys\n"
    f"assert _sys.prefix == {sys.prefix!r}, "
    f"f'the python3 kernel runs in {{_sys.prefix}}, not in the test environment {sys.prefix}'\n"
    "del _sys"
)


def test_notebooks_found() -> None:
    assert NOTEBOOKS, f"no notebooks found in {NOTEBOOK_DIR}"


@pytest.mark.slow
@pytest.mark.parametrize("path", NOTEBOOKS, ids=[p.name for p in NOTEBOOKS])
def test_notebook_runs(path: pathlib.Path, monkeypatch: pytest.MonkeyPatch) -> None:
    # The kernel inherits this process's environment: run the notebook's small size.
    monkeypatch.setenv("JAXUNILAT_NOTEBOOK_QUICK", "1")
    nb = nbformat.read(path, as_version=4)
    nb.cells.insert(0, nbformat.v4.new_code_cell(_SAME_ENV_CHECK))
    client = nbclient.NotebookClient(
        nb,
        kernel_name="python3",
        timeout=CELL_TIMEOUT_S,
        allow_errors=False,
        resources={"metadata": {"path": str(path.parent)}},
    )
    try:
        client.execute()
    except CellExecutionError as err:
        pytest.fail(f"{path.name} failed in a cell:\n{err}", pytrace=False)
