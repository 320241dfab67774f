"""The notebooks in `notebooks/` run, and their stored outputs are current.

Each notebook is executed once, as `python notebooks/refresh.py` executes it: in a fresh
`python3` kernel of this environment (a cell prepended in memory checks that), with
`notebooks/` as its working directory and the environment `refresh.environment(name)` (the
size the notebook is stored at: its quick size, `JAXUNILAT_NOTEBOOK_QUICK=1`, unless it is in
`refresh.FULL_SIZE`). The executed notebook stays in memory;
`refresh.compare` then checks the stored one against it: an output of the same kind for every
output of the fresh run, figures of the same pixel size, and the same printed text with every
number within a relative 1e-6 (or one unit of its last printed digit); lines reporting wall
times are skipped. A notebook edited without refreshing fails with the command that fixes it.
"""

from __future__ import annotations

import base64
import importlib.util
import pathlib
import struct

import pytest

nbformat = pytest.importorskip("nbformat")
pytest.importorskip("nbclient")
pytest.importorskip("ipykernel")

from nbclient.exceptions import CellExecutionError  # noqa: E402

NOTEBOOK_DIR = pathlib.Path(__file__).resolve().parent.parent / "notebooks"
NOTEBOOKS = sorted(NOTEBOOK_DIR.glob("*.ipynb"))
# Notebooks with a cell that needs an optional package: without it they run, uncompared.
OPTIONAL = {"04_identify_contact_parameters.ipynb": "mujoco"}


def _load_refresh():
    spec = importlib.util.spec_from_file_location("notebook_refresh", NOTEBOOK_DIR / "refresh.py")
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


refresh = _load_refresh()


def test_notebooks_found() -> None:
    assert NOTEBOOKS, f"no notebooks found in {NOTEBOOK_DIR}"


@pytest.mark.slow
@pytest.mark.parametrize("path", NOTEBOOKS, ids=[p.name for p in NOTEBOOKS])
def test_notebook_runs_and_is_current(path: pathlib.Path) -> None:
    try:
        fresh = refresh.execute(path)
    except CellExecutionError as err:
        pytest.fail(f"{path.name} failed in a cell:\n{err}", pytrace=False)
    optional = OPTIONAL.get(path.name)
    if optional and importlib.util.find_spec(optional) is None:
        pytest.skip(f"{path.name} ran; its stored outputs were made with {optional}, not installed here")
    problems = refresh.compare(nbformat.read(path, as_version=4), fresh)
    if problems:
        pytest.fail(
            f"{path.name}: the stored outputs are not those of its code; run "
            f"`{refresh.REFRESH_COMMAND} {path.name}`:\n  " + "\n  ".join(problems),
            pytrace=False,
        )


# ---------------------------------------------------------------- the comparison itself


def _png(width: int, height: int) -> str:
    """Base64 of the start of a PNG file of `width` x `height` pixels (all `compare` reads)."""
    header = b"\x89PNG\r\n\x1a\n" + struct.pack(">I", 13) + b"IHDR" + struct.pack(">II", width, height)
    return base64.b64encode(header + bytes(5)).decode()


def _notebook(source: str, text: str | None, images: int = 1, size: tuple[int, int] = (400, 300)):
    """A notebook whose code cell printed `text` and showed `images` figures (`text` None: not run)."""
    outputs = []
    if text is not None:
        outputs.append(nbformat.v4.new_output("stream", name="stdout", text=text))
        figure = {"image/png": _png(*size), "text/plain": "<Figure size 400x300 with 1 Axes>"}
        outputs += [nbformat.v4.new_output("display_data", data=figure) for _ in range(images)]
    cell = nbformat.v4.new_code_cell(source, outputs=outputs)
    cell["id"] = "c0"
    return nbformat.v4.new_notebook(cells=[nbformat.v4.new_markdown_cell("# t"), cell])


FRESH_TEXT = "e = 0.9350 (95% CI 0.9312 to 0.9388)\nkappa = 26660.127826 N/m\nfit took 12.3 s of wall time\n"


def test_compare_accepts_a_current_notebook() -> None:
    fresh = _notebook("print(e)", FRESH_TEXT)
    rerun = _notebook(
        "print(e)",
        "e = 0.9351 (95% CI 0.9312 to 0.9388)\n"  # one unit of the last printed digit
        "kappa = 26660.14 N/m\n"  # within 1e-6 relative
        "fit took 99.0 s of wall time\n",  # wall times are not compared
    )
    assert refresh.compare(fresh, fresh) == []
    assert refresh.compare(rerun, fresh) == []


@pytest.mark.parametrize(
    ("stored", "expected"),
    [
        (_notebook("print(e)", FRESH_TEXT.replace("0.9350", "0.9370")), "0.9370 stored, 0.9350"),
        (_notebook("print(e)", FRESH_TEXT.replace("26660.127826", "26661.0")), "26661.0 stored"),
        (_notebook("print(e)", FRESH_TEXT.replace("N/m", "N*s/m")), "stored 'kappa"),
        (_notebook("print(e)", FRESH_TEXT, images=0), "stored outputs"),
        (_notebook("print(e)", None), "stored outputs []"),
        (_notebook("print(e)", FRESH_TEXT.split("\n", 1)[1]), "1 printed lines stored, 2 in a fresh run"),
    ],
    ids=["number", "number-relative", "text", "figure-missing", "never-executed", "line-added"],
)
def test_compare_rejects_a_stale_notebook(stored, expected: str) -> None:
    problems = refresh.compare(stored, _notebook("print(e)", FRESH_TEXT))
    assert len(problems) == 1 and problems[0].startswith("cell 1: ") and expected in problems[0], problems


def test_compare_rejects_a_figure_of_another_size() -> None:
    stored = _notebook("print(e)", FRESH_TEXT, size=(800, 300))
    problems = refresh.compare(stored, _notebook("print(e)", FRESH_TEXT))
    assert len(problems) == 1 and "(800, 300) pixels stored" in problems[0], problems


def test_normalize_strips_volatile_metadata() -> None:
    nb = _notebook("print(e)", FRESH_TEXT)
    nb.cells[1].execution_count = 7
    nb.cells[1].metadata["execution"] = {"iopub.execute_input": "a time"}
    nb.metadata["language_info"] = {"name": "python", "version": "3.x.y"}
    out = refresh.normalize(nb, "x.ipynb")
    assert out.cells[1].execution_count is None and "execution" not in out.cells[1].metadata
    assert out.metadata["language_info"] == {"name": "python"} and out.cells[1]["id"] == "c0"


def test_merge_keeps_stored_outputs_that_differ_only_in_wall_times() -> None:
    stored = _notebook("print(e)", FRESH_TEXT.replace("12.3 s", "45.6 s"))
    kept = refresh.merge(stored, _notebook("print(e)", FRESH_TEXT))
    assert kept.cells[1].outputs[0]["text"] == stored.cells[1].outputs[0]["text"]
    taken = refresh.merge(stored, _notebook("print(e)", FRESH_TEXT.replace("0.9350", "0.9351")))
    assert "0.9351" in taken.cells[1].outputs[0]["text"]
