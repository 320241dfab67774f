"""`jaxunilat import`: WAV onsets, phyphox exports, video-tracking tables, and the CLI.

The references are independent of the importers: the test WAVs are rendered here by a
small click renderer (not data/generate.py's) and written by the stdlib `wave` module
(PCM16) or by a RIFF writer in this file; the truth of the bundled files is read from
data/README.md.
"""

import os
import re
import shutil
import struct
import wave

import numpy as np
import pytest
from jaxunilat.identify import detect_onsets, import_phyphox, import_video, import_wav, load_dataset, read_wav

from jaxunilat._cli._main import main

DATA = os.path.join(os.path.dirname(os.path.dirname(os.path.abspath(__file__))), "data")
TOL = 0.1e-3  # onset accuracy asked of the detector, s


# -- an independent click renderer and WAV writers ---------------------------------------


def ball_onsets(n=10, start=0.21, first=0.32, ratio=0.95):
    """Onsets of a bouncing ball: intervals shrinking by `ratio` (s)."""
    return start + np.concatenate([[0.0], np.cumsum(first * ratio ** np.arange(n - 1))])


def render(rate, onsets, amplitudes, *, freq=3000.0, tau=1.0e-3, noise=0.002, hum=0.0, seed=0, extra=()):
    """Clicks A sin(2 pi f s) exp(-s/tau) starting at each onset (s = time since it), plus white
    noise (sd `noise`), 50 Hz hum and `extra` clicks ((onset, amplitude, freq)); clipped to +-1."""
    duration = float(np.max(onsets)) + 0.3
    t = np.arange(int(duration * rate)) / rate
    rng = np.random.default_rng(seed)
    x = noise * rng.standard_normal(len(t)) + hum * np.sin(2 * np.pi * 50.0 * t + 0.3)
    for t0, a, f in [*zip(onsets, amplitudes, [freq] * len(onsets), strict=True), *extra]:
        s = t - t0
        on = s >= 0
        x[on] += a * np.sin(2 * np.pi * f * s[on]) * np.exp(-s[on] / tau)
    return np.clip(x, -1.0, 1.0)


def write_stdlib_pcm16(path, x, rate, channels=1):
    q = np.clip(np.round(x * 32767.0), -32768, 32767).astype("<i2")
    if channels == 2:
        q = np.stack([q, q], axis=1)
    with wave.open(str(path), "wb") as w:
        w.setnchannels(channels)
        w.setsampwidth(2)
        w.setframerate(rate)
        w.writeframes(q.tobytes())


def write_riff(path, x, rate, *, bits, encoding="pcm", channels=1, extensible=False, tag=None):
    """A RIFF/WAVE writer written for these tests (PCM 8/16/24/32, float 32/64, extensible)."""
    x = np.repeat(np.asarray(x, dtype=float)[:, None], channels, axis=1)
    if encoding == "float":
        payload = x.astype("<f4" if bits == 32 else "<f8").tobytes()
        code = 3
    else:
        full = 2 ** (bits - 1)
        q = np.clip(np.round(x * (full - 1)), -full, full - 1).astype(np.int64)
        if bits == 8:
            payload = (q + 128).astype(np.uint8).tobytes()
        else:
            payload = b"".join(int(v).to_bytes(bits // 8, "little", signed=True) for v in q.ravel())
        code = 1
    code = code if tag is None else tag
    align = channels * bits // 8
    if extensible:
        fmt = struct.pack("<HHIIHH", 0xFFFE, channels, rate, rate * align, align, bits)
        guid_tail = b"\x00\x00\x00\x00\x10\x00\x80\x00\x00\xaa\x00\x38\x9b\x71"
        fmt += struct.pack("<HHI", 22, bits, 0) + struct.pack("<H", code) + guid_tail
    else:
        fmt = struct.pack("<HHIIHH", code, channels, rate, rate * align, align, bits)
    chunks = b"fmt " + struct.pack("<I", len(fmt)) + fmt
    chunks += b"LIST" + struct.pack("<I", 4) + b"INFO"  # an unrelated chunk to skip
    chunks += b"data" + struct.pack("<I", len(payload)) + payload + (b"\0" if len(payload) % 2 else b"")
    with open(path, "wb") as f:
        f.write(b"RIFF" + struct.pack("<I", 4 + len(chunks)) + b"WAVE" + chunks)


# -- the WAV reader ----------------------------------------------------------------------

FORMATS = [
    # label, rate, bits, encoding, channels, extensible, writer
    ("pcm16-stdlib", 44100, 16, "pcm", 1, False, "stdlib"),
    ("pcm16-stereo-stdlib", 48000, 16, "pcm", 2, False, "stdlib"),
    ("pcm24", 48000, 24, "pcm", 1, False, "riff"),
    ("pcm32", 48000, 32, "pcm", 1, False, "riff"),
    ("float32", 48000, 32, "float", 1, False, "riff"),
    ("float64-stereo", 22050, 64, "float", 2, False, "riff"),
    ("pcm24-extensible", 96000, 24, "pcm", 1, True, "riff"),
    ("float32-extensible", 44100, 32, "float", 2, True, "riff"),
    ("pcm16-8k", 8000, 16, "pcm", 1, False, "stdlib"),
    ("pcm16-96k", 96000, 16, "pcm", 1, False, "riff"),
]


def _write(path, x, rate, bits, encoding, channels, extensible, writer):
    if writer == "stdlib":
        write_stdlib_pcm16(path, x, rate, channels)
    else:
        write_riff(path, x, rate, bits=bits, encoding=encoding, channels=channels, extensible=extensible)


@pytest.mark.parametrize(
    "label, rate, bits, encoding, channels, extensible, writer", FORMATS, ids=[f[0] for f in FORMATS]
)
def test_read_wav_formats(tmp_path, label, rate, bits, encoding, channels, extensible, writer):
    x = 0.9 * np.sin(2 * np.pi * 440.0 * np.arange(2000) / rate)
    path = tmp_path / f"{label}.wav"
    _write(path, x, rate, bits, encoding, channels, extensible, writer)
    audio = read_wav(path)
    assert audio.rate == rate and audio.channels == channels and audio.bits == bits
    assert audio.encoding == encoding and audio.samples.dtype == np.float64
    assert len(audio.samples) == len(x)
    lsb = 1.0 / 2 ** (bits - 1) if encoding == "pcm" else 1e-7
    np.testing.assert_allclose(audio.samples, x, atol=2 * lsb)


@pytest.mark.parametrize(
    "label, bits, encoding, channels, rate, tag, cause",
    [
        # 8-bit, mu-law, A-law, any channel count and 8-384 kHz are read: tests/test_audio_formats.py
        ("rate-4k", 16, "pcm", 1, 4000, None, "sample rate = 4000 Hz is out of range"),
        ("rate-768k", 16, "pcm", 1, 768000, None, "sample rate = 768000 Hz is out of range"),
        ("float16", 16, "float", 1, 44100, None, "16-bit floating-point"),
    ],
)
def test_read_wav_refuses_unsupported(tmp_path, label, bits, encoding, channels, rate, tag, cause):
    path = tmp_path / f"{label}.wav"
    if encoding == "float" and bits == 16:
        write_riff(path, np.zeros(100), rate, bits=16, encoding="pcm", tag=3)
    else:
        write_riff(path, np.zeros(100), rate, bits=bits, encoding=encoding, channels=channels, tag=tag)
    with pytest.raises(ValueError) as err:
        read_wav(path)
    message = str(err.value)
    assert "\n" not in message and str(path) in message and cause in message, message


def test_read_wav_damaged_files(tmp_path):
    cases = {
        "text.wav": (b"t,x\n0,1\n", "not a WAV file"),
        "nodata.wav": (
            b"RIFF"
            + struct.pack("<I", 28)
            + b"WAVE"
            + b"fmt "
            + struct.pack("<I", 16)
            + struct.pack("<HHIIHH", 1, 1, 8000, 16000, 2, 16),
            "no 'data' chunk",
        ),
        "mp3.wav": (b"ID3\x03\x00" + bytes(40), "MP3"),
    }
    for name, (raw, cause) in cases.items():
        (tmp_path / name).write_bytes(raw)
        with pytest.raises(ValueError, match=re.escape(cause)) as err:
            read_wav(tmp_path / name)
        assert name in str(err.value) and "\n" not in str(err.value)
    # An unfinished recording: the data size field overstates the file; whole frames are read.
    write_stdlib_pcm16(tmp_path / "ok.wav", np.full(1000, 0.5), 8000)
    raw = bytearray((tmp_path / "ok.wav").read_bytes())
    raw[40:44] = struct.pack("<I", 0xFFFFFFFF)
    (tmp_path / "open.wav").write_bytes(bytes(raw[:-3]))
    assert len(read_wav(tmp_path / "open.wav").samples) == 998


# -- onset detection ---------------------------------------------------------------------

DETECT = [
    # label, format index, noise, hum, first amplitude, spurious
    ("clean-pcm16", 0, 0.0005, 0.0, 0.8, False),
    ("noisy-hum-pcm24", 2, 0.006, 0.02, 0.8, False),
    ("clipped-float32", 4, 0.002, 0.0, 4.0, False),
    ("spurious-pcm32", 3, 0.002, 0.01, 2.0, True),
    ("stereo-float64", 5, 0.002, 0.0, 0.8, True),
    ("8k", 8, 0.002, 0.0, 1.5, True),
    ("96k-extensible", 6, 0.003, 0.01, 2.0, True),
]


@pytest.mark.parametrize("label, fi, noise, hum, first, spurious", DETECT, ids=[d[0] for d in DETECT])
def test_onsets_found_and_spurious_rejected(tmp_path, label, fi, noise, hum, first, spurious):
    _, rate, bits, encoding, channels, extensible, writer = FORMATS[fi]
    onsets = ball_onsets()
    amplitudes = first * (0.95**2) ** np.arange(len(onsets))  # v^2: the late ones are quiet
    freq = 1200.0 if rate <= 8000 else 3000.0
    extra = [(onsets[3] + 0.07, 0.05 * amplitudes[3], freq * 0.7)] if spurious else []
    x = render(rate, onsets, amplitudes, freq=freq, noise=noise, hum=hum, extra=extra, seed=fi)
    path = tmp_path / f"{label}.wav"
    _write(path, x, rate, bits, encoding, channels, extensible, writer)
    result = import_wav(path, ball="pingpong")
    found = result.accepted
    assert len(found) == len(onsets), (found, result.summary())
    assert np.max(np.abs(found - onsets)) <= TOL, np.abs(found - onsets) * 1e6
    assert found[0] >= onsets[0] - TOL  # the start of the click, not its peak...
    assert result.detection.coarse[0] <= onsets[0] + 1e-3
    if spurious:
        assert len(result.rejected) == 1
        r = result.rejected[0]
        assert (
            abs(r.time - extra[0][0]) < TOL and "spurious" in r.reason and "lands where no bounce" in r.reason
        )
        assert "left out" in result.summary() and "spurious" in result.summary()
    else:
        assert result.rejected == ()
    # The timing-noise estimate: at least one sample, at most a few ms for this regular sequence.
    assert 1.0 / rate <= result.noise_estimate < 2e-3
    assert result.dataset.noise == result.noise_estimate


def test_clipped_click_timed_by_its_rise():
    rate = 48000
    onsets = ball_onsets(n=6)
    x = render(rate, onsets, [10.0] * 6, noise=0.001)  # far beyond full scale
    det = detect_onsets(x, rate)
    assert det.clipped.all()
    assert np.max(np.abs(det.onsets - onsets)) < 0.05e-3
    peaks = np.array([np.argmax(np.abs(x[int(t * rate) : int(t * rate) + 200])) for t in onsets]) / rate
    assert np.all(det.onsets - onsets < peaks)  # earlier than the first full-scale sample


def test_echo_closer_than_min_gap_is_reported(tmp_path):
    rate = 48000
    onsets = ball_onsets(n=8)
    amplitudes = 0.8 * 0.9 ** np.arange(8)
    echo = onsets[2] + 0.025  # rises from below (its click has decayed), but closer than min-gap
    x = render(rate, onsets, amplitudes, extra=[(echo, 0.3 * amplitudes[2], 3000.0)])
    det = detect_onsets(x, rate)
    assert np.max(np.abs(det.onsets - onsets)) <= TOL
    (r,) = det.rejected
    assert abs(r.time - echo) < TOL and "echo or double trigger" in r.reason and "min-gap" in r.reason
    # An echo 8 ms after its click, inside the click's own loud past, does not rise from below:
    # it is part of the click.
    x = render(rate, onsets, amplitudes, extra=[(onsets[2] + 0.008, 0.3 * amplitudes[2], 3000.0)])
    assert detect_onsets(x, rate).rejected == ()


def test_loud_misplaced_click_left_out_by_the_chain():
    # As loud as its neighbours, but where no bounce can be: the bouncing ball's chain of
    # intervals leaves it out, and says why.
    rate = 48000
    onsets = ball_onsets(n=8)
    amplitudes = 0.8 * 0.9 ** np.arange(8)
    loud = onsets[4] + 0.07
    x = render(rate, onsets, amplitudes, extra=[(loud, amplitudes[4], 2000.0)])
    det = detect_onsets(x, rate)
    assert np.max(np.abs(det.onsets - onsets)) <= TOL
    (r,) = det.rejected
    assert abs(r.time - loud) < TOL and "lands where no bounce can be" in r.reason


def test_detect_onsets_validates_settings():
    x = np.zeros(1000)
    with pytest.raises(ValueError, match=r"rel_level = 1.5 is out of range; valid range is \(0, 1\)"):
        detect_onsets(x, 8000, rel_level=1.5)
    with pytest.raises(ValueError, match="threshold = -1"):
        detect_onsets(x, 8000, threshold=-1)


# -- the bundled WAV against its truth ---------------------------------------------------


def _readme():
    with open(os.path.join(DATA, "README.md"), encoding="utf-8") as f:
        return f.read()


def phone_truth():
    """(onsets of the rendered clicks, the missed bounce's onset, the spurious click) from README."""
    section = _readme().split("### `phone_drop.wav`")[1].split("###")[0]
    rows = [[c.strip() for c in line.strip().strip("|").split("|")] for line in section.splitlines()]
    rows = [r for r in rows if len(r) == 5 and re.fullmatch(r"\d+\.\d{6}", r[1])]
    clicks = np.array([float(r[1]) for r in rows if r[4] == "click"])
    (missed,) = [float(r[1]) for r in rows if r[4].startswith("MISSED")]
    (spurious,) = [float(r[1]) for r in rows if r[4].startswith("SPURIOUS")]
    return clicks, missed, spurious


def test_bundled_wav_against_truth(tmp_path):
    clicks, missed, spurious = phone_truth()
    assert len(clicks) >= 30
    path = os.path.join(DATA, "phone_drop.wav")
    assert os.path.getsize(path) <= 1_000_000
    result = import_wav(path, ball="pingpong")
    found = result.accepted
    assert len(found) == len(clicks), result.summary()
    assert np.max(np.abs(found - clicks)) <= TOL
    (r,) = result.rejected
    assert abs(r.time - spurious) < TOL and "spurious" in r.reason
    assert np.min(np.abs(found - missed)) > 0.05  # the missed bounce is absent...
    assert any("missed bounce" in w for w in result.warnings)  # ...and its doubled interval reported
    assert result.detection.clipped[:3].all()
    # The written file loads, and says what was left out.
    out = tmp_path / "phone.csv"
    result.write(out)
    ds = load_dataset(out)
    assert ds.observe == "impacts" and ds.scene == "drop" and np.array_equal(ds.t, found)
    assert (
        ds.noise == result.noise_estimate
        and ds.source == "phone_drop.wav (jaxunilat import wav, ball: pingpong)"
    )
    text = out.read_text()
    assert "## left out: t = " in text and "spurious" in text and "## x0 = " in text


# -- phyphox -----------------------------------------------------------------------------

TIMES = np.array([1.483583, 1.937875, 2.358625, 2.746917, 3.110375, 3.450812, 3.770604, 4.071062])


def _rows(times, dec=".", first_interval=""):
    out = []
    for i, t in enumerate(times):
        iv = first_interval if i == 0 else f"{times[i] - times[i - 1]:.6f}"
        out.append((f"{t:.6f}".replace(".", dec), iv.replace(".", dec)))
    return out


def _variants():
    head = ('"Event time (s)"', '"Interval (s)"')
    yield "comma-point", ",".join(head) + "\n" + "\n".join(",".join(r) for r in _rows(TIMES)) + "\n"
    yield (
        "semicolon-comma",
        ";".join(head) + "\r\n" + "\r\n".join(";".join(r) for r in _rows(TIMES, ",")) + "\r\n",
    )
    yield (
        "tab-unquoted",
        "Event time (s)\tInterval (s)\n" + "\n".join("\t".join(r) for r in _rows(TIMES)) + "\n",
    )
    yield "quoted-cells", ",".join(head) + "\n" + "\n".join(f'"{a}","{b}"' for a, b in _rows(TIMES)) + "\n"
    yield "times-only", '"Time (s)"\n' + "\n".join(f"{t:.6f}" for t in TIMES) + "\n"
    yield "milliseconds", "t (ms);Interval (ms)\n" + "\n".join(f"{t * 1e3:.3f};" for t in TIMES) + "\n"
    junk = "\n".join(",".join(r) for r in _rows(TIMES)) + '\n"Average",0.95\n,,\n"exported by phyphox"\n'
    yield "trailing-junk", ",".join(head) + "\n" + junk
    yield (
        "bom-blank-lines",
        "\ufeff" + ",".join(head) + "\n\n" + "\n\n".join(",".join(r) for r in _rows(TIMES)) + "\n",
    )


@pytest.mark.parametrize("label, text", list(_variants()), ids=[v[0] for v in _variants()])
def test_phyphox_variants_load_the_same_times(tmp_path, label, text):
    path = tmp_path / f"{label}.csv"
    path.write_text(text, encoding="utf-8", newline="")
    before = path.read_bytes()
    result = import_phyphox(path, ball="pingpong")
    np.testing.assert_allclose(result.dataset.t, TIMES, rtol=0, atol=1e-9)
    assert path.read_bytes() == before
    assert result.dataset.noise is None  # a fit estimates it
    if label == "trailing-junk":
        assert len(result.rejected) == 2 and all("junk after the data" in r.reason for r in result.rejected)
        assert [r.line for r in result.rejected] == [10, 12]


def test_phyphox_intervals_only_and_one_row_exports(tmp_path):
    intervals = np.diff(TIMES)
    (tmp_path / "iv.csv").write_text('"Interval (s)"\n\n' + "\n".join(f"{v:.6f}" for v in intervals) + "\n")
    got = import_phyphox(tmp_path / "iv.csv", ball="pingpong").dataset.t
    np.testing.assert_allclose(got, TIMES - TIMES[0], atol=1e-9)  # the clock offset is unknown
    (tmp_path / "iv2.csv").write_text('"Interval (s)"\n' + "\n".join(f"{v:.6f}" for v in intervals) + "\n")
    np.testing.assert_allclose(
        import_phyphox(tmp_path / "iv2.csv", ball="pingpong").dataset.t, TIMES - TIMES[0], atol=1e-9
    )
    # The app's one-row "Multiple" and "(In)elastic collision" exports.
    heads = ['"Start (s)"'] + [f'"Stop {k} (s)"' for k in range(1, 6)]
    (tmp_path / "stop.csv").write_text(
        ",".join(heads) + "\n" + ",".join(f"{t:.6f}" for t in TIMES[:6]) + "\n"
    )
    np.testing.assert_allclose(
        import_phyphox(tmp_path / "stop.csv", ball="pingpong").dataset.t, TIMES[:6], atol=1e-9
    )
    heads, cells = [], []
    for k in range(6):
        heads += [f'"Bounce {k} (s)"', f'"Height {k} (m)"']
        cells += [f"{TIMES[k]:.6f}" if k < 5 else "0", "0.2"]
    (tmp_path / "bounce.csv").write_text(";".join(heads) + "\n" + ";".join(cells) + "\n")
    result = import_phyphox(tmp_path / "bounce.csv", ball="pingpong")
    np.testing.assert_allclose(result.dataset.t, TIMES[:5], atol=1e-9)
    assert "not triggered" in result.rejected[0].reason  # the sixth bounce never came


def test_phyphox_xlsx(tmp_path):
    openpyxl = pytest.importorskip("openpyxl")
    book = openpyxl.Workbook()
    simple = book.active  # phyphox writes one sheet per export set; the fullest one is read
    simple.title = "Simple"
    simple.append(["Start (s)", "Stop (s)", "Difference (s)"])
    simple.append([float(TIMES[0]), float(TIMES[1]), float(TIMES[1] - TIMES[0])])
    sheet = book.create_sheet("Multiple")
    sheet.append(["Event time (s)", "Interval (s)"])
    for i, t in enumerate(TIMES):
        sheet.append([float(t), None if i == 0 else float(TIMES[i] - TIMES[i - 1])])
    book.save(tmp_path / "export.xlsx")
    result = import_phyphox(tmp_path / "export.xlsx", ball="pingpong")
    np.testing.assert_allclose(result.dataset.t, TIMES, atol=1e-12)
    assert result.info[0].startswith("xlsx") and len(result.dataset.t) == len(TIMES)


def test_phyphox_xlsx_without_openpyxl_says_so(tmp_path, monkeypatch):
    import builtins

    real = builtins.__import__

    def no_openpyxl(name, *args, **kwargs):
        if name == "openpyxl":
            raise ImportError(name)
        return real(name, *args, **kwargs)

    (tmp_path / "e.xlsx").write_bytes(b"PK\x03\x04" + bytes(100))
    monkeypatch.setattr(builtins, "__import__", no_openpyxl)
    with pytest.raises(ValueError, match=r"e\.xlsx: an \.xlsx workbook; reading it needs openpyxl"):
        import_phyphox(tmp_path / "e.xlsx", ball="pingpong")


def test_phyphox_duplicates_and_suspicious_rows(tmp_path):
    # A regular decay, then a missed bounce, an echo, and the echo's duplicate (0.000).
    t = list(TIMES) + [TIMES[-1] + 0.27 + 0.255, TIMES[-1] + 0.27 + 0.255 + 0.130]
    t.append(t[-1])
    t.insert(3, TIMES[2] - 0.001)  # a row before the previous one (negative interval)
    text = '"Event time (s)","Interval (s)"\n' + "\n".join(
        f"{v:.6f}," + ("" if i == 0 else f"{v - t[i - 1]:.6f}") for i, v in enumerate(t)
    )
    (tmp_path / "faulty.csv").write_text(text + "\n")
    result = import_phyphox(tmp_path / "faulty.csv", ball="pingpong")
    reasons = {r.line: r.reason for r in result.rejected}
    assert set(reasons) == {5, 12, 13}
    assert "negative interval" in reasons[5] and "duplicate" in reasons[13]
    assert reasons[12].startswith("after the last bounce of the chain")  # the trailing echo
    assert len(result.dataset.t) == len(TIMES) + 1
    warnings = " | ".join(result.warnings)
    assert "line 11:" in warnings and "missed bounce" in warnings
    summary = result.summary()
    assert "line 13" in summary and "duplicate" in summary and "missed bounce" in summary


def phyphox_truth():
    """{file: true onsets} from data/README.md."""
    out = {}
    for line in _readme().splitlines():
        m = re.fullmatch(r"- `(phyphox_drop_\w+\.csv)`: ([\d., ]+)", line.strip())
        if m:
            out[m.group(1)] = np.array([float(v) for v in m.group(2).split(", ")])
    return out


def test_bundled_phyphox_exports_against_truth():
    truth = phyphox_truth()
    assert sorted(truth) == sorted(f for f in os.listdir(DATA) if f.startswith("phyphox_drop_"))
    assert len(truth) <= 5
    for name, onsets in truth.items():
        x0 = int(re.search(r"(\d+)cm", name).group(1)) / 100
        result = import_phyphox(os.path.join(DATA, name), x0=x0, ball="pingpong")
        t = result.dataset.t
        # phyphox's own convention: the interval to the next event, 0 on the last row.
        assert any("to the NEXT event" in n for n in result.notes)
        if name == "phyphox_drop_12cm.csv":  # starts at bounce 2: the release height is not x0
            assert np.max(np.abs(t - onsets[1:])) < 0.1e-3 and result.rejected == ()
            (late,) = result.warnings
            assert late.startswith("late start: the export starts at bounce 2")
            assert 0.9 * 0.12 * 0.93**2 < result.dataset.x0 < 1.1 * 0.12 * 0.93**2
            continue
        if name == "phyphox_drop_22cm.csv":  # a stray onset (line 6) between bounces 4 and 5
            (r,) = result.rejected
            assert r.line == 6 and "stray onset" in r.reason and result.warnings == ()
            assert np.max(np.abs(t - onsets)) < 0.1e-3
            continue
        if name != "phyphox_drop_30cm.csv":
            assert result.rejected == () and result.warnings == ()
            assert np.max(np.abs(t - onsets)) < 0.1e-3  # ~1 audio sample of timing noise
            continue
        # Bounce 16 was missed; then an echo 0.130 s after bounce 17 and its duplicate. The
        # echo ends the sequence off the ball's chain: left out with its reason.
        assert len(t) == len(onsets) - 1
        np.testing.assert_array_less(np.abs(t[:15] - onsets[:15]), 0.1e-3)
        assert abs(t[15] - onsets[16]) < 0.1e-3
        reasons = {r.line: r.reason for r in result.rejected}
        assert set(reasons) == {18, 19} and "duplicate" in reasons[19]
        assert reasons[18].startswith("after the last bounce of the chain")
        assert any(w.startswith("line 17:") and "missed bounce" in w for w in result.warnings)


# -- video tracking ----------------------------------------------------------------------

TRACK_T = np.arange(8) / 30.0 + 0.4
TRACK_Y = 0.25 - 0.5 * 9.81 * (TRACK_T - 0.4) ** 2


def _track(header, heights, *, sep=",", dec=".", preamble=None, times=TRACK_T):
    lines = ([preamble] if preamble else []) + [sep.join(header)]
    for t, h in zip(times, heights, strict=True):
        lines.append(sep.join(f"{v:.6f}".replace(".", dec) for v in (t, h, 0.01)))
    return "\n".join(lines) + "\n"


@pytest.mark.parametrize(
    "label, header, scale_from_unit, kw",
    [
        ("cm", ("t (s)", "y (cm)", "x (cm)"), 100.0, {}),
        ("mm-brackets", ("t [s]", "y [mm]", "x [mm]"), 1000.0, {}),
        ("metres", ("t (s)", "y (m)", "x (m)"), 1.0, {}),
        ("tracker-preamble", ("t", "y (cm)", "x (cm)"), 100.0, dict(preamble="mass A")),
        ("semicolon-comma", ("t (s)", "y (cm)", "x (cm)"), 100.0, dict(sep=";", dec=",")),
        ("tab", ("time (s)", "y (cm)", "x (cm)"), 100.0, dict(sep="\t")),
    ],
)
def test_video_units_to_metres(tmp_path, label, header, scale_from_unit, kw):
    path = tmp_path / f"{label}.csv"
    path.write_text(_track(header, TRACK_Y * scale_from_unit, **kw))
    result = import_video(path, ball="pingpong")
    ds = result.dataset
    assert (ds.observe, ds.scene, ds.v0) == ("trace", "drop", 0.0)
    np.testing.assert_allclose(ds.t, TRACK_T - TRACK_T[0], atol=2e-6)  # t = 0 at the first frame
    np.testing.assert_allclose(ds.x, TRACK_Y, atol=1e-6 / scale_from_unit * 1.01)
    assert ds.x0 == ds.x[0]
    assert any("first tracked sample" in n for n in result.notes)


def test_video_column_and_scale(tmp_path):
    header = ("t (s)", "y (px)", "h (px)")
    path = tmp_path / "px.csv"
    path.write_text(_track(header, TRACK_Y * 1000.0))
    with pytest.raises(
        ValueError, match=r"px\.csv: line 1: column 'y \(px\)': unit 'px' is not a length unit"
    ):
        import_video(path, ball="pingpong")
    ds = import_video(path, scale=1e-3, ball="pingpong").dataset
    np.testing.assert_allclose(ds.x, TRACK_Y, atol=1e-8)
    ds = import_video(path, column="h", scale=2.0, ball="pingpong").dataset
    np.testing.assert_allclose(ds.x, 0.02, atol=1e-12)
    # No y column: the second column; no unit: --scale needed.
    (tmp_path / "z.csv").write_text(_track(("t (s)", "height", "other"), TRACK_Y * 100))
    with pytest.raises(ValueError, match=r"z\.csv: line 1: column 'height' has no unit.*--scale"):
        import_video(tmp_path / "z.csv", ball="pingpong")
    np.testing.assert_allclose(
        import_video(tmp_path / "z.csv", scale=0.01, ball="pingpong").dataset.x, TRACK_Y, atol=1e-8
    )
    with pytest.raises(
        ValueError, match=r"--column 'q' is not a column; columns: 't \(s\)', 'height', 'other'"
    ):
        import_video(tmp_path / "z.csv", column="q", scale=1, ball="pingpong")


def test_video_untracked_frames_reported(tmp_path):
    text = _track(("t (s)", "y (cm)", "x (cm)"), TRACK_Y * 100).splitlines()
    text[4] = f"{TRACK_T[3]:.6f},,0.01"  # Tracker leaves an untracked frame empty
    (tmp_path / "gap.csv").write_text("\n".join(text) + "\n")
    result = import_video(tmp_path / "gap.csv", ball="pingpong")
    (r,) = result.rejected
    assert r.line == 5 and "untracked frame" in r.reason and len(result.dataset.t) == 7


# -- bad files: one line, the file, the line, the cause -----------------------------------

BAD = [
    (
        "phyphox",
        "decimal-comma-comma-sep",
        '"Event time (s)","Interval (s)"\n1,483583,\n1,937875,0,454292\n',
        "line 2",
        "decimal commas in a comma-separated file",
    ),
    (
        "phyphox",
        "unit-in-cells",
        "Event time (s);Interval (s)\n1.48 s;\n1.93 s;0.45 s\n",
        "line 2",
        "units belong in the header",
    ),
    (
        "phyphox",
        "no-numbers",
        "Event time (s),Interval (s)\nfirst,second\n",
        "line 2",
        "no numeric data rows",
    ),
    ("phyphox", "empty", "\n\n", "line 1", "the file is empty"),
    ("phyphox", "no-header", "1.48,0\n1.93,0.45\n", "line 1", "no header row"),
    (
        "phyphox",
        "no-time-column",
        "Height (m),Energy\n0.2,1\n0.18,0.9\n",
        "line 1",
        "no event-time or interval column",
    ),
    (
        "phyphox",
        "mixed-decimals",
        "Event time (s);Interval (s)\n1,483583;\n1.937875;0,454292\n2,358625;0,420750\n",
        "line 3",
        "a decimal point in a file whose other numbers have decimal commas",
    ),
    (
        "phyphox",
        "bad-time-unit",
        "Event time (min),Interval (min)\n1.0,\n2.0,1.0\n",
        "line 1",
        "unit 'min' is not a time unit",
    ),
    ("video", "units-missing", "t,y\n0,10\n0.033,9.9\n0.066,9.6\n", "line 1", "has no unit"),
    (
        "video",
        "non-increasing",
        "t (s),y (cm)\n0,10\n0.033,9.9\n0.033,9.6\n",
        "line 4",
        "times must increase",
    ),
    ("video", "one-column", "t (s)|y (cm)\n0|10\n0.033|9.9\n", "line 2", "a separator other than comma"),
    ("video", "below-floor", "t (s),y (cm)\n0,-10\n0.033,-9.9\n0.066,-9.6\n", "line 2", "below the floor"),
    ("video", "binary", "\0\0\0RIFF", "line 1", "a binary file"),
]


@pytest.mark.parametrize("kind, label, text, line, cause", BAD, ids=[b[1] for b in BAD])
def test_bad_files_give_one_line_with_file_line_and_cause(tmp_path, kind, label, text, line, cause):
    path = tmp_path / f"{label}.csv"
    path.write_text(text, encoding="utf-8")
    before = path.read_bytes()
    with pytest.raises(ValueError) as err:
        (import_phyphox if kind == "phyphox" else import_video)(path, ball="pingpong")
    message = str(err.value)
    assert "\n" not in message and message.startswith(f"{path}: {line}:") and cause in message, message
    assert path.read_bytes() == before


# -- the command line ---------------------------------------------------------------------


def _run(args, capsys):
    code = main(args)
    out = capsys.readouterr()
    return code, out.out, out.err


def test_cli_import_bundled_files(tmp_path, capsys):
    wav = os.path.join(DATA, "phone_drop.wav")
    before = open(wav, "rb").read()
    out, png = tmp_path / "phone.csv", tmp_path / "phone.png"
    code, stdout, err = _run(
        ["import", "wav", wav, "--ball", "pingpong", "--out", str(out), "--plot", str(png), "--x0", "0.25"],
        capsys,
    )
    assert code == 0, err
    assert (
        "32 onsets" in stdout
        and "spurious click" in stdout
        and "missed bounce" in stdout
        and "noise" in stdout
    )
    assert f"wrote      {out}" in stdout
    ds = load_dataset(out)
    assert ds.x0 == 0.25 and ds.num_rows == 32
    assert png.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    assert open(wav, "rb").read() == before
    for name in ("phyphox_drop_15cm.csv", "phyphox_drop_30cm.csv"):
        out = tmp_path / name
        code, stdout, err = _run(
            [
                "import",
                "phyphox",
                os.path.join(DATA, name),
                "--out",
                str(out),
                "--noise",
                "5e-4",
                "--mass",
                "0.0028",
                "--drag",
                "0.12",
            ],
            capsys,
        )
        assert code == 0, err
        ds = load_dataset(out)
        assert (ds.observe, ds.noise, ds.mass, ds.drag) == ("impacts", 5e-4, 0.0028, 0.12)
        assert "x0 = " in out.read_text() and "with the interval ratios' e = " in out.read_text()
    (tmp_path / "track.csv").write_text(_track(("t", "y (cm)", "x (cm)"), TRACK_Y * 100, preamble="mass A"))
    code, stdout, err = _run(
        [
            "import",
            "video",
            str(tmp_path / "track.csv"),
            "--ball",
            "pingpong",
            "--out",
            str(tmp_path / "v.csv"),
        ],
        capsys,
    )
    assert code == 0, err
    np.testing.assert_allclose(load_dataset(tmp_path / "v.csv").x, TRACK_Y, atol=1e-8)


def test_cli_refuses_to_overwrite_the_source(tmp_path, capsys):
    for name, kind in (("phone_drop.wav", "wav"), ("phyphox_drop_30cm.csv", "phyphox")):
        src = tmp_path / name
        shutil.copyfile(os.path.join(DATA, name), src)
        before = src.read_bytes()
        link = tmp_path / "link"
        link.unlink(missing_ok=True)
        link.symlink_to(src)
        spellings = [str(src), os.path.join(str(tmp_path), ".", "sub", "..", name), str(link)]
        os.makedirs(tmp_path / "sub", exist_ok=True)
        for out in spellings:
            code, stdout, err = _run(["import", kind, str(src), "--ball", "pingpong", "--out", out], capsys)
            assert code == 2 and stdout == "", (out, stdout)
            assert err.count("\n") == 1 and "--out" in err and "refusing to overwrite" in err
        code, _, err = _run(
            [
                "import",
                kind,
                str(src),
                "--ball",
                "pingpong",
                "--out",
                str(tmp_path / "ok.csv"),
                "--plot",
                str(src),
            ],
            capsys,
        )
        assert code == 2 and "--plot" in err and "refusing to overwrite" in err
        assert src.read_bytes() == before


def test_cli_errors_and_help(tmp_path, capsys):
    bad = tmp_path / "bad.csv"
    bad.write_text('"Event time (s)","Interval (s)"\n1,483583,\n1,937875,0,454292\n')
    code, _, err = _run(
        ["import", "phyphox", str(bad), "--ball", "tennis", "--out", str(tmp_path / "o.csv")], capsys
    )
    assert code == 2 and err.count("\n") == 1 and "bad.csv: line 2:" in err and "decimal commas" in err
    assert not (tmp_path / "o.csv").exists()
    code, _, err = _run(
        ["import", "wav", str(bad), "--ball", "golf", "--out", str(tmp_path / "o.csv")], capsys
    )
    assert code == 2 and "not a WAV file" in err
    code, _, err = _run(["import", "wav", str(bad), "--out", str(tmp_path / "o.csv"), "--mass", "-1"], capsys)
    assert code == 2 and "mass = -1 kg is out of range" in err
    code, _, err = _run(["import", "phyphox", str(bad)], capsys)
    assert code == 2 and "--out" in err
    code, stdout, _ = _run(["import", "wav", "--help"], capsys)
    assert code == 0
    text = " ".join(stdout.split())
    assert "the e of the interval ratios" in text and "--ball NAME" in text and "pingpong, tennis" in text
    assert "--diameter M" in text and "C_d = 0.47" in text and "default 1.204" in text
    assert "--min-gap" in text and "default 0.03" in text
    code, stdout, _ = _run(["import", "video", "--help"], capsys)
    assert "--column" in stdout and "--scale" in stdout and "first frame" in " ".join(stdout.split())


def test_result_write_and_text(tmp_path):
    result = import_phyphox(os.path.join(DATA, "phyphox_drop_30cm.csv"), ball="pingpong")
    text = result.text()
    assert text.startswith("# jaxunilat-data: 1\n") and "## left out: line 19:" in text
    result.write(tmp_path / "a.csv")
    with pytest.raises(ValueError, match="the file exists"):
        result.write(tmp_path / "a.csv")
    assert load_dataset(tmp_path / "a.csv").num_rows == 16
    with pytest.raises(ValueError, match="refusing to overwrite"):
        result.write(os.path.join(DATA, "phyphox_drop_30cm.csv"), overwrite=True)
    # x0 from the first interval with the ratios' e (drag-free): within 6% of the true 0.30 m,
    # where the old assumed e = 0.95 gave 0.223 m.
    assert abs(result.dataset.x0 - 0.30) < 0.06 * 0.30
