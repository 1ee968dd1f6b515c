"""Issue 23's last "Done when": a show cued by bar and beat on a drifting song (a tempo map)
moves its robots within 20 ms of the true beats in a simulator run, checked in the log.

The song is made here: drums and a bass whose tempo swings 3 % either side of 120 bpm over its
12 s, so one tempo cannot place its beats (a straight line through them misses by 64 ms) and a
tempo map must. `choreo beats` writes the map; the show pastes it and cues its plays
in bars and beats; the run plays the song on miniaudio's null output (silent, in real time) with
the simulator as the robot. The log then says, for every play, the cue the plan put it on (within
20 ms of the true beat: the map's accuracy) and when its motion started (on that cue, less the
wake-up lateness the run logged itself: `runlog.off_cue_s`, as every real-time test allows for a
loaded machine).
"""

from __future__ import annotations

import math
import wave
from pathlib import Path

import numpy as np
import pytest

from choreo.cli import main
from choreo.show.load import load_show, load_show_bytes
from choreo.show.model import Tempo
from choreo.show.plan import compile_plan
from runlog import read_log, started_on_cue, write_show

RATE = 22050
SONG_S = 12.0
FIRST_S = 0.5  # bar 1 beat 1, after a little silence
BPM, SWING, PERIOD_S = 120.0, 0.03, 12.0  # the tempo swings 3 % either side of 120 bpm, once a song
METER = 4
WITHIN_S = 0.020  # the figure: a cue within 20 ms of the true beat
# (bar, beat) of each play: on beats, between them, early and late in the song
CUES = ((2, 1), (2, 3), (3, 2.5), (4, 4), (5, 1), (5, 3))


def true_beats(seconds: float = SONG_S) -> np.ndarray:
    """Every beat of the song, bar 1 beat 1 first: each beat lasts 60 / tempo where it starts."""
    times = [FIRST_S]
    while times[-1] < seconds - 0.6:
        tempo = BPM * (1 + SWING * math.sin(2 * math.pi * times[-1] / PERIOD_S))
        times.append(times[-1] + 60.0 / tempo)
    return np.array(times)


def true_time(beats: np.ndarray, bar: int, beat: float) -> float:
    """The song's own time of a bar and beat: its beats, and a fraction of a beat between two."""
    index = (bar - 1) * METER + (beat - 1)
    whole = int(index)
    return float(beats[whole] + (index - whole) * (beats[whole + 1] - beats[whole]))


def drum_song(path: Path, beats: np.ndarray) -> Path:
    """Kick on 1 and 3, snare on 2 and 4, hi-hats on the eighths, a bass note on each bar's 1
    (its pitch changes each bar, so bar 1 is plain): a 16-bit mono WAV."""
    out = np.zeros(int(SONG_S * RATE))
    rng = np.random.default_rng(23)

    def hit(sound: np.ndarray, at: float) -> None:
        i = int(round(at * RATE))
        j = min(len(out), i + len(sound))
        out[i:j] += sound[: j - i]

    def tone(hz_from: float, hz_to: float, length: float, decay: float) -> np.ndarray:
        t = np.arange(int(length * RATE)) / RATE
        hz = hz_to + (hz_from - hz_to) * np.exp(-t / 0.03)
        return np.sin(2 * np.pi * np.cumsum(hz) / RATE) * np.exp(-t / decay)

    def noise(length: float, decay: float) -> np.ndarray:
        t = np.arange(int(length * RATE)) / RATE
        return np.diff(rng.standard_normal(len(t)), prepend=0.0) * np.exp(-t / decay)

    for k, at in enumerate(beats):
        beat_s = float(beats[k + 1] - at) if k + 1 < len(beats) else float(at - beats[k - 1])
        if k % 2 == 0:
            hit(tone(150, 50, 0.3, 0.08), at)
        else:
            hit(0.5 * noise(0.2, 0.05) + 0.4 * tone(220, 180, 0.2, 0.04), at)
        if k % METER == 0:
            hz = (55.0, 43.65, 65.41, 49.0)[k // METER % 4]
            hit(0.6 * tone(hz, hz, METER * beat_s, 0.6), at)
        for half in (0.0, 0.5):
            hit(0.15 * noise(0.05, 0.012), at + half * beat_s)
    samples = np.round(out / (np.max(np.abs(out)) * 1.1) * 32767).astype("<i2")
    with wave.open(str(path), "wb") as wav:
        wav.setnchannels(1)
        wav.setsampwidth(2)
        wav.setframerate(RATE)
        wav.writeframes(samples.tobytes())
    return path


def map_show(tempo_block: str) -> str:
    """The show: the song, its tempo block as given, a short play on each of `CUES`."""
    steps = "".join(f"  - play: tap\n    at: {{bar: {bar}, beat: {beat}}}\n" for bar, beat in CUES)
    return (f"version: 1\nmusic: {{file: song.wav}}\n{tempo_block.rstrip()}\n"
            f"motions:\n  tap: {{number: 3, duration: 0.1}}\nsteps:\n{steps}")


def printed_tempo_block(song: Path, capsys: pytest.CaptureFixture[str]) -> str:
    """What `choreo beats SONG` prints to paste into a show: the `tempo:` line and the lines of
    its wrapped list after it."""
    assert main(["beats", str(song)]) == 0
    lines = capsys.readouterr().out.splitlines()
    start = next(i for i, line in enumerate(lines) if line.startswith("tempo:"))
    end = next((i for i in range(start + 1, len(lines)) if not lines[i].startswith(" ")), len(lines))
    return "\n".join(lines[start:end])


def true_tempo_block(beats: np.ndarray) -> str:
    """The song's true downbeats as a `tempo:` block, in the shape `choreo beats` prints."""
    return f"tempo: {{meter: {METER}, bars: [{', '.join(f'{t:.3f}' for t in beats[::METER])}]}}"


def test_one_tempo_cannot_place_this_songs_beats_and_its_true_map_can():
    """The song needs a map (the best straight line misses a beat by far more than 20 ms), and
    a map of its true downbeats puts every beat within 20 ms of its true time, beats evenly
    spaced within each bar: the map's model is good enough for the issue's figure."""
    beats = true_beats()
    slope, intercept = np.polyfit(np.arange(len(beats)), beats, 1)
    assert np.max(np.abs(beats - (intercept + slope * np.arange(len(beats))))) > 3 * WITHIN_S
    show = load_show_bytes(map_show(true_tempo_block(beats)).encode())
    tempo = show.tempo
    assert tempo is not None and len(tempo.bars) == len(beats[::METER])
    placed = [tempo.seconds(k // METER + 1, k % METER + 1) for k in range(len(beats))]
    assert np.max(np.abs(np.array(placed) - beats)) < WITHIN_S
    planned = [step.at for step in compile_plan(show).steps]
    misses = [abs(at - true_time(beats, bar, beat)) for at, (bar, beat) in zip(planned, CUES, strict=True)]
    assert max(misses) < WITHIN_S, misses


def test_a_show_cued_through_the_map_choreo_beats_writes_moves_on_the_true_beats(tmp_path, capsys):
    beats = true_beats()
    block = printed_tempo_block(drum_song(tmp_path / "song.wav", beats), capsys)
    show = write_show(tmp_path, map_show(block))
    tempo = load_show(show).tempo
    assert tempo is not None and tempo.bars, block  # a map, not one tempo
    log_path = tmp_path / "run.mcap"
    assert main(["run", str(show), "--audio-device", "null", "--log", str(log_path)]) == 0
    capsys.readouterr()
    steps = read_log(log_path).topic("/choreo/step")
    ends = [m for m in steps if m["event"] == "end" and m["kind"] == "play"]
    assert len(ends) == len(CUES)
    for end, (bar, beat) in zip(ends, CUES, strict=True):
        truth = true_time(beats, bar, beat)
        assert abs(end["cue"] - truth) < WITHIN_S, (bar, beat, end["cue"], truth, block)  # the plan: the map
        assert end["cue"] == pytest.approx(tempo.seconds(bar, beat), abs=1e-6)
        assert started_on_cue(steps, end), end  # the run: the motion on its cue
    assert Tempo.of_bars(tempo.bars, METER) == tempo
