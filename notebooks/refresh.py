"""Execute the notebooks in this directory and store them with their outputs.

    python notebooks/refresh.py            # every notebook
    python notebooks/refresh.py 04 06      # the ones named (file name, or its number)
    python notebooks/refresh.py --check    # execute and compare with the stored ones; write nothing

Needs nbformat, nbclient and ipykernel (the `test` extra: `pip install -e ".[test]"`).

Each notebook runs in a fresh `python3` kernel of this interpreter's environment, with this
directory as its working directory and `environment(name)` set: its full size if it is in
`FULL_SIZE`, else its quick size (`tests/test_notebooks.py` re-executes it at the same size).
It is written back only if every cell ran, atomically (a temporary file renamed over the old
one), with execution counts stripped, the kernel metadata normalized and no timestamps. A cell
whose fresh outputs equal the stored ones keeps them byte for byte, as does a cell whose outputs
differ only in lines reporting wall times, and a cell tagged `timing` (its figure shows measured
run times) whose outputs agree by `compare`; so a second run in a row changes nothing.

`compare(stored, fresh)` is the check the test suite applies: the stored notebook must hold an
output of the same kind for every output of a fresh run, the same printed text up to numbers, and
numbers that agree within `RTOL` relative (or one unit of their last printed digit). Lines that
report wall times (containing the word "wall") are not compared.
"""

from __future__ import annotations

import argparse
import contextlib
import hashlib
import os
import pathlib
import re
import struct
import sys
import tempfile

NOTEBOOK_DIR = pathlib.Path(__file__).resolve().parent
REFRESH_COMMAND = "python notebooks/refresh.py"
# Notebooks stored (and tested) at their full size, which runs about as fast as their quick one;
# the others at their quick size (JAXUNILAT_NOTEBOOK_QUICK=1), as their first cell says.
FULL_SIZE = frozenset({"01_ball_between_rackets.ipynb"})
RTOL = 1e-6  # relative tolerance on every printed number
CELL_TIMEOUT_S = 600
KERNELSPEC = {"display_name": "Python 3 (ipykernel)", "language": "python", "name": "python3"}
TIMING_TAG = "timing"  # cell tag: outputs show measured run times (figure size not compared)
WALL_LINE = re.compile(r"\bwall\b", re.IGNORECASE)
NUMBER = re.compile(r"[-+]?(?:\d+\.?\d*|\.\d+)(?:[eE][-+]?\d+)?")


def environment(name: str) -> dict[str, str]:
    """The environment notebook `name` is stored and tested in.

    JAXUNILAT_BENCH_JSON="" keeps notebook 05 from reading a local bench.json.
    """
    return {"JAXUNILAT_NOTEBOOK_QUICK": "0" if name in FULL_SIZE else "1", "JAXUNILAT_BENCH_JSON": ""}


def _same_env_check() -> str:
    """Source of a cell that fails unless the kernel runs in this interpreter's environment."""
    return (
        "import sys as _sys\n"
        f"assert _sys.prefix == {sys.prefix!r}, "
        f"f'the python3 kernel runs in {{_sys.prefix}}, not in {sys.prefix}'\n"
        "del _sys"
    )


def notebooks(names: list[str] | None = None) -> list[pathlib.Path]:
    """The notebooks in this directory, or those whose file name or number prefix is in `names`."""
    paths = sorted(NOTEBOOK_DIR.glob("*.ipynb"))
    if not names:
        return paths
    chosen = [p for p in paths if any(p.name == n or p.name.split("_")[0] == n.zfill(2) for n in names)]
    unknown = [n for n in names if not any(p.name == n or p.name.split("_")[0] == n.zfill(2) for p in paths)]
    if unknown:
        raise SystemExit(f"refresh.py: no notebook named {', '.join(unknown)} in {NOTEBOOK_DIR.name}/")
    return chosen


@contextlib.contextmanager
def _environment(env: dict[str, str]):
    saved = {k: os.environ.get(k) for k in env}
    os.environ.update(env)
    try:
        yield
    finally:
        for k, v in saved.items():
            if v is None:
                os.environ.pop(k, None)
            else:
                os.environ[k] = v


def execute(path: pathlib.Path):
    """Run the notebook at `path` in a fresh kernel; return it executed and normalized.

    Raises nbclient's CellExecutionError if a cell fails.
    """
    import nbclient
    import nbformat

    nb = nbformat.read(path, as_version=4)
    nb.cells.insert(0, nbformat.v4.new_code_cell(_same_env_check()))
    client = nbclient.NotebookClient(
        nb,
        kernel_name="python3",
        timeout=CELL_TIMEOUT_S,
        allow_errors=False,
        record_timing=False,
        resources={"metadata": {"path": str(path.parent)}},
    )
    with _environment(environment(path.name)):
        client.execute()
    del nb.cells[0]
    return normalize(nb, path.name)


def _coalesce(outputs: list) -> list:
    """Merge consecutive stream outputs of the same stream (their split depends on timing)."""
    merged: list = []
    for out in outputs:
        if out.get("output_type") == "stream" and merged and merged[-1].get("output_type") == "stream":
            if merged[-1]["name"] == out["name"]:
                merged[-1]["text"] += out["text"]
                continue
        merged.append(out)
    return merged


def normalize(nb, name: str):
    """Strip volatile metadata: execution counts, timings, kernel versions; stable cell ids."""
    nb.metadata = {"kernelspec": dict(KERNELSPEC), "language_info": {"name": "python"}}
    nb.nbformat, nb.nbformat_minor = 4, 5
    for index, cell in enumerate(nb.cells):
        if not cell.get("id"):
            cell["id"] = hashlib.sha1(f"{name}:{index}".encode()).hexdigest()[:8]
        cell.metadata.pop("execution", None)
        cell.metadata.pop("ExecuteTime", None)
        if cell.cell_type != "code":
            continue
        cell.execution_count = None
        cell.outputs = _coalesce(cell.outputs)
        for out in cell.outputs:
            if "execution_count" in out:
                out["execution_count"] = None
    return nb


# ---------------------------------------------------------------- comparison


def _kind(out) -> str:
    if out.get("output_type") == "stream":
        return f"stream {out['name']}"
    if out.get("output_type") == "error":
        return "error"
    return "image" if "image/png" in out.get("data", {}) else "text"


def _text(out) -> str:
    if out.get("output_type") == "stream":
        return out["text"]
    if out.get("output_type") == "error":
        return f"{out['ename']}: {out['evalue']}"
    text = out.get("data", {}).get("text/plain", "")
    return text if isinstance(text, str) else "".join(text)


def _png_size(out) -> tuple[int, int] | None:
    import base64

    data = out.get("data", {}).get("image/png")
    if not data:
        return None
    raw = base64.b64decode(data if isinstance(data, str) else "".join(data))
    return struct.unpack(">II", raw[16:24]) if raw[:8] == b"\x89PNG\r\n\x1a\n" else None


def _resolution(token: str) -> float:
    """One unit of the last printed digit of a number printed as `token`."""
    mantissa, _, exponent = token.lower().partition("e")
    decimals = len(mantissa.split(".")[1]) if "." in mantissa else 0
    return 10.0 ** (int(exponent or 0) - decimals)


def _numbers_agree(a: str, b: str, rtol: float) -> bool:
    x, y = float(a), float(b)
    tol = max(rtol * max(abs(x), abs(y)), _resolution(a), _resolution(b))
    return abs(x - y) <= tol * (1 + 1e-9)


def compare_lines(stored: str, fresh: str, rtol: float = RTOL) -> str | None:
    """None when the two texts agree line by line up to numbers; else the first difference."""
    old = [ln for ln in stored.splitlines() if not WALL_LINE.search(ln)]
    new = [ln for ln in fresh.splitlines() if not WALL_LINE.search(ln)]
    if len(old) != len(new):
        return f"{len(old)} printed lines stored, {len(new)} in a fresh run"
    for a, b in zip(old, new, strict=True):
        if NUMBER.sub("#", a) != NUMBER.sub("#", b):
            return f"stored {a.strip()!r}, fresh {b.strip()!r}"
        for x, y in zip(NUMBER.findall(a), NUMBER.findall(b), strict=True):
            if not _numbers_agree(x, y, rtol):
                return f"{x} stored, {y} in a fresh run (relative tolerance {rtol:g}): {b.strip()!r}"
    return None


def compare_cell(stored, fresh, rtol: float = RTOL) -> str | None:
    """None when the stored cell is current with the fresh one; else what differs."""
    if stored.source != fresh.source:
        return "its source differs from the executed one"
    if fresh.cell_type != "code":
        return None
    old = [o for o in stored.get("outputs", []) if _kind(o) != "stream stderr"]
    new = [o for o in fresh.get("outputs", []) if _kind(o) != "stream stderr"]
    if [_kind(o) for o in old] != [_kind(o) for o in new]:
        return f"stored outputs {[_kind(o) for o in old]}, a fresh run gives {[_kind(o) for o in new]}"
    for a, b in zip(old, new, strict=True):
        if _kind(b) == "image":
            if _png_size(a) != _png_size(b) and TIMING_TAG not in fresh.metadata.get("tags", []):
                return f"a figure of {_png_size(a)} pixels stored, {_png_size(b)} in a fresh run"
        elif (problem := compare_lines(_text(a), _text(b), rtol)) is not None:
            return problem
    return None


def compare(stored, fresh, rtol: float = RTOL) -> list[str]:
    """Every way the stored notebook is out of date against a fresh execution of it (empty: current)."""
    if len(stored.cells) != len(fresh.cells):
        return [f"{len(stored.cells)} cells stored, {len(fresh.cells)} executed"]
    problems = []
    for index, (a, b) in enumerate(zip(stored.cells, fresh.cells, strict=True)):
        if (problem := compare_cell(a, b, rtol)) is not None:
            problems.append(f"cell {index}: {problem}")
    return problems


# ---------------------------------------------------------------- writing


def merge(stored, fresh):
    """`fresh`, except that cells whose outputs did not change keep the stored ones byte for byte."""
    if len(stored.cells) != len(fresh.cells):
        return fresh
    for old, new in zip(stored.cells, fresh.cells, strict=True):
        if new.cell_type != "code" or old.source != new.source:
            continue
        timing = TIMING_TAG in new.metadata.get("tags", [])
        if _masked(old.get("outputs", [])) == _masked(new.outputs) or (
            timing and compare_cell(old, new) is None
        ):
            new.outputs = old.outputs
    return fresh


def _masked(outputs: list) -> list:
    """`outputs` as compared by `merge`: the lines that report wall times blanked out."""
    masked = []
    for out in outputs:
        out = dict(out)
        if out.get("output_type") == "stream":
            out["text"] = "\n".join(
                "(wall)" if WALL_LINE.search(ln) else ln for ln in out["text"].split("\n")
            )
        masked.append(out)
    return masked


def write_atomic(text: str, path: pathlib.Path) -> None:
    """Write `text` to `path` through a temporary file in the same directory, renamed over it."""
    fd, tmp = tempfile.mkstemp(prefix=f".{path.stem}-", suffix=".tmp", dir=path.parent)
    try:
        with os.fdopen(fd, "w", encoding="utf-8", newline="\n") as f:
            f.write(text)
        os.chmod(tmp, path.stat().st_mode & 0o777 if path.exists() else 0o644)
        os.replace(tmp, path)
    except BaseException:
        os.unlink(tmp)
        raise


def refresh(path: pathlib.Path, check: bool = False) -> bool:
    """Execute one notebook; write it back (or, with `check`, compare). True when all went well."""
    import nbformat
    from nbclient.exceptions import CellExecutionError

    stored = nbformat.read(path, as_version=4)
    try:
        fresh = execute(path)
    except CellExecutionError as err:
        print(f"{path.name}: FAILED, left unchanged\n{err}", file=sys.stderr)
        return False
    stderr = [
        i for i, c in enumerate(fresh.cells) if any(_kind(o) == "stream stderr" for o in c.get("outputs", []))
    ]
    note = f" (cells {stderr} wrote to stderr)" if stderr else ""
    if check:
        problems = compare(stored, fresh)
        print(f"{path.name}: " + ("current" if not problems else "STALE: " + "; ".join(problems)) + note)
        return not problems
    text = nbformat.writes(merge(stored, fresh)).rstrip("\n") + "\n"
    size = len(text.encode())
    if text == path.read_text(encoding="utf-8"):
        print(f"{path.name}: unchanged ({size / 1e3:.0f} kB){note}")
        return True
    write_atomic(text, path)
    print(f"{path.name}: written ({size / 1e3:.0f} kB){note}")
    return True


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("names", nargs="*", help="notebooks to run (file name or number); default: all")
    parser.add_argument("--check", action="store_true", help="compare with the stored outputs, write nothing")
    args = parser.parse_args(argv)
    try:
        import ipykernel  # noqa: F401
        import nbclient  # noqa: F401
        import nbformat  # noqa: F401
    except ImportError as err:
        print(f"refresh.py needs {err.name}: pip install -e '.[test]'", file=sys.stderr)
        return 2
    ok = [refresh(path, check=args.check) for path in notebooks(args.names)]
    return 0 if all(ok) else 1


if __name__ == "__main__":
    sys.exit(main())
