"""The data format: reading, writing, and clear errors for bad files."""

import hashlib
import os

import numpy as np
import pytest
from jaxunilat.identify import Dataset, load_dataset, write_dataset

from jaxunilat import identify

GOOD = """# jaxunilat-data: 1
# scene = drop
# mass = 0.0027
# drag = 0.11           (k = 1/terminal speed, s/m)
# x0 = 0.305
# v0 = 0
# noise = 0.0005
# observe = trace       (columns t,x)
t,x
0.000,0.3051
0.001,0.3046
0.002,0.3049
0.003,0.3040
"""


def _write(tmp_path, text, name="data.csv", mode="w"):
    path = tmp_path / name
    if mode == "wb":
        path.write_bytes(text)
    else:
        path.write_text(text, encoding="utf-8")
    return path


def _replace(old, new, text=GOOD):
    assert old in text
    return text.replace(old, new, 1)


def test_good_file_reads(tmp_path):
    ds = load_dataset(_write(tmp_path, GOOD))
    assert (ds.scene, ds.observe) == ("drop", "trace")
    assert (ds.mass, ds.drag, ds.x0, ds.v0, ds.noise, ds.gravity) == (0.0027, 0.11, 0.305, 0.0, 0.0005, 9.81)
    assert ds.gap is None and ds.h is None and ds.source is None
    np.testing.assert_array_equal(ds.t, [0.0, 0.001, 0.002, 0.003])
    np.testing.assert_array_equal(ds.x, [0.3051, 0.3046, 0.3049, 0.3040])
    assert ds.path == str(tmp_path / "data.csv") and ds.num_rows == 4 and ds.columns == ("t", "x")
    assert not ds.t.flags.writeable


def test_format_options(tmp_path):
    """Comments, blank lines, CRLF, a BOM, column order, gravity, source free text, rackets, apex."""
    text = (
        "\ufeff# jaxunilat-data: 1\r\n##  a free comment = not a key\r\n#\r\n"
        "# observe = apex\r\n# scene = rackets\r\n# gap = 0.8(m)\r\n# mass = 2.37e-3\r\n"
        "# drag = 0\r\n# x0 = -0.4\r\n# v0 = -8\r\n# gravity = 9.80665\r\n"
        "# source = lab  notebook (p. 3), 2026\r\n\r\nh , t\r\n0.25,0.5\r\n\r\n0.2,0.9\r\n"
    )
    ds = load_dataset(_write(tmp_path, text))
    assert (ds.scene, ds.observe, ds.gap, ds.gravity, ds.drag) == ("rackets", "apex", 0.8, 9.80665, 0.0)
    assert ds.source == "lab  notebook (p. 3), 2026"
    np.testing.assert_array_equal(ds.h, [0.25, 0.2])
    np.testing.assert_array_equal(ds.t, [0.5, 0.9])
    assert ds.x is None and ds.columns == ("t", "h")


def test_write_round_trip_and_refusals(tmp_path):
    rng = np.random.default_rng(0)
    ds = Dataset(
        scene="drop",
        observe="trace",
        mass=2.7e-3,
        drag=0.12,
        x0=0.305,
        v0=0.0,
        noise=5e-4,
        gravity=9.7,
        t=np.arange(50) * 1e-3,
        x=0.3 + 1e-3 * rng.standard_normal(50),
        source="unit test",
    )
    out = tmp_path / "out.csv"
    write_dataset(out, ds)
    back = load_dataset(out)
    for f in ("scene", "observe", "mass", "drag", "x0", "v0", "gap", "noise", "gravity", "source"):
        assert getattr(back, f) == getattr(ds, f), f
    np.testing.assert_array_equal(back.t, ds.t)  # bit-for-bit: shortest exact repr
    np.testing.assert_array_equal(back.x, ds.x)
    before = out.read_bytes()
    with pytest.raises(ValueError, match="exists; pass overwrite=True"):
        write_dataset(out, ds)
    with pytest.raises(ValueError, match="the file this dataset was read from"):
        write_dataset(out, back, overwrite=True)
    assert out.read_bytes() == before
    write_dataset(out, ds, overwrite=True)
    with pytest.raises(ValueError, match="is a directory"):
        write_dataset(tmp_path, ds)
    with pytest.raises(ValueError, match="does not exist"):
        write_dataset(tmp_path / "missing" / "x.csv", ds)
    # Impacts: negative (offset) times are fine; a written apex file without t reads back.
    imp = Dataset(scene="drop", observe="impacts", mass=1.0, drag=0.0, x0=1.0, v0=0.0, t=[-0.2, 0.1, 0.3])
    write_dataset(tmp_path / "imp.csv", imp)
    np.testing.assert_array_equal(load_dataset(tmp_path / "imp.csv").t, [-0.2, 0.1, 0.3])
    apex = Dataset(scene="drop", observe="apex", mass=1.0, drag=0.0, x0=1.0, v0=0.0, h=[0.5])
    write_dataset(tmp_path / "apex.csv", apex)
    assert load_dataset(tmp_path / "apex.csv").t is None


def test_reexported():
    assert identify.Dataset is Dataset and identify.load_dataset is load_dataset
    assert identify.write_dataset is write_dataset


def test_dataset_constructor_validates():
    kw = dict(scene="drop", observe="trace", mass=1.0, drag=0.0, x0=1.0, v0=0.0, t=[0, 1, 2], x=[1, 1, 1])
    Dataset(**kw)
    with pytest.raises(ValueError, match=r"Dataset: mass = -1 is out of range; valid range is \(0, inf\) kg"):
        Dataset(**{**kw, "mass": -1.0})
    with pytest.raises(ValueError, match=r"Dataset: t \(row 3\) = 1.0 is a duplicate"):
        Dataset(**{**kw, "t": [0, 1, 1]})
    with pytest.raises(ValueError, match="Dataset: x has 2 values; t has 3"):
        Dataset(**{**kw, "x": [1, 1]})
    with pytest.raises(ValueError, match="Dataset: h: not allowed for observe = trace"):
        Dataset(**{**kw, "h": [1, 1, 1]})


# (label, file text or bytes, expected message pattern). Each message names the line and field.
BAD = [
    ("missing key", _replace("# mass = 0.0027\n", ""), r"line 8: mass: missing key"),
    ("unknown key", _replace("# v0 = 0\n", "# v0 = 0\n# speed = 3\n"), r"line 7: speed: unknown key"),
    ("key case", _replace("# mass =", "# Mass ="), r"line 3: Mass: unknown key .*did you mean 'mass'"),
    ("duplicate key", _replace("# v0 = 0\n", "# v0 = 0\n# v0 = 1\n"), r"line 7: v0: duplicate key .*line 6"),
    ("non-numeric", _replace("# mass = 0.0027", "# mass = heavy"), r"line 3: mass = 'heavy' is not a number"),
    (
        "unit after value",
        _replace("# mass = 0.0027", "# mass = 2.7 g"),
        r"line 3: mass = '2.7 g'.*unexpected",
    ),
    ("NaN key", _replace("# drag = 0.11", "# drag = nan"), r"line 4: drag = nan is not finite"),
    ("inf in data", _replace("0.002,0.3049", "0.002,inf"), r"line 12: x = inf is not finite"),
    ("NaN in data", _replace("0.002,0.3049", "0.002,NaN"), r"line 12: x = NaN is not finite"),
    ("unsorted times", _replace("0.002,0.3049", "0.0005,0.3049"), r"line 12: t = 0.0005 is before"),
    ("duplicate times", _replace("0.002,0.3049", "0.001,0.3049"), r"line 12: t = 0.001 is a duplicate"),
    ("wrong column", _replace("t,x\n", "t,y\n"), r"line 9: column 'y' is not allowed .*expected t,x"),
    ("missing column", _replace("t,x\n", "t\n"), r"line 9: column 'x' is missing"),
    ("extra column", _replace("t,x\n", "t,x,v\n"), r"line 9: column 'v' is not allowed"),
    ("duplicate column", _replace("t,x\n", "t,x,x\n"), r"line 9: column 'x' appears twice"),
    ("row too long", _replace("0.001,0.3046", "0.001,0.3046,7"), r"line 11: 3 fields, expected 2"),
    ("row too short", _replace("0.001,0.3046", "0.001"), r"line 11: 1 fields, expected 2"),
    ("empty field", _replace("0.001,0.3046", "0.001,"), r"line 11: x = '' is not a number"),
    ("empty data", GOOD.split("t,x\n")[0] + "t,x\n", r"line 9: no data rows"),
    ("no header", GOOD.split("t,x\n")[0], r"line 9: no column header"),
    ("numbers as header", _replace("t,x\n", ""), r"line 9: expected the column header t,x, got numbers"),
    (
        "mass zero",
        _replace("# mass = 0.0027", "# mass = 0"),
        r"line 3: mass = 0 is out of range; valid range is \(0, inf\) kg",
    ),
    ("mass negative", _replace("# mass = 0.0027", "# mass = -2"), r"line 3: mass = -2 is out of range"),
    (
        "drag negative",
        _replace("# drag = 0.11", "# drag = -0.1"),
        r"line 4: drag = -0.1 is out of range; valid range is \[0, inf\) s/m",
    ),
    ("noise zero", _replace("# noise = 0.0005", "# noise = 0"), r"line 7: noise = 0 is out of range"),
    (
        "gap for drop",
        _replace("# v0 = 0\n", "# v0 = 0\n# gap = 0.8\n"),
        r"line 7: gap = 0.8 is not allowed for scene = drop",
    ),
    (
        "no gap for rackets",
        _replace("scene = drop", "scene = rackets"),
        r"line 9: gap: missing; scene = rackets needs gap",
    ),
    (
        "x0 outside rackets",
        _replace("scene = drop\n", "scene = rackets\n# gap = 0.5\n"),
        r"line 6: x0 = 0.305 is out of range; valid range is \[-0.25, 0.25\] m",
    ),
    ("drop below surface", _replace("# x0 = 0.305", "# x0 = -0.01"), r"line 5: x0 = -0.01 is out of range"),
    (
        "bad scene",
        _replace("scene = drop", "scene = table"),
        r"line 2: scene = 'table' is not supported; choose one of \('drop', 'rackets'\)",
    ),
    (
        "bad observe",
        _replace("observe = trace", "observe = video"),
        r"line 8: observe = 'video' is not supported",
    ),
    (
        "apex height <= 0",
        _replace("observe = trace", "observe = apex")
        .replace("t,x\n", "h\n")
        .replace("0.000,0.3051\n0.001,0.3046\n0.002,0.3049\n0.003,0.3040\n", "0.25\n-0.01\n"),
        r"line 11: h = -0.01 is out of range; valid range is \(0, inf\) m",
    ),
    ("short trace", GOOD.split("0.002,")[0], r"line 9: data: 2 data rows; observe = trace needs at least 3"),
    (
        "negative trace time",
        _replace("0.000,0.3051", "-0.001,0.3051"),
        r"line 10: t = -0.001 is out of range",
    ),
    ("no version line", GOOD.split("\n", 1)[1], r"line 1: expected '# jaxunilat-data: 1' as the first line"),
    (
        "wrong version",
        _replace("jaxunilat-data: 1", "jaxunilat-data: 2"),
        r"line 1: jaxunilat-data = '2' is not supported",
    ),
    (
        "version twice",
        _replace("# v0 = 0\n", "# v0 = 0\n# jaxunilat-data: 1\n"),
        r"line 7: jaxunilat-data: duplicate key",
    ),
    (
        "not key = value",
        _replace("# v0 = 0\n", "# v0 = 0\n# recorded with phyphox\n"),
        r"line 7: expected a metadata line '# key = value'",
    ),
    ("no value", _replace("# v0 = 0", "# v0 =   (unknown)"), r"line 6: v0: no value"),
    (
        "# after header",
        _replace("0.003,0.3040\n", "0.003,0.3040\n# mass = 1\n"),
        r"line 14: a '#' line after the column header",
    ),
    (
        "python expression",
        _replace("# mass = 0.0027", "# mass = __import__('os').getpid()"),
        r"line 3: mass = .*unexpected|not a number",
    ),
    (
        "underscore number",
        _replace("# mass = 0.0027", "# mass = 1_000"),
        r"line 3: mass = '1_000' is not a number",
    ),
    ("empty file", "", r"line 1: the file is empty"),
    (
        "non-UTF-8",
        _replace("# v0 = 0\n", "# v0 = 0\n# source = Z\xfcrich\n").encode("latin-1"),
        r"line 7: the file is not UTF-8",
    ),
    ("binary", b"\x80\x03}q\x00.", r"line 1: the file is not UTF-8"),
]


@pytest.mark.parametrize("label, content, pattern", BAD, ids=[b[0] for b in BAD])
def test_bad_data(tmp_path, label, content, pattern):
    """A clear ValueError naming the file and line; the input file is left unchanged."""
    path = _write(tmp_path, content, mode="wb" if isinstance(content, bytes) else "w")
    digest, mtime = hashlib.sha256(path.read_bytes()).hexdigest(), os.stat(path).st_mtime_ns
    with pytest.raises(ValueError, match=pattern) as info:
        load_dataset(path)
    message = str(info.value)
    assert message.startswith(f"{path}: line "), message
    assert "\n" not in message
    assert hashlib.sha256(path.read_bytes()).hexdigest() == digest
    assert os.stat(path).st_mtime_ns == mtime
    assert sorted(os.listdir(tmp_path)) == ["data.csv"]


def test_bad_paths(tmp_path):
    with pytest.raises(ValueError, match=r"no such file"):
        load_dataset(tmp_path / "missing.csv")
    with pytest.raises(ValueError, match=r"is a directory, not a data file"):
        load_dataset(tmp_path)
    path = _write(tmp_path, GOOD)
    os.chmod(path, 0)
    try:
        if os.access(path, os.R_OK):  # running as root: permissions do not apply
            assert load_dataset(path).num_rows == 4
        else:
            with pytest.raises(ValueError, match=r"cannot be read"):
                load_dataset(path)
    finally:
        os.chmod(path, 0o644)
    with pytest.raises(ValueError, match="not a file path"):
        load_dataset(3.5)


def test_minimum_rows(tmp_path):
    """Impacts need two onsets (one says nothing with an unknown clock offset); apex needs one height."""
    head = GOOD.split("t,x\n")[0].replace("observe = trace", "observe = impacts")
    with pytest.raises(ValueError, match=r"line 9: data: 1 data rows; observe = impacts needs at least 2"):
        load_dataset(_write(tmp_path, head + "t\n0.3\n"))
    assert load_dataset(_write(tmp_path, head + "t\n0.3\n0.7\n", name="ok.csv")).num_rows == 2
