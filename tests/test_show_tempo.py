"""Tempo cues: `tempo:` and `at: {bar, beat}` resolve to seconds on the show clock, `choreo plan`
shows both forms, and mistakes are located."""

from __future__ import annotations

import json
from pathlib import Path
from textwrap import dedent

import pytest

from choreo.cli import main
from choreo.errors import ShowError
from choreo.show.load import load_show
from choreo.show.model import Tempo
from choreo.show.plan import compile_plan

SHOW = """
    version: 1
    tempo: {bpm: 120, offset: 0.5, meter: 4}
    steps:
      - play: 1
        at: {bar: 1}
      - play: 2
        at: {bar: 2, beat: 2.5}
      - repeat: 2
        at: {bar: 4}
        steps:
          - play: 3
          - wait: 0.5
      - play: 4
        at: 9
"""


def write(tmp_path: Path, text: str) -> Path:
    path = tmp_path / "show.yaml"
    path.write_text(dedent(text).lstrip())
    return path


def test_bars_and_beats_are_seconds_from_the_first_downbeat():
    tempo = Tempo(120, offset=0.5, meter=4)
    assert tempo.seconds(1) == 0.5 and tempo.seconds(2) == 2.5 and tempo.seconds(2, 2.5) == 3.25
    assert Tempo(90, meter=3).seconds(3, 1) == 4.0


def test_the_plan_puts_tempo_cues_where_the_music_has_them(tmp_path, capsys, monkeypatch):
    plan = compile_plan(load_show(write(tmp_path, SHOW)))
    assert [(s.at, s.at_beat) for s in plan.steps if s.at is not None] == [
        (0.5, (1, 1.0)), (3.25, (2, 2.5)), (6.5, (4, 1.0)), (9.0, None)]
    monkeypatch.setenv("COLUMNS", "200")
    assert main(["plan", str(tmp_path / "show.yaml")]) == 0
    out = capsys.readouterr().out
    assert "3.250 s (at 3.25 = bar 2 beat 2.5)" in out and "6.500 s (at 6.5 = bar 4 beat 1)" in out
    assert "9.000 s (at 9)" in out
    assert main(["plan", "--json", str(tmp_path / "show.yaml")]) == 0
    steps = json.loads(capsys.readouterr().out)["plan"]
    assert (steps[1]["cue"], steps[1]["cue_bar"], steps[1]["cue_beat"]) == (3.25, 2, 2.5)
    assert "cue_bar" not in steps[6]


@pytest.mark.parametrize("text, where, message", [
    ("version: 1\nsteps:\n  - play: 1\n    at: {bar: 2}\n", (4, 9, "steps[0].at"),
     "a cue in bars and beats needs the music's `tempo:`"),
    ("version: 1\ntempo: {bpm: 100, meter: 3}\nsteps:\n  - play: 1\n    at: {bar: 2, beat: 4}\n",
     (5, 24, "steps[0].at.beat"), "beat 4: a bar has 3 beats (tempo.meter)"),
    ("version: 1\ntempo: {bpm: 100}\nsteps:\n  - play: 1\n    at: {bar: 2, beet: 4}\n",
     (5, 18, "steps[0].at.beet"), "unknown key 'beet': did you mean `beat`?"),
    ("version: 1\ntempo: {bpm: 100}\nsteps:\n  - play: 1\n    at: {beat: 2}\n", (5, 9, "steps[0].at"),
     "needs its `bar:`"),
    ("version: 1\ntempo: {bpm: 100}\nsteps:\n  - play: 1\n    at: {bar: 0}\n", (5, 15, "steps[0].at.bar"),
     "must be at least 1, not 0"),
    ("version: 1\nsteps:\n  - play: 1\n    at: -1\n", (4, 9, "steps[0].at"), "must be at least 0, not -1"),
    ("version: 1\ntempo: {bpm: 120}\nsteps:\n  - play: 1\n    at: {bar: 3}\n  - play: 2\n    at: 1\n",
     (7, 9, "steps[1].at"), "cue at 1 s comes after the cue at 4 s"),
    ("version: 1\ntempo: {bpm: 0}\nsteps: [{play: 1}]\n", (2, 14, "tempo.bpm"), "must be more than 0, not 0"),
])
def test_tempo_mistakes_are_located(tmp_path, text, where, message):
    with pytest.raises(ShowError) as info:
        load_show(write(tmp_path, text))
    found = [(p.line, p.column, p.path, p.message) for p in info.value.problems]
    assert any((line, column, path) == where and message in said for line, column, path, said in found), found


@pytest.mark.parametrize("at, tempo", [
    ("{bar: }", "{bpm: 120}"),
    ("{beat: 2}", "{bpm: 120}"),
    ("{bar: play3}", "{bpm: 120}"),
    ("{bar: 2, beat: x}", "{bpm: 120}"),
    ("{bar: 2}", "{bpm: }"),
    ("{bar: 2}", "{bpm: 120, meter: four}"),
])
def test_a_broken_bar_and_beat_cue_or_tempo_is_a_located_error_not_a_crash(tmp_path, at, tempo):
    """Found by tests/test_show_fuzz.py once shows/music.yaml had bar-and-beat cues."""
    show = write(tmp_path, f"version: 1\ntempo: {tempo}\nsteps:\n  - play: 1\n    at: {at}\n")
    with pytest.raises(ShowError) as error:
        load_show(show)
    assert all(line.startswith(str(show) + ":") for line in error.value.lines())
