"""Where a song's beats and bars fall: the tempo, the first downbeat, every beat (`choreo beats`).

An author cues a show to music in bars and beats (`tempo: {bpm, offset, meter}`), so the figures
have to come from the music, not a stopwatch. The estimate works in three steps, in numpy alone:
librosa's first call JIT-compiles for 20 to 35 s on a fresh machine (measured for its STFT,
onset strength and beat tracker alike), longer than choreo's whole test suite.

1. a coarse onset envelope (spectral flux of the log magnitude, 11.6 ms frames) gives the
   tempo by autocorrelation and the beat phase by folding the envelope on that period;
2. a fine attack envelope (the rise of log energy, 1.45 ms steps) finds the onset nearest each
   beat, and a robust straight-line fit through those onsets gives the period and phase to
   about a millisecond on clean material;
3. among the `meter` places in the bar, the one whose beats carry the most accent is taken for
   the downbeat: accents fall on the one. In the bass when the song has one (kick drum and bass
   mark the bar, where a snare backbeat outweighs them over the whole spectrum), else in all.

It is an estimate: the figures say how many beats an onset confirmed, and how clearly the
downbeats stood out, so that the author knows how much to trust them before checking by ear.
"""

from __future__ import annotations

import math
import os
from dataclasses import dataclass

import miniaudio
import numpy as np

from choreo.errors import UsageError
from choreo.show.model import MUSIC_FORMATS_TEXT, Tempo
from choreo.textfit import visible
from choreo.userfile import read_input

SAMPLE_RATE = 22050  # Hz: enough for onsets, half the work of 44.1 kHz
SONG_FORMATS = MUSIC_FORMATS_TEXT
# The file is read whole before it is decoded: an hour of WAV at CD quality is 635 MB.
MAX_SONG_BYTES = 1024 * 1024 * 1024
BPM_RANGE = (40.0, 240.0)  # searched by default; `tempo.bpm` itself may be up to 400
BPM_LIMITS = (1.0, 400.0)  # what a search range may span: the show schema's bpm range
METER_LIMITS = (1, 16)  # beats a bar, as the show schema allows
MIN_BEATS = 4  # beats an onset must confirm before a tempo is worth printing
ON_BEAT_S = 0.03  # an onset farther than this from the fitted beat does not confirm it

_FRAME = 1024  # coarse analysis window, samples (46 ms)
_HOP = 256  # coarse frame step, samples (11.6 ms)
_BLOCK = 2048  # coarse frames transformed at once: bounds memory on a long song
_FINE_WINDOW = 256  # fine energy window, samples (11.6 ms), trailing: an onset starts it
_FINE_HOP = 32  # fine step, samples (1.45 ms)
_PRIOR_BPM = 120.0  # the centre of the tempo prior, which settles half- and double-time
_PRIOR_OCTAVES = 1.0  # its width (standard deviation) in octaves
_PHASE_BINS = 64
_BASS_HZ = 200.0  # kick drums and bass notes, which mark the bar, lie below this
# The share of the song's energy below `_BASS_HZ` under which the bar is not found by the bass:
# a band with a bass has far more there (the generated band tracks: 50 to 85 %), a metronome's
# sharp clicks a few % of spectral leakage, larger from its softer, lower click: the bass would
# put that downbeat on another beat.
_BASS_SHARE = 0.1
_HEARD = 0.2  # a beat is heard when its onset strength is this share of the song's strong beats
_SEARCH_S = (0.08, 0.04, 0.025)  # successive half-widths of the window an onset is sought in
_SIGNIFICANT = 4.0  # robust deviations of the attack envelope that make an onset


@dataclass(frozen=True)
class Song:
    """A decoded song: mono samples at `sample_rate`, peak-normalised (silence stays zeros)."""

    path: str
    samples: np.ndarray
    sample_rate: int = SAMPLE_RATE

    @property
    def duration_s(self) -> float:
        return len(self.samples) / self.sample_rate


@dataclass(frozen=True)
class Beat:
    """One beat on the printed tempo's grid, and the onset heard there (None: none near it)."""

    time_s: float
    bar: int
    beat: int
    onset_s: float | None = None


@dataclass(frozen=True)
class BeatEstimate:
    """The tempo block for a show, with what it rests on.

    `bpm` and `offset` are rounded to what a show file needs (0.01 bpm, 1 ms), and `beats` are
    the times `Tempo.seconds` gives for those rounded figures: what `choreo plan` will show.
    """

    bpm: float
    offset: float
    meter: int
    beats: tuple[Beat, ...]  # from bar 1 beat 1 to the last beat heard
    duration_s: float
    confirmed: int  # beats from the first downbeat on with an onset within `ON_BEAT_S`
    timing_rms_ms: float  # how far those onsets lie from the grid, root mean square
    downbeat_contrast: float | None  # downbeats' accent over the next likeliest place's; None: meter 1
    downbeat_by: str  # "bass" or "all": the onsets whose accents placed the downbeat
    other_beat: int | None  # the beat of the bar that is the next likeliest downbeat
    other_offset: float | None  # and the offset that would make it beat 1

    def tempo(self) -> Tempo:
        return Tempo(self.bpm, self.offset, self.meter)


@dataclass(frozen=True)
class _Grid:
    """Beat k is at `start + k * period` seconds; `strengths[k]` is its onset strength, and
    `accents[k]` that of the onsets that mark the bar."""

    start: float
    period: float
    strengths: np.ndarray
    accents: np.ndarray

    def time(self, k: np.ndarray | int) -> np.ndarray | float:
        return self.start + np.asarray(k) * self.period


def read_song(path: str, sample_rate: int = SAMPLE_RATE) -> Song:
    """The song as mono floats, read with miniaudio so that every format decodes without system
    libraries; unreadable files become one line that says what to do."""
    name = os.fspath(path)
    data = read_input(name, "sound file", MAX_SONG_BYTES)  # a pipe, a device, a read error: one line
    if not data:
        raise UsageError(f"{visible(name)}: the file is empty")
    try:
        decoded = miniaudio.decode(data, output_format=miniaudio.SampleFormat.FLOAT32,
                                   nchannels=1, sample_rate=sample_rate)
    except miniaudio.DecodeError as exc:
        raise UsageError(f"{visible(name)}: cannot decode: not a {SONG_FORMATS} file, or a damaged one "
                         f"(miniaudio: {exc.args[0] if exc.args else exc})") from None
    samples = np.frombuffer(decoded.samples, dtype=np.float32)
    if samples.size == 0:
        raise UsageError(f"{visible(name)}: no audio in it (0 samples)")
    peak = float(np.max(np.abs(samples)))
    return Song(name, samples / peak if peak > 0 else samples.copy(), sample_rate)


def estimate(song: Song, meter: int = 4, bpm_range: tuple[float, float] = BPM_RANGE) -> BeatEstimate:
    """Tempo, first downbeat and beats of `song`, with `meter` beats a bar."""
    _check_arguments(meter, bpm_range)
    if not np.any(song.samples):
        raise UsageError(f"{song.path}: no beat found: the song is silent")
    fps = song.sample_rate / _HOP
    onsets = onset_envelopes(song.samples, song.sample_rate)
    period = tempo_period(onsets.full, fps, bpm_range, song.path)
    by_bass = onsets.bass_share >= _BASS_SHARE
    grid = _coarse_grid(onsets.full, onsets.bass if by_bass else onsets.full, fps, period,
                        beat_phase(onsets.full, period))
    heard = np.flatnonzero(_heard(grid))
    if heard.size < MIN_BEATS:
        raise UsageError(f"{song.path}: no steady beat found (fewer than {MIN_BEATS} beats heard)")
    ks = np.arange(heard[0], heard[-1] + 1)
    attack = attack_envelope(song.samples)
    grid, times = refine(grid, ks, attack, song.sample_rate)
    return _estimate_from(song, grid, ks, times, meter, "bass" if by_bass else "all")


def _heard(grid: _Grid) -> np.ndarray:
    """Which beats have an onset worth the name, in the whole spectrum or in the accents: a share
    of the strong beats' (a kick under a loud snare backbeat still counts)."""
    return np.logical_or(*((values >= _HEARD * np.percentile(values, 90)) & (values > 0)
                           for values in (grid.strengths, grid.accents)))


def _check_arguments(meter: int, bpm_range: tuple[float, float]) -> None:
    if not METER_LIMITS[0] <= meter <= METER_LIMITS[1]:
        raise UsageError(f"meter {meter}: give {METER_LIMITS[0]}..{METER_LIMITS[1]} beats a bar")
    lo, hi = bpm_range
    if not BPM_LIMITS[0] <= lo < hi <= BPM_LIMITS[1]:
        raise UsageError(f"bpm range {lo:g}..{hi:g}: give LO..HI with "
                         f"{BPM_LIMITS[0]:g} <= LO < HI <= {BPM_LIMITS[1]:g}")


@dataclass(frozen=True)
class Onsets:
    """Coarse onset envelopes, one value every `_HOP` samples."""

    full: np.ndarray  # the whole spectrum: what the beat is found by
    bass: np.ndarray  # below `_BASS_HZ`: what the bar is found by
    bass_share: float  # of the song's energy below `_BASS_HZ`


def onset_envelopes(samples: np.ndarray, sample_rate: int) -> Onsets:
    """How much new sound each coarse frame brings: the positive change of the log magnitude
    spectrum (log, so that a quiet hi-hat counts beside a loud bass), less its running mean over
    about a second, so that a crescendo is not taken for onsets. The bass gets an envelope of its
    own: a snare spreads over the whole spectrum and outweighs the kick on the one."""
    window = np.hanning(_FRAME + 1)[:-1].astype(np.float32)
    padded = np.pad(samples.astype(np.float32), (_FRAME // 2, _FRAME // 2))
    frames = np.lib.stride_tricks.sliding_window_view(padded, _FRAME)[::_HOP]
    bass_bins = int(_BASS_HZ * _FRAME / sample_rate) + 1
    flux = np.zeros((len(frames), 2))
    energy = np.zeros(2)
    previous = np.zeros((1, _FRAME // 2 + 1))  # silence before the song: a sound at 0 s is an onset
    for start in range(0, len(frames), _BLOCK):
        magnitude = np.abs(np.fft.rfft(frames[start:start + _BLOCK] * window, axis=1))
        power = (magnitude * magnitude).sum(axis=0)
        energy += (power[:bass_bins].sum(), power.sum())
        spectrum = np.log1p(magnitude)
        rises = np.maximum(np.diff(np.vstack([previous, spectrum]), axis=0), 0.0)
        flux[start:start + len(spectrum)] = np.column_stack([rises.mean(axis=1), rises[:, :bass_bins].mean(axis=1)])
        previous = spectrum[-1:]
    width = int(sample_rate / _HOP)
    full, bass = (np.maximum(flux[:, i] - _running_mean(flux[:, i], width), 0.0) for i in (0, 1))
    return Onsets(full, bass, float(energy[0] / energy[1]) if energy[1] > 0 else 0.0)


def _running_mean(values: np.ndarray, width: int) -> np.ndarray:
    width = max(1, min(width, len(values)))
    sums = np.cumsum(np.concatenate([[0.0], values]))
    lo = np.clip(np.arange(len(values)) - width // 2, 0, len(values))
    hi = np.clip(lo + width, 0, len(values))
    return (sums[hi] - sums[lo]) / np.maximum(hi - lo, 1)


def tempo_period(envelope: np.ndarray, fps: float, bpm_range: tuple[float, float], name: str) -> float:
    """The beat period in coarse frames.

    The autocorrelation's peaks in the range are the candidates, each sharpened on the peaks at
    its multiples (one frame of error shared by many beats). The one chosen has the onsets most on
    its beats and least halfway between them, weighed by a prior around 120 bpm: half the tempo
    puts the backbeat between its beats, double the tempo puts its beats on the off-beats.
    """
    correlation = _autocorrelation(envelope)
    n = len(correlation)
    lo_lag = max(2, int(math.floor(fps * 60.0 / bpm_range[1])))
    hi_lag = min(n // 2, int(math.ceil(fps * 60.0 / bpm_range[0])))
    if hi_lag <= lo_lag + 2 or correlation[0] <= 0:
        raise UsageError(f"{name}: too short to find a beat ({n / fps:.1f} s)")
    best, best_score = 0.0, -math.inf
    for lag in _correlation_peaks(correlation, lo_lag, hi_lag):
        period = _sharpened(correlation, float(lag))
        bpm = fps * 60.0 / period
        prior = math.exp(-0.5 * (math.log2(bpm / _PRIOR_BPM) / _PRIOR_OCTAVES) ** 2)
        score = _pulse_contrast(envelope, period) * prior
        if bpm_range[0] <= bpm <= bpm_range[1] and score > best_score:
            best, best_score = period, score
    if best_score <= 0:
        raise UsageError(f"{name}: no steady beat found (no tempo between "
                         f"{bpm_range[0]:g} and {bpm_range[1]:g} bpm repeats)")
    return best


def _autocorrelation(envelope: np.ndarray) -> np.ndarray:
    centred = envelope - envelope.mean()
    spectrum = np.fft.rfft(centred, 2 * len(centred))
    return np.fft.irfft(spectrum * np.conj(spectrum))[:len(centred)]


def _correlation_peaks(correlation: np.ndarray, lo: int, hi: int, keep: int = 12) -> list[int]:
    """The lags in lo..hi where the autocorrelation peaks, the strongest `keep` of them."""
    lags = np.arange(max(lo, 1), min(hi, len(correlation) - 2) + 1)
    values = correlation[lags]
    peaks = lags[(values >= correlation[lags - 1]) & (values > correlation[lags + 1]) & (values > 0)]
    return sorted(peaks, key=lambda lag: -correlation[lag])[:keep]


def _sharpened(correlation: np.ndarray, lag: float) -> float:
    """The period at `lag`, read again on the autocorrelation's peaks at 2, 4, 8... times it."""
    period = _peak_near(correlation, lag, 1)
    multiple = 2
    while multiple * (period + 1) < len(correlation) // 2:
        period = _peak_near(correlation, multiple * period, max(1, int(period / 4))) / multiple
        multiple *= 2
    return period


def _pulse_contrast(envelope: np.ndarray, period: float) -> float:
    """Mean onset strength on the beats less that halfway between them, the envelope folded on
    `period` (as the mean per phase bin, so that periods compare)."""
    histogram = _folded(envelope, period)
    i = int(np.argmax(histogram))
    return float(histogram[i] - histogram[(i + _PHASE_BINS // 2) % _PHASE_BINS])


def _folded(envelope: np.ndarray, period: float) -> np.ndarray:
    """The envelope's mean in each of `_PHASE_BINS` phases of `period`, lightly smoothed."""
    phases = (np.arange(len(envelope)) % period) / period
    bins = np.minimum((phases * _PHASE_BINS).astype(int), _PHASE_BINS - 1)
    sums = np.bincount(bins, weights=envelope, minlength=_PHASE_BINS)
    counts = np.maximum(np.bincount(bins, minlength=_PHASE_BINS), 1)
    mean = sums / counts
    return (np.roll(mean, 1) + 2.0 * mean + np.roll(mean, -1)) / 4.0


def _peak_near(values: np.ndarray, where: float, reach: int) -> float:
    """The maximum of `values` within `reach` of `where`, interpolated between samples."""
    lo = max(1, int(round(where)) - reach)
    hi = min(len(values) - 2, int(round(where)) + reach)
    i = lo + int(np.argmax(values[lo:hi + 1]))
    return i + _parabola(values[i - 1], values[i], values[i + 1])


def _parabola(left: float, centre: float, right: float) -> float:
    """Where the parabola through three equally spaced points peaks, from the middle one."""
    curve = left - 2.0 * centre + right
    return 0.0 if curve >= 0 else float(np.clip(0.5 * (left - right) / curve, -0.5, 0.5))


def beat_phase(envelope: np.ndarray, period: float) -> float:
    """Where in the period the onsets gather, in frames from the song's start: the peak of the
    envelope folded onto one period."""
    histogram = _folded(envelope, period)
    i = int(np.argmax(histogram))
    offset = _parabola(histogram[i - 1], histogram[i], histogram[(i + 1) % _PHASE_BINS])
    return ((i + 0.5 + offset) / _PHASE_BINS * period) % period


def _coarse_grid(full: np.ndarray, accents: np.ndarray, fps: float, period: float, phase: float) -> _Grid:
    """Every beat of the song on the coarse estimate, with the envelopes' peaks within two
    frames of it as its strength and accent."""
    if phase > 0.75 * period:
        phase -= period  # a beat just before 0 s on the coarse frames is the one at 0 s
    frames = np.round(np.arange(phase, len(full) - 1, period)).astype(int)

    def peaks(envelope: np.ndarray) -> np.ndarray:
        return np.array([envelope[max(0, f - 2):max(0, f + 3)].max(initial=0.0) for f in frames])

    return _Grid(phase / fps, period / fps, peaks(full), peaks(accents))


def attack_envelope(samples: np.ndarray) -> np.ndarray:
    """The rise of log energy every `_FINE_HOP` samples, over a trailing window of the signal's
    first difference (attacks are bright): it jumps in the step where a sound starts, which
    places an onset within about a millisecond, where a spectral frame smears it over 46 ms.
    Value j belongs to the samples from `(j - 1) * _FINE_HOP` to `j * _FINE_HOP`."""
    bright = np.diff(samples.astype(np.float64), prepend=0.0)
    energy = np.cumsum(np.concatenate([np.zeros(_FINE_WINDOW + 1), bright * bright]))
    ends = np.arange(_FINE_WINDOW, len(energy), _FINE_HOP)
    windowed = energy[ends] - energy[ends - _FINE_WINDOW]
    floor = 1e-3 * float(windowed.mean()) + 1e-12  # quiet passages: no rises out of nothing
    return np.diff(np.log(windowed + floor), prepend=np.log(floor))


def refine(grid: _Grid, ks: np.ndarray, attack: np.ndarray, sample_rate: int) -> tuple[_Grid, np.ndarray]:
    """The grid moved onto the onsets: the sharpest attack near each heard beat, a straight line
    (beat number to time) fitted through them, again with a narrower search. Returns the fitted
    grid and the onset time on each of the beats `ks` (NaN: none within `ON_BEAT_S`).

    An attack counts only when it stands out from the song's usual ups and downs (`_SIGNIFICANT`
    robust deviations): noise always has a largest value near any time, but no onset."""
    heard = _heard(grid)[ks]
    significant = _SIGNIFICANT * 1.4826 * float(np.median(np.abs(attack - np.median(attack))))
    times = np.full(len(ks), np.nan)
    for reach in _SEARCH_S:
        found = _attacks_near(np.asarray(grid.time(ks)), attack, sample_rate, min(reach, 0.25 * grid.period),
                              significant)
        use = heard & ~np.isnan(found)
        if np.count_nonzero(use) < MIN_BEATS:
            break
        start, period = _robust_line(ks[use], found[use])
        grid = _Grid(start, period, grid.strengths, grid.accents)
        times = np.where(np.abs(found - grid.time(ks)) <= ON_BEAT_S, found, np.nan)
    return grid, times


def _attacks_near(times: np.ndarray, attack: np.ndarray, sample_rate: int, reach: float,
                  significant: float) -> np.ndarray:
    """For each time, the time of the largest attack within `reach` of it, when it is at least
    `significant` (else NaN): the middle of the fine step whose samples made the energy jump."""
    step = _FINE_HOP / sample_rate
    first = -step / 2  # the time of step 0
    found = np.full(len(times), np.nan)
    for i, time in enumerate(times):
        lo = max(0, int(math.ceil((time - reach - first) / step)))
        hi = min(len(attack), int(math.floor((time + reach - first) / step)) + 1)
        if hi - lo >= 3:
            j = lo + int(np.argmax(attack[lo:hi]))
            if attack[j] >= significant:
                found[i] = first + j * step
    return found


def _robust_line(ks: np.ndarray, times: np.ndarray) -> tuple[float, float]:
    """Least squares `time = start + k * period`, refitted on the onsets within three robust
    deviations (and `ON_BEAT_S`) of the line: a beat whose onset is something else must not pull."""
    keep = np.ones(len(ks), dtype=bool)
    start, period = 0.0, 0.0
    for _ in range(3):
        period, start = np.polyfit(ks[keep].astype(float), times[keep], 1)
        residuals = np.abs(times - (start + ks * period))
        spread = 1.4826 * float(np.median(residuals[keep]))
        narrower = residuals <= min(ON_BEAT_S, max(3.0 * spread, 0.002))
        if np.count_nonzero(narrower) < MIN_BEATS:
            break
        keep = narrower
    return float(start), float(period)


def _estimate_from(song: Song, grid: _Grid, ks: np.ndarray, times: np.ndarray, meter: int,
                   accents_by: str) -> BeatEstimate:
    """Choose the downbeat, round to what a show file holds, and list the beats on that grid."""
    places, contrast = downbeat_places(ks, grid.accents[ks], meter)
    first = _first_at(places[0], grid, ks, meter)
    if first + MIN_BEATS > ks[-1] + 1:
        raise UsageError(f"{song.path}: no steady beat found "
                         f"(fewer than {MIN_BEATS} beats heard from the first downbeat)")
    tempo = Tempo(round(60.0 / grid.period, 2), max(0.0, round(float(grid.time(first)), 3)), meter)
    beats = []
    for i, k in enumerate(range(first, int(ks[-1]) + 1)):
        bar, beat = divmod(i, meter)
        onset = times[k - ks[0]]
        beats.append(Beat(tempo.seconds(bar + 1, beat + 1), bar + 1, beat + 1,
                          None if np.isnan(onset) else round(float(onset), 4)))
    deviations = [b.onset_s - b.time_s for b in beats if b.onset_s is not None]
    if len(deviations) < MIN_BEATS:
        raise UsageError(f"{song.path}: no steady beat found (an onset on {len(deviations)} beats only)")
    rms = 1000.0 * math.sqrt(sum(d * d for d in deviations) / len(deviations))
    other_beat = other = None
    if len(places) > 1:
        other_beat = (places[1] - places[0]) % meter + 1
        other = max(0.0, round(float(grid.time(_first_at(places[1], grid, ks, meter))), 3))
    return BeatEstimate(tempo.bpm, tempo.offset, meter, tuple(beats), round(song.duration_s, 3),
                        len(deviations), round(rms, 2), contrast, accents_by, other_beat, other)


def _first_at(place: int, grid: _Grid, ks: np.ndarray, meter: int) -> int:
    """The first heard beat at `place` in the bar (beat numbers modulo `meter`) at or after 0 s."""
    first = int(ks[0] + (place - ks[0]) % meter)
    while grid.time(first) < -0.0005:  # 0.000 s once rounded to the millisecond
        first += meter
    return first


def downbeat_places(ks: np.ndarray, accents: np.ndarray, meter: int) -> tuple[list[int], float | None]:
    """The places in the bar (beat numbers modulo `meter`) from likeliest downbeat to least: by
    the mean accent of their beats, since accents fall on the one. With how much the first stands
    out from the second (a ratio; None with one beat a bar)."""
    if meter == 1:
        return [0], None
    means = np.array([accents[ks % meter == place].mean() if np.any(ks % meter == place) else 0.0
                      for place in range(meter)])
    order = [int(place) for place in np.argsort(-means, kind="stable")]
    runner_up = float(means[order[1]])
    contrast = float(means[order[0]]) / runner_up if runner_up > 0 else math.inf
    return order, round(contrast, 2)
