"""Where a song's beats and bars fall: the tempo, bar 1, every beat (`choreo beats`).

An author cues a show to music in bars and beats, so the figures have to come from the music, not
a stopwatch. The estimate reads a song's `Features` (choreo.music.features: decoded in blocks,
memory bounded) in four steps, numpy alone:

1. the tempo level (choreo.music.tempo): onset strength by band, its autocorrelation summed over
   multiples under a broad prior, the level that explains the onsets and the chords best;
2. every beat (choreo.music.tracking): a local tempo followed through the song, dynamic
   programming over beat times on it, each beat moved onto the attack within 25 ms;
3. bar 1: the first downbeat at or after the music's start;
4. steady or not: a robust straight line through the beats; if it puts the attacks on them
   within MAP_WHEN_OFF_S of it (all but a stray few in STEADY_SHARE: an attack near a beat may be
   another sound) and no beat more than STRAY_S off, the song has one tempo (bpm to 0.01, or
   finer where a long song needs it, offset to 1 ms: on clean material the line through a hundred
   attacks is good to a millisecond), else
   `bars` holds each bar's beat 1, a tempo map a show can follow.

It is an estimate: the figures say how many beats an attack confirmed and how clearly the
downbeats stood out, so that the author knows how much to trust them before checking by ear.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from choreo.errors import UsageError
from choreo.music import tempo as tempo_level
from choreo.music.downbeats import EARLY_S, Downbeats, find_downbeats, music_start
from choreo.music.features import FRAME, Features
from choreo.music.tempo import onset_strength
from choreo.music.tracking import beat_frames, local_periods, snapped
from choreo.show.model import MAX_BPM, Tempo

__all__ = ["BPM_LIMITS", "BPM_RANGE", "METER_LIMITS", "MIN_BEATS", "ON_BEAT_S", "MAP_WHEN_OFF_S",
           "Beat", "BeatEstimate", "estimate", "onset_strength"]

BPM_RANGE = (40.0, 240.0)  # searched by default; `tempo.bpm` itself may be up to MAX_BPM
BPM_LIMITS = (1.0, MAX_BPM)  # what a search range may span: the show schema's bpm range
METER_LIMITS = (1, 16)  # beats a bar, as the show schema allows
MIN_BEATS = 4  # beats an attack must confirm before a tempo is worth printing
ON_BEAT_S = 0.03  # an attack farther than this from the beat does not confirm it
MAP_WHEN_OFF_S = 0.02  # a straight line that puts a beat farther off than this: a tempo map
STEADY_SHARE = 0.95  # of the beats with an attack that must lie within MAP_WHEN_OFF_S of a steady tempo's line
ROUNDED_S = 0.001  # how far the bpm's rounding may move the last beat of a steady song
STRAY_S = 0.05  # and no beat farther off than this (one an attack confirms, or the tracker's guess)
PULSE_S = 30.0  # the stretches whose repetition is measured
MIN_PULSE = 0.1  # the onsets' autocorrelation at a beat (share of their energy) below which nothing repeats
_LAST_BEAT = 0.2  # a last beat with less onset than this share of the median beat's is past the music
_SOUND = 0.02  # the music ends after the last frame whose bands' sum reaches this share of the median frame's


@dataclass(frozen=True)
class Beat:
    """One beat where the show will put it, and the attack heard there (None: none near it)."""

    time_s: float
    bar: int
    beat: int
    onset_s: float | None = None


@dataclass(frozen=True)
class BeatEstimate:
    """The tempo block for a show, with what it rests on.

    `bpm` and `offset` are rounded to what a show file needs (0.01 bpm or finer, 1 ms); with a map,
    `bars` holds each bar's beat 1 (1 ms) and `bpm` the median tempo. `beats` are the times
    `tempo().seconds` gives: what `choreo plan` will show.
    """

    bpm: float
    offset: float
    meter: int
    beats: tuple[Beat, ...]  # from bar 1 beat 1 to the last beat heard
    duration_s: float
    confirmed: int  # beats from bar 1 on with an attack within `ON_BEAT_S`
    timing_rms_ms: float  # how far those attacks lie from the beats, root mean square
    downbeat_contrast: float | None  # downbeats' accent over the next likeliest place's; None: meter 1
    downbeat_by: str  # what placed the downbeat
    other_beat: int | None  # the beat of the bar that is the next likeliest downbeat
    other_offset: float | None  # and where bar 1 would then be
    bars: tuple[float, ...] = ()  # the tempo map: each bar's beat 1, bar 1 first; () when one tempo fits
    curve: tuple[tuple[float, float], ...] = ()  # (time_s, bpm) of each beat-to-beat interval

    def tempo(self) -> Tempo:
        """The `tempo:` block as a show holds it: where cues by bar and beat will fall."""
        return Tempo(self.bpm, self.offset, self.meter, self.bars)


def estimate(features: Features, meter: int = 4, bpm_range: tuple[float, float] = BPM_RANGE) -> BeatEstimate:
    """Tempo, bar 1 and every beat of the song, with `meter` beats a bar."""
    _check_arguments(meter, bpm_range)
    name = features.path
    if features.peak <= 0:
        raise UsageError(f"{name}: no beat found: the song is silent")
    onsets = tempo_level.onsets_of(features)
    period = tempo_level.best_period(onsets, features, meter, bpm_range)
    if _pulse(onsets.strength, onsets.fps, bpm_range) < MIN_PULSE:
        raise UsageError(f"{name}: no steady beat found (nothing repeats between "
                         f"{bpm_range[0]:g} and {bpm_range[1]:g} bpm)")
    periods = local_periods(onsets.strength, onsets.fps, period)
    start, end = music_start(features), _music_end(features)
    times = _beat_times(onsets.strength, periods, onsets.fps, start, end)
    times, heard = _ending(*snapped(times, features), onsets)
    if np.count_nonzero(heard) < MIN_BEATS:
        raise UsageError(f"{name}: no steady beat found (fewer than {MIN_BEATS} beats heard)")
    bar1 = find_downbeats(features, times, meter)
    if len(times) - bar1.first < MIN_BEATS:
        raise UsageError(f"{name}: no steady beat found (fewer than {MIN_BEATS} beats from bar 1 on)")
    return _estimate_from(features, times, heard, meter, bar1)


def _check_arguments(meter: int, bpm_range: tuple[float, float]) -> None:
    if not METER_LIMITS[0] <= meter <= METER_LIMITS[1]:
        raise UsageError(f"meter {meter}: give {METER_LIMITS[0]}..{METER_LIMITS[1]} beats a bar")
    lo, hi = bpm_range
    if not BPM_LIMITS[0] <= lo < hi <= BPM_LIMITS[1]:
        raise UsageError(f"bpm range {lo:g}..{hi:g}: give LO..HI with "
                         f"{BPM_LIMITS[0]:g} <= LO < HI <= {BPM_LIMITS[1]:g}")


def _pulse(strength: np.ndarray, fps: float, bpm_range: tuple[float, float]) -> float:
    """How much the onsets repeat: in each stretch of PULSE_S, the best mean autocorrelation at a
    period in the range and its multiples, as a share of the onsets' energy; the median over the
    onsets' energy (each stretch weighs by its own). Noise has onsets but nothing that repeats; a
    long mix of songs repeats in each song; minutes of silence before or after a song have no
    onsets, and must not outvote it."""
    count = max(1, int(round(len(strength) / (PULSE_S * fps))))
    edges = np.linspace(0, len(strength), count + 1).astype(int)  # every frame in one: a song at the end too
    stretches = [strength[a:b] for a, b in zip(edges[:-1], edges[1:], strict=True)]
    pulses = np.array([_stretch_pulse(stretch, fps, bpm_range) for stretch in stretches])
    energy = np.array([float(np.var(stretch)) for stretch in stretches])
    if not np.any(energy > 0):
        return 0.0
    order = np.argsort(pulses)
    share = np.cumsum(energy[order]) / energy.sum()
    return float(pulses[order][np.searchsorted(share, 0.5)])


def _stretch_pulse(strength: np.ndarray, fps: float, bpm_range: tuple[float, float]) -> float:
    correlation = tempo_level.autocorrelation(strength)
    lo, hi = int(fps * 60.0 / bpm_range[1]), int(math.ceil(fps * 60.0 / bpm_range[0]))
    lags = np.arange(max(2, lo), min(hi, (len(correlation) - 2) // 4) + 1)
    if correlation[0] <= 0 or not len(lags):
        return 0.0
    peaks = np.maximum(correlation[:-1], correlation[1:])  # a period between two frames
    comb = np.mean([peaks[k * lags - 1] for k in (1, 2, 3, 4)], axis=0)
    return float(comb.max() / correlation[0])


def _music_end(features: Features) -> float:
    """Seconds to the last sound: a frame sounds once its bands reach a small share of the song's
    usual level."""
    level = features.bands.sum(axis=1)
    loud = level[level > 0]
    if not len(loud):
        return features.duration_s
    sounding = np.flatnonzero(level >= _SOUND * float(np.median(loud)))
    return min(features.duration_s, sounding[-1] / features.fps + 0.5 * FRAME / features.sample_rate)


def _beat_times(strength: np.ndarray, periods: np.ndarray, fps: float, start: float, end: float) -> np.ndarray:
    """The tracked beats, in seconds, from where the music starts to where it ends (the beat
    goes on at the local period before the first beat the tracker placed). Before the music
    there is nothing to follow: a noise floor's flickers must not start the beats off."""
    music = strength.copy()
    music[:max(0, int((start - EARLY_S) * fps))] = 0.0  # an attack rises a little before it is heard
    frames = beat_frames(music, periods)
    times = frames / fps
    first_period = periods[frames[0]] / fps
    before = np.arange(times[0] - first_period, start - 0.5 * first_period, -first_period)[::-1]
    times = np.concatenate([before, times])
    return times[(times >= start - 0.5 * first_period) & (times <= end)]


def _ending(times: np.ndarray, heard: np.ndarray, onsets: tempo_level.Onsets) -> tuple[np.ndarray, np.ndarray]:
    """The beats up to the last one the music plays: one an attack confirms and with a fair onset
    under it. Past it a song's last notes ring out, or stop (a sound's end makes no attack, though
    its cut can splash across the spectrum)."""
    if not len(times):
        return times, heard
    frames = np.clip(np.round(times * onsets.fps).astype(int), 0, len(onsets.strength) - 1)
    strength = np.array([onsets.strength[max(0, f - 2):f + 3].max() for f in frames])
    weak = ~heard | (strength < _LAST_BEAT * float(np.median(strength)))
    last = len(times) - int(np.argmin(weak[::-1])) if not np.all(weak) else 0
    return times[:last], heard[:last]


def _robust_line(ks: np.ndarray, times: np.ndarray) -> tuple[float, float]:
    """Least squares `time = start + k * period`, refitted on the beats within three robust
    deviations of the line: a beat whose attack is something else must not pull."""
    keep = np.ones(len(ks), dtype=bool)
    start, period = 0.0, 0.0
    for _ in range(4):
        period, start = np.polyfit(ks[keep].astype(float), times[keep], 1)
        residuals = np.abs(times - (start + ks * period))
        spread = 1.4826 * float(np.median(residuals[keep]))
        narrower = residuals <= min(ON_BEAT_S, max(3.0 * spread, 0.002))
        if np.count_nonzero(narrower) < MIN_BEATS:
            break
        keep = narrower
    return float(start), float(period)


def _estimate_from(features: Features, times: np.ndarray, heard: np.ndarray, meter: int,
                   bar1: Downbeats) -> BeatEstimate:
    """Steady tempo or a map; the beats where the show will put them, and what they rest on."""
    other = None
    if bar1.other_first is not None and bar1.other_first < len(times):
        other = max(0.0, round(float(times[bar1.other_first]), 3))
    times, heard = times[bar1.first:], heard[bar1.first:]
    show = _show_tempo(times, heard, meter)
    beats = [Beat(show.seconds(k // meter + 1, k % meter + 1), k // meter + 1, k % meter + 1,
                  round(float(t), 4) if h else None) for k, (t, h) in enumerate(zip(times, heard, strict=True))]
    deviations = np.array([b.onset_s - b.time_s for b in beats if b.onset_s is not None])
    rms = 1000.0 * math.sqrt(float(np.mean(deviations ** 2))) if len(deviations) else 0.0
    other_beat = None if bar1.other_first is None else (bar1.other_first - bar1.first) % meter + 1
    curve = tuple((round(float(a), 3), round(60.0 / float(b - a), 2))
                  for a, b in zip(times[:-1], times[1:], strict=True))
    return BeatEstimate(show.bpm, show.offset, meter, tuple(beats), round(features.duration_s, 3),
                        len(deviations), round(rms, 2), bar1.contrast, bar1.by, other_beat, other, show.bars, curve)


def _show_tempo(times: np.ndarray, heard: np.ndarray, meter: int) -> Tempo:
    """One tempo when a robust straight line through the beats (bar 1 first) puts the attacks on
    them within MAP_WHEN_OFF_S of it (all but a stray few: an attack near a beat may be another
    sound) and no beat farther than STRAY_S, else a map of the bars; the figures rounded as a
    show file holds them."""
    ks = np.arange(len(times))
    fit = heard if np.count_nonzero(heard) >= MIN_BEATS else np.ones(len(ks), dtype=bool)
    start, period = _robust_line(ks[fit], times[fit])
    off = np.abs(times - (start + ks * period))
    on_line = np.count_nonzero(off[fit] <= MAP_WHEN_OFF_S) >= STEADY_SHARE * np.count_nonzero(fit)
    if on_line and float(np.max(off)) <= STRAY_S:
        return _steady(start, period, len(times), meter)
    return Tempo.of_bars(_bar_anchors(times, meter), meter)  # its bpm figured where plan's is


def _steady(start: float, period: float, count: int, meter: int) -> Tempo:
    """One tempo as a show file holds it: bar 1 to 1 ms and the bpm to 0.01, or to as many more
    digits as keep the `count`th beat within ROUNDED_S of the line: 0.01 bpm is 30 ms by the end
    of a quarter of an hour at 123.456 bpm, and a show cues every beat by it."""
    bpm = 60.0 / period
    digits = next((d for d in range(2, 7) if (count - 1) * abs(60.0 / round(bpm, d) - period) <= ROUNDED_S), 7)
    return Tempo(round(bpm, digits), max(0.0, round(start, 3)), meter)


def _bar_anchors(times: np.ndarray, meter: int) -> tuple[float, ...]:
    """Each bar's beat 1, and where the bar after the last beat's would begin (so that the last
    bar's beats keep their own tempo)."""
    firsts = times[::meter]
    last = len(times) - 1
    interval = float(times[-1] - times[-2])
    closing = times[-1] + (meter - last % meter) * interval
    anchors = [round(float(t), 3) for t in np.concatenate([firsts, [closing]])]
    anchors[0] = max(0.0, anchors[0])  # a bar 1 heard a hair before the first sample is at 0 s, as a steady offset is
    return tuple(anchors)


def one_tempo_miss(found: BeatEstimate) -> tuple[float, float]:
    """The largest distance (s) from a beat to the least-squares line through all of them
    (beat number against time), and where that beat is: what one tempo would get wrong, said
    beside a map so that its reader knows why it is one."""
    count = np.array([(b.bar - 1) * found.meter + b.beat - 1 for b in found.beats], dtype=np.float64)
    times = np.array([b.time_s for b in found.beats], dtype=np.float64)
    if len(times) < 2:
        return 0.0, float(times[0]) if len(times) else 0.0
    slope, start = np.polyfit(count, times, 1)
    misses = np.abs(times - (start + slope * count))
    worst = int(np.argmax(misses))
    return float(misses[worst]), float(times[worst])
