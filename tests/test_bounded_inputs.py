"""Bounded inputs: what `jaxunilat import` refuses before it reads too much or waits forever.

Every importer refuses a FIFO and a device as SOURCE in one line with exit 2, without
opening it; a table beyond its size or row limit, and an `.xlsx` whose contents expand
beyond the limit (a zip bomb), are refused naming the limit; formula cells without a
cached value are named as such; a long phyphox export (10^5 rows) is imported or refused
in seconds; a recording beyond the reader's sample limit is refused from its header.
Every input is generated here (seeded), none is committed. The FIFO and device cases run
the command line in a child process with a timeout and a memory limit, so that a reader
that waits or reads without end fails the test instead of hanging it.
"""

from __future__ import annotations

import json
import os
import struct
import subprocess
import sys
import zipfile

import numpy as np
import pytest
from jaxunilat.identify import import_phyphox, import_wav

from jaxunilat._cli._main import main

KINDS = ("wav", "audio", "phyphox", "video")
#: The child's limits: a reader that waits or reads /dev/zero to its (missing) end fails.
CHILD_TIMEOUT, CHILD_MEMORY = 120, 3 << 30


def _in_child(source: str, out: str) -> list[dict]:
    """`jaxunilat import KIND SOURCE --ball pingpong --out OUT` for every kind, in one child
    process under `CHILD_TIMEOUT` s and `CHILD_MEMORY` bytes: each one's exit code and stderr."""
    script = (
        "import contextlib, io, json, resource, sys\n"
        f"resource.setrlimit(resource.RLIMIT_AS, ({CHILD_MEMORY}, {CHILD_MEMORY}))\n"
        "from jaxunilat._cli._main import main\n"
        f"for kind in {KINDS!r}:\n"
        "    err = io.StringIO()\n"
        "    with contextlib.redirect_stderr(err), contextlib.redirect_stdout(io.StringIO()):\n"
        f"        code = main(['import', kind, {source!r}, '--ball', 'pingpong', '--out', {out!r}])\n"
        "    print(json.dumps({'kind': kind, 'code': code, 'err': err.getvalue()}), flush=True)\n"
    )
    try:
        done = subprocess.run(
            [sys.executable, "-c", script],
            capture_output=True,
            text=True,
            timeout=CHILD_TIMEOUT,
            cwd=os.path.dirname(os.path.abspath(__file__)),
        )
    except subprocess.TimeoutExpired as err:
        pytest.fail(f"an importer waited on {source} (no answer in {CHILD_TIMEOUT} s): {err.stdout!r}")
    results = [json.loads(line) for line in done.stdout.splitlines() if line.startswith("{")]
    assert len(results) == len(KINDS), (done.returncode, done.stdout, done.stderr[-2000:])
    return results


def _refused_in_one_line(results: list[dict], what: str) -> None:
    for r in results:
        assert r["code"] == 2, r
        assert r["err"].count("\n") == 1 and what in r["err"], r


def test_a_fifo_is_refused_by_every_importer_without_waiting(tmp_path):
    fifo = tmp_path / "pipe.csv"
    os.mkfifo(fifo)
    _refused_in_one_line(_in_child(str(fifo), str(tmp_path / "out.csv")), "is a FIFO")
    for read in (import_phyphox, import_wav):  # the functions too, before any open
        with pytest.raises(ValueError, match="is a FIFO, not a regular file"):
            read(fifo, ball="pingpong")
    assert not (tmp_path / "out.csv").exists()


@pytest.mark.skipif(not os.path.exists("/dev/zero"), reason="no /dev/zero here")
def test_a_character_device_is_refused_by_every_importer(tmp_path):
    _refused_in_one_line(_in_child("/dev/zero", str(tmp_path / "out.csv")), "is a character device")


def test_an_oversized_table_is_refused_with_the_limit(tmp_path, capsys):
    big = tmp_path / "huge.csv"
    with open(big, "wb") as f:  # a real header and rows, then a sparse hole past 20 MB
        f.write(b'"Event time (s)","Interval (s)"\n0.1,0.5\n0.6,0.45\n')
        f.truncate(20_000_001)
    code = main(["import", "phyphox", str(big), "--ball", "pingpong", "--out", str(tmp_path / "o.csv")])
    err = capsys.readouterr().err
    assert code == 2 and err.count("\n") == 1 and "larger than the 20 MB a table is read up to" in err, err
    rows = tmp_path / "rows.csv"
    rows.write_bytes(b"t (s)\n" + b"1\n" * 1_000_000)  # 2 MB, but 10^6 + 2 lines
    code = main(["import", "video", str(rows), "--ball", "pingpong", "--out", str(tmp_path / "o.csv")])
    err = capsys.readouterr().err
    assert code == 2 and err.count("\n") == 1 and "more than the 1,000,000 a table is read up to" in err, err


def _workbook(tmp_path, name: str, rows, *, title: str = "Events") -> str:
    openpyxl = pytest.importorskip("openpyxl")
    book = openpyxl.Workbook()
    sheet = book.active
    sheet.title = title
    for row in rows:
        sheet.append(row)
    path = str(tmp_path / name)
    book.save(path)
    return path


def _padded(source: str, target: str, pad: int) -> None:
    """`source` (an .xlsx) with `pad` bytes of whitespace inside its first sheet's data:
    valid XML that deflates about 1000-fold."""
    with zipfile.ZipFile(source) as zin, zipfile.ZipFile(target, "w", zipfile.ZIP_DEFLATED) as zout:
        for info in zin.infolist():
            data = zin.read(info)
            if info.filename != "xl/worksheets/sheet1.xml":
                zout.writestr(info, data)
                continue
            head, tail = data.split(b"<sheetData>", 1)
            with zout.open(info.filename, "w", force_zip64=True) as member:
                member.write(head + b"<sheetData>")
                block = b" " * (1 << 20)
                for _ in range(pad // len(block)):
                    member.write(block)
                member.write(tail)


def test_an_xlsx_zip_bomb_is_refused_with_the_limit(tmp_path, capsys):
    rows = [["Event time (s)", "Interval (s)"]] + [[0.5 + 0.45 * k, None] for k in range(8)]
    plain = _workbook(tmp_path, "plain.xlsx", rows)
    bomb = str(tmp_path / "bomb.xlsx")
    _padded(plain, bomb, 21 << 20)  # expands past 20 MB from well under 1 MB
    assert os.path.getsize(bomb) < 1_000_000
    code = main(["import", "phyphox", bomb, "--ball", "pingpong", "--out", str(tmp_path / "o.csv")])
    err = capsys.readouterr().err
    assert code == 2 and err.count("\n") == 1, err
    assert "expands to" in err and "larger than the 20 MB a table is read up to" in err, err
    dense = str(tmp_path / "dense.xlsx")
    _padded(plain, dense, 10 << 20)  # under the size limit, but 1000-fold: no spreadsheet compresses so
    code = main(["import", "phyphox", dense, "--ball", "pingpong", "--out", str(tmp_path / "o.csv")])
    err = capsys.readouterr().err
    assert code == 2 and err.count("\n") == 1 and "beyond the 200-fold" in err, err
    assert not (tmp_path / "o.csv").exists()


def test_formula_cells_without_a_cached_value_are_named(tmp_path, capsys):
    intervals = [0.5 * 0.9**k for k in range(14)]
    # Intervals typed in, event times as formulas that no spreadsheet ever computed.
    rows = [["Interval (s)", "Event time (s)"]]
    rows += [[d, f"=SUM($A$2:A{k + 2})"] for k, d in enumerate(intervals)]
    path = _workbook(tmp_path, "formulas.xlsx", rows)
    code = main(["import", "phyphox", path, "--ball", "pingpong", "--out", str(tmp_path / "o.csv")])
    err = capsys.readouterr().err
    assert code == 2 and err.count("\n") == 1, err
    assert "(sheet 'Events'): column B ('Event time (s)'): 14 formula cells without a cached value" in err
    assert "save the file in a spreadsheet program, or export CSV" in err
    # With values, the import's summary names the sheet it read.
    times = np.cumsum(intervals)
    rows = [["Event time (s)", "Interval (s)"]] + [[t, d] for t, d in zip(times, intervals, strict=True)]
    result = import_phyphox(_workbook(tmp_path, "values.xlsx", rows, title="Run 3"), ball="pingpong")
    assert "xlsx, sheet 'Run 3'; header on row 1" in result.info[0]


def test_a_100000_row_phyphox_export_is_answered_in_seconds(tmp_path, capsys):
    """10^5 rows of random intervals, no bouncing ball: refused (exit 3) with the reason. The
    stray search used to re-read the whole ratio chain once per row (hours at this length)."""
    rng = np.random.default_rng(20260101)
    times = np.cumsum(rng.uniform(0.05, 0.5, 100_000))
    path = tmp_path / "long.csv"
    intervals = np.append(np.diff(times), 0.0)
    path.write_text(
        '"Event time (s)","Interval (s)"\n'
        + "".join(f"{t:.6f},{d:.6f}\n" for t, d in zip(times, intervals, strict=True))
    )
    code = main(["import", "phyphox", str(path), "--ball", "pingpong", "--out", str(tmp_path / "o.csv")])
    err = capsys.readouterr().err
    assert code == 3 and err.count("\n") == 1 and "not one bouncing ball: the interval" in err, err[-500:]
    assert not (tmp_path / "o.csv").exists()


def test_a_recording_beyond_the_sample_limit_is_refused_from_its_header(tmp_path, capsys):
    from jaxunilat.identify._data._audio_read import MAX_SAMPLES

    path = tmp_path / "long.wav"
    frames = MAX_SAMPLES + 1
    data = 2 * frames  # 16-bit mono
    header = b"RIFF" + struct.pack("<I", 36 + data) + b"WAVE"
    header += b"fmt " + struct.pack("<IHHIIHH", 16, 1, 1, 48000, 96000, 2, 16)
    header += b"data" + struct.pack("<I", data)
    with open(path, "wb") as f:  # sparse: the samples take no disk
        f.write(header)
        f.truncate(len(header) + data)
    code = main(["import", "wav", str(path), "--ball", "pingpong", "--out", str(tmp_path / "o.csv")])
    err = capsys.readouterr().err
    assert code == 2 and err.count("\n") == 1, err
    assert f"{frames:,} frames" in err and f"more than the {MAX_SAMPLES:,} samples" in err, err
