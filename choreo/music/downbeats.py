"""Where the bars start: which beats are downbeats, and which one is bar 1 (issue 23).

The bar is heard in more than the bass's loudness, and no one cue is right in every song: a kick
on 1 and 3 makes beats 1 and 3 alike, dembow's kick falls on every beat, a breakdown has no drums,
a pads-only intro has nothing but chords, a metronome has nothing but a louder click. So several
cues each say, beat by beat, how much that beat sounds like the one:

- harmony, harmony/bar: chords change on bar lines. The pitch classes over the beat (the bar)
  after each eighth are compared with those over the beat (the bar) before it, what repeats
  every bar taken out first; a change in the half beat before a beat belongs to it: a chord
  anticipated by an eighth.
- bass, bass/bar: the bass notes (`bass_chroma`) change on bar lines, compared the same way.
- kick: low-band onsets (kick drum, bass-note attacks) on the beat.
- backbeat: a snare on the beat speaks against it being the one (backbeat on 2 and 4).
- sections: the whole sound (drums coming in, a breakdown ending) changes on bar lines.
- accent: the beat's whole onset (a metronome's louder click).

Each cue counts as far as the song has it (pitch classes that vary at all; low onsets that are
not leakage; a snare band that rises as noise; a pattern on the beats that stands out by a share
of the cue's own hits), so a cue a song lacks does not vote with its artefacts. The meter's
phases (phase p: the beats whose index modulo the meter is p) are scored jointly over all cues,
each cue's evidence in standard errors (a t statistic: no cue weighs more for its units),
capped, and less what chance gives, in stretches of about WINDOW_BEATS beats. That learns the
bar's pattern of each cue over the song; then every beat's place in the bar is decided along the
likeliest path through the beats (a hidden Markov model: from each place to the next, or over to
another place at a cost, for a beat the tracker added or missed, or an odd bar; cheap only where
a beat's interval is off the local beat, as an extra or a missed beat leaves it), each beat's
cue values against the pattern, so bar 1 is where the song's opening says, not where the
majority of its bars would put it after a slip.

Bar 1 is the first beat at that phase where the music has begun: `music_start` is the first
moment a band rises above its own noise floor, so a fade-in from silence begins bar 1 where it
becomes audible at all, not where it reaches some share of the peak.

The work is per beat and per feature frame, never per sample: an hour of audio is a few thousand
beats (under a second, and 25 MB besides the features).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from choreo.errors import UsageError
from choreo.music.features import Features
from choreo.music.tempo import running_mean

CUES = ("harmony", "bass", "harmony/bar", "bass/bar", "kick", "backbeat", "sections", "accent")
WEIGHTS = {"harmony": 0.5, "bass": 0.5, "harmony/bar": 0.5, "bass/bar": 0.5, "kick": 1.0, "backbeat": 1.0,
           "sections": 0.5, "accent": 0.5}
# The pitch classes' spread over a song (mean cosine distance from their mean shape, a row each
# half beat) under which they carry no harmony (a click track: 0.005) and over which they do
# (the generated songs: 0.03 to 0.35).
VARIETY = (0.01, 0.025)
PATTERN_BARS = 9  # what repeats every bar is measured over this many bars around each
HIT_PERCENTILE = 95  # a hit of a drum: this percentile of its rises over every sixteenth
# An onset cue's phases differ by less than SALIENT[0] of a hit: not a pattern of the beats (a
# dembow's or four on the floor's: about 0.05); by SALIENT[1] or more: one (a backbeat: 0.6 to 1).
SALIENT = (0.1, 0.3)
WINDOW_BEATS = 16  # the phase is scored in stretches of this many beats (whole bars, at least)
SWITCH = 4.0  # what going over to another phase costs between stretches, in their evidence
BEAT_SWITCH = 8.0  # and between beats, in their log-likelihoods
BEAT_SLIP = 2.0  # and after a beat whose interval to the next is off the local beat by more than
SLIP = 0.15  # this (natural log: 16 %), the median of SLIP_NEIGHBOURS intervals either side
SLIP_NEIGHBOURS = 8
BEAT_CAP = 2.0  # a cue's log-likelihood for one beat's place in the bar counts up to this much
CAP = 4.0  # a cue's evidence for a phase, in standard errors, counts up to this much
CHANCE = 1.0  # standard errors of evidence that chance alone gives a cue: they do not count
ONSET_REACH_S = 0.04  # an onset this near a beat is on it (a tracker's beats are ~10 ms off)
KICK_HZ = (30.0, 150.0)  # kick drums and bass-note attacks
# A snare's noise (hats sound on every beat alike); lower than tempo.SNARE_HZ, which keeps pitched
# sound out of its backbeat: here a tone is told from noise by its flatness (`_noise_trust`)
BACKBEAT_HZ = (1000.0, 5000.0)
# The spectral flatness of the rises there (geometric over arithmetic mean across the bands): a
# tone's (a click, a piano) is about 0.4 or less, a snare's or a hat's noise 0.9 or more.
FLAT_TONE, FLAT_NOISE = 0.5, 0.8
# A kick's or a bass note's rise in the low bands, over the rise of the loudest band (each summed
# over its frequencies), is 1 or more at some beats; leakage from higher sounds a few hundredths.
LOW_LEAK, LOW_SOUND = 0.1, 0.3
NOISE_FLOOR_DB = 12.0  # the music starts where a band rises this much above the silence's level there
QUIETEST_S = 0.1  # the sound is measured in stretches this long, band by band
QUIET_STRETCHES = 3  # the noise floor: the quietest this many stretches in a row
# Below the song's loudest, a floor deeper than this (digital silence) is taken as this: float32
# audio is exact to about -140 dB.
DEEPEST_DB = -120.0
EARLY_BEAT = 0.4  # a downbeat up to this share of a beat before `music_start` may be bar 1
EARLY_S = 0.05  # and at least this much before (an attack's rise, the analysis window)
_BLOCK_BEATS = 2048  # beats whose onsets are measured at once
# A log-likelihood under this for the likeliest phase over the next (less than one beat's
# BEAT_CAP): no cue tells the bar (a metronome without accents), and bar 1 is the music's first beat
UNDECIDED = 1.0
MIN_VOTING = 0.25  # a cue is named in `by` when it gave this share of the winning margin


@dataclass(frozen=True)
class Cue:
    """One cue's value at each beat (NaN where it cannot be told, as a bar window past an end),
    and how far this song lets it be trusted (0..1: a song without drums has no backbeat)."""

    values: np.ndarray
    trust: float = 1.0
    hit: float = 0.0  # what a clear hit of this cue measures in this song (0: no such scale)
    reach: int = 0  # the beats before a beat that its value draws on (a change: the ones before it)

    def usable(self, heard: np.ndarray) -> np.ndarray:
        """The beats whose value was drawn from the music alone: the beat and the `reach` before
        it heard, the value known (a change measured against the silence before is no change)."""
        before = np.zeros(len(heard), dtype=bool)
        before[self.reach:] = heard[:max(len(heard) - self.reach, 0)]
        return np.asarray(before & heard & np.isfinite(self.values))


@dataclass(frozen=True)
class Downbeats:
    """Bar 1 among the tracked beats, and how sure that is."""

    first: int  # index in beat_times of bar 1 beat 1: the first downbeat at or after the music starts
    # The chosen phase's log-likelihood over the runner-up's (natural log) on the beats up to the
    # first change of phase; under UNDECIDED, no cue told and bar 1 is the music's first beat; None: meter 1
    contrast: float | None
    by: str  # the cues that decided, strongest first, joined by "+" ("" when none did)
    other_first: int | None  # bar 1 at the next likeliest phase (None: meter 1)


def find_downbeats(features: Features, beat_times: np.ndarray, meter: int) -> Downbeats:
    """Bar 1 among `beat_times` (every tracked beat in seconds, ascending; it may start before the
    music) with `meter` beats a bar."""
    beats = np.asarray(beat_times, dtype=np.float64)
    if beats.ndim != 1 or len(beats) == 0:
        raise UsageError("no beats to find the bars among: the song needs a beat first")
    start = music_start(features)
    if meter <= 1:
        return Downbeats(_first_from(beats, 0, 1, start), None, "", None)
    cues = beat_cues(features, beats, meter)
    heard = beats >= start - _early(beats)
    evidence = phase_evidence(features, beats, meter, start, cues)
    scores = np.sum([WEIGHTS[name] * evidence[name] for name in CUES], axis=0)
    windows = _windows(heard, meter)
    costs = np.full(len(scores), SWITCH)
    stretches = _best_paths(scores, costs)
    phase_of = _path(stretches, int(np.argmax(stretches[0])), costs)[windows]
    emissions = _emissions(cues, heard, meter, (np.arange(len(beats)) - phase_of) % meter)
    places = _places(emissions, _switch_costs(beats))
    sums = _rigid_sums(emissions, places)  # cue x shift of every place in the bar
    shift = 1 + int(np.argmax(sums.sum(axis=0)[1:]))  # the runner-up: the bar shifted by this
    margins = {name: float(sums[c, 0] - sums[c, shift]) for c, name in enumerate(CUES)}
    best, runner_up = (-int(places[0])) % meter, (-int(places[0]) - shift) % meter
    first, other = _first_from(beats, best, meter, start), _first_from(beats, runner_up, meter, start)
    contrast = float(sum(margins.values()))
    if contrast >= UNDECIDED:
        return Downbeats(first, round(contrast, 2), _deciders(margins), other)
    opening = _first_from(beats, 0, 1, start)  # no cue tells: a song starts on its one
    return Downbeats(opening, round(contrast, 2) if opening == first else 0.0, "", first if opening != first else other)


def _places(emissions: dict[str, np.ndarray], costs: np.ndarray) -> np.ndarray:
    """Each beat's place in the bar (0: the one) along the likeliest path through the beats: from
    place to next place, beat by beat, or over to any other place at a cost (`_switch_costs`)."""
    likelihood = np.sum(list(emissions.values()), axis=0)
    totals = _best_paths(likelihood, costs, cyclic=True)
    return _path(totals, int(np.argmax(totals[0])), costs, cyclic=True)


def _rigid_sums(emissions: dict[str, np.ndarray], places: np.ndarray) -> np.ndarray:
    """Each cue's log-likelihood (cues x meter) over the beats up to the path's first change of
    phase, for the path's places (shift 0) and for them shifted by each number of beats: how
    much likelier bar 1's phase is than each other, and by which cue."""
    meter = emissions[CUES[0]].shape[1]
    steps = np.flatnonzero(places[1:] != (places[:-1] + 1) % meter)
    end = int(steps[0]) + 1 if len(steps) else len(places)
    rows = np.arange(end)
    return np.array([[float(np.sum(emissions[name][rows, (places[:end] + shift) % meter])) for shift in range(meter)]
                     for name in CUES])


def _emissions(cues: dict[str, Cue], heard: np.ndarray, meter: int, position: np.ndarray) -> dict[str, np.ndarray]:
    """Each cue's log-likelihood (beats x meter) of each beat being at each place in the bar (0:
    the one): the bar's pattern of the cue (its mean at each place, where `position` puts the
    beats) against the beat's value, in standard deviations within places; no more than BEAT_CAP
    a beat, weighed by WEIGHTS and the cue's trust and salience."""
    out = {}
    for name in CUES:
        cue, ok = cues[name], cues[name].usable(heard)
        if np.count_nonzero(ok) <= meter:
            out[name] = np.zeros((len(heard), meter))
            continue
        x, place = cue.values[ok], position[ok]
        n = np.bincount(place, minlength=meter).astype(np.float64)
        pattern = np.bincount(place, weights=x, minlength=meter) / np.maximum(n, 1.0)
        spread = np.sqrt(np.sum((x - pattern[place]) ** 2) / max(len(x) - meter, 1))
        spread = max(spread, 0.05 * float(np.std(x)), 1e-12)
        values = np.where(ok, np.nan_to_num(cue.values), 0.0)
        distance = np.minimum(((values[:, None] - pattern[None, :]) / spread) ** 2 / 2.0, BEAT_CAP)
        gain = WEIGHTS[name] * cue.trust * _salience(cue, pattern)
        out[name] = np.where(ok[:, None], -gain * distance, 0.0)
    return out


def _salience(cue: Cue, pattern: np.ndarray) -> float:
    """How far the cue's pattern over the bar stands out, 0..1: by SALIENT of a hit of its own
    (1 for cues without such a scale)."""
    if cue.hit <= 0:
        return 1.0
    share = float(pattern.max() - pattern.min()) / cue.hit
    return float(np.clip((share - SALIENT[0]) / (SALIENT[1] - SALIENT[0]), 0.0, 1.0))


def _windows(heard: np.ndarray, meter: int) -> np.ndarray:
    """Each beat's stretch: about WINDOW_BEATS beats (whole bars) from the first heard beat on."""
    first = int(np.argmax(heard)) if np.any(heard) else len(heard)
    width = meter * max(1, -(-WINDOW_BEATS // meter))
    return np.asarray(np.maximum(np.arange(len(heard)) - first, 0) // width)


def _best_paths(scores: np.ndarray, costs: np.ndarray, cyclic: bool = False) -> np.ndarray:
    """totals[i, k]: the best sum of scores from row i on with state k in row i. A state goes on
    to itself (a phase from stretch to stretch) or, `cyclic`, to the next place in the bar (beat
    to beat); going over to any other after row i costs costs[i] (a tracker's extra or missed
    beat, an odd bar)."""
    totals = np.zeros_like(scores)
    ahead = np.zeros(scores.shape[1])
    for i in range(len(scores) - 1, -1, -1):
        follow = np.roll(ahead, -1) if cyclic else ahead
        totals[i] = scores[i] + (np.maximum(follow, ahead.max() - costs[i]) if i < len(costs) else 0.0)
        ahead = totals[i]
    return totals


def _path(totals: np.ndarray, state: int, costs: np.ndarray, cyclic: bool = False) -> np.ndarray:
    """The state in each row along the best path that starts in `state`."""
    path = np.empty(len(totals), dtype=np.int64)
    path[0] = state
    for i in range(1, len(totals)):
        follow = (path[i - 1] + 1) % totals.shape[1] if cyclic else path[i - 1]
        keep = totals[i, follow] >= totals[i].max() - costs[i - 1]
        path[i] = follow if keep else int(np.argmax(totals[i]))
    return path


def _switch_costs(beats: np.ndarray) -> np.ndarray:
    """What a change of place costs after each beat: BEAT_SWITCH, or BEAT_SLIP where the beat to
    the next is off the local beat (the median of SLIP_NEIGHBOURS either side) by more than SLIP:
    an extra beat halves an interval, a missed one doubles it."""
    steps = np.diff(beats)
    if len(steps) == 0:
        return np.zeros(0)
    padded = np.pad(steps, SLIP_NEIGHBOURS, mode="edge")
    local = np.median(np.lib.stride_tricks.sliding_window_view(padded, 2 * SLIP_NEIGHBOURS + 1), axis=1)
    off = np.abs(np.log(np.maximum(steps, 1e-6) / np.maximum(local, 1e-6)))
    return np.where(off > SLIP, BEAT_SLIP, BEAT_SWITCH)


def phase_evidence(features: Features, beats: np.ndarray, meter: int, start: float,
                   cues: dict[str, Cue] | None = None) -> dict[str, np.ndarray]:
    """Each cue's evidence for each phase (capped standard errors; higher: likelier the one) in
    each stretch of about WINDOW_BEATS beats from the music's start (stretches x meter)."""
    cues = cues or beat_cues(features, beats, meter)
    heard = beats >= start - _early(beats)
    windows = _windows(heard, meter)
    phases = np.arange(len(beats)) % meter
    count = int(windows[-1]) + 1
    return {name: cues[name].trust * _phase_t(cues[name], phases, heard, windows, count, meter) for name in CUES}


def beat_cues(features: Features, beats: np.ndarray, meter: int) -> dict[str, Cue]:
    """Each cue's value at each beat, and how far the song lets it be trusted."""
    chroma_at = _frame_times(len(features.chroma), features.chroma_fps)
    band_at = _frame_times(len(features.bands), features.fps)
    return {
        "harmony": _changes(features.chroma, chroma_at, beats, meter, 1),
        "bass": _changes(features.bass_chroma, chroma_at, beats, meter, 1),
        "harmony/bar": _changes(features.chroma, chroma_at, beats, meter, meter),
        "bass/bar": _changes(features.bass_chroma, chroma_at, beats, meter, meter),
        **_onset_cues(features, beats),
        "sections": Cue(_novelty(_beat_means(features.bands, band_at, beats), meter), reach=meter),
    }


def _onset_cues(features: Features, beats: np.ndarray) -> dict[str, Cue]:
    """The kick, the backbeat and the accent at each beat, each with the size of a hit of its own
    (its HIT_PERCENTILE over every sixteenth of the song): a pattern of the beats counts as far
    as it stands out by a hit's share, so that a dembow's snare, which never falls on a beat,
    does not vote by the ringing of its off-beat hits."""
    width = np.diff(features.band_hz, axis=1)[:, 0]  # a band's rise summed over its frequencies
    low, noise = features.band_range(*KICK_HZ), features.band_range(*BACKBEAT_HZ)

    def values(rises: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        return rises[:, low].mean(axis=1), np.median(rises[:, noise], axis=1), (rises * width).sum(axis=1)

    rises = _rises_at(features, beats)
    at_beats, hits = values(rises), values(_rises_at(features, _sixteenths(beats)))
    size = [float(np.percentile(h, HIT_PERCENTILE)) if len(h) else 0.0 for h in hits]
    summed = rises * width
    return {
        "kick": Cue(at_beats[0], _low_trust(summed[:, low].sum(axis=1), summed.max(axis=1)), size[0]),
        "backbeat": Cue(-at_beats[1], _noise_trust(rises[:, noise]), size[1]),
        "accent": Cue(at_beats[2], 1.0, size[2]),
    }


def _sixteenths(beats: np.ndarray) -> np.ndarray:
    """Each beat and the three sixteenths after it (the last beat alone)."""
    if len(beats) < 2:
        return beats
    steps = np.diff(beats)[:, None] * np.arange(4)[None, :] / 4.0
    return np.append((beats[:-1, None] + steps).ravel(), beats[-1])


def _frame_times(count: int, fps: float) -> np.ndarray:
    return np.arange(count) / fps


def _beat_means(frames: np.ndarray, times: np.ndarray, beats: np.ndarray) -> np.ndarray:
    """The mean of `frames` over each beat (from it to the next; the last beat as long as the one
    before it), a row a beat; a beat with no frame in it takes the nearest frame. Summed a beat
    at a time, never copying `frames` (an hour's bands are 50 MB)."""
    ends = np.append(beats[1:], beats[-1] + (beats[-1] - beats[-2] if len(beats) > 1 else 0.5))
    last = len(frames) - 1
    lo = np.clip(np.searchsorted(times, beats), 0, last)
    hi = np.clip(np.maximum(np.searchsorted(times, ends), lo + 1), 1, last + 1)
    lo = np.minimum(lo, hi - 1)
    bounds = np.empty(2 * len(lo), dtype=np.int64)
    bounds[0::2], bounds[1::2] = lo, np.minimum(hi, last)  # a beat's sum, then the gap to the next
    sums = np.add.reduceat(frames, bounds, axis=0)[0::2].astype(np.float64)  # a beat: float32 is exact enough
    whole = hi > last  # reaching the last frame: reduceat stopped before it
    sums[whole] += frames[last]
    sums[hi - lo == 1] = frames[lo[hi - lo == 1]]
    return np.asarray(sums / (hi - lo)[:, None])


def _changes(frames: np.ndarray, times: np.ndarray, beats: np.ndarray, meter: int, span: int) -> Cue:
    """How much the pitch classes change at each beat or in the half beat before it (a chord
    anticipated by an eighth belongs to the bar line after it): the distance between their shape
    over the `span` beats after each eighth and the `span` before it, the larger of the two
    eighths. A span of 1 is sharp (the chord's own beat); a bar's is steady under a walking bass
    or an arpeggio, whose notes change every beat within a chord. What repeats every bar (a
    pitched kick drum, a comping pattern) is taken out first: it changes at the same place in
    every bar, whichever place the bar starts at. Trusted as far as the pitch classes vary at all
    (a click track's never do)."""
    if len(beats) < 2:
        return Cue(np.full(len(beats), np.nan), 0.0)
    last = beats[-1] + (beats[-1] - beats[-2])
    edges = np.concatenate([beats, [last]])
    grid = np.empty(2 * len(edges) - 1)
    grid[0::2], grid[1::2] = edges, (edges[:-1] + edges[1:]) / 2
    slots = _beat_means(frames, times, grid)[:-1]  # one a half beat
    loudness = running_mean(np.linalg.norm(slots, axis=1), 2 * meter)[:, None]
    shapes = np.divide(slots, loudness, out=np.zeros_like(slots), where=loudness > 0)
    residual = shapes - _bar_pattern(shapes, 2 * meter)
    novelty = _novelty(residual, 2 * span)  # at each eighth
    on_beat = novelty[0::2][:len(beats)]
    before = np.concatenate([[np.nan], novelty[1::2]])[:len(beats)]
    return Cue(np.fmax(on_beat, before), _variety(slots), reach=span + 1)  # NaN only where both are


def _variety(rows: np.ndarray) -> float:
    """How much the pitch classes vary over the song, 0..1: the mean cosine distance of each
    sounding row's shape from the song's mean shape, scaled by VARIETY."""
    norms = np.linalg.norm(rows, axis=1)
    sounding = norms > 1e-6 * max(float(norms.max(initial=0.0)), 1e-30)
    if np.count_nonzero(sounding) < 2:
        return 0.0
    shapes = rows[sounding] / norms[sounding, None]
    mean = shapes.mean(axis=0)
    spread = float(np.mean(1.0 - shapes @ (mean / max(float(np.linalg.norm(mean)), 1e-30))))
    return float(np.clip((spread - VARIETY[0]) / (VARIETY[1] - VARIETY[0]), 0.0, 1.0))


def _bar_pattern(rows: np.ndarray, period: int) -> np.ndarray:
    """The mean of `rows` at each place in a `period` (rows i, i + period, ...) over the
    PATTERN_BARS periods around each, row by row: what repeats bar after bar where it is, so that a
    section's own drum pattern, or a tracker's extra beat that shifts the places, leaves the rest
    of the song alone."""
    count = -(-len(rows) // period)
    padded = np.zeros((count * period, rows.shape[1]))
    padded[:len(rows)] = rows
    sums = np.concatenate([np.zeros((1, period, rows.shape[1])),
                           np.cumsum(padded.reshape(count, period, -1), axis=0)])
    index = np.arange(count)
    lo = np.maximum(index - PATTERN_BARS // 2, 0)
    hi = np.minimum(index + PATTERN_BARS // 2 + 1, count)
    counts = (hi - lo)[:, None].astype(np.float64)
    if len(rows) % period:  # the last period's missing rows are not zeros to average in
        last = np.zeros(period)
        last[len(rows) % period:] = 1.0
        counts = counts - np.clip(hi - count + 1, 0, None)[:, None] * last[None, :]
    means = (sums[hi] - sums[lo]) / np.maximum(counts, 1.0)[:, :, None]
    return np.asarray(means.reshape(count * period, -1)[:len(rows)])


def _novelty(per_beat: np.ndarray, meter: int) -> np.ndarray:
    """How different the bar after each beat sounds from the bar before it: the distance between
    their means (NaN where either bar runs past the beats)."""
    count = len(per_beat)
    out = np.full(count, np.nan)
    if count < 2 * meter:
        return out
    sums = np.concatenate([np.zeros((1, per_beat.shape[1])), np.cumsum(per_beat, axis=0)])
    bars = (sums[meter:] - sums[:-meter]) / meter  # bars[i]: the bar from beat i on
    after, before = bars[meter:], bars[:-meter]  # the bars after and before beats meter..count-meter
    out[meter:count - meter + 1] = np.linalg.norm(after - before, axis=1)
    return out


def _rises_at(features: Features, beats: np.ndarray) -> np.ndarray:
    """The strongest rise of each band's magnitude from one frame to the next within
    ONSET_REACH_S of each beat (beats x bands). In magnitude, not its log: a kick adds as much
    over a bass note held from an eighth before as over silence."""
    if len(features.bands) < 2:
        return np.zeros((len(beats), features.bands.shape[1]))
    reach = max(1, int(round(ONSET_REACH_S * features.fps)))
    centre = np.round(beats * features.fps).astype(np.int64)
    out = np.empty((len(beats), features.bands.shape[1]))
    for first in range(0, len(beats), _BLOCK_BEATS):  # a block at a time: an hour's sixteenths are many
        near = centre[first:first + _BLOCK_BEATS, None] + np.arange(-reach - 1, reach + 1)[None, :]
        levels = np.expm1(features.bands[np.clip(near, 0, len(features.bands) - 1)])  # beats x frames x bands
        out[first:first + _BLOCK_BEATS] = np.diff(levels, axis=1).max(axis=1).clip(0.0, None)
    return out


def _low_trust(low_sums: np.ndarray, loudest: np.ndarray) -> float:
    """How far low onsets (kick drums, bass notes) can be told in this song: they can where some
    onsets sound mostly low, not where all that rises there is leakage from a click or a hat."""
    share = low_sums / np.maximum(loudest, 1e-12)
    lows = float(np.percentile(share, 90)) if len(share) else 0.0
    return float(np.clip((lows - LOW_LEAK) / (LOW_SOUND - LOW_LEAK), 0.0, 1.0))


def _noise_trust(rises: np.ndarray) -> float:
    """How far a snare can be told in this song: by how noise-like its rises in the snare's bands
    are (their spectral flatness, beats x bands); a click's or a piano's tone rises in one band
    and leaks into the others."""
    if rises.size == 0:
        return 0.0
    flatness = np.exp(np.mean(np.log(rises + 1e-12), axis=1)) / (rises.mean(axis=1) + 1e-12)
    return float(np.clip((float(np.median(flatness)) - FLAT_TONE) / (FLAT_NOISE - FLAT_TONE), 0.0, 1.0))


def _phase_t(cue: Cue, phases: np.ndarray, heard: np.ndarray, windows: np.ndarray, count: int,
             meter: int) -> np.ndarray:
    """Evidence for each phase in each stretch from one cue's beat values: the phase's mean over
    the mean of all phases, in standard errors of the spread within phases; capped at +-CAP,
    less the CHANCE share, and scaled down where the phases differ over the song by less than
    SALIENT of a hit; 0 without data (stretches x meter)."""
    usable = cue.usable(heard)
    x, cell = cue.values[usable], windows[usable] * meter + phases[usable]
    if len(x) <= meter:
        return np.zeros((count, meter))
    n = np.bincount(cell, minlength=count * meter).reshape(count, meter).astype(np.float64)
    sums = np.bincount(cell, weights=x, minlength=count * meter).reshape(count, meter)
    squares = np.bincount(cell, weights=x * x, minlength=count * meter).reshape(count, meter)
    means = sums / np.maximum(n, 1.0)
    inside = np.maximum(squares - sums * means, 0.0).sum(axis=1)  # squares about each phase's mean
    dof = n.sum(axis=1) - meter
    spread = np.sqrt(inside / np.maximum(dof, 1.0))
    spread = np.maximum(spread, max(0.05 * float(np.std(x)), 1e-12))[:, None]
    t = np.clip((means - means.mean(axis=1, keepdims=True)) / (spread / np.sqrt(np.maximum(n, 1.0))), -CAP, CAP)
    t[(n.min(axis=1) == 0) | (dof <= 0)] = 0.0
    evidence = np.sign(t) * np.maximum(np.abs(t) - CHANCE, 0.0)
    return np.asarray(evidence * _salience(cue, sums.sum(axis=0) / np.maximum(n.sum(axis=0), 1.0)))


def _deciders(margins: dict[str, float]) -> str:
    """The cues that favoured the winner over the runner-up by MIN_VOTING of the margin or more
    (a cue's changes over a beat and over a bar, "harmony" and "harmony/bar", count as one)."""
    kinds: dict[str, float] = {}
    for name, margin in margins.items():
        kinds[name.split("/")[0]] = kinds.get(name.split("/")[0], 0.0) + margin
    margins = kinds
    total = sum(m for m in margins.values() if m > 0)
    if total <= 0:
        return ""
    named = sorted((m, name) for name, m in margins.items() if m >= MIN_VOTING * total)
    return "+".join(name for _, name in reversed(named))


def _early(beats: np.ndarray) -> float:
    """How far before `music_start` a downbeat may fall and still be bar 1."""
    beat_s = float(np.median(np.diff(beats))) if len(beats) > 1 else 0.0
    return max(EARLY_S, EARLY_BEAT * beat_s)


def _first_from(beats: np.ndarray, phase: int, meter: int, start: float) -> int:
    """The first beat at `phase` at or after the music starts (the last such beat if the music
    starts after them all, the first beat if there is none at that phase)."""
    at_phase = np.arange(phase, len(beats), meter)
    if len(at_phase) == 0:
        return 0
    after = at_phase[beats[at_phase] >= start - _early(beats)]
    return int(after[0]) if len(after) else int(at_phase[-1])


def music_start(features: Features) -> float:
    """Seconds from the file's start where the music begins: the first moment any band rises
    NOISE_FLOOR_DB above that band's quietest stretch (the recording's noise floor there, or
    digital silence), so a fade-in begins where it is first heard at all. Band by band, because
    a pad's first notes stand out of a hiss in their own band long before they outweigh it whole."""
    bands = features.bands
    if len(bands) == 0 or features.peak <= 0:
        return 0.0
    width = max(1, min(len(bands), int(round(QUIETEST_S * features.fps))))
    stretches = np.expm1(bands[: len(bands) // width * width].reshape(-1, width, bands.shape[1])
                         .mean(axis=1, dtype=np.float64))  # each band's mean magnitude a stretch
    floor = np.maximum(_quietest(stretches), stretches.max() * 10.0 ** (DEEPEST_DB / 20.0))
    threshold = floor * 10.0 ** (NOISE_FLOOR_DB / 20.0)
    loud = np.flatnonzero(np.any(stretches > threshold, axis=1))
    if len(loud) == 0:
        return 0.0
    # The first frame above the threshold, in the stretch before the first loud one or in it
    lo = max(0, int(loud[0]) - 1) * width
    frames = np.expm1(bands[lo: lo + 2 * width].astype(np.float64))
    first = lo + int(np.argmax(np.any(frames > threshold, axis=1)))
    # A frame hears half a window ahead of its centre: the sound began between the previous
    # frame's leading edge and this one's.
    lead = (features.hop * 1.5) / features.sample_rate
    return max(0.0, first / features.fps + lead)


def _quietest(stretches: np.ndarray) -> np.ndarray:
    """Each band's mean level over the song's quietest QUIET_STRETCHES stretches in a row (all
    bands together): the noise floor, measured long enough that its own flicker stays under
    NOISE_FLOOR_DB (the quietest single stretch of each band would be a dip of the noise)."""
    run = min(QUIET_STRETCHES, len(stretches))
    totals = np.concatenate([[0.0], np.cumsum(stretches.sum(axis=1))])
    begin = int(np.argmin(totals[run:] - totals[:-run]))
    return np.asarray(stretches[begin:begin + run].mean(axis=0))
