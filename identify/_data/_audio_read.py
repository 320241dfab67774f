"""A recording's samples: WAV through `scipy.io.wavfile`, every other format through PyAV.

`read_audio(path)` is the one reader of every import: a `WavAudio` record (samples,
rate, channels, bits, encoding, container, start, `describe()`).

- WAV (RIFF, RF64, RIFX) in PCM (8-bit unsigned, 16, 24, 32, 64-bit) or IEEE float (32,
  64-bit), plain or WAVE_FORMAT_EXTENSIBLE: `scipy.io.wavfile` (imported on use: importing
  identify loads no scipy), memory-mapped where it can be. No PyAV needed.
- WAV in another encoding (μ-law and A-law, format tags 7 and 6; ADPCM, GSM, MP3 in WAV)
  and every other container (m4a/AAC, mp3, ogg (Vorbis, Opus), flac, 3gp, and the
  soundtrack of a video clip: mp4, mov, mkv/webm, avi, its first audio stream): decoded
  by PyAV (`pip install "jaxunilat[video]"`), whose bundled FFmpeg drops a codec's
  priming samples where the container states them (an MP4 edit list, the LAME header of
  an mp3, the Opus pre-skip), so the onsets keep the recording's clock. Without PyAV
  these are refused in one line naming the pip command and the equivalent
  `ffmpeg -i IN -ac 1 OUT.wav`.

Channels are mixed to mono by their mean (`mono=False` keeps them); 8–384 kHz. Only
regular files are read: a FIFO or a device is refused before it is opened
(`_source.regular_source`).

**Memory.** The samples are returned as float64: 8 bytes per frame (mono) or per sample
(`mono=False`), and at most `MAX_SAMPLES` (2^27) of them are read: 1.07 GB, 46.6 minutes
of 48 kHz mono. A longer recording is refused in one line before its samples are read
(from the WAV header's data size, or the container's duration; a decoded stream that
runs past the limit stops there). A WAV is converted from its memory-mapped file in
blocks of `BLOCK` frames, so reading peaks near that array plus the file's pages: a
16-bit mono WAV needs about 5× its size, an 8-bit one about 9× (20 minutes at 48 kHz,
16-bit, 115 MB: 0.46 GB of samples, 0.55 GB in all). Where scipy cannot map the file (a
24-bit WAV; an unfinished recording whose data size overstates the file) its bytes, and
for 24-bit an int32 copy of its samples, are held while it is read: about 4× a 24-bit
mono file. A decoded format is written frame by frame into one array sized from the
container's duration (grown by half where that is short): about the array itself,
whatever the (much smaller) compressed file's size (20 minutes of 48 kHz AAC: 0.44 GB in
all). An import's onset detection adds its envelope and about 2 bytes a sample
(`_import_audio.detect_onsets`): about 20 bytes a frame in all, 10× a 16-bit mono WAV.
"""

from __future__ import annotations

import dataclasses
import os
import shlex
import struct
import warnings

import numpy as np

from jaxunilat._internal import InputError

from ._source import regular_source

#: The sample rates read, Hz.
RATE_RANGE = (8000, 384000)
#: Frames converted at a time (the memory a conversion adds beyond its output).
BLOCK = 1 << 20
#: The most samples read (frames, or frames × channels with `mono=False`): 2^27 float64
#: values, 1.07 GB; 46.6 minutes of 48 kHz mono, 11.6 minutes at 192 kHz.
MAX_SAMPLES = 1 << 27
_PCM, _FLOAT, _EXTENSIBLE = 0x0001, 0x0003, 0xFFFE
#: WAVE format tags decoded by PyAV (scipy reads PCM and float only).
_WAVE_TAGS = {0x0002: "MS ADPCM", 0x0006: "A-law", 0x0007: "mu-law", 0x0011: "IMA ADPCM", 0x0031: "GSM"}
_WAVE_TAGS |= {0x0055: "MP3"}
_G711_TAGS = (0x0006, 0x0007)
_LOSSLESS = ("flac", "alac", "pcm_", "wavpack", "tta", "ape")
#: The sample-by-sample companding codecs (ITU-T G.711): lossy in level, exact in time.
_G711 = ("mu-law", "A-law")


@dataclasses.dataclass(frozen=True, eq=False)
class WavAudio:
    """A recording's samples, mixed down to mono (or its channels, `read_audio(mono=False)`).

    - `samples`: float64, full scale = 1 (PCM divided by 2^(bits−1), 8-bit PCM centred on
      128; float and decoded formats as they come); shape (frames,) or (frames, channels).
    - `rate`: samples per second, Hz.
    - `channels`: in the file (averaged into `samples` unless kept).
    - `bits`: bits per sample in the file (0 for a lossy codec, which has none).
    - `encoding`: `"pcm"`, `"float"`, `"mu-law"`, `"A-law"`, or the codec's name (`"aac"`,
      `"mp3"`, `"opus"`, `"vorbis"`, `"flac"`, ...).
    - `path`: the file. `container`: `"WAV"`, `"M4A/MP4"`, `"MP3"`, `"Ogg"`, `"FLAC"`, ...
    - `lossy`: whether the codec discards information (AAC, MP3, Opus, Vorbis, AMR; and
      μ-law and A-law, which keep every sample's time but not its level).
    - `bit_rate`: the stream's bit rate, bit/s (None where the container gives none).
    - `notes`: what the decoding changed (gaps in the time stamps filled with silence).
    - `start`: the first sample's time on the container's clock, s (its presentation
      time stamp: where a video's soundtrack starts against its picture; 0 for WAV).
    """

    samples: np.ndarray
    rate: float
    channels: int
    bits: int
    encoding: str
    path: str | None = None
    container: str = "WAV"
    lossy: bool = False
    bit_rate: float | None = None
    notes: tuple[str, ...] = ()
    start: float = 0.0

    @property
    def framed(self) -> bool:
        """Whether a lossy codec coded the sound in frames (AAC, MP3, Opus, ...): its
        quantisation noise spreads over a frame, so before a click (pre-echo)."""
        return self.lossy and self.encoding not in _G711 and not self.encoding.startswith("adpcm")

    @property
    def duration(self) -> float:
        """Length of the recording, s."""
        return len(self.samples) / self.rate

    def describe(self) -> str:
        """One line: container, rate, format, channels, duration (and how it was decoded)."""
        if self.encoding in ("pcm", "float"):
            kind = f"{self.bits}-bit {'PCM' if self.encoding == 'pcm' else 'float'}"
        elif self.encoding in _G711:
            kind = f"8-bit {self.encoding} (G.711)"
        else:
            rate = f" {self.bit_rate / 1e3:.0f} kb/s" if self.bit_rate else ""
            kind = f"{self.encoding}{rate}{' (lossy)' if self.lossy else ''}"
        chans = {1: "mono", 2: "stereo"}.get(self.channels, f"{self.channels} channels")
        if self.channels > 1 and self.samples.ndim == 1:
            chans += " mixed to mono"
        extra = "".join(f"; {n}" for n in self.notes)
        extra += "" if self.encoding in ("pcm", "float") else " (decoded by PyAV)"
        return f"{self.container}, {self.rate:g} Hz, {kind}, {chans}, {self.duration:.3f} s{extra}"


class NoAudioStream(InputError):
    """`read_audio` of a container that holds no audio stream (a video clip without a
    soundtrack): an `InputError` a caller can tell apart from an unreadable one."""


def read_audio(path, *, mono: bool = True) -> WavAudio:
    """A recording's samples as a `WavAudio`: float64 at full scale 1, mono (the channels'
    mean) or, with `mono=False`, (frames, channels); its rate, Hz; what was read (channels,
    bits, encoding, container, `describe()`). Formats, memory and the `MAX_SAMPLES` limit:
    the module's docstring; `path` may name a video clip (its soundtrack is read). A file
    that cannot be read raises a one-line `InputError` naming it; the file is only read."""
    name, _ = regular_source(path, "an audio file")
    try:
        with open(name, "rb") as f:
            head = f.read(12)
            wav = _wav_format(f, head, name) if _is_wave(head) else None
    except OSError as err:
        raise InputError(f"{name}: cannot be read ({err.strerror or err})") from None
    if wav is not None and wav[0] in (_PCM, _FLOAT, *_G711_TAGS):  # the header's frames are exact
        _check_length(name, wav[4], wav[1], wav[2], mono)
    if wav is not None and wav[0] in (_PCM, _FLOAT):
        return _scipy_wav(name, wav[:4], mono)
    if wav is not None:
        return _decode(name, "WAV", mono, _WAVE_TAGS.get(wav[0], f"format tag 0x{wav[0]:04x}"))
    return _decode(name, _container_kind(head), mono)


def _check_length(name: str, frames: int, channels: int, rate: float, mono: bool) -> None:
    """Refuse `frames` frames of `channels` at `rate` Hz beyond `MAX_SAMPLES` (one line)."""
    values = frames * (1 if mono else max(channels, 1))
    if values <= MAX_SAMPLES:
        return
    what = f" ({frames / rate / 60:.1f} min at {rate:g} Hz)" if rate > 0 else ""
    stem = os.path.splitext(name)[0]
    cut = f"ffmpeg -ss START -t 60 -i {shlex.quote(name)} -ac 1 {shlex.quote(stem + '-drop.wav')}"
    raise InputError(
        f"{name}: {frames:,} frames{what}, more than the {MAX_SAMPLES:,} samples a recording is read up to "
        f"({MAX_SAMPLES * 8 / 1e9:.2f} GB as float64, {MAX_SAMPLES / 48000 / 60:.1f} min at 48 kHz mono); cut "
        f"the drop out first: {cut}"
    )


def _is_wave(head: bytes) -> bool:
    return len(head) == 12 and head[:4] in (b"RIFF", b"RF64", b"RIFX") and head[8:12] == b"WAVE"


def _wav_format(f, head: bytes, name: str) -> tuple[int, int, int, int, int]:
    """(format tag, channels, rate, bits, frames) of a WAVE file's `fmt ` chunk (for
    WAVE_FORMAT_EXTENSIBLE, its sub-format's tag) and its `data` chunk (the frames it holds,
    at most what the file holds), `f` just after the 12-byte `head`: which reader gets the
    file, what its description says, whether it is too long. Only chunk headers up to
    `data` are read; the samples are scipy's or PyAV's."""
    order, fmt = (">" if head[:4] == b"RIFX" else "<"), None
    while True:
        chunk = f.read(8)
        if len(chunk) < 8:
            what = "'data'" if fmt is not None else "'fmt '"
            raise InputError(f"{name}: no {what} chunk; the WAV file is damaged or holds no samples")
        cid, size = chunk[:4], struct.unpack(order + "I", chunk[4:])[0]
        if cid == b"data":
            if fmt is None:
                raise InputError(f"{name}: no 'fmt ' chunk before the data; the WAV file is damaged")
            size = min(size, os.fstat(f.fileno()).st_size - f.tell())  # RF64's 0xFFFFFFFF, a short file
            block = fmt[1] * -(-fmt[3] // 8)
            return (*fmt, size // block if block > 0 else 0)
        skip = size + (size & 1)
        if cid == b"fmt ":
            body = f.read(min(size, 26))
            if len(body) < 16:
                raise InputError(
                    f"{name}: the 'fmt ' chunk has {len(body)} bytes, expected at least 16; damaged"
                )
            tag, channels, rate, _, _, bits = struct.unpack(order + "HHIIHH", body[:16])
            if tag == _EXTENSIBLE and len(body) == 26:
                tag = struct.unpack(order + "H", body[24:26])[0]
            fmt, skip = (tag, channels, rate, bits), skip - len(body)
        f.seek(skip, os.SEEK_CUR)


def _check_shape(name: str, rate: float, channels: int, frames: int) -> None:
    if not RATE_RANGE[0] <= rate <= RATE_RANGE[1]:
        raise InputError(
            f"{name}: sample rate = {rate:.10g} Hz is out of range; valid range is [{RATE_RANGE[0]}, {RATE_RANGE[1]}] Hz"
        )
    if channels < 1:
        raise InputError(f"{name}: {channels} channels; the file is damaged")
    if frames == 0:
        raise InputError(f"{name}: the recording holds no samples")


_VALID = "valid: PCM 8 to 64-bit or float 32 or 64-bit (other encodings are decoded by PyAV)"


def _scipy_wav(name: str, fmt: tuple[int, int, int, int], mono: bool) -> WavAudio:
    """A PCM or float WAV by `scipy.io.wavfile`: memory-mapped where scipy can (not a
    3-byte container, nor a data size past the end of an unfinished recording, which is
    read up to its last whole frame), converted `BLOCK` frames at a time."""
    from scipy.io import wavfile

    tag, channels, rate, bits = fmt
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", wavfile.WavFileWarning)  # unknown chunks, a short file
        try:
            try:
                data = wavfile.read(name, mmap=True)[1]
            except ValueError:
                data = wavfile.read(name, mmap=False)[1]
        except ValueError as err:
            raise InputError(f"{name}: unsupported or damaged WAV ({err}); {_VALID}") from None
    _check_shape(name, rate, channels, data.shape[0])
    samples = _to_float(data, mono, name)
    return WavAudio(samples, float(rate), channels, bits, "pcm" if tag == _PCM else "float", name)


def _to_float(data: np.ndarray, mono: bool, name: str) -> np.ndarray:
    """scipy's samples as float64 at full scale 1 (integers over 2^(bits−1) of their
    container, 8-bit centred on 128), the channels averaged if `mono`; `BLOCK` frames at a
    time, so only the output and one block are held beyond the (mapped) file."""
    multi = data.ndim == 2
    out = np.empty(data.shape[:1] if mono or not multi else data.shape, dtype=np.float64)
    kind, size = data.dtype.kind, data.dtype.itemsize
    for a in range(0, len(data), BLOCK):
        x = data[a : a + BLOCK].astype(np.float64)
        if kind == "u":  # 8-bit PCM is unsigned, 128 its zero
            x -= 128.0
            x /= 128.0
        elif kind == "i":
            x /= float(1 << (8 * size - 1))  # a 24-bit sample comes shifted into an int32
        elif not np.all(np.isfinite(x)):
            i = a + int(np.flatnonzero(~np.isfinite(x).reshape(len(x), -1).all(axis=1))[0])
            raise InputError(f"{name}: sample {i} is not finite (NaN or inf); damaged float WAV")
        out[a : a + BLOCK] = x.mean(axis=1) if multi and mono else x
    return out


# -- everything else: PyAV -----------------------------------------------------------------

_PIP = 'pip install "jaxunilat[video]"'
#: The least bit rate assumed when the array is sized from a duration, bit/s (a longer stream grows it).
_LEAST_BIT_RATE = 16000
_VALID_CODECS = "valid: WAV, m4a/AAC, mp3, ogg (Vorbis, Opus), flac, 3gp and the other formats FFmpeg decodes"
#: Names for the decoders whose FFmpeg name says little.
_CODEC_NAMES = {
    "mp3float": "mp3",
    "pcm_mulaw": "mu-law",
    "pcm_alaw": "A-law",
    "amrnb": "AMR-NB",
    "amrwb": "AMR-WB",
}


def _container_kind(head: bytes) -> str | None:
    """What a non-WAV file looks like from its first 12 bytes (None: unknown), for messages."""
    if head[4:8] == b"ftyp":
        return "3GP" if head[8:11] == b"3gp" else "MOV" if head[8:12] == b"qt  " else "M4A/MP4"
    if head[:3] == b"ID3" or (len(head) > 1 and head[0] == 0xFF and head[1] & 0xE0 == 0xE0):
        return "AAC (ADTS)" if len(head) > 1 and head[1] & 0xF6 == 0xF0 else "MP3"
    kinds = {b"fLaC": "FLAC", b"OggS": "Ogg", b"#!AM": "AMR", b"caff": "CAF", b"FORM": "AIFF"}
    return kinds.get(head[:4], "WebM/Matroska" if head[:4] == b"\x1a\x45\xdf\xa3" else None)


def _convert_hint(name: str) -> str:
    stem = os.path.splitext(name)[0]
    out = stem + ("-pcm.wav" if name.lower().endswith(".wav") else ".wav")
    return f"ffmpeg -i {shlex.quote(name)} -ac 1 {shlex.quote(out)}"


def _require_av(name: str, kind: str | None, encoding: str | None):
    """The `av` module, or one line saying how to install it or convert the file to WAV."""
    from ._video_decode import require_av

    try:
        return require_av()
    except InputError:
        if kind is None:
            what = "not a WAV file (no RIFF/WAVE header); other formats (m4a, mp3, ogg, opus, flac, 3gp) need"
        else:
            what = f"{encoding} WAV needs" if encoding else f"{kind} audio needs"
        raise InputError(
            f"{name}: {what} PyAV to decode: {_PIP}; or convert it to WAV: {_convert_hint(name)}"
        ) from None


def _undecodable(name: str, kind: str | None, err) -> str:
    cause = getattr(err, "strerror", None) or str(err)
    if kind is None:
        return f"{name}: not a WAV file (no RIFF/WAVE header), nor audio that PyAV can decode ({cause})"
    return f"{name}: PyAV cannot decode it as {kind} ({cause}); a damaged file, or a recording not finished?"


def _decode(name: str, kind: str | None, mono: bool, encoding: str | None = None) -> WavAudio:
    """Any format FFmpeg reads, by PyAV: its first audio stream (`_Decoded`)."""
    av = _require_av(name, kind, encoding)
    try:
        container = av.open(name, metadata_errors="ignore")
    except av.error.FFmpegError as err:
        raise InputError(_undecodable(name, kind, err)) from None
    with container:
        kind = kind or container.format.long_name
        if not container.streams.audio:
            raise NoAudioStream(f"{name}: the {kind} file holds no audio stream")
        stream = container.streams.audio[0]
        if stream.codec_context is None:  # FFmpeg knows no decoder for it
            what = f"{encoding} WAV" if encoding else f"{kind} audio"
            raise InputError(f"{name}: PyAV has no decoder for this {what}; {_VALID_CODECS}")
        try:
            got = _Decoded(av, container, stream, mono, name)
        except av.error.FFmpegError as err:
            raise InputError(_undecodable(name, kind, err)) from None
        codec = stream.codec_context
    if got.rate is None:
        raise InputError(f"{name}: the {kind} file holds no audio samples")
    samples = got.samples()
    _check_shape(name, got.rate, got.channels, len(samples))
    lossy = bool(getattr(codec.codec, "lossy", not codec.name.startswith(_LOSSLESS)))
    return WavAudio(
        samples, float(got.rate), got.channels, 8 if codec.name in ("pcm_mulaw", "pcm_alaw") else 0,
        _CODEC_NAMES.get(codec.name, codec.name), name, container=kind, lossy=lossy,
        bit_rate=float(codec.bit_rate) if codec.bit_rate else None, notes=got.notes(),
        start=float(got.first) if got.first is not None else 0.0,
    )  # fmt: skip


class _Decoded:
    """The samples of one stream, frame by frame into one float64 array (sized from the
    container's duration, grown by half where that is short). Frames are placed by their
    time stamps relative to the first: a damaged packet that is skipped, or a gap in the
    stamps, becomes silence and the clock after it is kept."""

    def __init__(self, av, container, stream, mono, name):
        self.rate = self.channels = self.first = None
        self.mono, self.name, self.n, self.buf = mono, name, 0, None
        self.gaps, self.damaged = [], 0
        rate = stream.codec_context.sample_rate or 0
        seconds = float(stream.duration * stream.time_base) if stream.duration and stream.time_base else 0.0
        seconds = seconds or (container.duration or 0) / 1e6
        seconds = min(seconds, os.path.getsize(name) * 8 / _LEAST_BIT_RATE)  # a damaged header's duration
        channels = 1 if mono else getattr(stream.codec_context, "channels", 0) or 1
        _check_length(name, int(seconds * rate), channels, rate, mono)
        self.expected = min(int(seconds * 1.02 * rate) + rate, MAX_SAMPLES // channels)
        for packet in container.demux(stream):
            try:
                frames = packet.decode()
            except av.error.InvalidDataError:
                self.damaged += 1
                continue
            for frame in frames:
                self.add(frame)

    def add(self, frame) -> None:
        x = _frame_samples(frame)
        if self.rate is None:
            self.rate, self.channels = frame.sample_rate, x.shape[1]
            _check_shape(self.name, self.rate, self.channels, len(x) or 1)  # before decoding the rest
            self.first = frame.pts * frame.time_base if frame.pts is not None else None
        elif frame.sample_rate != self.rate:
            raise InputError(
                f"{self.name}: the sample rate changes from {self.rate} to {frame.sample_rate} Hz"
            )
        elif x.shape[1] != self.channels and not self.mono:
            raise InputError(f"{self.name}: the channels change from {self.channels} to {x.shape[1]}")
        if frame.pts is not None and self.first is not None:
            gap = round((frame.pts * frame.time_base - self.first) * self.rate) - self.n
            if gap > 1:
                self.gaps.append(gap)
                self.put(np.zeros((gap, x.shape[1])))
        self.put(x)

    def put(self, x: np.ndarray) -> None:
        x = x.mean(axis=1) if self.mono else x
        end = self.n + len(x)
        if end * (1 if self.mono else self.channels) > MAX_SAMPLES:  # longer than its duration said
            _check_length(self.name, end, self.channels, self.rate, self.mono)
        if self.buf is None or end > len(self.buf):
            most = MAX_SAMPLES // (1 if self.mono else self.channels)
            grown = np.empty(
                (max(end, min(max(self.expected, int(1.5 * self.n) + BLOCK), most)), *x.shape[1:])
            )
            if self.buf is not None:
                grown[: self.n] = self.buf[: self.n]
            self.buf = grown
        self.buf[self.n : end] = x
        self.n = end

    def samples(self) -> np.ndarray:
        out = self.buf[: self.n]
        return out.copy() if self.n < 0.9 * len(self.buf) else out

    def notes(self) -> tuple[str, ...]:
        out = []
        if self.gaps:
            ms = 1e3 * sum(self.gaps) / self.rate
            out.append(f"{len(self.gaps)} gap(s) in the time stamps ({ms:.1f} ms) filled with silence")
        if self.damaged:
            out.append(f"{self.damaged} damaged packet(s) skipped")
        return tuple(out)


def _frame_samples(frame) -> np.ndarray:
    """A decoded frame as (samples, channels) float64 at full scale 1."""
    a = frame.to_ndarray()
    channels = len(frame.layout.channels)
    a = a.T if frame.format.is_planar else a.reshape(-1, channels)
    base = frame.format.name.rstrip("p")
    if base == "u8":
        return (a.astype(np.float64) - 128.0) / 128.0
    if base in ("s16", "s32", "s64"):
        return a.astype(np.float64) / float(1 << (int(base[1:]) - 1))
    return a.astype(np.float64)
