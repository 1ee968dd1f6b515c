"""Hostile logs against the reviews of a live show (issue 24): a hold that never ends, thousands
of state flips, states in the wrong order, a resume before any pause, absurd show times, cue
numbers and labels that are huge, hold terminal controls or matplotlib's `$`, skips of no cue.
Every review answers (exit 0, or one line, exit 2), lists a bounded page, and the PNG draws; and
the music's resume gap is pause time, not drift."""

from __future__ import annotations

import pytest

from choreo.events import Answer, Command, CommandEvent
from choreo.log.format import ClockRecord, StepRecord
from choreo.log.reader import LogReader
from choreo.log.recorder import Recorder, RunInfo
from choreo.review.showtime import ShowTimes
from choreo.review.summary import summarize
from choreo.review.timeline import LISTED_CUES, LISTED_MARKS, build, render_text
from runlog import vmain

S, T0 = 10**9, 10**18
SHOW = b"version: 1\nsteps:\n  - play: 1\n    at: go\n    label: a\n  - play: 2\n    at: 1.0\n"
REVIEWS = (["summary"], ["summary", "--json"], ["timeline"], ["frames"], ["export", "--csv", "-"],
           ["export", "--cues", "--json", "-"])


def logged(path, fill):  # type: ignore[no-untyped-def]
    recorder = Recorder(path, RunInfo("show.yaml", "x", SHOW, "sim://", 115200, T0))
    fill(recorder)
    recorder.close({"outcome": "aborted"})
    return path


def never_ends(r: Recorder) -> None:
    r.on_clock(ClockRecord(0.0, 0, state="running"), T0)
    r.on_step_record(StepRecord(0, "play", "start", 0.0), T0)
    r.on_clock(ClockRecord(0.5, S // 2, state="held"), T0 + S // 2)
    for n in range(1, 20):
        r.on_step_record(StepRecord(n, "wait", "start", 0.5 + n), T0 + S + n * S)


def flips(r: Recorder) -> None:
    r.on_step_record(StepRecord(0, "play", "start", 0.0), T0)
    for n in range(3000):
        t = n * 2_000_000
        r.on_clock(ClockRecord(n / 1000, t, state="held"), T0 + t)
        r.on_clock(ClockRecord(n / 1000, t + 1_000_000, state="running"), T0 + t + 1_000_000)


def wrong_order(r: Recorder) -> None:
    r.on_step_record(StepRecord(0, "play", "start", 0.0), T0)
    for i, state in enumerate(["paused", "held", "running", "running", "paused", "paused", "held"]):
        r.on_clock(ClockRecord(1.0 + i * 0.1, (i + 1) * S, state=state), T0 + (i + 1) * S)


def resume_first(r: Recorder) -> None:
    for i, show_s in enumerate((0.0, 0.0, 0.5)):
        r.on_clock(ClockRecord(show_s, i * S, "music", state="running"), T0 + i * S)
    r.on_step_record(StepRecord(0, "play", "start", 0.6), T0 + 2 * S + S // 10)


def absurd(r: Recorder) -> None:
    r.on_clock(ClockRecord(-1e18, 0, state="running"), T0)
    r.on_step_record(StepRecord(0, "play", "start", -1e18), T0 + 1)
    r.on_clock(ClockRecord(1e18, S, state="held"), T0 + S)
    r.on_clock(ClockRecord(-5.0, 2 * S, state="running"), T0 + 2 * S)


def names(r: Recorder) -> None:
    r.on_step_record(StepRecord(0, "play", "start", 0.0, go=True, cue_number="9" * 100_000, label="$x^{$\\"), T0)
    r.on_step_record(StepRecord(1, "play", "skip", 0.0, cue_number="\x1b[2J\u202e", label="\x1b]0;evil\x07"), T0 + 1)
    r.on_step_record(StepRecord(2, "play", "skip", 0.0), T0 + 2)  # a skip of a step no cue starts
    answer = Answer("ok", "m", {"cue": "\x1b[31m" * 1000, "label": "$"})
    r.on_command(CommandEvent(Command("cue_go", "key", "$\\frac{"), answer, T0 + 3, 0.0))


@pytest.mark.parametrize("fill", [never_ends, flips, wrong_order, resume_first, absurd, names])
def test_every_review_answers_a_hostile_log(tmp_path, capsys, fill):
    log = logged(tmp_path / "h.mcap", fill)
    for review in REVIEWS:
        assert vmain(["log", review[0], str(log), *review[1:]]) == 0, review
        out = capsys.readouterr().out
        if review[0] != "export":
            assert "\x1b" not in out and "\u202e" not in out, review  # controls shown as escapes
            assert len(out) < 60_000, review  # a page, not one line a flip


@pytest.mark.parametrize("fill", [flips, names])
def test_the_png_of_a_hostile_log_draws(tmp_path, fill):
    pytest.importorskip("matplotlib")
    log = logged(tmp_path / "h.mcap", fill)
    assert vmain(["log", "timeline", str(log), "--png", str(tmp_path / "t.png")]) == 0  # `$` no mathtext
    assert (tmp_path / "t.png").read_bytes()[:4] == b"\x89PNG"


def test_the_timeline_lists_a_page_of_marks_and_cues(tmp_path):
    with LogReader(logged(tmp_path / "h.mcap", flips)) as reader:
        timeline = build(reader)
    assert len(timeline.stands) == 3000
    lines = list(render_text(timeline, 120))
    assert sum(line.startswith("  ") and " held 0.001 s" in line for line in lines) == LISTED_MARKS
    assert f"  ... and {3000 - LISTED_MARKS} more" in lines
    assert LISTED_CUES < LISTED_MARKS


def test_a_hold_that_never_ends_lasts_to_the_logs_end(tmp_path):
    summary = summarize(logged(tmp_path / "h.mcap", never_ends))
    assert summary.lengths is not None and summary.lengths.holds == 1
    assert summary.lengths.held_s == pytest.approx(19.5)
    assert summary.stands[0].stand.end_ns is None and "to the end of the log" in summary.stands[0].text(summary.end_ns)


def _fed(samples):  # type: ignore[no-untyped-def]
    times = ShowTimes(0)
    for log_time, record in samples:
        times.see_clock(log_time, record)
    return times


def test_the_musics_resume_gap_is_pause_time_not_drift():
    """Paused at 1 s for 2 s; the resume sample says 1.0 (true: the song is not heard yet); show
    time moves 30 ms later, as the next sample (at 3.53 s, show 1.5) says: the pause ends there."""
    ms = 10**6
    times = _fed([(0, ClockRecord(0.0, 0, "music", "running")), (S, ClockRecord(1.0, S, "music", "paused")),
                  (3 * S, ClockRecord(1.0, 3 * S, "music", "running")),
                  (3 * S + 20 * ms, ClockRecord(1.0, 3 * S + 20 * ms, "music", "running")),  # still not heard
                  (3530 * ms, ClockRecord(1.5, 3530 * ms, "music", "running"))])
    (pause,) = times.stands
    assert pause.end_ns == 3 * S + 30 * ms and pause.seconds(None) == pytest.approx(2.03)
    assert times.seconds(3 * S + 10 * ms) == 1.0 and times.seconds(3200 * ms) == pytest.approx(1.17)
    machine = _fed([(0, ClockRecord(0.0, 0, state="running")), (S, ClockRecord(1.0, S, state="paused")),
                    (3 * S, ClockRecord(1.0, 3 * S, state="running")), (3530 * ms, ClockRecord(1.53, 3530 * ms))])
    assert machine.stands[0].end_ns == 3 * S  # the machine's clock goes on at once: its resume is exact


def test_a_loop_pass_is_counted_and_the_axis_goes_on():
    times = _fed([(0, ClockRecord(0.5, 0, state="running")), (S, ClockRecord(1.5, S, state="running")),
                  (S + 10, ClockRecord(0.5, S + 10, state="running")), (2 * S, ClockRecord(1.5, 2 * S))])
    assert times.passes() == 2 and times.rewound_s() == pytest.approx(1.0, abs=1e-6)
    assert times.elapsed(2 * S) == pytest.approx(2.5, abs=1e-6) and times.seconds(2 * S) == pytest.approx(1.5)
