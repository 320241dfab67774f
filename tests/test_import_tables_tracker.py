"""`jaxunilat import video TABLE.csv` on tables as trackers write them (Tracker, OpenCV,
hand tracking): image coordinates (y down), frame numbers, a wrong frame rate, repeated
rows, a length unit read wrong.

Every table is generated here from a drag-free closed form: a ball dropped from rest,
restitution 0.8, filmed at 30 frames/s, tracked in pixels (400 px per metre, the floor on
pixel row 950, y down) with 1 px of noise.
"""

from __future__ import annotations

import json

import numpy as np
import pytest
from jaxunilat.identify import ImplausibleRecording, import_video, load_dataset

from jaxunilat._cli._main import main

G = 9.81
E = 0.8
FPS = 30.0
PX_PER_M = 400.0
FLOOR_PX = 950.0
BALL = ["--mass", "0.046", "--drag", "0"]  # a drag-free ball, as the closed form


def _heights(t, *, h0=0.8, e=E, release=0.1):
    """The height (m) at times `t` (s) of a ball held at h0 until `release`, then dropped
    from rest, every bounce leaving at e times its landing speed; no drag."""
    t = np.asarray(t, dtype=float)
    out = np.full(t.shape, h0)
    start, x, v = release, h0, 0.0
    while v >= 0 and start < t.max():
        # Fall (or rise and fall) from (x, v) at `start` to the floor.
        land = start + (v + np.sqrt(v * v + 2 * G * x)) / G
        inside = (t >= start) & (t < land)
        tau = t[inside] - start
        out[inside] = x + v * tau - 0.5 * G * tau**2
        v = e * np.sqrt(v * v + 2 * G * x)
        start, x = land, 0.0
        if v < 0.05:
            out[t >= start] = 0.0
            break
    return out


def _pixels(t, seed):
    """Image rows (px, y down) of the ball at times `t`, with 1 px of noise."""
    rng = np.random.default_rng(seed)
    return FLOOR_PX - PX_PER_M * _heights(t) + rng.normal(0.0, 1.0, len(t))


def _write(path, header, columns):
    lines = [",".join(header)]
    lines += [",".join(f"{v:.4f}" for v in row) for row in zip(*columns, strict=True)]
    path.write_text("\n".join(lines) + "\n")
    return path


def _clip_times(duration=2.5):
    return np.arange(int(duration * FPS)) / FPS


def _import(args, capsys):
    code = main(["import", "video", *args, *BALL])
    out = capsys.readouterr()
    return code, out.out, out.err


@pytest.fixture
def y_down(tmp_path):
    """A Tracker/OpenCV table in pixels, y down, times in seconds."""
    t = _clip_times()
    return _write(tmp_path / "y_down.csv", ("t (s)", "y (px)"), (t, _pixels(t, 1)))


@pytest.fixture
def frames(tmp_path):
    """An OpenCV script's table: frame number, x and y in pixels (y down)."""
    t = _clip_times()
    n = np.arange(len(t))
    x = 320.0 + np.random.default_rng(2).normal(0.0, 1.0, len(t))
    return _write(tmp_path / "frames.csv", ("frame", "x", "y"), (n, x, _pixels(t, 3)))


def test_y_down_is_refused_naming_flip(y_down, tmp_path, capsys):
    code, _, err = _import([str(y_down), "--scale", "0.0025", "--out", str(tmp_path / "v.csv")], capsys)
    assert code == 3, err
    assert "the heights point down (image coordinates)" in err and "pass --flip" in err
    assert not (tmp_path / "v.csv").exists()
    with pytest.raises(ImplausibleRecording, match="pass --flip"):
        import_video(y_down, scale=0.0025, mass=0.046, drag=0.0)


def test_flip_imports_and_the_fit_finds_e(y_down, tmp_path, capsys):
    out = tmp_path / "v.csv"
    code, stdout, err = _import([str(y_down), "--scale", "0.0025", "--flip", "--out", str(out)], capsys)
    assert code == 0, err
    assert "--flip: heights = -y" in stdout and "apparent g = " in stdout
    ds = load_dataset(out)
    assert ds.x0 == pytest.approx(0.8, abs=0.01)  # held at 0.8 m above the contact level
    assert abs(float(np.min(ds.x))) < 0.02 and ds.estimated == ("x0", "scale", "level") and ds.measured == ()
    fit = tmp_path / "fit.json"
    code = main(["identify", str(out), "--json", str(fit)])
    capsys.readouterr()
    assert code == 0
    e = json.loads(fit.read_text())["derived"]["restitution"]["value"]
    assert abs(e - E) < 0.03, e
    # --measured names what a ruler and a floor line measured: the fit holds them.
    measured = tmp_path / "m.csv"
    code, _, err = _import(
        [str(y_down), "--scale", "0.0025", "--flip", "--measured", "scale,level", "--out", str(measured)],
        capsys,
    )
    assert code == 0, err
    ds = load_dataset(measured)
    assert ds.estimated == ("x0",) and ds.measured == ("scale", "level")


def test_floor_sets_the_contact_level(y_down):
    result = import_video(y_down, scale=0.0025, flip=True, floor=FLOOR_PX, mass=0.046, drag=0.0)
    np.testing.assert_allclose(result.dataset.x[:3], 0.8, atol=0.01)  # (950 - y) px * 2.5 mm
    assert any(n.startswith("--floor 950: heights = 950 - y") for n in result.notes)


def test_frame_numbers_need_fps(frames, tmp_path, capsys):
    out = tmp_path / "v.csv"
    code, _, err = _import([str(frames), "--scale", "0.0025", "--out", str(out)], capsys)
    assert code == 2 and not out.exists()
    assert len(err.strip().splitlines()) == 1 and "holds frame numbers" in err and "pass --fps" in err
    code, stdout, err = _import(
        [str(frames), "--scale", "0.0025", "--flip", "--fps", "30", "--out", str(out)], capsys
    )
    assert code == 0, err
    assert "t = frame / 30 frames/s" in stdout
    np.testing.assert_allclose(np.diff(load_dataset(out).t), 1 / FPS, atol=1e-9)


def test_seconds_as_whole_numbers_are_frame_numbers(tmp_path):
    t = _clip_times()
    path = _write(tmp_path / "t.csv", ("t (s)", "y (px)"), (np.arange(len(t)), _pixels(t, 4)))
    with pytest.raises(ValueError, match=r"column 't \(s\)' holds frame numbers \(whole numbers.*pass --fps"):
        import_video(path, scale=0.0025, flip=True, mass=0.046, drag=0.0)
    seconds = _write(tmp_path / "s.csv", ("t (s)", "y (px)"), (t, _pixels(t, 4)))
    with pytest.raises(
        ValueError, match=r"--fps 24 disagrees with column 't \(s\)', whose rows are 0.0333 s apart"
    ):
        import_video(seconds, scale=0.0025, flip=True, fps=24, mass=0.046, drag=0.0)
    result = import_video(seconds, scale=0.0025, flip=True, fps=30, mass=0.046, drag=0.0)
    assert "--fps 30 agrees with column 't (s)' (1 frame(s) per row)" in result.notes


def test_a_wrong_frame_rate_is_refused_naming_the_time_axis(frames, tmp_path, capsys):
    out = tmp_path / "v.csv"
    code, _, err = _import(
        [str(frames), "--scale", "0.0025", "--flip", "--fps", "24", "--out", str(out)], capsys
    )
    assert code == 3 and not out.exists()
    assert "the time axis looks off by a factor 1.2" in err and "a 30 frames/s clip timed at 24" in err
    assert "wrong --fps" in err


def test_repeated_rows_are_left_out(tmp_path):
    """Tracker on a screen recording at 60 frames/s of the 30 frames/s clip: every frame
    twice (heights up, in cm)."""
    t = _clip_times()
    heights = 100.0 * (FLOOR_PX - _pixels(t, 5)) / PX_PER_M
    y = np.repeat(heights, 2) + np.random.default_rng(6).normal(0.0, 0.01, 2 * len(t))
    path = _write(tmp_path / "doubled.csv", ("t (s)", "y (cm)"), (np.arange(len(y)) / 60.0, y))
    result = import_video(path, mass=0.046, drag=0.0)
    repeats = [r for r in result.rejected if "a repeated frame" in r.reason]
    # Every 2nd row, held frames included (the pattern of repeats found in flight).
    assert len(t) - 3 <= len(repeats) <= len(t)
    assert all(r.line % 2 == 1 for r in repeats)  # the second row of each pair (line 1 is the header)
    assert any("30 unique frames/s in a 59.9 rows/s table" in n for n in result.notes)  # 4 decimals
    assert not result.problems and np.median(np.diff(result.dataset.t)) == pytest.approx(1 / FPS, abs=1e-4)


def test_centimetres_written_as_metres_are_named(tmp_path, capsys):
    t = _clip_times()
    heights_cm = 100.0 * (FLOOR_PX - _pixels(t, 7)) / PX_PER_M
    path = _write(tmp_path / "cm.csv", ("t (s)", "y (m)"), (t, heights_cm))
    code, _, err = _import([str(path), "--out", str(tmp_path / "v.csv")], capsys)
    assert code == 3, err
    assert "a length-unit slip" in err and "centimetres read as metres" in err
    forced = import_video(path, mass=0.046, drag=0.0, force=True)
    assert any("100 times too large" in p for p in forced.problems)
