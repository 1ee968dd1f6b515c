"""The tempo level and the beat tracker on their own (choreo.music.tempo, choreo.music.tracking):
`--bpm-range` finds a tempo the song supports wherever it lies in the range (at an edge, or a
level folded into it), the onset strength is what the picture draws, a tempo change is followed
bar by bar, and noise has no beat."""

from __future__ import annotations

import sys
from pathlib import Path

import numpy as np
import pytest

REPO = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(REPO))
from choreo.errors import UsageError  # noqa: E402
from choreo.music.beats import estimate, onset_strength  # noqa: E402
from choreo.music.features import Features, features_of  # noqa: E402

from dataclasses import replace  # noqa: E402

from bench.songs import CASES, Song, make_song  # noqa: E402

CASE = {case.name: case for case in CASES}


@pytest.fixture(scope="module")
def pop() -> tuple[Song, Features]:
    song = make_song(CASE["pop/rock"], 9101)
    return song, features_of([song.samples])


@pytest.mark.parametrize("low, high, level", [
    (1.0, 1.3, 1.0),  # the tempo at the range's lower edge
    (0.7, 1.0, 1.0),  # at its upper edge
    (0.4, 0.6, 0.5),  # only half the tempo in the range: the half level, not a refusal
    (1.8, 2.1, 2.0),  # only double
])
def test_a_bpm_range_finds_the_level_of_the_song_it_holds(pop, low, high, level):
    song, features = pop
    found = estimate(features, bpm_range=(round(low * song.bpm, 2), round(high * song.bpm, 2)))
    assert found.bpm == pytest.approx(level * song.bpm, rel=0.01)


def test_the_onset_strength_is_one_value_a_frame_and_peaks_on_the_beats(pop):
    song, features = pop
    strength = onset_strength(features)
    assert strength.shape == (len(features.bands),) and np.all(strength >= 0)
    beats = np.round(np.array(song.beats) * features.fps).astype(int)
    on = np.array([strength[b - 2:b + 3].max() for b in beats])
    between = np.round((np.array(song.beats[:-1]) + np.diff(song.beats) / 4) * features.fps).astype(int)
    assert np.median(on) > 3 * np.median(strength[between])


def test_a_tempo_change_is_followed_bar_by_bar():
    song = make_song(CASE["tempo change"], 9112)
    found = estimate(features_of([song.samples]), meter=song.meter)
    bars = np.array(found.bars)
    true = np.array(song.downbeats)
    n = min(len(bars), len(true))
    assert n >= len(true) - 1 and np.max(np.abs(bars[:n] - true[:n])) < 0.03
    lengths = np.diff(bars)
    assert abs(lengths[0] / lengths[-2] - song.curve[-1] / song.curve[0]) < 0.02  # the two tempi


POP = CASE["pop/rock"]
HARD = {  # kinds of song beyond the bench's, each a principle of the level choice
    # a kick on every sixteenth says nothing about the beat; the snare on 2 and 4 does
    "double kick": replace(POP, name="double kick", bpm=(145.0, 170.0), kick="x" * 16, hat="",
                           open_hat="x.x.x.x.x.x.x.x."),
    # no drums, a bass on 1 and stabs on 2 and 3: the quarter note, not the bar (chords change per bar)
    "fast waltz, no drums": replace(CASE["waltz 3/4"], name="fast waltz", bpm=(145.0, 165.0), kick="", snare="",
                                    hat="", comp="....x...x..."),
    # loud open hats on every eighth, swung and loosely played: the backbeat still says quarters
    "loose boom bap": replace(CASE["hip-hop swing"], name="boom bap", swing=0.58, jitter_s=0.008,
                              open_hat="x.x.x.x.x.x.x.x."),
}


@pytest.mark.parametrize("name", sorted(HARD))
def test_the_level_is_the_beat_in_harder_kinds_of_song(name):
    song = make_song(HARD[name], 9202)
    found = estimate(features_of([song.samples]), meter=song.meter)
    assert found.bpm == pytest.approx(song.median_bpm, rel=0.04)


def test_noise_and_silence_have_no_beat():
    noise = 0.3 * np.random.default_rng(0).standard_normal(8 * 22050).astype(np.float32)
    with pytest.raises(UsageError, match="no steady beat found"):
        estimate(features_of([noise], path="noise.wav"))
    with pytest.raises(UsageError, match="silent.wav: no beat found: the song is silent"):
        estimate(features_of([np.zeros(5 * 22050, dtype=np.float32)], path="silent.wav"))
