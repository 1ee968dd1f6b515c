"""`choreo beats SONG` (issue 13, item 2): tempo and first downbeat of click tracks of known tempo,
the `tempo:` block it prints loading in a show, `--beats`, `--json`, `--meter`, and one-line
errors with exit 2 for songs that cannot be read or have no beat."""

from __future__ import annotations

import json
import subprocess
import sys
import wave
from pathlib import Path

import numpy as np
import pytest

import choreo.music
from choreo.music import beats
from choreo.music.beats import estimate
from choreo.music.features import features_of, read_features
from choreo.music.tempo import running_mean
from choreo.cli import main
from choreo.cli.beats import MUSIC_EXTRA
from choreo.show.load import load_show
from choreo.show.model import Tempo
from choreo.show.plan import compile_plan

RATE = 22050


def write_wav(path: Path, samples: np.ndarray, rate: int = RATE) -> Path:
    with wave.open(str(path), "wb") as out:
        out.setnchannels(1)
        out.setsampwidth(2)
        out.setframerate(rate)
        out.writeframes((np.clip(samples, -1.0, 1.0) * 32767).astype("<i2").tobytes())
    return path


def click_track(path: Path, bpm: float, offset: float, meter: int = 4, seconds: float = 12.0) -> Path:
    """A metronome: a short click on every beat from `offset` on, the first of each bar louder
    and higher, as a metronome accents the one."""
    song = np.zeros(int(seconds * RATE))
    t = np.arange(int(0.03 * RATE)) / RATE
    beat = 0
    while (start := offset + beat * 60.0 / bpm) < seconds - 0.05:
        accent = beat % meter == 0
        click = (0.9 if accent else 0.4) * np.sin(2 * np.pi * (1760 if accent else 880) * t) * np.exp(-t / 0.008)
        at = int(round(start * RATE))
        song[at:at + len(click)] += click[:len(song) - at]
        beat += 1
    return write_wav(path, song)


def band_track(path: Path, bpm: float, offset: float, seconds: float = 12.0) -> Path:
    """Kick drum on 1 and 3, a snare louder than the kick on 2 and 4, hi-hat on every eighth, a
    bass note on each bar: the backbeat outweighs the one over the whole spectrum."""
    rng = np.random.default_rng(7)
    song = np.zeros(int(seconds * RATE))
    t = np.arange(int(0.3 * RATE)) / RATE
    kick = np.sin(2 * np.pi * (50 + 100 * np.exp(-t / 0.03)) * t) * np.exp(-t / 0.12)
    snare = 1.5 * rng.standard_normal(len(t)) * np.exp(-t / 0.06)
    hat = 0.15 * np.diff(rng.standard_normal(len(t)) * np.exp(-t / 0.01), prepend=0.0)
    period = 60.0 / bpm

    def add(start: float, sound: np.ndarray) -> None:
        at = int(round(start * RATE))
        if at < len(song):
            song[at:at + len(sound)] += sound[:len(song) - at]

    beat = 0
    while (start := offset + beat * period) < seconds:
        add(start, kick if beat % 2 == 0 else snare)
        add(start, hat)
        add(start + period / 2, hat)
        if beat % 4 == 0:
            bass = np.arange(int(4 * period * RATE)) / RATE
            add(start, 0.3 * np.sin(2 * np.pi * (110, 147, 165, 131)[beat // 4 % 4] * bass) * np.exp(-bass / 2))
        beat += 1
    return write_wav(path, 0.5 * song / np.abs(song).max())


@pytest.fixture(scope="module")
def songs(tmp_path_factory) -> dict[str, Path]:
    folder = tmp_path_factory.mktemp("songs")
    return {
        "96": click_track(folder / "clicks96.wav", 96, 0.75),
        "128": click_track(folder / "clicks128.wav", 128, 0.3),
        "waltz": click_track(folder / "waltz.wav", 90, 1.2, meter=3),
        "band": band_track(folder / "band.wav", 123.7, 0.61),
    }


@pytest.mark.parametrize("name, bpm, offset", [("96", 96, 0.75), ("128", 128, 0.3)])
def test_a_click_track_gives_its_tempo_and_first_downbeat_to_the_millisecond(songs, name, bpm, offset):
    found = estimate(read_features(songs[name]))
    assert abs(found.bpm - bpm) <= 0.05 and abs(found.offset - offset) <= 0.005
    assert found.meter == 4 and found.downbeat_contrast > 0 and found.bars == ()
    assert found.confirmed == len(found.beats) and found.timing_rms_ms < 2.0
    assert (found.beats[0].bar, found.beats[0].beat) == (1, 1) and found.beats[0].time_s == found.offset


def test_the_downbeat_of_a_band_is_found_in_the_bass_under_a_louder_backbeat(songs):
    found = estimate(read_features(songs["band"]))
    assert abs(found.bpm - 123.7) <= 0.05 and abs(found.offset - 0.61) <= 0.005
    assert "bass" in found.downbeat_by.split("+") and found.other_beat == 3  # the kick on 3 is the runner-up


def test_the_shipped_click_track_gives_the_tempo_its_show_was_written_with():
    shows = Path(__file__).resolve().parent.parent / "shows"
    found = estimate(read_features(shows / "music-120.wav"))
    assert found.tempo() == load_show(shows / "music.yaml").tempo == Tempo(120, 0, 4)


def test_the_command_prints_a_tempo_block_to_paste_after_what_it_rests_on(songs, capsys):
    assert main(["beats", str(songs["96"])]) == 0
    out, err = capsys.readouterr()
    *comments, block = out.splitlines()
    assert block == "tempo: {bpm: 96.0, offset: 0.75, meter: 4}" and err == ""
    assert all(line.startswith("# ") for line in comments)
    assert comments[0].startswith(f"# {songs['96']} (12.0 s): 96 bpm; ")
    assert "check it by ear" in comments[-1]


def test_the_printed_block_loads_in_a_show_and_bar_2_is_one_bar_after_the_offset(songs, capsys, tmp_path):
    assert main(["beats", str(songs["128"])]) == 0
    show = tmp_path / "dance.yaml"
    show.write_text("version: 1\n" + capsys.readouterr().out
                    + "steps:\n  - play: 1\n    at: {bar: 1}\n  - play: 2\n    at: {bar: 2, beat: 1}\n")
    loaded = load_show(show)
    assert loaded.tempo is not None and loaded.tempo.meter == 4
    starts = [step.at for step in compile_plan(loaded).steps]
    assert starts == [0.3, pytest.approx(0.3 + 4 * 60 / 128, abs=1e-9)]


def test_beats_lists_every_beat_from_bar_1_with_the_onset_heard_there(songs, capsys):
    assert main(["beats", str(songs["96"]), "--beats"]) == 0
    lines = capsys.readouterr().out.splitlines()
    listed = lines[lines.index("tempo: {bpm: 96.0, offset: 0.75, meter: 4}") + 1:]
    assert listed[0].split()[:6] == ["0.750", "s", "bar", "1", "beat", "1"]
    assert listed[4].split()[:6] == ["3.250", "s", "bar", "2", "beat", "1"]
    assert all(" onset " in line and line.endswith(" ms") for line in listed)
    assert len(listed) == 18  # 0.75 s to 11.375 s, every 0.625 s


def test_json_has_the_tempo_the_figures_and_every_beat(songs, capsys):
    assert main(["beats", str(songs["128"]), "--json"]) == 0
    record = json.loads(capsys.readouterr().out)
    assert record["tempo"] == {"bpm": 128.0, "offset": 0.3, "meter": 4}
    assert record["song"] == str(songs["128"]) and record["duration_s"] == 12.0
    assert record["beats_on_onset"] == len(record["beats"]) and record["timing_rms_ms"] < 2.0
    assert record["downbeat"]["contrast"] > 0
    second_bar = record["beats"][4]
    assert (second_bar["bar"], second_bar["beat"]) == (2, 1)
    assert second_bar["time_s"] == pytest.approx(0.3 + 4 * 60 / 128, abs=1e-9)
    assert abs(second_bar["onset_s"] - second_bar["time_s"]) < 0.002


def test_meter_3_counts_bars_of_three_from_the_accented_beat(songs, capsys):
    assert main(["beats", str(songs["waltz"]), "--meter", "3", "--beats"]) == 0
    lines = capsys.readouterr().out.splitlines()
    assert "tempo: {bpm: 90.0, offset: 1.2, meter: 3}" in lines
    assert any(line.split()[:6] == ["3.200", "s", "bar", "2", "beat", "1"] for line in lines)


def test_a_narrower_bpm_range_picks_half_the_tempo(songs, capsys):
    assert main(["beats", str(songs["128"]), "--bpm-range", "40..100", "--json"]) == 0
    assert json.loads(capsys.readouterr().out)["tempo"]["bpm"] == pytest.approx(64, abs=0.05)


def test_songs_that_cannot_be_read_or_have_no_beat_are_one_line_and_exit_2(tmp_path, capsys):
    text = tmp_path / "notes.txt"
    text.write_text("not a song\n")
    empty = tmp_path / "empty.wav"
    empty.write_bytes(b"")
    silent = write_wav(tmp_path / "silent.wav", np.zeros(5 * RATE))
    for path, says in [
        (tmp_path / "missing.mp3", "cannot read the sound file: No such file or directory"),
        (text, "cannot decode: not a wav, mp3, flac or ogg file"),
        (empty, "the file is empty"),
        (silent, "no beat found: the song is silent"),
        (tmp_path, "not a regular file (a folder): give a sound file"),
    ]:
        assert main(["beats", str(path)]) == 2, path
        out, err = capsys.readouterr()
        assert out == "" and err.startswith(f"{path}: {says}") and err.count("\n") == 1, err


def test_noise_has_no_steady_beat(tmp_path, capsys):
    noise = write_wav(tmp_path / "noise.wav", 0.3 * np.random.default_rng(0).standard_normal(8 * RATE))
    assert main(["beats", str(noise)]) == 2
    assert capsys.readouterr().err.startswith(f"{noise}: no steady beat found")


@pytest.mark.parametrize("argv, says", [
    (["--meter", "17"], "choreo beats: --meter 17: give 1..16 beats a bar"),
    (["--bpm-range", "fast"], "choreo beats: --bpm-range fast: give LO..HI in bpm"),
    (["--bpm-range", "200..100"], "choreo beats: --bpm-range 200..100: give LO..HI in bpm"),
])
def test_bad_options_are_usage_errors(songs, capsys, argv, says):
    assert main(["beats", str(songs["96"]), *argv]) == 2
    assert capsys.readouterr().err.startswith(says)


def test_without_numpy_the_command_names_the_extra_to_install(songs, capsys, monkeypatch):
    monkeypatch.delitem(sys.modules, "choreo.music.beats")
    monkeypatch.delattr(choreo.music, "beats")
    monkeypatch.setitem(sys.modules, "numpy", None)
    assert main(["beats", str(songs["96"])]) == 2
    assert capsys.readouterr().err == MUSIC_EXTRA + "\n"
    assert beats.ON_BEAT_S > 0  # the module this file imported is left as it was


def test_choreo_help_does_not_load_numpy_or_miniaudio():
    code = ("import sys; from choreo.cli import build_parser; build_parser(); "
            "print(sorted({'numpy', 'miniaudio'} & set(sys.modules)))")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=60, check=True).stdout
    assert out.strip() == "[]"


def float_wav(path: Path, samples: np.ndarray, rate: int = RATE) -> Path:
    """A mono 32-bit float WAV (format 3), which can hold NaN and infinities."""
    data = np.asarray(samples, dtype="<f4").tobytes()
    header = (b"RIFF" + (36 + len(data)).to_bytes(4, "little") + b"WAVEfmt " + (16).to_bytes(4, "little")
              + np.array([3, 1], "<u2").tobytes() + np.array([rate, 4 * rate], "<u4").tobytes()
              + np.array([4, 32], "<u2").tobytes() + b"data" + len(data).to_bytes(4, "little"))
    path.write_bytes(header + data)
    return path


def samples_of(path: Path) -> np.ndarray:
    with wave.open(str(path)) as song:
        return np.frombuffer(song.readframes(song.getnframes()), "<i2") / 32767.0


def test_nan_and_infinite_samples_in_a_float_wav_are_no_sound_not_a_crash(songs, tmp_path):
    band = samples_of(songs["band"]).astype(np.float32)
    band[RATE * 3:RATE * 3 + 50], band[RATE * 5], band[RATE * 7] = np.nan, np.inf, -np.inf
    found = estimate(read_features(float_wav(tmp_path / "nan.wav", band)))
    assert abs(found.bpm - 123.7) <= 0.05 and abs(found.offset - 0.61) <= 0.005


@pytest.mark.parametrize("before", [False, True])
def test_minutes_of_silence_before_or_after_a_song_do_not_hide_its_beat(songs, before):
    band = samples_of(songs["band"]).astype(np.float32)
    silence = np.zeros(70 * RATE, dtype=np.float32)
    found = estimate(features_of(iter([silence, band] if before else [band, silence]), RATE, "song"))
    assert abs(found.bpm - 123.7) <= 0.05 and abs(found.offset - (0.61 + 70 * before)) <= 0.005


@pytest.mark.parametrize("bpm_range, bpm", [((127.9, 128.1), 128.0), ((127.0, 128.0), 128.0),
                                            ((60.0, 64.0), 64.0), ((64.0, 64.5), 64.0)])
def test_a_range_as_narrow_as_a_frame_or_with_the_tempo_at_its_edge_is_not_refused(songs, bpm_range, bpm):
    """A tempo read to a fraction of a frame may fall a hair past a round range's edge."""
    assert estimate(read_features(songs["128"]), bpm_range=bpm_range).bpm == pytest.approx(bpm, abs=0.05)


def test_a_slow_click_at_the_default_ranges_edge_is_found_at_its_own_tempo(tmp_path):
    found = estimate(read_features(click_track(tmp_path / "slow.wav", 40, 0.5, seconds=24.0)))
    assert found.bpm == pytest.approx(40, abs=0.05) and found.offset == pytest.approx(0.5, abs=0.005)


def clicks(bpm: float, seconds: float) -> np.ndarray:
    """The same short click on every beat from 0.5 s: no accent, no pitch change."""
    song = np.zeros(int(seconds * RATE), dtype=np.float32)
    t = np.arange(int(0.02 * RATE)) / RATE
    click = (0.8 * np.sin(2 * np.pi * 1000 * t) * np.exp(-t / 0.005)).astype(np.float32)
    for at in np.round(np.arange(0.5, seconds - 0.5, 60.0 / bpm) * RATE).astype(int):
        song[at:at + len(click)] += click
    return song


def test_slow_clicks_are_not_counted_as_five_beats_each():
    """Beats of which one in five has an onset are no beat; a slow beat's onset, folded over its
    period, must weigh as much as a fast one's (it was spread over bins wider than a frame)."""
    found = estimate(features_of([clicks(40, 60.0)], RATE, "slow"))
    assert found.bpm == pytest.approx(40, abs=0.05) and found.confirmed == len(found.beats)


def test_the_running_mean_is_centred_at_the_ends_too():
    """Onsets are measured against it: the first frames' mean must be theirs, not the next ones'."""
    means = running_mean(np.array([4.0, 0.0, 0.0, 0.0, 0.0, 8.0]), 4)
    assert means.tolist() == pytest.approx([2.0, 4 / 3, 1.0, 0.0, 2.0, 8 / 3])


def test_a_range_below_the_songs_tempo_takes_its_half_not_its_third():
    """40..60 on a 120-bpm song whose bass changes each bar: 60 (two beats a bar), not 40, whose
    bars of four would each hold three of the song's and so match its chord changes too."""
    from drumsong import beat_times, drums

    song = drums(RATE, 1, 30.0, beat_times(30.0))[:, 0].astype(np.float32)
    assert estimate(features_of([song], RATE, "song"), bpm_range=(40.0, 60.0)).bpm == pytest.approx(60.0, abs=0.05)


def test_a_long_steady_songs_bpm_keeps_the_digits_its_last_beats_need():
    """At 123.456 bpm, 123.46 would put the beats 4 ms late after two minutes."""
    found = estimate(features_of([clicks(123.456, 120.0)], RATE, "long"))
    assert found.bars == () and found.bpm == 123.456
    assert max(abs(b.onset_s - b.time_s) for b in found.beats if b.onset_s is not None) < 0.002
