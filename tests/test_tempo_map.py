"""Tempo maps in shows (issue 23): `tempo: {meter, bars: [...]}` places each bar's downbeat where
the music has it, `at: {bar, beat}` cues follow the map, its mistakes are located, and `choreo
validate`, `choreo plan` (text and JSON) and the live console's bar.beat all read it."""

from __future__ import annotations

import io
import json
from itertools import pairwise
from pathlib import Path

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from rich.console import Console as RichConsole

from choreo.cli import main
from choreo.cli.console import Console
from choreo.cli.screen import Row, Screen, render
from choreo.clock import MachineShowClock
from choreo.errors import ShowError
from choreo.events import StopRequest
from choreo.live.controls import Live
from choreo.run.session import Session
from choreo.run.settings import RunRequest
from choreo.show.cues import cue_list
from choreo.show.load import load_show, load_show_bytes
from choreo.show.model import MAX_BPM, MAX_CUE_S, MAX_TEMPO_BARS, Tempo
from choreo.show.plan import compile_plan
from runlog import write_show

# bars of 2.0, 2.1, 1.9 and 2.2 s: 120, 114.3, 126.3 and 109.1 bpm
MAP = Tempo.of_bars((0.5, 2.5, 4.6, 6.5, 8.7))

MAP_SHOW = """\
    version: 1
    tempo:
      meter: 4
      bars: [0.5, 2.5, 4.6,
             6.5, 8.7]
    steps:
      - play: 1
        at: {bar: 2, beat: 3}
      - play: 2
        at: {bar: 4}
      - play: 3
        at: {bar: 6, beat: 2}
"""


# --------------------------------------------------------------------------- the map


def test_a_bar_and_beat_is_placed_between_its_bars_downbeats():
    assert [MAP.seconds(bar) for bar in range(1, 6)] == [0.5, 2.5, 4.6, 6.5, 8.7]
    assert MAP.seconds(2, 3) == 3.55  # halfway through bar 2's 2.1 s
    assert MAP.seconds(3, 2.5) == pytest.approx(4.6 + 1.5 / 4 * 1.9)
    assert (MAP.meter, MAP.offset, MAP.bpm) == (4, 0.5, 117.143)  # the median of the bars' tempi


def test_a_maps_tempo_is_its_bars_median_so_one_odd_bar_does_not_move_it():
    assert Tempo.of_bars((0, 2, 4, 6, 30)).bpm == 120.0  # a fermata's 24 s bar: 10 bpm
    assert Tempo.of_bars((0, 2, 4, 4.6, 6.6, 8.6)).bpm == 120.0  # a 400 bpm glitch among four at 120
    assert Tempo.of_bars((0, 2, 4.4)).bpm == 110.0  # two bars: halfway between 120 and 100


def test_past_the_last_bar_and_before_the_first_the_nearest_bars_length_goes_on():
    assert MAP.seconds(5, 3) == pytest.approx(8.7 + 2.2 / 2)  # the last bar has no end: bar 4's length
    assert MAP.seconds(7) == pytest.approx(8.7 + 2 * 2.2)
    assert MAP.position(0.0) == (0, pytest.approx(4.0))  # a count-in bar before bar 1, at bar 1's length
    assert MAP.position(-1.5) == (0, pytest.approx(1.0))
    assert not MAP.past_map(5) and MAP.past_map(5, 1.5) and MAP.past_map(9)
    assert not Tempo(120).past_map(999)


def test_one_tempo_is_the_straight_line_it_was():
    tempo = Tempo(120, offset=0.5, meter=4)
    assert (tempo.seconds(2, 2.5), tempo.position(3.25), tempo.position(2.5)) == (3.25, (2, 2.5), (2, 1.0))
    assert tempo.bars == () and tempo.bar_bpm == ()
    assert hash(MAP) == hash(Tempo.of_bars((0.5, 2.5, 4.6, 6.5, 8.7)))  # frozen, hashable: a tuple


@settings(max_examples=300, deadline=None)
@given(bpm=st.floats(1.0, 400.0), offset=st.floats(0.0, 100.0), meter=st.integers(1, 16),
       bar=st.integers(1, 100_000), fraction=st.floats(0.0, 0.999))
def test_one_tempo_keeps_the_arithmetic_it_had_to_the_nanosecond(bpm, offset, meter, bar, fraction):
    """Shows written before maps plan to the same nanosecond: the docs' formula, as it was computed."""
    beat = 1 + fraction * meter
    formula = round(offset + ((bar - 1) * meter + (beat - 1)) * 60.0 / bpm, 9)
    assert Tempo(bpm, offset, meter).seconds(bar, beat) == formula


def test_one_tempo_is_not_divided_by_its_meter_and_multiplied_back():
    assert Tempo(120, 0.48, 14).seconds(157, 3.53349281299991) == 1093.746746407  # was 1093.746746406


@pytest.mark.parametrize("bars", [(), (1.0,), (0.0, 2.0, 2.0), (0.0, 2.0, 1.0)])
def test_a_map_that_does_not_go_forward_is_no_map(bars):
    if bars:
        with pytest.raises(ValueError, match="two or more bars, each after the one before"):
            Tempo(120, bars[0], 4, bars)
    with pytest.raises(ValueError, match="two or more bars, each after the one before"):
        Tempo.of_bars(bars)  # not an IndexError or a ZeroDivisionError on the way


def test_a_maps_bar_1_is_its_first_entry():
    with pytest.raises(ValueError, match=r"a tempo map's offset is its bar 1 \(0.5\), not 0.0"):
        Tempo(120, 0.0, 4, (0.5, 2.5))
    assert Tempo(120, 0.5, 4, (0.5, 2.5)) == Tempo.of_bars((0.5, 2.5))


bar_lengths = st.lists(st.floats(0.2, 8.0), min_size=1, max_size=40)


@settings(max_examples=200, deadline=None)
@given(start=st.floats(0.0, 100.0), lengths=bar_lengths, meter=st.integers(1, 16),
       bar=st.integers(1, 60), fraction=st.floats(0.0, 0.999))
def test_position_is_the_inverse_of_seconds(start, lengths, meter, bar, fraction):
    bars = [start]
    for length in lengths:
        bars.append(bars[-1] + length)
    tempo = Tempo.of_bars(tuple(bars), meter)
    beat = 1 + fraction * meter
    found_bar, found_beat = tempo.position(tempo.seconds(bar, beat))
    assert found_bar * meter + found_beat == pytest.approx(bar * meter + beat, abs=1e-6)


tempi = st.one_of(
    st.builds(lambda bpm, offset, meter: Tempo(bpm, offset, meter),
              st.floats(1.0, 400.0), st.floats(0.0, 100.0), st.integers(1, 16)),
    st.builds(lambda start, lengths, meter: Tempo.of_bars(tuple(start + sum(lengths[:k])
                                                                for k in range(len(lengths) + 1)), meter),
              st.floats(0.0, 100.0), st.lists(st.floats(2.4, 60.0), min_size=1, max_size=40), st.integers(1, 16)))


@settings(max_examples=400, deadline=None)
@given(tempo=tempi, bar=st.integers(-20, 5000), eighths=st.integers(0, 127), thousandths=st.integers(0, 999))
def test_a_cues_own_time_reads_back_as_the_very_bar_and_beat_written(tempo, bar, eighths, thousandths):
    """Before bar 1, on and around the anchors, far past the map: `position(seconds(...))` is
    the bar and beat as written (2.75, 4.999), never a hair before it nor the bar before."""
    for beat in (1 + eighths % (8 * tempo.meter) / 8, round(1 + (eighths % tempo.meter) + thousandths / 1000, 3)):
        assert tempo.position(tempo.seconds(bar, beat)) == (bar, beat)


@settings(max_examples=400, deadline=None)
@given(tempo=tempi, seconds=st.floats(-100.0, 5000.0))
def test_seconds_undoes_position_to_a_millionth_of_a_beat(tempo, seconds):
    bar, beat = tempo.position(seconds)
    assert 1 <= beat < tempo.meter + 1
    # its beats are even within a bar; rounded up to a downbeat, the time was in the bar before
    beat_s = max(tempo.seconds(bar + 1) - tempo.seconds(bar), tempo.seconds(bar) - tempo.seconds(bar - 1)) / tempo.meter
    assert tempo.seconds(bar, beat) == pytest.approx(seconds, abs=1e-6 * beat_s + 2e-9)


@settings(max_examples=200, deadline=None)
@given(lengths=bar_lengths, meter=st.integers(1, 16), bar=st.integers(1, 50))
def test_the_map_goes_forward_beat_by_beat_and_meets_every_anchor(lengths, meter, bar):
    bars = [0.25]
    for length in lengths:
        bars.append(bars[-1] + length)
    tempo = Tempo.of_bars(tuple(bars), meter)
    times = [tempo.seconds(bar, beat) for beat in range(1, meter + 1)] + [tempo.seconds(bar + 1)]
    assert all(b > a for a, b in pairwise(times))
    if bar <= len(bars):
        assert tempo.seconds(bar) == pytest.approx(bars[bar - 1], abs=1e-9)


# --------------------------------------------------------------------------- the show file


def write(tmp_path: Path, body: str) -> Path:
    return write_show(tmp_path, body)


def test_cues_in_bars_and_beats_follow_the_map(tmp_path):
    show = load_show(write(tmp_path, MAP_SHOW))
    assert show.tempo == MAP
    plan = compile_plan(show)
    assert [(s.at, s.at_beat) for s in plan.steps] == [(3.55, (2, 3.0)), (6.5, (4, 1.0)),
                                                       (pytest.approx(8.7 + 2.2 + 2.2 / 4), (6, 2.0))]


def problems(tmp_path: Path, tempo: str, cue: str = "{bar: 2}") -> list[tuple[int, int, str, str]]:
    path = write(tmp_path, f"version: 1\ntempo: {tempo}\nsteps:\n  - play: 1\n    at: {cue}\n")
    with pytest.raises(ShowError) as info:
        load_show(path)
    return [(p.line, p.column, p.path, p.message) for p in info.value.problems]


@pytest.mark.parametrize("tempo, where, message", [
    ("{bpm: 120, bars: [0, 2]}", (2, 9, "tempo.bpm"),
     "a tempo map (`bars:`) places bar 1 and every bar itself: leave out `bpm:`"),
    ("{offset: 1, bars: [0, 2]}", (2, 9, "tempo.offset"),
     "a tempo map (`bars:`) places bar 1 and every bar itself: leave out `offset:`"),
    ("{meter: 3}", (2, 8, "tempo"), "needs `bpm:` (one tempo, e.g. `{bpm: 120, offset: 0.5}`) or `bars:` (a tempo "
                                    "map: each bar's start in seconds, as `choreo beats` prints it)"),
    ("{bars: [1]}", (2, 15, "tempo.bars"),
     "a tempo map needs at least 2 bars (where each starts, in seconds); for one tempo give `bpm:` and `offset:`"),
    ("{bars: []}", (2, 15, "tempo.bars"), "a tempo map needs at least 2 bars"),
    ("{bars: 3}", (2, 15, "tempo.bars"), "expected a list (`- item` lines), not the number 3"),
    ("{bars: [0, x]}", (2, 19, "tempo.bars[1]"), "expected a number, not the text 'x'"),
    ("{bars: [0, true]}", (2, 19, "tempo.bars[1]"), "expected a number, not true"),
    ("{bars: [-1, 2]}", (2, 16, "tempo.bars[0]"), "must be at least 0, not -1"),
    ("{bars: [0, .inf]}", (2, 19, "tempo.bars[1]"), "must be at most 86400, not .inf"),
    ("{bars: [0, .nan]}", (2, 19, "tempo.bars[1]"), "not-a-number (.nan) is not allowed here"),
    ("{bars: [0, 90000]}", (2, 19, "tempo.bars[1]"), "must be at most 86400, not 90000"),
    ("{bars: [0, 2, 1.5, 4]}", (2, 22, "tempo.bars[2]"),
     "bar 3 starts at 1.5 s, not after bar 2's 2 s: each bar of the map starts later than the one before"),
    ("{bars: [0, 2, 2]}", (2, 22, "tempo.bars[2]"), "bar 3 starts at 2 s, not after bar 2's 2 s"),
    ("{bars: [0, 2], meter: 0}", (2, 30, "tempo.meter"), "must be at least 1, not 0"),
    ("{bars: [0, 5e-324]}", (2, 19, "tempo.bars[1]"), "faster than 400 bpm: its 4 beats take 0.6 s or more"),
    ("{meter: 3.0, bars: [0, 0.5, 0.6]}", (2, 36, "tempo.bars[2]"),
     "bar 2 lasts 0.1 s (0.5 to 0.6 s), faster than 400 bpm: its 3 beats take 0.45 s or more"),
    ("{bars: [0, 2], bpn: 3}", (2, 23, "tempo.bpn"), "unknown key 'bpn': did you mean `bpm`?"),
])
def test_tempo_map_mistakes_are_located(tmp_path, tempo, where, message):
    found = problems(tmp_path, tempo)
    assert any((line, column, path) == where and message in said for line, column, path, said in found), found
    assert len(found) == 1, found  # one mistake, one message: the cue says nothing more


def test_the_fastest_bar_a_map_may_hold_is_the_fastest_tempo(tmp_path):
    shortest = 60.0 / MAX_BPM  # meter 1
    body = f"version: 1\ntempo: {{meter: 1, bars: [0, {shortest}, 1]}}\nsteps: [{{play: 1}}]\n"
    show = load_show(write(tmp_path, body))
    assert show.tempo is not None and max(show.tempo.bar_bpm) == MAX_BPM


@pytest.mark.parametrize("tempo, bar, seconds", [
    ("{bars: [0, 86400]}", 3, "172,800"),  # carried past the map
    ("{bars: [0, 2]}", 100_000, "199,998"),
    ("{bpm: 1}", 100_000, "23,999,760"),  # one tempo too: no bar cue where no seconds cue may be
])
def test_a_cue_in_bars_falls_within_a_day_as_a_cue_in_seconds_must(tmp_path, tempo, bar, seconds):
    found = problems(tmp_path, tempo, f"{{bar: {bar}}}")
    assert [(f[0], f[1], f[2], f[3]) for f in found] == [
        (5, 9, "steps[0].at",
         f"bar {bar} beat 1 falls {seconds} s into the show, past the 86,400 s (a day) a cue may be")]


def test_the_schema_says_the_limits_the_code_checks():
    schema = json.loads((Path(__file__).parents[1] / "schemas" / "show.schema.json").read_text())
    tempo = schema["properties"]["tempo"]["properties"]
    cue = schema["$defs"]["step"]["properties"]["at"]["anyOf"]
    seconds = next(form for form in cue if form.get("type") == "number")
    assert (tempo["bars"]["maxItems"], tempo["bpm"]["maximum"]) == (MAX_TEMPO_BARS, MAX_BPM)
    assert tempo["bars"]["items"]["maximum"] == seconds["maximum"] == MAX_CUE_S


def test_a_beat_past_the_bar_is_said_with_a_map_too(tmp_path):
    found = problems(tmp_path, "{meter: 3, bars: [0, 2]}", "{bar: 2, beat: 4}")
    assert [(f[2], f[3]) for f in found] == [
        ("steps[0].at.beat", "beat 4: a bar has 3 beats (tempo.meter), so beats run from 1 to below 4")]


def test_cues_through_a_map_must_not_go_back_in_time(tmp_path):
    path = write(tmp_path, "version: 1\ntempo: {bars: [0, 2, 5]}\nsteps:\n  - play: 1\n    at: {bar: 3}\n"
                           "  - play: 2\n    at: 4.9\n")
    with pytest.raises(ShowError) as info:
        load_show(path)
    assert "cue at 4.9 s comes after the cue at 5 s (steps[0].at, line 5)" in info.value.problems[0].message


def test_a_map_longer_than_the_limit_is_refused_in_one_message():
    """A hostile file of 100,001 tiny entries (within the size limit) costs one message."""
    bars = ",".join(["1"] * (MAX_TEMPO_BARS + 1))
    source = f"version: 1\ntempo: {{bars: [{bars}]}}\nsteps: [{{play: 1, at: {{bar: 2}}}}]\n".encode()
    with pytest.raises(ShowError) as info:
        load_show_bytes(source, "big.yaml")
    assert [(p.path, p.message) for p in info.value.problems] == [
        ("tempo.bars", "a tempo map of 100,001 bars is more than the 100,000 a show may hold")]


# --------------------------------------------------------------------------- validate, plan


def test_validate_and_plan_say_the_map_and_its_cues(tmp_path, capsys, monkeypatch):
    path = write(tmp_path, MAP_SHOW)
    assert main(["validate", str(path)]) == 0
    line = capsys.readouterr().out.strip()
    assert line.endswith("; 1 cue past the tempo map's last bar (5), timed at its length")
    monkeypatch.setenv("COLUMNS", "200")
    assert main(["plan", str(path)]) == 0
    out = capsys.readouterr().out.splitlines()
    assert out[1] == "tempo map: 5 bars, 4 beats a bar, 109.1-126.3 bpm, bar 1 at 0.5 s"
    assert any("3.550 s (at 3.55 = bar 2 beat 3)" in line for line in out)
    assert any("11.450 s (at 11.45 = bar 6 beat 2, past the tempo map)" in line for line in out)


def test_plan_never_rounds_a_beat_up_to_one_the_bar_has_not(tmp_path, capsys, monkeypatch):
    path = write(tmp_path, "version: 1\ntempo: {bars: [0, 2, 4]}\nsteps:\n"
                           "  - play: 1\n    at: {bar: 2, beat: 4.9999999}\n  - play: 1\n    at: {bar: 3, beat: 2.5}\n")
    monkeypatch.setenv("COLUMNS", "200")
    assert main(["plan", str(path)]) == 0
    out = capsys.readouterr().out
    assert "= bar 2 beat 4.9999999)" in out and "= bar 3 beat 2.5, past the tempo map)" in out


def test_plan_and_validate_json_carry_the_map(tmp_path, capsys):
    path = write(tmp_path, MAP_SHOW)
    tempo = {"bpm": 117.143, "offset": 0.5, "meter": 4, "bars": [0.5, 2.5, 4.6, 6.5, 8.7]}
    assert main(["plan", "--json", str(path)]) == 0
    record = json.loads(capsys.readouterr().out)
    assert record["tempo"] == tempo
    assert [(s["cue"], s["cue_bar"], s["cue_beat"]) for s in record["plan"][:2]] == [(3.55, 2, 3.0), (6.5, 4, 1.0)]
    assert main(["validate", "--json", str(path)]) == 0
    assert json.loads(capsys.readouterr().out)["files"][0]["tempo"] == tempo
    one = write(tmp_path, "version: 1\ntempo: {bpm: 100}\nsteps: [{play: 1}]\n")
    assert main(["plan", "--json", str(one)]) == 0
    assert json.loads(capsys.readouterr().out)["tempo"] == {"bpm": 100.0, "offset": 0.0, "meter": 4}


# --------------------------------------------------------------------------- the console


def screen_at(tmp_path: Path, body: str, show_s: float) -> Screen:
    session = Session.prepare(RunRequest(str(write(tmp_path, body)), no_log=True))
    live = Live(StopRequest(), cues=cue_list(session.settings.plans))
    console = Console(session, live, out=io.StringIO(), keys=io.StringIO())
    live.use_clock(MachineShowClock(session.clock.mono() - show_s))
    return console.screen()


def test_the_console_shows_bar_and_beat_through_the_map(tmp_path):
    assert screen_at(tmp_path, MAP_SHOW, 3.6).bar == (2, 3)  # 3.55 s is bar 2 beat 3
    assert screen_at(tmp_path, MAP_SHOW, 1.0).cue == "next cue in 2.5 s: cue 1 at 3.55 s, bar 2 beat 3"
    assert screen_at(tmp_path, MAP_SHOW, 6.49).bar == (3, 4)
    assert screen_at(tmp_path, MAP_SHOW, 6.51).bar == (4, 1)
    assert screen_at(tmp_path, "version: 1\ntempo: {bpm: 120}\nsteps: [{play: 1}]\n", 2.6).bar == (2, 2)
    assert screen_at(tmp_path, "version: 1\nsteps: [{play: 1}]\n", 2.6).bar is None


def test_before_bar_1_the_console_counts_in_from_bar_0():
    """A count-in reads as a drummer counts it: bar 0's beats lead into bar 1 (at bar 1's
    length), the bars before it -1, -2..."""
    counted = [(bar, int(beat)) for bar, beat in map(MAP.position, (0.49, 0.0, -1.5, -1.51))]
    assert counted == [(0, 4), (0, 4), (0, 1), (-1, 4)]


@pytest.mark.parametrize("width", (60, 80))
def test_eight_robots_and_a_count_in_fit_the_console(width):
    rows = tuple(Row(f"dancer{k}", f"{k}: play 1 (wave)", "-", 1.25, 0) for k in range(8))
    screen = Screen("eight", 0.2, "music clock", "next cue in 0.3 s", "next GO: none ahead", False, rows, (),
                    bar=(-12, 4))
    out = io.StringIO()
    RichConsole(file=out, width=width, color_system=None).print(render(screen, width))
    lines = out.getvalue().splitlines()
    assert lines[0].endswith("show 0.2 s · bar -12.4 · music clock")
    assert all(len(line) <= width for line in lines) and sum(line.startswith("dancer") for line in lines) == 8


@pytest.mark.parametrize("width", (60, 80, 120))
def test_the_bar_stays_readable_beside_the_show_time(width):
    screen = Screen("a show whose name is long enough to be cut at sixty columns", 123.4, "music clock, held for GO",
                    "next cue in 1.0 s: step 3 at 125 s", "next GO: none ahead", False,
                    (Row("robot", "2: play 1", "-", 1.25, 0),), (), bar=(62, 3))
    out = io.StringIO()
    RichConsole(file=out, width=width, color_system=None).print(render(screen, width))
    first = out.getvalue().splitlines()[0]
    assert first.endswith("show 123.4 s · bar 62.3 · music clock, held for GO") and len(first) <= width
