"""`jaxunilat import wav` (alias `import audio`) reads the formats phones record in.

The compressed versions of data/phone_drop.wav (m4a/AAC, mp3, ogg/Vorbis, opus, flac, 3gp)
are encoded here by PyAV, the decoder the importer uses (a codec its FFmpeg lacks is skipped,
saying so); the WAV variants are written here: 8-bit, 24-bit at 192 kHz, float32 in RF64 and 4
channels with numpy/scipy and a RIFF writer in this file, μ-law and A-law by PyAV. Each must
give the WAV's onsets within one sample period of 48 kHz (20.8 µs) with no constant shift:
FFmpeg drops a codec's priming samples where the container states them (the MP4 edit list,
the mp3's LAME header, the Opus pre-skip), so no onset moves. AMR-NB (8 kHz speech codec)
keeps every bounce but not their sub-millisecond timing. Non-regular files are refused in one
line; without PyAV a compressed file is refused in one line naming the pip and ffmpeg
commands, and PCM WAV still reads (scipy).
"""

import fractions
import os
import struct
import sys

import numpy as np
import pytest
from helpers import fifo_errors
from jaxunilat.identify import import_wav, read_wav

from jaxunilat._cli._main import main

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
WAV = os.path.join(ROOT, "data", "phone_drop.wav")
RATE = 48000
SAMPLE = 1.0 / RATE  # one sample period of the original: the onsets' agreement
LOSSY = "the recording is lossy"


@pytest.fixture(scope="module")
def reference():
    """The WAV's samples (int16) and its imported onsets, s."""
    from scipy.io import wavfile

    rate, x = wavfile.read(WAV)
    assert rate == RATE and x.dtype == np.int16
    return x, import_wav(WAV, ball="pingpong").accepted


def _agree(onsets, ref, tol=SAMPLE):
    """The same bounces, each onset within `tol` s of the WAV's (no shift allowed)."""
    assert len(onsets) == len(ref), (len(onsets), len(ref))
    d = np.asarray(onsets) - ref
    assert np.max(np.abs(d)) <= tol, (
        f"max |dt| = {np.max(np.abs(d)) * 1e6:.2f} us (median {np.median(d) * 1e6:.2f})"
    )


# -- compressed formats, encoded by PyAV ------------------------------------------------------


def encode(path, x, rate, fmt, codec, *, bit_rate=None, layout="mono", options=None):
    """Encode int16 samples `x` with PyAV into `path` (container `fmt`, encoder `codec`)."""
    av = pytest.importorskip("av")
    try:
        av.codec.Codec(codec, "w")
    except Exception:
        pytest.skip(f"the FFmpeg bundled with PyAV {av.__version__} has no {codec} encoder")
    planes = 2 if layout == "stereo" else 1
    with av.open(str(path), "w", format=fmt) as out:
        stream = out.add_stream(codec, rate=rate, options=options or {})
        stream.layout = layout
        if bit_rate:
            stream.bit_rate = bit_rate
        for i in range(0, len(x), 4800):
            block = np.repeat(x[None, i : i + 4800], planes, axis=0)
            frame = av.AudioFrame.from_ndarray(np.ascontiguousarray(block), format="s16p", layout=layout)
            frame.sample_rate, frame.pts, frame.time_base = RATE, i, fractions.Fraction(1, RATE)
            for packet in stream.encode(frame):
                out.mux(packet)
        for packet in stream.encode(None):
            out.mux(packet)
    return path


CODECS = [
    # label, extension, container, encoder, bit rate, layout (FFmpeg's own Vorbis encoder is stereo only)
    ("m4a-aac", "m4a", "mp4", "aac", 192_000, "mono"),
    ("mp3", "mp3", "mp3", "libmp3lame", 192_000, "mono"),
    ("ogg-vorbis", "ogg", "ogg", "vorbis", None, "stereo"),
    ("opus", "opus", "opus", "libopus", 96_000, "mono"),
    ("flac", "flac", "flac", "flac", None, "mono"),
    ("3gp-aac", "3gp", "3gp", "aac", 192_000, "mono"),
]


@pytest.mark.parametrize("label, ext, fmt, codec, bit_rate, layout", CODECS, ids=[c[0] for c in CODECS])
def test_compressed_formats_give_the_wavs_onsets(
    tmp_path, reference, label, ext, fmt, codec, bit_rate, layout
):
    x, ref = reference
    options = {"strict": "experimental"} if codec == "vorbis" else None
    path = encode(
        tmp_path / f"drop.{ext}", x, RATE, fmt, codec, bit_rate=bit_rate, layout=layout, options=options
    )
    result = import_wav(path, ball="pingpong")
    _agree(result.accepted, ref)
    assert "decoded by PyAV" in result.info[0] and f"{RATE} Hz" in result.info[0], result.info[0]
    assert (LOSSY in " ".join(result.notes)) == (codec != "flac")  # a lossy codec is said to be


def test_amr_nb_3gp_keeps_the_bounces_not_their_timing(tmp_path, reference):
    """AMR-NB (8 kHz, 12.2 kb/s: old phones' 3gp) codes speech below 3.4 kHz: the clicks
    (3.3 and 5.2 kHz) come out smeared, the onsets a millisecond or two off."""
    x, ref = reference
    path = encode(tmp_path / "drop.3gp", x, 8000, "3gp", "libopencore_amrnb", bit_rate=12_200)
    audio = read_wav(path)
    assert audio.rate == 8000 and audio.encoding == "AMR-NB" and audio.lossy
    result = import_wav(path, ball="pingpong", force=True)
    assert abs(len(result.accepted) - len(ref)) <= 2
    nearest = ref[np.argmin(np.abs(ref[None, :] - result.accepted[:, None]), axis=1)]
    assert np.median(np.abs(result.accepted - nearest)) < 3e-3


def test_import_audio_is_import_wav(tmp_path, reference, capsys):
    x, _ = reference
    path = encode(tmp_path / "drop.m4a", x, RATE, "mp4", "aac", bit_rate=192_000)
    texts = []
    for kind in ("audio", "wav"):
        out = tmp_path / f"{kind}.csv"
        assert main(["import", kind, str(path), "--ball", "pingpong", "--out", str(out)]) == 0
        texts.append(out.read_text())
    assert texts[0] == texts[1] and "import wav from drop.m4a" in texts[0]
    assert "M4A/MP4, 48000 Hz, aac" in capsys.readouterr().out


# -- WAV variants -----------------------------------------------------------------------------

_GUID_TAIL = b"\x00\x00\x00\x00\x10\x00\x80\x00\x00\xaa\x00\x38\x9b\x71"


def write_riff(path, payload: bytes, rate, *, channels=1, bits=16, tag=1, extensible=False, rf64=False):
    """A WAVE file written for these tests: plain or WAVE_FORMAT_EXTENSIBLE `fmt `, RIFF or RF64."""
    align = channels * bits // 8
    fmt = struct.pack("<HHIIHH", 0xFFFE if extensible else tag, channels, rate, rate * align, align, bits)
    if extensible:
        fmt += struct.pack("<HHIH", 22, bits, (1 << channels) - 1, tag) + _GUID_TAIL
    pad = b"\0" if len(payload) % 2 else b""
    chunks = b"fmt " + struct.pack("<I", len(fmt)) + fmt + b"LIST" + struct.pack("<I", 4) + b"INFO"
    if rf64:
        size = 4 + 36 + len(chunks) + 8 + len(payload) + len(pad)
        ds64 = struct.pack("<QQQI", size, len(payload), len(payload) // align, 0)
        head = (
            b"RF64" + struct.pack("<I", 0xFFFFFFFF) + b"WAVE" + b"ds64" + struct.pack("<I", len(ds64)) + ds64
        )
        data = b"data" + struct.pack("<I", 0xFFFFFFFF)
    else:
        head = b"RIFF" + struct.pack("<I", 4 + len(chunks) + 8 + len(payload) + len(pad)) + b"WAVE"
        data = b"data" + struct.pack("<I", len(payload))
    with open(path, "wb") as f:
        f.write(head + chunks + data + payload + pad)
    return path


def _pcm8(path, x):
    """8-bit unsigned, as FFmpeg converts 16 bits to 8 ((x >> 8) + 128)."""
    from scipy.io import wavfile

    wavfile.write(path, RATE, ((x.astype(np.int32) >> 8) + 128).astype(np.uint8))
    return path


def _pcm24_192k(path, x):
    """Resampled to 192 kHz (scipy's polyphase filter), 24-bit."""
    from scipy.signal import resample_poly

    y = np.clip(np.round(resample_poly(x / 32768.0, 4, 1) * 2**23), -(2**23), 2**23 - 1).astype("<i4")
    return write_riff(path, y.view(np.uint8).reshape(-1, 4)[:, :3].tobytes(), 192000, bits=24)


def _float32_rf64(path, x):
    """IEEE float 32-bit in an RF64 file (long recordings from field recorders)."""
    return write_riff(path, (x / 32768.0).astype("<f4").tobytes(), RATE, bits=32, tag=3, rf64=True)


def _four_channels(path, x):
    """4 channels, 16-bit, WAVE_FORMAT_EXTENSIBLE: two at full level, two at half."""
    y = np.stack([x, x, x // 2, x // 2], axis=1).astype("<i2")
    return write_riff(path, y.tobytes(), RATE, channels=4, extensible=True)


def _g711(codec):
    def write(path, x):
        return encode(path, x, RATE, "wav", codec)

    write.__doc__ = f"{codec} (G.711) by PyAV"
    return write


VARIANTS = [
    # label, writer, (rate, channels, bits, encoding)
    ("pcm8", _pcm8, (RATE, 1, 8, "pcm")),
    ("pcm24-192k", _pcm24_192k, (192000, 1, 24, "pcm")),
    ("float32-rf64", _float32_rf64, (RATE, 1, 32, "float")),
    ("pcm16-4-channels", _four_channels, (RATE, 4, 16, "pcm")),
    ("mu-law", _g711("pcm_mulaw"), (RATE, 1, 8, "mu-law")),
    ("a-law", _g711("pcm_alaw"), (RATE, 1, 8, "A-law")),
]


@pytest.mark.parametrize("label, writer, expect", VARIANTS, ids=[v[0] for v in VARIANTS])
def test_wav_variants_give_the_wavs_onsets(tmp_path, reference, label, writer, expect):
    x, ref = reference
    path = writer(tmp_path / f"{label}.wav", x)
    audio = read_wav(path)
    assert (audio.rate, audio.channels, audio.bits, audio.encoding) == expect
    assert audio.samples.ndim == 1 and audio.samples.dtype == np.float64
    result = import_wav(path, ball="pingpong")
    _agree(result.accepted, ref)
    assert LOSSY not in " ".join(result.notes)  # G.711 keeps every sample's time


def test_read_audio_keeps_the_channels_when_asked(tmp_path, reference):
    from jaxunilat.identify._data._audio_read import read_audio

    x, _ = reference
    path = _four_channels(tmp_path / "four.wav", x)
    audio = read_audio(path, mono=False)
    assert audio.samples.shape == (len(x), 4) and audio.rate == RATE and "4 channels" in audio.describe()
    np.testing.assert_array_equal(audio.samples[:, 0], x / 32768.0)
    mono = read_audio(path)
    np.testing.assert_allclose(mono.samples, audio.samples.mean(axis=1), rtol=0, atol=0)
    assert "4 channels mixed to mono" in mono.describe() and mono.start == 0.0
    with pytest.raises(TypeError):  # a record, read by its attributes: no tuple to unpack
        tuple(mono)


# -- what cannot be read ------------------------------------------------------------------------


def test_a_fifo_or_a_device_is_refused_without_waiting(tmp_path, capsys):
    fifo = tmp_path / "pipe.wav"
    os.mkfifo(fifo)
    errors = fifo_errors(read_wav, fifo)
    assert len(errors) == 1 and "is a FIFO" in errors[0] and "\n" not in errors[0], errors
    code = main(["import", "audio", str(fifo), "--ball", "pingpong", "--out", str(tmp_path / "o.csv")])
    err = capsys.readouterr().err
    assert code == 2 and err.count("\n") == 1 and "is a FIFO" in err, err
    if os.path.exists("/dev/zero"):
        with pytest.raises(ValueError, match="is a character device") as info:
            read_wav("/dev/zero")
        assert "\n" not in str(info.value)


def test_without_pyav_compressed_is_refused_in_one_line_and_pcm_reads(
    tmp_path, reference, monkeypatch, capsys
):
    x, ref = reference
    m4a = tmp_path / "memo.m4a"
    m4a.write_bytes(struct.pack(">I", 24) + b"ftypM4A " + bytes(12))  # no PyAV needed to make it
    mulaw = tmp_path / "mulaw.wav"
    write_riff(mulaw, bytes(200), 8000, bits=8, tag=7)
    plain = [_pcm8(tmp_path / "pcm8.wav", x), _float32_rf64(tmp_path / "f32.wav", x)]
    monkeypatch.setitem(sys.modules, "av", None)  # `import av` fails: PyAV is not installed
    for path, what in ((m4a, "M4A/MP4 audio"), (mulaw, "mu-law WAV")):
        code = main(["import", "audio", str(path), "--ball", "pingpong", "--out", str(tmp_path / "o.csv")])
        err = capsys.readouterr().err
        assert code == 2 and err.count("\n") == 1 and f"{what} needs PyAV" in err, err
        assert 'pip install "jaxunilat[video]"' in err and f"ffmpeg -i {path} -ac 1 " in err, err
    assert not (tmp_path / "o.csv").exists()
    _agree(import_wav(WAV, ball="pingpong").accepted, ref, tol=0.0)
    for path in plain:  # scipy reads every PCM and float WAV
        _agree(import_wav(path, ball="pingpong").accepted, ref)
