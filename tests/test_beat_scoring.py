"""The beat scoring of issue 23 (choreo/music/scoring.py), on cases worked out by hand: the
window's edge, duplicates, empty lists, an off-beat grid, each tempo level, bar 1, a set's totals."""

from __future__ import annotations

import pytest

from choreo.music.scoring import (
    GOAL_F_MEDIAN,
    FMeasure,
    bar_one_right,
    f_measure,
    median_bpm,
    score_set,
    score_song,
    tempo_level,
)

GRID = [0.5 * k for k in range(1, 9)]  # 120 bpm, 8 beats from 0.5 s


def test_the_same_beats_score_1():
    found = f_measure(GRID, GRID)
    assert (found.matched, found.precision, found.recall, found.f) == (8, 1.0, 1.0, 1.0)


def test_a_beat_at_the_windows_edge_counts_and_one_just_past_it_does_not():
    assert f_measure([1.0], [1.07]).matched == 1
    assert f_measure([1.0], [0.93]).matched == 1
    assert f_measure([1.0], [1.0701]).matched == 0
    assert f_measure([1.0], [1.0701], window=0.08).matched == 1


def test_a_duplicate_beat_matches_once_and_lowers_precision():
    found = f_measure([1.0, 2.0], [1.0, 1.01, 2.0])
    assert (found.matched, found.recall) == (2, 1.0)
    assert found.precision == pytest.approx(2 / 3)
    assert found.f == pytest.approx(2 * 2 / (2 + 3))  # 0.8


def test_two_reference_beats_in_one_window_take_one_estimated_beat_each_nearest_first():
    # 1.05 is nearer 1.08 (0.03) than 1.0 (0.05): it goes to 1.08, and 1.0 finds 0.99
    assert f_measure([1.0, 1.08], [0.99, 1.05]).matched == 2
    # one estimated beat between two reference beats matches only one of them
    found = f_measure([1.0, 1.1], [1.05])
    assert (found.matched, found.precision, found.recall) == (1, 1.0, 0.5)


def test_empty_lists_score_0():
    assert f_measure([], GRID).f == 0.0
    assert f_measure(GRID, []).f == 0.0
    assert f_measure([], []) == FMeasure(0, 0, 0)
    assert f_measure([], []).f == 0.0


def test_an_off_beat_grid_scores_0_and_half_the_beats_score_two_thirds():
    assert f_measure(GRID, [t + 0.25 for t in GRID]).f == 0.0
    half = f_measure(GRID, GRID[::2])  # half tempo: every second beat, all right
    assert (half.precision, half.recall) == (1.0, 0.5)
    assert half.f == pytest.approx(2 / 3)
    double = f_measure(GRID, sorted(GRID + [t + 0.25 for t in GRID]))
    assert (double.precision, double.recall, double.f) == (0.5, 1.0, pytest.approx(2 / 3))


@pytest.mark.parametrize("found, level", [
    (120.0, "same"), (124.8, "same"), (115.2, "same"), (125.0, "other"),
    (240.0, "double"), (60.0, "half"), (180.0, "3/2"), (80.0, "2/3"), (100.0, "other"), (None, "other"),
])
def test_the_tempo_level_is_right_within_4_percent_and_named_otherwise(found, level):
    scored = tempo_level(120.0, found)
    assert scored.level == level
    assert scored.right == (level == "same")


def test_bar_1_is_right_within_70_ms():
    assert bar_one_right(2.0, 2.07) and bar_one_right(2.0, 1.93)
    assert not bar_one_right(2.0, 2.0701)
    assert not bar_one_right(2.0, 2.5)  # the second beat
    assert not bar_one_right(2.0, None)


def test_a_song_found_one_beat_late_has_every_beat_but_bar_1_wrong():
    beats = [0.5 * k for k in range(16)]
    downbeats = beats[::4]
    found_downbeats = beats[1::4]
    scored = score_song(beats, downbeats, 120.0, beats[1:], found_downbeats, 120.3)
    assert scored.tempo.right and scored.tempo.level == "same"
    assert not scored.bar_one_right
    assert scored.beats.f == pytest.approx(2 * 15 / 31)
    assert scored.downbeats.f == 0.0


def test_a_set_gives_its_shares_median_and_mean():
    beats = [0.5 * k for k in range(8)]
    right = score_song(beats, beats[::4], 120.0, beats, beats[::4], 120.0)
    doubled = score_song(beats, beats[::4], 120.0, sorted(beats + [b + 0.25 for b in beats]), beats[::4], 240.0)
    total = score_set([right, right, doubled])
    assert total.songs == 3
    assert total.level_share == pytest.approx(2 / 3)
    assert total.bar_one_share == 1.0
    assert total.f_median == 1.0
    assert total.f_mean == pytest.approx((1 + 1 + 2 / 3) / 3)
    assert total.meets_goals() == {"tempo level": False, "bar 1": True, "F median": True, "F mean": False}
    assert total.f_median >= GOAL_F_MEDIAN
    assert score_set([]).songs == 0


def test_the_median_tempo_of_a_beat_list():
    assert median_bpm([0.0, 0.5, 1.0, 1.6, 2.1]) == pytest.approx(120.0)
    assert median_bpm([1.0]) == 0.0
