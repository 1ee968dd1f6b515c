"""How right a beat estimate is against a song's known beats: the one place the scoring lives.

Issue 23's measures, as the beat-tracking literature (MIREX, mir_eval) takes them:

- beat F-measure: each estimated beat may match one reference beat within +-70 ms (a window's
  edge counts), pairs taken nearest first; precision is the share of estimated beats matched,
  recall the share of reference beats matched, F their harmonic mean. A duplicate beat matches
  once and lowers precision; an empty list scores 0, as an off-beat grid does.
- tempo level: the found tempo is at the right level when within 4 % of the true tempo; else
  the level it is at is named (double, half, 2/3, 3/2) when within 4 % of that, or `other`.
- bar 1: right when the found first downbeat is within +-70 ms of the true one.
- downbeat F-measure: the beat F-measure over the downbeats alone.

Pure Python: no numpy, so the scores can be read and checked by hand.
"""

from __future__ import annotations

import bisect
import statistics
from collections.abc import Sequence
from dataclasses import dataclass

WINDOW_S = 0.07  # a beat within this of a reference beat matches it
TEMPO_TOLERANCE = 0.04  # a tempo within this share of a level's tempo is at that level
_EDGE = 1e-9  # a difference of exactly the window or tolerance, after float arithmetic, still counts
# (name, found tempo / true tempo), the right level first
LEVELS: tuple[tuple[str, float], ...] = (
    ("same", 1.0), ("double", 2.0), ("half", 0.5), ("3/2", 1.5), ("2/3", 2.0 / 3.0),
)
OTHER_LEVEL = "other"

# Issue 23's goals, over a set of songs
GOAL_LEVEL_SHARE = 0.975
GOAL_BAR_ONE_SHARE = 0.975
GOAL_F_MEDIAN = 0.99
GOAL_F_MEAN = 0.97
GOAL_S_PER_MINUTE = 1.0


@dataclass(frozen=True)
class FMeasure:
    """Beats matched one to one within the window, and what that makes of precision and recall."""

    matched: int
    reference: int  # beats in the reference
    estimated: int  # beats in the estimate

    @property
    def precision(self) -> float:
        return self.matched / self.estimated if self.estimated else 0.0

    @property
    def recall(self) -> float:
        return self.matched / self.reference if self.reference else 0.0

    @property
    def f(self) -> float:
        total = self.reference + self.estimated
        return 2.0 * self.matched / total if self.matched else 0.0


@dataclass(frozen=True)
class TempoLevel:
    """The found tempo against the true one: the level it is at, and whether that is the right one."""

    true_bpm: float
    found_bpm: float | None  # None: no tempo found
    level: str  # a name in LEVELS, or OTHER_LEVEL

    @property
    def right(self) -> bool:
        return self.level == LEVELS[0][0]


@dataclass(frozen=True)
class SongScore:
    """Every measure for one song."""

    tempo: TempoLevel
    bar_one_right: bool
    beats: FMeasure
    downbeats: FMeasure


@dataclass(frozen=True)
class SetScore:
    """A set of songs' scores against issue 23's goals (shares are 0..1)."""

    songs: int
    level_share: float
    bar_one_share: float
    f_median: float
    f_mean: float
    downbeat_f_mean: float

    def meets_goals(self) -> dict[str, bool]:
        return {"tempo level": self.level_share >= GOAL_LEVEL_SHARE,
                "bar 1": self.bar_one_share >= GOAL_BAR_ONE_SHARE,
                "F median": self.f_median >= GOAL_F_MEDIAN,
                "F mean": self.f_mean >= GOAL_F_MEAN}


def f_measure(reference: Sequence[float], estimated: Sequence[float], window: float = WINDOW_S) -> FMeasure:
    """Match each estimated beat to at most one reference beat within `window` seconds (and each
    reference beat to at most one estimated beat), closest pairs first."""
    order = sorted(range(len(estimated)), key=lambda j: estimated[j])
    times = [estimated[j] for j in order]
    pairs = []
    for i, r in enumerate(reference):  # only the estimated beats near each one: long songs stay fast
        for k in range(bisect.bisect_left(times, r - window - _EDGE), bisect.bisect_right(times, r + window + _EDGE)):
            pairs.append((abs(times[k] - r), i, order[k]))
    pairs.sort()
    used_reference: set[int] = set()
    used_estimated: set[int] = set()
    for _, i, j in pairs:
        if i not in used_reference and j not in used_estimated:
            used_reference.add(i)
            used_estimated.add(j)
    return FMeasure(len(used_reference), len(reference), len(estimated))


def tempo_level(true_bpm: float, found_bpm: float | None, tolerance: float = TEMPO_TOLERANCE) -> TempoLevel:
    """The level `found_bpm` is at: the first of LEVELS whose tempo it is within `tolerance` of."""
    if found_bpm is not None and true_bpm > 0:
        for name, ratio in LEVELS:
            if abs(found_bpm / (true_bpm * ratio) - 1.0) <= tolerance + _EDGE:  # 4 % itself counts
                return TempoLevel(true_bpm, found_bpm, name)
    return TempoLevel(true_bpm, found_bpm, OTHER_LEVEL)


def bar_one_right(true_s: float, found_s: float | None, window: float = WINDOW_S) -> bool:
    """Whether the found first downbeat is within `window` seconds of the true one."""
    return found_s is not None and abs(found_s - true_s) <= window + _EDGE


def median_bpm(beats: Sequence[float]) -> float:
    """A tempo for a beat list: 60 over the median interval between its beats (0: fewer than 2)."""
    intervals = [beats[i + 1] - beats[i] for i in range(len(beats) - 1)]
    return 60.0 / statistics.median(intervals) if intervals else 0.0


def score_song(true_beats: Sequence[float], true_downbeats: Sequence[float], true_bpm: float,
               found_beats: Sequence[float], found_downbeats: Sequence[float],
               found_bpm: float | None) -> SongScore:
    """One song's scores; bar 1 is each list's first downbeat (none found: wrong)."""
    found_first = found_downbeats[0] if found_downbeats else None
    right = bool(true_downbeats) and bar_one_right(true_downbeats[0], found_first)
    return SongScore(tempo_level(true_bpm, found_bpm), right, f_measure(true_beats, found_beats),
                     f_measure(true_downbeats, found_downbeats))


def score_set(scores: Sequence[SongScore]) -> SetScore:
    """The set's shares, and its F-measures' median and mean (an empty set scores 0)."""
    if not scores:
        return SetScore(0, 0.0, 0.0, 0.0, 0.0, 0.0)
    n = len(scores)
    fs = [s.beats.f for s in scores]
    return SetScore(n, sum(s.tempo.right for s in scores) / n, sum(s.bar_one_right for s in scores) / n,
                    statistics.median(fs), statistics.fmean(fs), statistics.fmean(s.downbeats.f for s in scores))
