"""Every beat of a song, where the tempo drifts, slows or changes (Ellis 2007's dynamic programming,
on a local tempo).

1. Local tempo: the onset strength's autocorrelation over windows of `WINDOW_S` every `STEP_S`
   (a tempogram, each lag summed with its double), at lags around the chosen period and pulled
   towards it, and the likeliest path through it (Viterbi: a change of tempo costs by its size,
   so a live band's 1 % drift, a ritardando and a sudden change are followed, but one bar's fill
   does not move the tempo). A path that stays far from the chosen period has locked onto a
   syncopation's period (a dembow's, a broken beat's) and is not used.
2. Beats: each frame's best score is its onset strength plus the best score of a frame one local
   period or so earlier, less a cost for the interval's departure from that period; the best end
   traced back gives every beat, through breakdowns and quiet intros alike (the cost keeps the
   beat going where no onset leads it).
3. Each beat is then moved onto the sharpest attack within `SNAP_S` of it in the fine attack
   envelope, when a significant one is there: a frame is 11.6 ms, an attack step 1.45 ms.
"""

from __future__ import annotations

import math

import numpy as np

from choreo.music.features import Features
from choreo.music.tempo import parabola

WINDOW_S = 7.0  # the tempogram's window
STEP_S = 0.5  # its step
TEMPO_SPAN = (0.7, 1.45)  # the local period is sought between these times the song's period
COMB = 2  # the tempogram sums the autocorrelation at each lag's multiples up to this
ASTRAY = 0.08  # a local tempo whose median is this far (log) from the song's is not the song's beat
PULL = 8.0  # how much a local period far from the song's counts less (squared log ratio, on the window's best)
CHANGE_COST = 12.0  # Viterbi: cost of a change of the period by a factor e (on unit-peak evidence)
TIGHTNESS = 200.0  # Ellis's: how much an interval off the local period costs (squared log ratio)
SNAP_S = 0.025  # a beat moves to an attack this near it
SIGNIFICANT = 4.0  # robust deviations of the attack envelope that make an attack
MIN_RISE = 0.25  # and at least this rise of log energy in a step (clean material's deviations are 0)


def local_periods(strength: np.ndarray, fps: float, period: float) -> np.ndarray:
    """The beat period (frames) at every frame, from the Viterbi path through the tempogram."""
    lags = np.arange(max(2, int(TEMPO_SPAN[0] * period)), int(math.ceil(TEMPO_SPAN[1] * period)) + 2)
    window = max(int(WINDOW_S * fps), int(2 * lags[-1]))
    step = max(1, int(STEP_S * fps))
    n = len(strength)
    if n < window + COMB * lags[-1]:
        return np.full(n, period)
    centred = strength - strength.mean()
    starts = np.arange(0, n - window - COMB * lags[-1] + 1, step)
    energy = _window_sums(centred * centred, window, starts)

    def gram_at(lag: int) -> np.ndarray:
        return _window_sums(centred[:n - lag] * centred[lag:], window, starts) / (energy + 1e-12)

    # the comb: a beat's period repeats at its multiples, a syncopation's (a dembow's three
    # sixteenths, a broken beat's kicks) at few of them
    gram = np.stack([sum(np.maximum(gram_at(k * lag), 0.0) for k in range(1, COMB + 1)) for lag in lags.tolist()],
                    axis=1)
    gram -= PULL * np.log(lags / period)[None, :] ** 2 * gram.max(axis=1, keepdims=True)
    path = _viterbi(gram, np.log(lags.astype(float)))
    fine = np.array([lag + _vertex(gram[i], lag) for i, lag in enumerate(path)]) + lags[0]
    if abs(math.log(float(np.median(fine)) / period)) > ASTRAY:
        return np.full(n, period)  # locked onto a syncopation's period, not the song's beat
    centres = starts + window / 2
    return np.interp(np.arange(n), centres, fine)


def _window_sums(values: np.ndarray, window: int, starts: np.ndarray) -> np.ndarray:
    """The sum of `values` over `window` frames from each start, from one running sum: every
    window of the tempogram at a lag in O(frames), never frames x window."""
    sums = np.concatenate([[0.0], np.cumsum(values, dtype=np.float64)])
    ends = np.minimum(starts + window, len(values))
    return sums[ends] - sums[np.minimum(starts, len(values))]


def _viterbi(gram: np.ndarray, log_lags: np.ndarray) -> np.ndarray:
    """The index of the lag at each window on the best path: evidence (each window's
    autocorrelation, scaled to its best lag) less CHANGE_COST per unit of log-period moved."""
    evidence = gram / (gram.max(axis=1, keepdims=True) + 1e-12)
    cost = CHANGE_COST * np.abs(log_lags[:, None] - log_lags[None, :])  # from (rows) to (columns)
    score = evidence[0].copy()
    back = np.zeros(gram.shape, dtype=np.int32)
    for i in range(1, len(gram)):
        options = score[:, None] - cost
        back[i] = np.argmax(options, axis=0)
        score = options[back[i], np.arange(len(score))] + evidence[i]
    path = np.zeros(len(gram), dtype=np.int32)
    path[-1] = int(np.argmax(score))
    for i in range(len(gram) - 1, 0, -1):
        path[i - 1] = back[i, path[i]]
    return path


def _vertex(row: np.ndarray, i: int) -> float:
    """Where the peak at `i` lies between frames (0 at either end of `row`)."""
    return parabola(row[i - 1], row[i], row[i + 1]) if 0 < i < len(row) - 1 else 0.0


def beat_frames(strength: np.ndarray, periods: np.ndarray) -> np.ndarray:
    """Ellis's dynamic programming over frames with the local period: the frames of every beat.

    Frames are scored a block of the shortest interval at a time (no beat in a block can follow
    another in the same block), so the work is numpy's: O(frames x intervals)."""
    n = len(strength)
    scale = float(np.std(strength)) or 1.0
    onset = strength / scale
    shortest = max(1, int(0.5 * periods.min()))
    longest = int(math.ceil(2.0 * periods.max()))
    gaps = np.arange(shortest, longest + 1)
    score = onset.astype(np.float64).copy()
    back = np.full(n, -1, dtype=np.int64)
    for t0 in range(shortest, n, shortest):
        t = np.arange(t0, min(n, t0 + shortest))
        before = t[:, None] - gaps[None, :]
        penalty = TIGHTNESS * np.log(gaps[None, :] / periods[t][:, None]) ** 2
        options = np.where(before >= 0, score[np.maximum(before, 0)] - penalty, -np.inf)
        best = np.argmax(options, axis=1)
        value = options[np.arange(len(t)), best]
        found = value > 0  # a beat starts afresh where no earlier one leads to it with gain
        score[t] = onset[t] + np.where(found, value, 0.0)
        back[t] = np.where(found, before[np.arange(len(t)), best], -1)
    return _traced(score, back, periods)


def _traced(score: np.ndarray, back: np.ndarray, periods: np.ndarray) -> np.ndarray:
    """The beats back from the best-scored frame within the last period."""
    n = len(score)
    tail = max(1, int(round(periods[-1])))
    frame = n - tail + int(np.argmax(score[n - tail:]))
    frames = [frame]
    while back[frames[-1]] >= 0:
        frames.append(int(back[frames[-1]]))
    return np.array(frames[::-1], dtype=np.int64)


def snapped(times: np.ndarray, features: Features) -> tuple[np.ndarray, np.ndarray]:
    """Each time moved to the largest attack within SNAP_S of it, when that attack is significant;
    returns the times and which moved (an attack confirmed them)."""
    attack = features.attack
    step = features.attack_hop / features.sample_rate
    first = -step / 2  # step m covers the samples (m - 1) * hop .. m * hop: its middle
    centre = np.median(attack)
    significant = max(centre + SIGNIFICANT * 1.4826 * float(np.median(np.abs(attack - centre))), MIN_RISE)
    reach = int(SNAP_S / step)
    at = np.round((times - first) / step).astype(np.int64)
    offsets = np.arange(-reach, reach + 1)
    index = np.clip(at[:, None] + offsets[None, :], 0, len(attack) - 1)
    values = attack[index]
    best = np.argmax(values, axis=1)
    peak = values[np.arange(len(times)), best]
    moved = peak >= significant
    where = first + index[np.arange(len(times)), best] * step
    return np.where(moved, where, times), moved
