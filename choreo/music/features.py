"""What beat finding hears in a song, computed while it is decoded, so that memory stays bounded.

An hour of audio is 318 MB of float32 samples at 22050 Hz; what the beat, tempo and bar finders
need from it is a hundredth of that: a log-frequency spectrogram (onsets by band: the kick, the
snare, the hats), chroma (which chords sound: chords change on bar lines), and a fine attack
envelope (where a sound starts, to the millisecond). So the song is streamed from its file in
blocks, each block reduced to those features, and the samples are never held whole: about
100 MB an hour of audio, whatever the file's format or sample rate.

The decoder is miniaudio (wav, mp3, flac, ogg, any sample rate, mixed down to mono), reading from
a file choreo opened and checked itself (a regular file, not a pipe or a device).
"""

from __future__ import annotations

import io
import math
import os
from collections.abc import Generator, Iterable, Iterator
from dataclasses import dataclass

import miniaudio
import numpy as np

from choreo.errors import UsageError
from choreo.show.model import MUSIC_FORMATS_TEXT
from choreo.textfit import visible
from choreo.userfile import open_input, reading

SAMPLE_RATE = 22050  # Hz: enough for onsets and chords, half the work of 44.1 kHz
MAX_SONG_S = 3 * 3600.0  # longer audio is refused: the features of 3 hours take about 300 MB
MAX_SONG_BYTES = 4 * 1024 ** 3  # a file past this is refused before it is decoded
FRAME = 1024  # spectrogram window, samples (46 ms)
HOP = 256  # spectrogram step, samples (11.6 ms): `Features.fps` frames a second
CHROMA_FRAME = 4096  # chroma window (186 ms): 5.4 Hz bins tell the semitones of a bass apart
CHROMA_EVERY = 4  # chroma is computed every this many spectrogram frames (21.5 a second)
ATTACK_HOP = 32  # the attack envelope's step, samples (1.45 ms)
ATTACK_WINDOW = 8  # its trailing energy window, in steps (256 samples, 11.6 ms)
BANDS_PER_OCTAVE = 6
LOWEST_HZ = 30.0
LOG_GAIN = 1000.0  # log(1 + gain * magnitude / full scale): a quiet hi-hat counts beside a kick
CHROMA_HZ = (110.0, 2000.0)  # pads and chords
BASS_CHROMA_HZ = (30.0, 220.0)  # bass notes
_READ_FRAMES = 65536  # samples decoded at a time
# Spectrogram frames transformed at once: temporaries small enough for the allocator to reuse
# (512 at once made 3.5 million page faults an hour of audio: 7 s of system time).
_BLOCK_FRAMES = 16


@dataclass(frozen=True)
class Features:
    """A song as the beat finders see it. Frame j of `bands` is centred on sample j * `hop`;
    chroma frame i on sample i * `hop` * `chroma_every`; attack step m ends at sample
    m * `attack_hop` (its value is how much the energy rose in that step)."""

    path: str
    duration_s: float
    sample_rate: int
    hop: int
    bands: np.ndarray  # (frames, len(band_hz)) float32: log(1 + LOG_GAIN * mean magnitude in the band)
    band_hz: np.ndarray  # (len, 2): each band's lower and upper edge, Hz
    chroma: np.ndarray  # (chroma frames, 12) float32: magnitude by pitch class (C = 0), CHROMA_HZ
    bass_chroma: np.ndarray  # (chroma frames, 12) float32: the same in BASS_CHROMA_HZ
    chroma_every: int
    attack: np.ndarray  # (steps,) float32: the rise of log energy of the signal's first difference
    attack_hop: int
    peak: float  # the largest sample's magnitude (0: silence)

    @property
    def fps(self) -> float:
        """Spectrogram frames a second."""
        return self.sample_rate / self.hop

    @property
    def chroma_fps(self) -> float:
        return self.sample_rate / (self.hop * self.chroma_every)

    def band_range(self, low_hz: float, high_hz: float) -> np.ndarray:
        """Indices of the bands whose centre lies in low_hz..high_hz."""
        centres = np.sqrt(self.band_hz[:, 0] * self.band_hz[:, 1])
        return np.flatnonzero((centres >= low_hz) & (centres < high_hz))


def read_features(path: str | os.PathLike[str], sample_rate: int = SAMPLE_RATE) -> Features:
    """The features of the song in the file at `path`, decoded in blocks; an unreadable file is
    one line that says what to do (`UsageError`, exit 2)."""
    name = os.fspath(path)
    return features_of(song_blocks(name, sample_rate), sample_rate, name)


def song_blocks(path: str | os.PathLike[str], sample_rate: int = SAMPLE_RATE,
                channels: int = 1) -> Generator[np.ndarray, None, None]:
    """The song in the file at `path` as float32 blocks (`channels` interleaved) at `sample_rate`,
    decoded as they are read (a second pass, such as `choreo beats --click`, reads it this way too)."""
    name = os.fspath(path)
    with open_input(name, "sound file", MAX_SONG_BYTES) as stream, reading(name, "sound file"):
        if not stream.peek(1):  # read, not stat: /proc files say 0 bytes, and a read may fail (EIO)
            raise UsageError(f"{visible(name)}: the file is empty")
        yield from _decoded(stream, name, sample_rate, channels)


def features_of(blocks: Iterable[np.ndarray], sample_rate: int = SAMPLE_RATE, path: str = "") -> Features:
    """The features of mono float samples that arrive in blocks (any lengths)."""
    extractor = _Extractor(sample_rate, path)
    for block in blocks:
        extractor.add(np.asarray(block, dtype=np.float32))
    return extractor.finish()


class _Source(miniaudio.StreamableSource):
    """A file choreo opened and checked, as miniaudio reads it. miniaudio calls `read` and `seek`
    from C: it takes any exception there for a damaged file (a disk error, Ctrl-C said as 'cannot
    decode'), cffi prints a KeyboardInterrupt and carries on, and a failed read at a block's edge
    looks like the end of the song. So a failure is kept, the file ends there, and `failed` raises
    it once miniaudio has returned."""

    def __init__(self, stream: io.BufferedReader) -> None:
        self.stream = stream
        self.failure: BaseException | None = None

    def read(self, num_bytes: int) -> bytes:
        if self.failure is None:
            try:
                return self.stream.read(num_bytes)
            except BaseException as exc:  # noqa: BLE001 kept and raised by `failed`, outside C
                self.failure = exc
        return b""

    def seek(self, offset: int, origin: miniaudio.SeekOrigin) -> bool:
        if self.failure is None:
            try:
                self.stream.seek(offset, os.SEEK_CUR if origin == miniaudio.SeekOrigin.CURRENT else os.SEEK_SET)
                return True
            except BaseException as exc:  # noqa: BLE001 kept and raised by `failed`, outside C
                self.failure = exc
        return False

    def failed(self) -> None:
        """Raise what a read or seek raised, if one did."""
        if self.failure is not None:
            raise self.failure


def _decoded(stream: io.BufferedReader, name: str, sample_rate: int, channels: int = 1) -> Iterator[np.ndarray]:
    """The file's audio as float32 blocks at `sample_rate`, `channels` interleaved."""
    limit = int(MAX_SONG_S * sample_rate)
    total = 0
    source = _Source(stream)
    try:
        for block in miniaudio.stream_any(source, output_format=miniaudio.SampleFormat.FLOAT32,
                                          nchannels=channels, sample_rate=sample_rate, frames_to_read=_READ_FRAMES):
            source.failed()
            samples = np.frombuffer(block, dtype=np.float32)
            if not np.isfinite(samples).all() or np.abs(samples).max(initial=0.0) > 1.0:
                # a float file's NaN is no sound and its inf or 1e30 full scale, as a sound card
                # would play them: a NaN otherwise hangs or crashes every step after
                samples = np.clip(np.nan_to_num(samples, nan=0.0, posinf=1.0, neginf=-1.0), -1.0, 1.0)
            total += len(samples) // channels
            if total > limit:
                raise UsageError(f"{visible(name)}: longer than {MAX_SONG_S / 3600:g} hours: "
                                 "give a shorter song (cut it where the show needs it)")
            yield samples
    except miniaudio.DecodeError as exc:
        source.failed()
        raise UsageError(f"{visible(name)}: cannot decode: not a {MUSIC_FORMATS_TEXT} file, or a damaged one "
                         f"(miniaudio: {exc.args[0] if exc.args else exc})") from None
    source.failed()
    if total == 0:
        raise UsageError(f"{visible(name)}: no audio in it (0 samples)")


class _Framer:
    """Cuts samples arriving in blocks into frames of `size` every `hop`, frame j centred on
    sample j * hop (zeros before the first sample and after the last)."""

    def __init__(self, size: int, hop: int) -> None:
        self.size, self.hop = size, hop
        self.pending = np.zeros(size // 2, dtype=np.float32)

    def frames(self, block: np.ndarray) -> np.ndarray:
        self.pending = np.concatenate([self.pending, block])
        count = (len(self.pending) - self.size) // self.hop + 1
        if count <= 0:
            return np.zeros((0, self.size), dtype=np.float32)
        out = np.lib.stride_tricks.sliding_window_view(self.pending, self.size)[: count * self.hop: self.hop].copy()
        self.pending = self.pending[count * self.hop:]
        return out


class _Extractor:
    """The features, block by block."""

    def __init__(self, sample_rate: int, path: str) -> None:
        self.rate, self.path = sample_rate, path
        self.window = np.hanning(FRAME + 1)[:-1].astype(np.float32)
        self.chroma_window = np.hanning(CHROMA_FRAME + 1)[:-1].astype(np.float32)
        self.edges = _band_edges(sample_rate)
        self.pitch_classes = _pitch_classes(sample_rate, CHROMA_HZ)
        self.bass_classes = _pitch_classes(sample_rate, BASS_CHROMA_HZ)
        self.framer = _Framer(FRAME, HOP)
        self.chroma_framer = _Framer(CHROMA_FRAME, HOP * CHROMA_EVERY)
        self.bands: list[np.ndarray] = []
        self.chroma: list[np.ndarray] = []
        self.bass_chroma: list[np.ndarray] = []
        self.windowed: list[np.ndarray] = []  # energy over the trailing ATTACK_WINDOW steps, by step
        self.last_steps = np.zeros(ATTACK_WINDOW)
        self.attack_pending = np.zeros(0, dtype=np.float64)
        self.previous = 0.0
        self.seen = 0
        self.peak = 0.0

    def add(self, block: np.ndarray) -> None:
        if block.size == 0:
            return
        self.seen += len(block)
        self.peak = max(self.peak, float(np.max(np.abs(block))))
        self._spectra(self.framer.frames(block), self.chroma_framer.frames(block))
        self._attack(block)

    def _spectra(self, frames: np.ndarray, chroma_frames: np.ndarray) -> None:
        for start in range(0, len(frames), _BLOCK_FRAMES):
            magnitude = np.abs(np.fft.rfft(frames[start:start + _BLOCK_FRAMES] * self.window, axis=1))
            self.bands.append(_band_means(magnitude, self.edges).astype(np.float32))
        for start in range(0, len(chroma_frames), _BLOCK_FRAMES):
            magnitude = np.abs(np.fft.rfft(chroma_frames[start:start + _BLOCK_FRAMES] * self.chroma_window, axis=1))
            self.chroma.append(_fold(magnitude, self.pitch_classes))
            self.bass_chroma.append(_fold(magnitude, self.bass_classes))

    def _attack(self, block: np.ndarray) -> None:
        """Energy of the signal's first difference every ATTACK_HOP samples, summed over the
        trailing ATTACK_WINDOW steps as the blocks come (kept as float32: 10 MB an hour)."""
        bright = np.diff(block.astype(np.float64), prepend=self.previous)
        self.previous = float(block[-1])
        pending = np.concatenate([self.attack_pending, bright * bright])
        whole = len(pending) // ATTACK_HOP * ATTACK_HOP
        steps = pending[:whole].reshape(-1, ATTACK_HOP).sum(axis=1)
        self.attack_pending = pending[whole:]
        self.windowed.append(self._windowed(steps))

    def _windowed(self, steps: np.ndarray) -> np.ndarray:
        reach = np.concatenate([self.last_steps, steps])
        sums = np.cumsum(np.concatenate([[0.0], reach]))
        self.last_steps = reach[len(reach) - ATTACK_WINDOW:]
        return (sums[ATTACK_WINDOW + 1:] - sums[1:len(sums) - ATTACK_WINDOW]).astype(np.float32)

    def finish(self) -> Features:
        wanted = self.seen // HOP + 1
        self._spectra(self.framer.frames(np.zeros(FRAME // 2, dtype=np.float32)),
                      self.chroma_framer.frames(np.zeros(CHROMA_FRAME // 2, dtype=np.float32)))
        full_scale = max(self.peak, 1e-12) * FRAME / 4.0  # a full-scale sine's peak bin, Hann window
        bands = _joined(self.bands, len(self.edges))[:wanted]
        bands *= np.float32(LOG_GAIN / full_scale)
        np.log1p(bands, out=bands)
        chroma_wanted = self.seen // (HOP * CHROMA_EVERY) + 1
        return Features(self.path, self.seen / self.rate, self.rate, HOP, bands,
                        _edges_hz(self.edges, self.rate),
                        _joined(self.chroma, 12)[:chroma_wanted], _joined(self.bass_chroma, 12)[:chroma_wanted],
                        CHROMA_EVERY, self._attack_envelope(), ATTACK_HOP, self.peak)

    def _attack_envelope(self) -> np.ndarray:
        """The rise of log energy over a trailing window of ATTACK_WINDOW steps: it jumps in the
        step where a sound starts (attacks are bright), placing an onset within a millisecond."""
        if len(self.attack_pending):
            self.windowed.append(self._windowed(np.array([self.attack_pending.sum()])))
        windowed = _joined(self.windowed, 0) if self.windowed else np.zeros(1, dtype=np.float32)
        floor = 1e-3 * float(windowed.mean(dtype=np.float64)) + 1e-12  # quiet passages: no rises out of nothing
        windowed += np.float32(floor)
        np.log(windowed, out=windowed)
        rises = np.empty(len(windowed) + 1, dtype=np.float32)  # value m: the samples (m-1)*hop..m*hop
        rises[0] = 0.0
        rises[1] = windowed[0] - np.float32(math.log(floor))
        np.subtract(windowed[1:], windowed[:-1], out=rises[2:])
        return rises


def _band_edges(sample_rate: int) -> list[tuple[int, int]]:
    """FFT bin ranges [lo, hi) of log-spaced bands, BANDS_PER_OCTAVE an octave from LOWEST_HZ;
    at the low end, where bins are wider than a band, each band gets at least one bin of its own."""
    bin_hz = sample_rate / FRAME
    top = sample_rate / 2
    count = int(math.log2(top / LOWEST_HZ) * BANDS_PER_OCTAVE)
    edges_hz = LOWEST_HZ * 2.0 ** (np.arange(count + 1) / BANDS_PER_OCTAVE)
    bins = sorted(set(int(round(hz / bin_hz)) for hz in edges_hz) | {FRAME // 2 + 1})
    return [(lo, hi) for lo, hi in zip(bins[:-1], bins[1:], strict=True) if hi > lo and lo >= 1]


def _edges_hz(edges: list[tuple[int, int]], sample_rate: int) -> np.ndarray:
    bin_hz = sample_rate / FRAME
    return np.array([(max(lo - 0.5, 0.5) * bin_hz, (hi - 0.5) * bin_hz) for lo, hi in edges])


def _band_means(magnitude: np.ndarray, edges: list[tuple[int, int]]) -> np.ndarray:
    sums = np.cumsum(np.pad(magnitude, ((0, 0), (1, 0))), axis=1)
    lo = np.array([e[0] for e in edges])
    hi = np.array([e[1] for e in edges])
    return (sums[:, hi] - sums[:, lo]) / (hi - lo)


def _pitch_classes(sample_rate: int, hz: tuple[float, float]) -> np.ndarray:
    """For each bin of the chroma FFT, its pitch class (C = 0), or -1 outside `hz`."""
    freqs = np.arange(CHROMA_FRAME // 2 + 1) * sample_rate / CHROMA_FRAME
    classes = np.full(len(freqs), -1)
    inside = (freqs >= hz[0]) & (freqs < hz[1])
    midi = 69.0 + 12.0 * np.log2(freqs[inside] / 440.0)
    classes[inside] = np.round(midi).astype(int) % 12
    return classes


def _fold(magnitude: np.ndarray, classes: np.ndarray) -> np.ndarray:
    out = np.zeros((len(magnitude), 12), dtype=np.float32)
    for pitch in range(12):
        out[:, pitch] = magnitude[:, classes == pitch].sum(axis=1)
    return out


def _joined(parts: list[np.ndarray], width: int) -> np.ndarray:
    """The blocks as one float32 array (rows of `width`; 0: a flat array), each block let go
    as soon as it is copied, so that the song's features are never held twice."""
    shape: tuple[int, ...] = (sum(len(part) for part in parts),) + ((width,) if width else ())
    out = np.empty(shape, dtype=np.float32)
    at = 0
    parts.reverse()
    while parts:
        part = parts.pop()
        out[at:at + len(part)] = part
        at += len(part)
    return out
