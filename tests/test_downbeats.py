"""Where the bars start (choreo.music.downbeats): bar 1 from harmony, bass notes and the kick and
snare pattern together, among beats a tracker gives (starting a beat or two before the music, a
few ms off, or missing the first ones), and where the music starts (a fade-in: where it is first
heard, not at some share of its peak)."""

from __future__ import annotations

import sys
from pathlib import Path

import numpy as np
import pytest

from choreo.errors import UsageError
from choreo.music.downbeats import UNDECIDED, beat_cues, find_downbeats, music_start, phase_evidence
from choreo.music.features import Features, features_of
from choreo.music.scoring import bar_one_right

REPO = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(REPO))
from bench.songs import CASES, Song, make_song  # noqa: E402

CASE = {case.name: case for case in CASES}
RATE = 22050
# Triads as semitones above C: C, Am, F, G (chords change on every bar line)
PROGRESSION = ((0, 4, 7), (9, 12, 16), (5, 9, 12), (7, 11, 14))


def tracked(beats: np.ndarray, rng: np.random.Generator, before: int = 1, jitter_s: float = 0.0,
            missing: int = 0) -> np.ndarray:
    """Beats as a tracker gives them: `before` more ahead of bar 1 (in the silence), each off by up
    to `jitter_s`, the first `missing` of the true ones left out."""
    step = beats[1] - beats[0]
    early = beats[0] - step * np.arange(before, 0, -1)
    out = np.concatenate([early, beats]) + rng.uniform(-jitter_s, jitter_s, len(beats) + before)
    return out[before + missing:] if missing else out


def bar_one(features: Features, beats: np.ndarray, meter: int) -> float:
    return float(beats[find_downbeats(features, beats, meter).first])


class _Songs(dict[str, tuple[Song, Features]]):
    """The bench's songs (seed 7), each made on first use: a test worker makes only the ones its
    tests need, once (making all ten took 4 s on every worker)."""

    def __missing__(self, name: str) -> tuple[Song, Features]:
        song = make_song(CASE[name], 7)
        self[name] = (song, features_of([song.samples]))
        return self[name]


@pytest.fixture(scope="module")
def bench_songs() -> dict[str, tuple[Song, Features]]:
    return _Songs()


@pytest.mark.parametrize("name", ["pop/rock", "pads-only intro", "fade-in", "anticipations", "waltz 3/4", "6/8",
                                  "reggaeton", "breakdown", "house", "quiet kit, room"])
def test_bar_1_is_found_in_every_kind_of_song_among_a_trackers_beats(bench_songs, name):
    song, features = bench_songs[name]
    beats = np.array(song.beats)
    rng = np.random.default_rng(1)
    for before, jitter in ((0, 0.0), (1, 0.0), (2, 0.0), (2, 0.01)):
        found = bar_one(features, tracked(beats, rng, before, jitter), song.meter)
        assert bar_one_right(song.downbeats[0], found), (before, jitter, found, song.downbeats[0])
    for missing in (1, 2):  # bar 1 itself untracked: the first downbeat there is, bar 2's
        found = bar_one(features, tracked(beats, rng, 0, 0.01, missing), song.meter)
        assert bar_one_right(song.downbeats[1], found), (missing, found, song.downbeats[1])


@pytest.mark.parametrize("name", ["pop/rock", "waltz 3/4", "anticipations", "breakdown"])
def test_a_beat_the_tracker_adds_or_misses_later_on_does_not_move_bar_1(bench_songs, name):
    # After the slip most of the song's bars start a beat later in the list: bar 1 is where its
    # own stretch says, not where the majority of the song's does.
    song, features = bench_songs[name]
    beats = tracked(np.array(song.beats), np.random.default_rng(10), 1, 0.005)
    slip = int(0.4 * len(beats)) + 1
    for given in (np.insert(beats, slip, (beats[slip - 1] + beats[slip]) / 2), np.delete(beats, slip)):
        assert bar_one_right(song.downbeats[0], bar_one(features, given, song.meter)), slip


def test_changes_against_the_silence_before_the_music_count_for_nothing():
    # The beats start at the music and stop two before the song's last (as a tracker's may): the
    # first bar's chords and bass notes "change" from the silence on every beat; they once had
    # this song's bar 1 put on beat 3.
    song = make_song(CASE["quiet kit, room"], 4039)
    features = features_of([song.samples])
    for jitter in (0.0, 0.003):
        beats = tracked(np.array(song.beats[:-2]), np.random.default_rng(12), 0, jitter)
        assert bar_one_right(song.downbeats[0], bar_one(features, beats, song.meter))


def test_the_pads_only_intro_starts_bar_1_at_the_first_chord_not_where_the_drums_come_in(bench_songs):
    song, features = bench_songs["pads-only intro"]
    beats = tracked(np.array(song.beats), np.random.default_rng(2))
    result = find_downbeats(features, beats, song.meter)
    assert beats[result.first] == pytest.approx(song.downbeats[0], abs=0.001)
    assert "harmony" in result.by.split("+")
    assert result.contrast is not None and result.contrast > 0
    assert result.other_first is not None and result.other_first % song.meter != result.first % song.meter


def synth(bars: int = 8, bpm: float = 110.0, meter: int = 4, start_s: float = 0.8, kick: dict[int, float] | None = None,
          snare: tuple[int, ...] = (1, 3), anticipate: bool = False, bass: bool = False,
          fade_s: float = 0.0, pads: bool = True) -> tuple[np.ndarray, np.ndarray]:
    """A small band: kick and snare on the given beats of the bar (0 = the one), hats on every
    eighth, a chord each bar (an eighth early when anticipated), optionally a bass note with it.
    Returns the samples and the true beats."""
    beat = 60.0 / bpm
    beats = start_s + beat * np.arange(bars * meter)
    out = np.zeros(int((beats[-1] + 2 * beat) * RATE), dtype=np.float64)
    t = np.arange(int(0.4 * RATE)) / RATE
    noise = np.random.default_rng(5).standard_normal(len(t))
    sounds = {"kick": np.sin(2 * np.pi * (50 * t + 2.4 * (1 - np.exp(-t / 0.024)))) * np.exp(-t / 0.11),
              "snare": 0.9 * noise * np.exp(-t / 0.05), "hat": 0.15 * np.diff(noise, prepend=0.0) * np.exp(-t / 0.012)}
    for i, at in enumerate(beats):
        place = i % meter
        hits = [("hat", 1.0)] + [("kick", (kick or {0: 1.0, 2: 1.0}).get(place, 0.0))] + \
            [("snare", 1.0 if place in snare else 0.0)]
        for name, gain in hits:
            for when in ((at, at + beat / 2) if name == "hat" else (at,)):
                n = int(round(when * RATE))
                out[n:n + len(t)] += gain * sounds[name][: len(out) - n]
    for bar in range(bars if pads else 0):
        begin = beats[bar * meter] - (beat / 2 if anticipate and bar else 0.0)
        n = int((beats[bar * meter] + meter * beat - begin) * RATE)
        tt = np.arange(n) / RATE
        shape = np.minimum(1.0, tt / 0.02) * np.minimum(1.0, (n - np.arange(n)) / (0.02 * RATE))
        root = 220.0 * 2 ** (PROGRESSION[bar % 4][0] / 12)
        pad = sum(np.sin(2 * np.pi * 220.0 * 2 ** (s / 12) * tt) for s in PROGRESSION[bar % 4])
        if bass:
            pad = pad + 2.0 * np.sin(2 * np.pi * root / 4 * tt) * np.exp(-tt / 1.0)
        k = int(round(begin * RATE))
        out[k:k + n] += 0.15 * shape * pad[: len(out) - k]
    if fade_s:
        out *= np.clip((np.arange(len(out)) / RATE - start_s) / fade_s, 0.0, 1.0) ** 2
    return (out / np.max(np.abs(out))).astype(np.float32), beats


def test_a_louder_kick_on_3_does_not_move_bar_1_there_for_the_chords_change_on_1():
    # Bass energy alone would take beat 3 for the one: its kick is the loudest thing in the bar.
    samples, beats = synth(kick={0: 0.5, 2: 1.0})
    features = features_of([samples])
    for before in (1, 2):
        given = tracked(beats, np.random.default_rng(3), before, 0.01)
        result = find_downbeats(features, given, 4)
        assert bar_one_right(beats[0], float(given[result.first])), result
        assert "harmony" in result.by.split("+")
        assert bar_one_right(beats[2], float(given[result.other_first]))  # beat 3: the runner-up


def test_a_kick_on_1_and_3_with_a_snare_backbeat_puts_bar_1_on_the_kick_that_starts_a_chord():
    samples, beats = synth(kick={0: 1.0, 2: 1.0}, bass=True)
    features = features_of([samples])
    given = tracked(beats, np.random.default_rng(4), 2, 0.01)
    result = find_downbeats(features, given, 4)
    assert bar_one_right(beats[0], float(given[result.first]))
    assert "backbeat" not in result.by  # the snare tells 1 and 3 from 2 and 4, not 1 from 3


def test_a_kick_over_a_bass_note_held_from_an_eighth_before_counts_as_much_as_over_silence():
    samples, beats = synth(kick={0: 1.0, 2: 1.0}, anticipate=True, bass=True)
    kick = beat_cues(features_of([samples]), beats, 4)["kick"].values
    assert np.nanmean(kick[0::4]) > 0.9 * np.nanmean(kick[2::4]) > 3 * np.nanmean(kick[1::2])


def test_without_chords_the_kick_and_snare_pattern_finds_the_bar():
    # 3/4: the kick on 1 alone, the snare on 2 and 3; no harmony to go by
    samples, beats = synth(meter=3, kick={0: 1.0}, snare=(1, 2), pads=False, bars=10)
    features = features_of([samples])
    for before in (1, 2):
        given = tracked(beats, np.random.default_rng(before), before, 0.01)
        result = find_downbeats(features, given, 3)
        assert bar_one_right(beats[0], float(given[result.first]))
        assert set(result.by.split("+")) <= {"kick", "backbeat", "sections"} and "kick" in result.by


def test_a_dembows_snare_off_the_beats_casts_no_vote_by_its_ringing():
    # The snare falls a sixteenth before beats 2 and 4 and an eighth before 1 and 3: its decay
    # makes 2 and 4 look less snare-like than 1 and 3, by a twentieth of a hit.
    song = make_song(CASE["reggaeton"], 3)
    features = features_of([song.samples])
    beats = tracked(np.array(song.beats), np.random.default_rng(9), 1)
    evidence = {name: e.sum(axis=0) for name, e in phase_evidence(features, beats, song.meter,
                                                                  music_start(features)).items()}
    assert np.all(np.abs(evidence["backbeat"]) < 0.5) and np.all(np.abs(evidence["accent"]) < 0.5)
    assert np.argmax(evidence["harmony"]) == 1  # bar 1 is beats[1]
    assert bar_one_right(song.downbeats[0], bar_one(features, beats, song.meter))


def click_track(bpm: float, offset: float, meter: int, seconds: float = 10.0) -> tuple[np.ndarray, np.ndarray]:
    """A metronome: a click on every beat, the one louder and an octave higher (the same pitch
    class: no harmony), no drum, no noise."""
    beats = offset + 60.0 / bpm * np.arange(int((seconds - offset - 0.1) * bpm / 60.0))
    out = np.zeros(int(seconds * RATE))
    t = np.arange(int(0.03 * RATE)) / RATE
    for i, at in enumerate(beats):
        one = i % meter == 0
        click = (0.9 if one else 0.4) * np.sin(2 * np.pi * (1760 if one else 880) * t) * np.exp(-t / 0.008)
        n = int(round(at * RATE))
        out[n:n + len(click)] += click
    return out.astype(np.float32), beats


@pytest.mark.parametrize("meter", [3, 4])
def test_a_metronome_puts_bar_1_on_its_accented_click(meter):
    samples, beats = click_track(96.0, 0.75, meter)
    features = features_of([samples])
    for given in (beats, tracked(beats, np.random.default_rng(meter), 1, 0.002)):
        result = find_downbeats(features, given, meter)
        assert bar_one_right(beats[0], float(given[result.first])), result
        assert result.by.split("+")[0] == "accent"
        assert not {"harmony", "bass", "kick", "backbeat"} & set(result.by.split("+"))  # none was heard


@pytest.mark.parametrize("bpm", [40.0, 240.0])
def test_a_metronome_without_accents_starts_bar_1_on_its_first_click(bpm):
    """Nothing tells the bar: the music's first beat is bar 1 (it was whichever phase the noise
    of a cue favoured, four clicks in), and the likeliest other place is still said."""
    beats = 0.5 + 60.0 / bpm * np.arange(int(9.5 * bpm / 60.0))
    samples = np.zeros(10 * RATE)
    t = np.arange(int(0.02 * RATE)) / RATE
    for at in np.round(beats * RATE).astype(int):
        samples[at:at + len(t)] += 0.8 * np.sin(2 * np.pi * 1000 * t) * np.exp(-t / 0.005)
    result = find_downbeats(features_of([samples.astype(np.float32)]), beats, 4)
    assert (result.first, result.by) == (0, "") and result.contrast < UNDECIDED and result.other_first in (1, 2, 3)


def test_chords_anticipated_by_an_eighth_still_belong_to_the_bar_line_after_them():
    samples, beats = synth(kick={b: 1.0 for b in range(4)}, snare=(), anticipate=True)  # no drum cue at all
    features = features_of([samples])
    for before in (1, 2, 3):
        given = tracked(beats, np.random.default_rng(before), before, 0.01)
        assert bar_one_right(beats[0], bar_one(features, given, 4))


def test_with_one_beat_a_bar_bar_1_is_the_first_beat_where_the_music_is_and_no_phase_is_chosen():
    samples, beats = synth()
    features = features_of([samples])
    given = tracked(beats, np.random.default_rng(6), 2)
    result = find_downbeats(features, given, 1)
    assert result.first == 2 and result.contrast is None and result.other_first is None


def test_a_few_beats_or_beats_outside_the_music_still_name_one_of_them():
    samples, beats = synth(bars=3)
    features = features_of([samples])
    for given in (beats[:1], beats[:2], beats[:3], beats[:5], beats - 100.0, beats + 100.0):
        for meter in (2, 3, 4, 7):
            result = find_downbeats(features, given, meter)
            assert 0 <= result.first < len(given) and result.contrast is not None
            assert result.other_first is not None and 0 <= result.other_first < len(given)


def test_no_beats_is_a_usage_error():
    samples, _ = synth(bars=2)
    with pytest.raises(UsageError, match="no beats"):
        find_downbeats(features_of([samples]), np.array([]), 4)


def test_music_starts_where_a_fade_in_from_silence_is_first_heard():
    samples, beats = synth(start_s=1.3, fade_s=6.0)
    features = features_of([samples])
    assert music_start(features) == pytest.approx(1.3, abs=0.03)
    level = np.abs(samples)
    assert np.flatnonzero(level > 0.2)[0] / RATE > 1.3 + 1.0  # where a 20 % threshold would put it
    given = tracked(beats, np.random.default_rng(7), 2, 0.01)
    assert bar_one_right(beats[0], bar_one(features, given, 4))


def test_music_starts_above_the_recordings_own_noise_floor():
    samples, _ = synth(start_s=1.1)
    hiss = np.random.default_rng(8).standard_normal(len(samples)) * 10 ** (-60 / 20)
    features = features_of([samples + hiss.astype(np.float32)])
    assert music_start(features) == pytest.approx(1.1, abs=0.03)
    assert music_start(features_of([np.zeros(RATE, dtype=np.float32)])) == 0.0
