"""How fast a song's beat goes: onset strength by band, and the tempo level that explains it.

A tempo tracker goes wrong by a level far more often than by a few percent: a ballad's eighth-note
hi-hats double it, house's off-beat open hats pull it to 2/3, a 6/8's eighths triple it, a funk
kick every three sixteenths suggests 4/3. So the tempo is chosen in two steps:

1. the autocorrelation of the onset strength, summed over multiples of each lag (a beat repeats
   at 2, 3, 4 periods too) and weighed by a broad log-normal prior around 120 bpm (Ellis 2007's
   centre), gives the comb's best few peaks; then
2. their levels (x1/3 .. x3) that lie in the search range (a range's edge or a level folded into
   it is a candidate too, so `--bpm-range` never refuses a tempo the song supports) are compared
   by how well each explains the music, stretch by stretch at each stretch's own phase: onsets on
   its beats against the strongest between them, whether successive beats
   are alike (every other beat much weaker: a subdivision), a snare on every other beat (the
   backbeat popular music is counted by), and whether its bars, of the meter the user gave, last
   as long as the chords do (chords change on bar lines, not on every beat nor mid-bar); all
   under the same prior.

Onset strength is the positive log-spectral flux of `Features.bands`, in three groups (the kick
below 150 Hz, the snare and everything pitched up to 5 kHz, the hats above), each normalised so
that a quiet kick counts as much as a loud pad, and weighed by what carries a beat: the kick most,
hats least.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from choreo.errors import UsageError
from choreo.music.features import Features

GROUPS_HZ = ((0.0, 150.0), (150.0, 5000.0), (5000.0, 1e9))  # kick; snare, bass and chords; hats
SNARE_HZ = (1500.0, 5000.0)  # a snare's noise, above most pitched sound, below the hats
GROUP_WEIGHTS = (1.5, 1.0, 0.2)  # the kick marks the beat most, hats mark subdivisions more often than beats
PRIOR_BPM = 120.0  # the centre of the tempo prior (log-normal), as in Ellis 2007
PRIOR_OCTAVES = 0.9  # its width (one standard deviation), in octaves
LEVELS = (1.0, 0.5, 2.0, 2.0 / 3.0, 1.5, 1.0 / 3.0, 3.0)  # tempo ratios to the best period's
_LOCAL_MEAN_S = 0.4  # the onset strength less its mean over this: a crescendo is no onset
BACKBEAT_WEIGHT = 3.0  # how much a snare on 2 and 4 counts for a level
EVENNESS_POWER = 0.5  # how much unlike successive beats count against a level
SEGMENT_BEATS = 24  # a level is judged on stretches of this many of its beats, each at its own phase
MAX_SEGMENTS = 24  # and on this many stretches at most, spread over the song (an hour needs no more)
EDGE = 0.02  # a level this near the search range (relative) is taken at its edge: 60 bpm read as 60.1 is in 40..60
_PEAKS = 3  # the comb's best peaks whose levels are compared
_MULTIPLES = 4  # lags summed in the comb: the period and its multiples up to this
_HARMONY_S = 0.4  # chroma is averaged over this either side of a possible chord change
_DRUM_S = 0.12  # a burst of noise shorter than twice this is no chord
_HARMONY_WEIGHT = 2.5  # how much bars that match the chords' changes count against the onsets


@dataclass(frozen=True)
class Onsets:
    """Onset strength, one value per `Features.bands` frame: by group (frames x 3) and weighed."""

    groups: np.ndarray
    strength: np.ndarray
    fps: float
    snare: np.ndarray  # the flux of the bands a snare's noise fills and pitched sound rarely (SNARE_HZ)


def onsets_of(features: Features) -> Onsets:
    """Positive log-spectral flux by band group, each group scaled by its own loud onsets (its
    99th percentile; a group with next to nothing in it is not blown up), less a local mean."""
    bands = features.bands
    groups = np.zeros((len(bands), len(GROUPS_HZ) + 1), dtype=np.float32)
    for i, (lo, hi) in enumerate((*GROUPS_HZ, SNARE_HZ)):
        picked = features.band_range(lo, hi)
        for band in picked:  # band by band: an hour's whole flux matrix would be 55 MB more
            column = bands[:, band]
            groups[1:, i] += np.maximum(column[1:] - column[:-1], 0.0)
            groups[0, i] += max(float(column[0]), 0.0)  # silence before the song: a sound at 0 s is an onset
        groups[:, i] /= max(len(picked), 1)
    snare = groups[:, -1].copy()
    groups = groups[:, :-1]
    scales = np.array([np.percentile(g, 99) if len(g) else 0.0 for g in groups.T])
    floor = 0.1 * float(scales.max()) + 1e-9
    groups /= np.maximum(scales, floor).astype(np.float32)
    width = max(1, int(round(_LOCAL_MEAN_S * features.fps)))
    for i in range(groups.shape[1]):
        groups[:, i] = np.maximum(groups[:, i] - running_mean(groups[:, i], width), 0.0)
    strength = groups @ np.asarray(GROUP_WEIGHTS, dtype=np.float32)
    return Onsets(groups, strength, features.fps, snare)


def onset_strength(features: Features) -> np.ndarray:
    """How much new sound each `bands` frame brings, weighed by what carries a beat."""
    return onsets_of(features).strength


def running_mean(values: np.ndarray, width: int) -> np.ndarray:
    """The mean of `values` over `width` frames centred on each (fewer at the ends: a window
    shifted inwards there would let a song's first beats be measured against later ones)."""
    width = max(1, width)
    sums = np.cumsum(np.concatenate([[0.0], values.astype(np.float64)]))
    index = np.arange(len(values))
    lo = np.maximum(index - width // 2, 0)
    hi = np.minimum(index + (width + 1) // 2, len(values))
    return np.asarray((sums[hi] - sums[lo]) / np.maximum(hi - lo, 1))


def prior(bpm: float | np.ndarray) -> np.ndarray:
    """The log-normal tempo prior (1 at its centre)."""
    return np.exp(-0.5 * (np.log2(np.asarray(bpm) / PRIOR_BPM) / PRIOR_OCTAVES) ** 2)


def autocorrelation(values: np.ndarray) -> np.ndarray:
    """The autocorrelation of `values` less their mean, lags 0.. len - 1 (by FFT: an hour's
    onsets in a fraction of a second)."""
    centred = values - values.mean()
    size = 1 << int(2 * len(centred) - 1).bit_length()
    spectrum = np.fft.rfft(centred, size)
    return np.fft.irfft(spectrum * np.conj(spectrum), size)[:len(centred)]


def best_period(onsets: Onsets, features: Features, meter: int, bpm_range: tuple[float, float]) -> float:
    """The beat period in frames: the comb's best lag, then the level that explains the song best."""
    fps = onsets.fps
    correlation = autocorrelation(onsets.strength)
    n = len(correlation)
    lo_lag = max(2.0, fps * 60.0 / bpm_range[1])
    hi_lag = min(n / 2.0, fps * 60.0 / bpm_range[0])
    if n / 2.0 <= lo_lag + 2 or correlation[0] <= 0:  # a narrow range is no short song: see _candidates
        raise UsageError(f"{features.path}: too short to find a beat ({features.duration_s:.1f} s)")
    # the comb over every tempo a level could reach, so that a range's edge never hides one
    lags = np.arange(max(2, int(lo_lag / 3)), int(min(n / 2, 3 * hi_lag)) + 1)
    comb = _comb(correlation, lags) / correlation[0]
    scored = comb * prior(fps * 60.0 / lags)
    harmony = _harmonic_change(features, fps)
    candidates = _candidates(correlation, lags, scored, lo_lag, hi_lag)
    scores = [explained(onsets, period, meter, harmony) * float(prior(fps * 60.0 / period)) for period in candidates]
    return candidates[int(np.argmax(scores))]


def _candidates(correlation: np.ndarray, lags: np.ndarray, scored: np.ndarray, lo: float, hi: float) -> list[float]:
    """The periods worth comparing: the levels (x1/3 .. x3) of the comb's best few peaks that lie
    in lo..hi frames, each read again on the autocorrelation. A syncopated pattern (a funk kick
    every three sixteenths) can make the comb's best peak a period no level of which is the beat."""
    inner = np.flatnonzero((scored[1:-1] >= scored[:-2]) & (scored[1:-1] > scored[2:])) + 1
    peaks = inner[np.argsort(-scored[inner])][:_PEAKS] if len(inner) else [int(np.argmax(scored))]
    found: list[float] = []
    for peak in peaks:
        best = _refine_lag(correlation, float(lags[peak]))
        for ratio in LEVELS:
            period = _refine_lag(correlation, best / ratio)
            if lo / (1.0 + EDGE) <= period <= hi * (1.0 + EDGE):
                period = float(np.clip(period, lo, hi))
                if all(abs(period / other - 1.0) > EDGE for other in found):
                    found.append(period)
    if found:
        return found
    inside = np.flatnonzero((lags >= lo) & (lags <= hi))
    if len(inside):  # every level lies outside the range: the range's own best lag
        return [_refine_lag(correlation, float(lags[inside[int(np.argmax(scored[inside]))]]))]
    # a range narrower than a frame's lag: the best peak's level nearest to it, at its edge
    levels = [_refine_lag(correlation, float(lags[peaks[0]])) / ratio for ratio in LEVELS]
    return [float(np.clip(min(levels, key=lambda p: abs(math.log(p / float(np.clip(p, lo, hi))))), lo, hi))]


def _comb(correlation: np.ndarray, lags: np.ndarray) -> np.ndarray:
    """The autocorrelation at each lag and its multiples (the nearest frame's, the best of three)."""
    n = len(correlation)
    total = np.zeros(len(lags))
    padded = np.concatenate([correlation, np.zeros(2)])
    for k in range(1, _MULTIPLES + 1):
        at = np.minimum(k * lags, n)
        near = np.maximum.reduce([padded[np.maximum(at - 1, 0)], padded[at], padded[np.minimum(at + 1, n + 1)]])
        total += np.where(k * lags < n, near, 0.0) / k ** 0.5
    return total


def _refine_lag(correlation: np.ndarray, lag: float) -> float:
    """The lag read again on the autocorrelation's peaks at its multiples (to a fraction of a frame)."""
    period = _peak_near(correlation, lag, 1)
    multiple = 2
    while multiple * (period + 1) < len(correlation) // 2 and multiple <= 16:
        period = _peak_near(correlation, multiple * period, max(1, min(2, int(period / 8)))) / multiple
        multiple *= 2
    return period


def _peak_near(values: np.ndarray, where: float, reach: int) -> float:
    lo = max(1, int(round(where)) - reach)
    hi = min(len(values) - 2, int(round(where)) + reach)
    if hi < lo:
        return where
    i = lo + int(np.argmax(values[lo:hi + 1]))
    return i + parabola(values[i - 1], values[i], values[i + 1])


def parabola(left: float, centre: float, right: float) -> float:
    """Where the parabola through three equally spaced points peaks, from the middle one."""
    curve = left - 2.0 * centre + right
    return 0.0 if curve >= 0 else float(np.clip(0.5 * (left - right) / curve, -0.5, 0.5))


def folded(values: np.ndarray, period: float, bins: int = 48) -> np.ndarray:
    """The mean of `values` in each of `bins` phases of `period` (frames), lightly smoothed."""
    phases = (np.arange(len(values)) % period) / period
    index = np.minimum((phases * bins).astype(int), bins - 1)
    sums = np.bincount(index, weights=values, minlength=bins)
    mean = sums / np.maximum(np.bincount(index, minlength=bins), 1)
    return (np.roll(mean, 1) + 2.0 * mean + np.roll(mean, -1)) / 4.0


def explained(onsets: Onsets, period: float, meter: int, harmony: np.ndarray | None) -> float:
    """How well beats every `period` frames explain the onsets (`_pulse_score`, stretch by
    stretch of SEGMENT_BEATS, each at its own phase: a live band's drift, a splice or a period a
    fraction of a percent off moves the phase over a song, and one fold over it all would blur
    the levels unevenly), times how well bars of
    `meter` such beats match the chords' changes."""
    size = int(SEGMENT_BEATS * period)
    count = max(1, (len(onsets.strength) + size // 2) // size)
    starts = (np.linspace(0, len(onsets.strength) - size, min(count, MAX_SEGMENTS)).astype(int) if count > 1 else [0])
    score = float(np.mean([_pulse_score(onsets.strength[a:a + size], onsets.groups[a:a + size, :2],
                                        onsets.snare[a:a + size], period) for a in starts]))
    if harmony is not None:
        scale = len(harmony) / len(onsets.strength)  # chroma frames a bands frame
        blur = 2 * _HARMONY_S * len(harmony) / (len(onsets.strength) / onsets.fps)  # chroma frames
        score *= math.exp(_HARMONY_WEIGHT * _bar_match(harmony, meter * period * scale, period * scale, blur))
    return score


def _pulse_score(strength: np.ndarray, marks: np.ndarray, snare: np.ndarray, period: float) -> float:
    """The weighed onset strength on the beats (at their best phase) less the strongest between
    them, times how alike successive beats are and a snare backbeat. The strongest, not the
    halfway point's: a kick on every sixteenth folded on five sixteenths leaves the halfway point
    empty, and would explain that period as well as the beat."""
    # a bin a frame at most: a wider one dilutes a slow beat's peak
    histogram = folded(strength, period, max(48, int(round(period))))
    bins = len(histogram)
    peak = int(np.argmax(histogram))
    between = float(np.roll(histogram, -peak)[bins // 6: bins - bins // 6].max())  # a sixth of a beat off or more
    alike = min(evenness(marks, period, 2), evenness(marks, period, 3)) ** EVENNESS_POWER
    score = max(float(histogram[peak] - between), 1e-9) * alike
    return score * (1.0 + BACKBEAT_WEIGHT * backbeat(snare, period, peak / bins))


def evenness(marks: np.ndarray, period: float, group: int) -> float:
    """How alike `group` successive beats are: the weakest one's mark over the strongest's, at
    their best phase, a beat's mark being its strongest onset among the bands that mark beats
    (`marks`: the kick's and the snare's, each normalised). Beats every other one of which has
    next to nothing there are a subdivision (eighths under a ballad's quarters: hats alone on
    the ands), not the beat; a kick on 1 and a louder snare on 2 are both beats."""
    bins = 16
    beats = np.max([folded(marks[:, g], group * period, bins * group) for g in range(marks.shape[1])], axis=0)
    beats = beats.reshape(group, bins).T  # row: a phase, columns: the group's beats there
    strongest = beats[int(np.argmax(beats.sum(axis=1)))]
    return float(strongest.min() / max(float(strongest.max()), 1e-12))


def backbeat(snare: np.ndarray, period: float, phase: float) -> float:
    """In 0..1: how much the snare band's onsets fall on every other beat (2 and 4) and not on
    the beats between (1 and 3): the backbeat that most popular music is counted by. A snare on
    every beat is a half-time reading; one on every other eighth, a double-time one."""
    bins = 64
    histogram = folded(snare, 4 * period, bins)
    at = np.round((phase + np.arange(4)) / 4 * bins).astype(int)  # the four beats' bins
    beats = np.max([histogram[(at + d) % bins] for d in (-1, 0, 1)], axis=0)
    loud = float(beats.max())
    if loud <= 0:
        return 0.0
    return float(max(0.0, min(beats[1], beats[3]) - max(beats[0], beats[2]),
                     min(beats[0], beats[2]) - max(beats[1], beats[3])) / loud)


def _harmonic_change(features: Features, fps: float) -> np.ndarray | None:
    """How much the chords change at each chroma frame: the cosine distance between the mean
    chroma of the `_HARMONY_S` before and after it (drums' noise averages out over that), or None
    when the song has next to no pitched sound."""
    # the pads' and chords' chroma only: in the bass band a kick drum is pitched too
    chroma = sustained(features.chroma.astype(np.float64), max(1, int(round(_DRUM_S * features.chroma_fps))))
    width = max(2, int(round(_HARMONY_S * features.chroma_fps)))
    if len(chroma) < 4 * width or not np.any(chroma):
        return None
    sums = np.concatenate([np.zeros((1, 12)), np.cumsum(chroma, axis=0)])
    at = np.arange(width, len(chroma) - width)
    before = sums[at] - sums[at - width]
    after = sums[at + width] - sums[at]
    cosine = np.sum(before * after, axis=1) / (np.linalg.norm(before, axis=1) * np.linalg.norm(after, axis=1) + 1e-12)
    change = np.zeros(len(chroma))
    change[at] = 1.0 - cosine
    change = np.maximum(change - running_mean(change, int(features.chroma_fps * 4)), 0.0)
    return change if np.any(change) else None


def sustained(chroma: np.ndarray, reach: int) -> np.ndarray:
    """Each chroma frame's least value over `reach` frames either side: what sounds on (chords,
    a bass note) stays, a drum's burst of noise across every pitch class goes."""
    out = chroma.copy()
    for shift in range(1, reach + 1):
        out[shift:] = np.minimum(out[shift:], chroma[:-shift])
        out[:-shift] = np.minimum(out[:-shift], chroma[shift:])
    return out


def _bar_match(change: np.ndarray, bar: float, beat: float, blur: float) -> float:
    """In -1..1: how much more the chord changes repeat every `bar` chroma frames than every
    half or third of a bar or every `beat` (chords change on bar lines, rarely in a bar's middle,
    and rarely on every beat: a level whose every beat brings a new chord is the bar, counted as
    beats; one whose bar holds three of the song's bars repeats its changes at a third, and a
    half of it falls mid-bar)."""
    correlation = autocorrelation(change)
    if bar >= len(correlation) - 2 or correlation[0] <= 0:
        return 0.0
    at = int(round(bar))
    at_bar = float(np.max(correlation[at - 1:at + 2]))
    half = correlation[int(round(bar / 2))] if bar >= 2 else 0.0
    if bar / 3 >= blur:
        half = max(half, float(correlation[int(round(bar / 3))]))
    if bar - beat >= 1 and beat >= blur:  # a shorter lag lies within one change's own blur
        half = max(half, float(np.max(correlation[max(0, int(round(beat)) - 1):int(round(beat)) + 2])))
    return float(np.clip((at_bar - half) / correlation[0], -1.0, 1.0))
