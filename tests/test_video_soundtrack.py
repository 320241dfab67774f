"""A video clip's soundtrack as a second measurement: `jaxunilat import video CLIP --onsets-out FILE`.

Synthetic clips are written here with PyAV (seeded, 160x120 px, 30 frames/s, 1.5 s, H.264):
a ball dropped from 0.3 m with e = 0.8 and a soundtrack of clicks at its impacts (AAC in
MP4, or PCM in MOV starting after the picture), a silent one, one without an audio
stream, and clicks that are no ball's. The onsets file must hold the clicks' times on the
soundtrack's clock within a sample period, agree with the picture's impacts within a frame
and be what `import wav` of the clip writes; a clip without sound must say so and still
write its trace. The real clips are read from `../shared/real-recordings/video/` (skipped
where absent). Also here: the leftovers of a reliability pass (`identify` of a FIFO or a
device, `--noise` ranges, control characters in `wrote` lines, bounded numbers in a
contradiction, the data format's documented noise range).
"""

from __future__ import annotations

import math
import os
import subprocess
import sys

import numpy as np
import pytest

av = pytest.importorskip("av", reason="PyAV (the video extra) is not installed")

from helpers import fifo_errors  # noqa: E402
from jaxunilat.identify import import_video, import_wav, load_dataset  # noqa: E402
from jaxunilat.identify._data._format import MAX_DATA_BYTES, NOISE_RANGE  # noqa: E402
from jaxunilat.identify._data._import import ratio_chain  # noqa: E402
from jaxunilat.identify._data._import_video import sound_agreement, with_soundtrack  # noqa: E402

from jaxunilat._cli._main import main  # noqa: E402

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
REAL = os.path.normpath(os.path.join(ROOT, os.pardir, "shared", "real-recordings", "video"))

# -- the synthetic clip ------------------------------------------------------------------------

W, H, FPS, SECONDS = 160, 120, 30, 1.5
RATE = 48000  # Hz, the soundtrack's
SCALE = 250.0  # px per m: a 40 mm ball is 10 px across
RADIUS = 5.0  # px
FLOOR = 110.0  # image y of the ball's lowest point at contact
DROP, E, G = 0.3, 0.8, 9.81  # m, restitution, m/s^2
RELEASE = -0.03  # s: the ball falls from the first frame on


def impact_times() -> np.ndarray:
    """The impacts within the clip, s on its clock."""
    out, t, v = [], RELEASE + math.sqrt(2 * DROP / G), math.sqrt(2 * G * DROP)
    while t < SECONDS:
        out.append(t)
        v *= E
        t += 2 * v / G
    return np.asarray(out)


CLICKS = impact_times()


def height(t: float) -> float:
    """The ball's lowest point above the floor, m, at clip time t (s)."""
    if t < CLICKS[0]:
        return DROP - 0.5 * G * (t - RELEASE) ** 2
    k = int(np.searchsorted(CLICKS, t)) - 1
    v, tau = math.sqrt(2 * G * DROP) * E ** (k + 1), t - CLICKS[k]
    return max(v * tau - 0.5 * G * tau * tau, 0.0)


@pytest.fixture(scope="module")
def pictures() -> list[np.ndarray]:
    """The clip's frames (rgb24): an orange ball over a textured wall and a wooden floor."""
    rng = np.random.default_rng(3)
    yy, xx = np.mgrid[0:H, 0:W].astype(float)
    texture = np.kron(rng.normal(0, 6, (H // 8 + 1, W // 8 + 1)), np.ones((8, 8)))[:H, :W]
    bg = np.stack([150 + 0.2 * yy, 160 + 0.1 * yy, 175 + 0.05 * yy], -1) + texture[..., None]
    bg[yy >= FLOOR] = [150.0, 108.0, 70.0]
    sub = (np.arange(4) + 0.5) / 4 - 0.5
    frames = []
    for k in range(int(SECONDS * FPS)):
        t = k / FPS
        cx, cy = 60 + 20 * t, FLOOR - RADIUS - height(t) * SCALE
        cover = sum(((xx + ox - cx) ** 2 + (yy + oy - cy) ** 2) <= RADIUS**2 for oy in sub for ox in sub) / 16
        img = bg * (1 - cover[..., None]) + cover[..., None] * np.array([240.0, 120.0, 35.0])
        frames.append(np.clip(img + rng.normal(0, 2, img.shape), 0, 255).astype(np.uint8))
    return frames


def clicks(times, *, seconds: float = SECONDS, start: float = 0.0, seed: int = 5) -> np.ndarray:
    """A soundtrack from clip time `start` (s) on: room noise (3e-4 rms) and a 3 kHz click at
    each of `times` (s, the clip's clock), starting at its full amplitude, fading in 4 ms."""
    rng = np.random.default_rng(seed)
    n = int(round((seconds - start) * RATE))
    t = start + np.arange(n) / RATE
    x = 3e-4 * rng.standard_normal(n)
    for k, tk in enumerate(times):
        after = t >= tk
        x[after] += (
            0.5 * 0.8**k * np.exp(-(t[after] - tk) / 0.004) * np.cos(2 * np.pi * 3000 * (t[after] - tk))
        )
    return x


def write_clip(path, pictures, sound=None, *, codec: str = "aac", start: float = 0.0) -> str:
    """The clip `pictures` (H.264, 30 frames/s) with the mono soundtrack `sound` (full scale
    1; None: no audio stream) encoded by `codec` ("aac" or "pcm_s16le"), its first sample
    at clip time `start` (s)."""
    codec_v = "libx264" if "libx264" in av.codecs_available else "mpeg4"
    with av.open(str(path), "w") as out:
        video = out.add_stream(codec_v, rate=FPS)
        video.width, video.height, video.pix_fmt = W, H, "yuv420p"
        if codec_v == "libx264":
            video.options = {"crf": "18", "preset": "veryfast", "x264-params": "no-mbtree=1"}
        audio = out.add_stream(codec, rate=RATE, layout="mono") if sound is not None else None
        if codec == "aac" and audio is not None:
            audio.bit_rate = 192_000
        for k, img in enumerate(pictures):
            frame = av.VideoFrame.from_ndarray(img, format="rgb24")
            frame.pts = k
            for packet in video.encode(frame):
                out.mux(packet)
        for packet in video.encode():
            out.mux(packet)
        if audio is None:
            return str(path)
        fmt = "fltp" if codec == "aac" else "s16"
        data = sound.astype(np.float32) if codec == "aac" else np.round(sound * 32767).astype(np.int16)
        first = int(round(start * RATE))
        for a in range(0, len(data), 1024):
            frame = av.AudioFrame.from_ndarray(data[None, a : a + 1024], format=fmt, layout="mono")
            frame.sample_rate, frame.pts = RATE, first + a
            for packet in audio.encode(frame):
                out.mux(packet)
        for packet in audio.encode():
            out.mux(packet)
    return str(path)


def _cli(capsys, *args) -> tuple[int, str, str]:
    code = main([str(a) for a in args])
    out = capsys.readouterr()
    return code, out.out, out.err


def _import(capsys, clip, tmp_path, *more) -> tuple[int, str, str]:
    return _cli(
        capsys, "import", "video", clip, "--ball", "pingpong", "--out", tmp_path / "v.csv", *more
    )  # fmt: skip


# -- the soundtrack ----------------------------------------------------------------------------


def test_the_clicks_become_an_impacts_file_that_agrees_with_the_picture(tmp_path, capsys, pictures):
    clip = write_clip(tmp_path / "drop.mp4", pictures, clicks(CLICKS))
    onsets = tmp_path / "a.csv"
    code, out, err = _import(capsys, clip, tmp_path, "--onsets-out", onsets)
    assert code == 0, out + err
    data = load_dataset(onsets)
    assert data.observe == "impacts" and data.mass == 0.0027 and len(data.t) == len(CLICKS), out
    assert np.max(np.abs(data.t - CLICKS)) <= 1.5 / RATE, (data.t - CLICKS) * 1e6  # AAC at 192 kb/s
    assert ratio_chain(data.t).restitution == pytest.approx(E, abs=0.005)
    assert f"wrote      {onsets} (impacts: {len(CLICKS)} rows, the clip's soundtrack)" in out
    assert load_dataset(tmp_path / "v.csv").observe == "trace"
    agreement = next(line for line in out.splitlines() if "soundtrack vs picture" in line)
    assert f"{len(CLICKS)} of {len(CLICKS)} audio onset(s) paired" in agreement
    assert ": within one frame (33.3 ms at 30 frames/s)" in agreement, agreement
    assert onsets.read_text() == import_wav(clip, ball="pingpong").text()  # what `import wav CLIP` writes


def test_a_soundtrack_that_starts_after_the_picture_keeps_its_own_clock(tmp_path, pictures):
    start = 0.15  # the first click 67 ms in: quiet before it to rise from
    sound = clicks(CLICKS, start=start)
    clip = write_clip(tmp_path / "late.mov", pictures, sound, codec="pcm_s16le", start=start)
    result = import_video(clip, ball="pingpong", soundtrack=True)
    onsets = result.soundtrack.dataset.t
    assert np.max(np.abs(onsets - (CLICKS - start))) <= 1.5 / RATE  # the soundtrack's clock
    notes = " ".join(result.notes)
    assert "starting at 0.15 s on the clip's clock" in notes
    assert ": within one frame" in notes and not result.warnings


@pytest.mark.parametrize(
    "label, sound, why",
    [
        ("digital silence", np.zeros(int(SECONDS * RATE)), "digital silence: 100% of its 1.5"),
        ("room noise only", clicks([]), "no click rises above 8 sigma of its noise floor"),
    ],
)
def test_a_silent_soundtrack_is_said_to_be_silent(tmp_path, capsys, pictures, label, sound, why):
    clip = write_clip(tmp_path / "quiet.mp4", pictures, sound, codec="pcm_s16le")
    onsets = tmp_path / "a.csv"
    code, out, err = _import(capsys, clip, tmp_path, "--onsets-out", onsets)
    assert code == 0 and err == "", out + err
    assert "the clip's soundtrack is silent: no impacts file written" in out and why in out, out
    assert not onsets.exists() and (tmp_path / "v.csv").exists()


def test_a_clip_without_an_audio_stream_says_so(tmp_path, capsys, pictures):
    clip = write_clip(tmp_path / "mute.mp4", pictures)
    onsets = tmp_path / "a.csv"
    code, out, err = _import(capsys, clip, tmp_path, "--onsets-out", onsets)
    assert code == 0 and err == "", out + err
    assert "the clip has no soundtrack (no audio stream): no impacts file written" in out
    assert not onsets.exists() and (tmp_path / "v.csv").exists()


def test_clicks_that_are_no_ball_leave_the_video_import_alone(tmp_path, capsys, pictures):
    """Clicks every 0.25 s (a metronome: intervals that do not shrink, e = 1) fail the audio's own
    gate: the trace is written, exit 0, the reason is told, no onsets file; --force writes it."""
    clip = write_clip(tmp_path / "metronome.mp4", pictures, clicks(np.arange(0.1, 1.45, 0.25)))
    onsets = tmp_path / "a.csv"
    code, out, err = _import(capsys, clip, tmp_path, "--onsets-out", onsets)
    assert code == 0 and err == "", out + err
    assert "no impacts file written: the soundtrack's clicks are not one bouncing ball's" in out, out
    assert "restitution e = 1.000, outside" in out and "(--force writes it anyway)" in out
    assert not onsets.exists() and (tmp_path / "v.csv").exists()
    code, out, err = _import(capsys, clip, tmp_path, "--onsets-out", onsets, "--force")
    assert (
        code == 0
        and "## not a bouncing ball (import forced): the interval ratios give a restitution e = 1.000"
        in onsets.read_text()
    )


def test_a_ball_heard_among_other_sounds_is_kept_where_the_picture_confirms_it(tmp_path, pictures):
    """The ball's clicks plus twice as many other clicks (a minority chain, which the audio's
    gate alone refuses): kept where every chain onset falls on one of the picture's impacts;
    the same other clicks with the ball's clicks shifted off the picture's impacts by 0.1 s
    (more than a frame, and no single offset lines them up with the picture as well) are
    refused."""
    rng = np.random.default_rng(11)
    others: list[float] = []  # other sounds at random, 50 ms from any click
    for t in rng.uniform(0.05, SECONDS - 0.05, 400):
        if len(others) < 2 * len(CLICKS) and np.min(np.abs(np.r_[CLICKS, others] - t)) > 0.05:
            others.append(float(t))
    others = np.asarray(others)
    heard = import_video(
        write_clip(tmp_path / "room.mp4", pictures, clicks(np.sort(np.r_[CLICKS, others]), seed=3)),
        ball="pingpong",
        soundtrack=True,
    )
    notes = " ".join(heard.notes)
    assert "is a minority of its clicks, but each of its" in notes and "kept as the ball's" in notes, notes
    assert np.max(np.abs(heard.soundtrack.dataset.t - CLICKS)) <= 1.5 / RATE
    # The ball's chain off the picture: refused by the gate, the picture no witness.
    shifted = CLICKS * 1.07 + 0.1
    off = import_video(
        write_clip(
            tmp_path / "off.mp4", pictures, clicks(np.sort(np.r_[shifted[shifted < SECONDS - 0.05], others]))
        ),
        ball="pingpong",
        soundtrack=True,
    )
    assert off.soundtrack is None and "kept as the ball's" not in " ".join(off.notes)


def test_onsets_out_is_checked_before_any_work(tmp_path, capsys, pictures):
    table = tmp_path / "track.csv"
    table.write_text("t (s),y (m)\n0,0.3\n0.033,0.29\n0.067,0.27\n")
    code, out, err = _cli(
        capsys, "import", "video", table, "--ball", "pingpong", "--out", tmp_path / "v.csv",
        "--onsets-out", tmp_path / "a.csv",
    )  # fmt: skip
    assert (
        code == 2
        and err.count("\n") == 1
        and "--onsets-out (the soundtrack's impacts) applies to a video clip" in err
    )
    clip = write_clip(tmp_path / "drop.mp4", pictures, clicks(CLICKS))
    code, out, err = _import(capsys, clip, tmp_path, "--onsets-out", tmp_path / "v.csv")
    assert code == 2 and "--out and --onsets-out name the same file" in err, err
    code, out, err = _import(capsys, clip, tmp_path, "--onsets-out", clip)
    assert code == 2 and "--onsets-out" in err and "refusing to overwrite it" in err, err
    assert os.path.getsize(clip) > 0 and not (tmp_path / "v.csv").exists()


def test_sound_agreement_pairs_onsets_and_finds_a_clock_offset():
    impacts = np.array([0.154, 0.554, 0.895, 1.186, 1.439, 1.660, 1.852, 2.016])
    jitter = np.array([0.3, -0.2, 0.1, -0.4, 0.2]) * 1e-3
    same = sound_agreement(impacts[2:7] + jitter, impacts, 1 / 30)
    assert same.within_frame and same.offset is None and len(same.pairs) == 5
    notes, warnings = same.lines()
    assert warnings == [] and "|video - audio| median 0.2 ms, max 0.4 ms" in notes[0]
    late = sound_agreement(impacts[2:7] - 0.109 + jitter, impacts, 1 / 30)  # the sound 109 ms early
    assert not late.within_frame and late.offset == pytest.approx(0.109, abs=0.5e-3)
    assert np.max(np.abs(late.residual)) < 1e-3
    notes, warnings = late.lines()
    assert "not within one frame" in notes[0] and "a constant offset explains it" in notes[1]
    assert f"video - audio = {late.offset * 1e3:+.1f} ms" in notes[1] and warnings == []
    chance = sound_agreement(np.array([0.3, 0.35, 1.0, 1.9]), impacts, 1 / 30)
    assert chance.offset is None and not chance.within_frame
    assert chance.lines()[0] == [] and "no constant offset" in chance.lines()[1][0]


# -- the real clips ----------------------------------------------------------------------------


def _real(name: str) -> str:
    path = os.path.join(REAL, name)
    if not os.path.exists(path):
        pytest.skip(
            f"{path} is absent (real recordings live in ../shared/real-recordings, beside the checkout)"
        )
    return path


@pytest.mark.slow
def test_real_pingpong_soundtrack_matches_the_picture_after_its_clock_offset(tmp_path):
    """zak_pingpong.mov: its clicks (e = 0.870 by the recordings' README) lie about 109 ms
    before the picture's impacts (a screen recording's audio latency), within a frame after
    that offset; its 5 chain onsets are a minority of 24 candidate clicks, which alone the
    audio's gate refuses, but every one falls on an impact of the picture: kept."""
    from jaxunilat.identify._data._balls import ball_spec

    path = _real("zak_pingpong.mov")
    result = import_video(path, ball="pingpong", soundtrack=True)
    notes = " ".join(result.notes)
    assert "a constant offset explains it" in notes, notes
    line = next(n for n in result.notes if n.startswith("a constant offset"))
    offset = float(line.split("video - audio = ")[1].split(" ms")[0])
    assert 100 <= offset <= 120 and ": within one frame" in line, line
    pairs = int(line.split(" pairs: ")[0].rsplit(" ", 1)[1])
    assert pairs >= 4, line
    assert "is a minority of its clicks, but each of its" in notes and "kept as the ball's" in notes, notes
    t = result.soundtrack.dataset.t
    assert len(t) >= 4 and ratio_chain(t).restitution == pytest.approx(0.870, abs=0.01)
    forced = with_soundtrack(result, path, ball_spec("pingpong"), force=True)
    t = forced.soundtrack.dataset.t
    assert len(t) >= 4 and ratio_chain(t).restitution == pytest.approx(0.870, abs=0.01)
    assert forced.soundtrack.text() == import_wav(path, ball="pingpong", force=True).text()


@pytest.mark.slow
def test_real_red_ball_soundtrack_is_digital_silence(tmp_path, capsys):
    onsets = tmp_path / "a.csv"
    code, out, err = _cli(
        capsys, "import", "video", _real("viraj_redball.mp4"), "--diameter", "0.034", "--mass", "0.02",
        "--out", tmp_path / "v.csv", "--onsets-out", onsets,
    )  # fmt: skip
    assert code == 0, out + err
    assert "the clip's soundtrack is silent: no impacts file written (digital silence: 100%" in out
    assert not onsets.exists() and (tmp_path / "v.csv").exists()


# -- leftovers of a reliability pass -----------------------------------------------------------


def test_identify_refuses_a_fifo_without_waiting(tmp_path, capsys):
    fifo = tmp_path / "pipe.csv"
    os.mkfifo(fifo)
    errors = fifo_errors(load_dataset, fifo)
    assert len(errors) == 1 and "is a FIFO, not a regular file" in errors[0], errors
    code, out, err = _cli(capsys, "identify", fifo)
    assert code == 2 and err.count("\n") == 1 and "is a FIFO" in err, err


@pytest.mark.skipif(not os.path.exists("/dev/zero"), reason="no /dev/zero here")
def test_identify_refuses_a_device_and_a_huge_file(tmp_path, capsys):
    script = (
        "import resource, sys\n"
        "resource.setrlimit(resource.RLIMIT_AS, (3 << 30, 3 << 30))\n"
        "from jaxunilat._cli._main import main\n"
        "sys.exit(main(['identify', '/dev/zero']))\n"
    )
    try:
        done = subprocess.run([sys.executable, "-c", script], capture_output=True, text=True, timeout=120)
    except subprocess.TimeoutExpired:
        pytest.fail("jaxunilat identify /dev/zero read without end")
    assert done.returncode == 2 and done.stderr.count("\n") == 1, done.stderr[-2000:]
    assert "/dev/zero: is a character device, not a regular file" in done.stderr
    big = tmp_path / "big.csv"
    with open(big, "wb") as f:  # a sparse file one byte past the limit
        f.write(b"# jaxunilat-data: 1\n")
        f.truncate(MAX_DATA_BYTES + 1)
    code, out, err = _cli(capsys, "identify", big)
    assert code == 2 and err.count("\n") == 1 and "larger than the 100 MB a data file is read up to" in err, (
        err
    )


def test_noise_is_checked_against_the_format_range_before_reading(tmp_path, capsys, pictures):
    table = tmp_path / "track.csv"
    table.write_text("t (s),y (m)\n0,0.3\n0.033,0.29\n0.067,0.27\n")
    clip = write_clip(tmp_path / "drop.mp4", pictures)
    missing = tmp_path / "never-read.wav"  # the range is checked before the source is read
    cases = [
        ("wav", missing, "5", "--noise 5 s is out of range; valid range is [1e-07, 1] s"),
        ("wav", missing, "1e-08", "--noise 1e-08 s is out of range; valid range is [1e-07, 1] s"),
        (
            "phyphox",
            tmp_path / "never-read.csv",
            "2",
            "--noise 2 s is out of range; valid range is [1e-07, 1] s",
        ),
        ("video", table, "2", "--noise 2 m is out of range; valid range is [1e-09, 1] m"),
        ("video", clip, "1e-12", "--noise 1e-12 m is out of range; valid range is [1e-09, 1] m"),
    ]
    for kind, source, noise, message in cases:
        out_path = tmp_path / "o.csv"
        code, out, err = _cli(
            capsys, "import", kind, source, "--ball", "pingpong", "--noise", noise, "--out", out_path
        )  # fmt: skip
        assert code == 2 and err.count("\n") == 1 and message in err, (kind, err)
        assert not out_path.exists()


def test_wrote_lines_escape_control_characters(tmp_path, capsys, pictures):
    clip = write_clip(tmp_path / "drop.mp4", pictures, clicks(CLICKS))
    out_path, onsets = tmp_path / "v\x1b[2J.csv", tmp_path / "a\n.csv"
    code, out, err = _cli(
        capsys, "import", "video", clip, "--ball", "pingpong", "--out", out_path, "--onsets-out", onsets
    )  # fmt: skip
    assert code == 0 and "\x1b" not in out, out + err
    wrote = [line for line in out.splitlines() if line.startswith("wrote")]
    assert len(wrote) == 2 and "v\\x1b[2J.csv (trace:" in wrote[0] and "a\\n.csv (impacts:" in wrote[1]
    assert out_path.exists() and onsets.exists()


def test_a_contradiction_prints_a_wild_e_in_bounded_width(monkeypatch):
    from types import SimpleNamespace

    from jaxunilat.identify._fit import _plausible

    form = _plausible.ClosedForm(restitution=0.9349, spread=0.001, count=8, first=None, launch=math.nan)
    monkeypatch.setattr(_plausible, "_forms", lambda result: [form, form])
    monkeypatch.setattr(_plausible, "_basin_misses", lambda result, forms: [(0, 1e170, 0.03)])
    data = SimpleNamespace(path="drop.csv")
    result = SimpleNamespace(
        datasets_data=[data, data], free=("e",), derived={"restitution": SimpleNamespace(value=1e170)}
    )  # fmt: skip
    found = _plausible.contradictions(result)
    assert any("the fit's e = 1e+170 contradicts the e = 0.9349" in line for line in found), found
    assert any("the joint fit's e = 1e+170 lies outside" in line for line in found), found
    assert all(len(line) < 400 for line in found)


def test_the_data_format_documents_the_noise_range():
    with open(os.path.join(ROOT, "data", "README.md"), encoding="utf-8") as f:
        row = next(line for line in f if line.startswith("| `noise` |"))
    (m_lo, m_hi), (s_lo, s_hi) = (
        [f"{x:g}".replace("e-0", "e-") for x in NOISE_RANGE[unit]] for unit in ("m", "s")
    )  # fmt: skip
    assert f"{m_lo} to {m_hi} m (trace, apex); {s_lo} to {s_hi} s (impacts)" in row, row
