"""Reviews that tell the truth about a live show (issue 24): a show held at GO cues and panicked
during a hold, on virtual time (the test moves the clock while the show waits, as an operator
taking their time), and every review says the same duration, hold time and step times; hostile
clock samples are one line or passed over, at a bounded cost."""

from __future__ import annotations

import csv
import io
import json
import threading

import pytest

from choreo.clock import VirtualTime
from choreo.events import Command, StopRequest
from choreo.live.controls import Live
from choreo.log.format import ClockRecord, parse
from choreo.log.reader import LogReader
from choreo.review.export import cue_rows
from choreo.review.showtime import ShowTimes
from choreo.review.summary import summarize, summary_record
from choreo.review.summarytext import render
from choreo.review.timeline import build, render_text
from choreo.run.session import Session
from choreo.run.settings import RunRequest
from choreo.show.cues import cue_list
from runlog import vmain, wait_for, write_show

SHOW = """\
version: 1
motions:
  wave: {number: 1, duration: 1.0}
  bow: {number: 2, duration: 0.5}
steps:
  - play: wave
  - wait: 0.1
  - play: bow
    at: go
    label: applause
  - wait: done
  - play: wave
    at: 2.0
    label: encore
  - wait: done
  - play: bow
    at: 3.0
    label: extra
  - play: bow
    at: go
    label: finale
  - wait: done
"""
FIRST_HOLD_S, SECOND_HOLD_S, PAUSE_S = 2.3, 1.7, 1.2


class PauseAfterFirstStep:
    """The operator pauses as the first play's motion has begun (its step ended): from the
    runner's own thread, so the pause falls at the same instant on any machine."""

    def __init__(self, live: Live) -> None:
        self.live = live

    def on_step(self, event) -> None:  # type: ignore[no-untyped-def]
        if event.step.index == 0 and event.event == "end":
            assert self.live.command(Command("pause", "key")).ok

    def on_log(self, *args) -> None:  # type: ignore[no-untyped-def]
        pass


@pytest.fixture(scope="module")
def held(tmp_path_factory):
    """Paused 1.2 s while the first wave runs, held 2.3 s at the first GO cue (GO from the key),
    1.7 s at the second, then a panic over OSC."""
    tmp = tmp_path_factory.mktemp("held")
    log = tmp / "run.mcap"
    source = VirtualTime()
    session = Session.prepare(RunRequest(str(write_show(tmp, SHOW)), log_path=str(log)), source)
    live = Live(StopRequest(), cues=cue_list(session.settings.plans), now=source.now, wall_ns=source.wall_ns)
    done = {}

    def run() -> None:
        with session:
            done["result"] = session.run([PauseAfterFirstStep(live)], live=live)

    thread = threading.Thread(target=run, daemon=True)
    thread.start()
    assert wait_for(lambda: bool(live.paused_robots), 20, 0.002)  # the runner stands before its next step
    source.advance(PAUSE_S)
    assert live.command(Command("skip", "key", label="extra")).ok  # a timed cue ahead: passed, never run
    assert live.command(Command("resume", "osc tcp 127.0.0.1:53000")).ok
    assert wait_for(lambda: bool(live.waiting), 20, 0.002)
    source.advance(FIRST_HOLD_S)  # nothing else runs while the show waits: the hold is exactly this long
    assert live.command(Command("go", "key")).ok
    assert wait_for(lambda: bool(live.waiting) and live.waiting[0].name == "finale", 20, 0.002)
    source.advance(SECOND_HOLD_S)
    assert live.command(Command("panic", "osc udp 127.0.0.1:53001")).ok
    thread.join(20)
    assert done["result"].outcome == "aborted"
    return log


def test_summary_timeline_export_and_replay_agree_to_the_millisecond(held, tmp_path, capsys):
    summary = summarize(held)
    with LogReader(held) as reader:
        timeline = build(reader)
        rows = cue_rows(reader)
    lengths = summary.lengths
    assert lengths is not None and timeline.lengths == lengths
    assert round(timeline.end_s, 3) == round(summary.duration_s, 3)
    assert lengths.holds == 2 and lengths.held_s == pytest.approx(FIRST_HOLD_S + SECOND_HOLD_S, abs=0.01)
    assert lengths.pauses == 1 and lengths.paused_s == pytest.approx(PAUSE_S, abs=0.001)
    assert lengths.wall_s == pytest.approx(lengths.show_s + lengths.held_s + lengths.paused_s)
    # the step times: the timeline's cues and the exported rows are the step records' own
    assert [(c.label, round(c.show_s, 3)) for c in timeline.cues] == [
        (r["label"], r["planned_s"] if r["released"] == "time" else r["actual_s"]) for r in rows][:2]
    assert [(r["number"], r["label"], r["released"]) for r in rows] == [
        ("1", "applause", "go key"), ("2", "encore", "time"), ("3", "extra", "skipped"),
        ("4", "finale", "waiting (stopped)")]
    assert vmain(["replay", str(held), "--log", str(tmp_path / "replay.mcap"), "--json"]) == 0
    replayed = json.loads(capsys.readouterr().out)
    assert replayed["recorded"] == lengths.to_json() and replayed["different"] == 0
    record = summary_record(summary)
    assert record["lengths"] == lengths.to_json() and record["duration_s"] == lengths.show_s


def test_hold_time_is_said_as_hold_time_not_drift(held):
    summary = summarize(held)
    text = "\n".join(render(summary))
    assert "held 4.0" in text and "at 2 GO cues, paused 1.200 s" in text
    assert summary.clock is not None and abs(summary.clock.drift_ms) < 1.0  # the machine's clock never drifts
    assert "minus machine clock +0.000 ms" in text
    assert [(n.stand.kind, n.cue, n.by) for n in summary.stands] == [
        ("paused", None, "resume from osc tcp 127.0.0.1:53000"), ("held", "cue 1 'applause'", "go from key"),
        ("held", None, "panic from osc udp 127.0.0.1:53001")]
    assert "held 2.300 s at cue 1 'applause', go from key" in text
    assert summary.steps_skipped == 1 and ", 1 skipped" in text


def test_the_timeline_draws_holds_commands_and_a_motion_through_a_hold_at_its_length(held):
    with LogReader(held) as reader:
        timeline = build(reader)
    through = timeline.runs[0]  # the wave, running while the show was paused, then held
    assert through.start_at is not None and through.drawn_end_at is not None
    assert through.drawn_end_at - through.start_at == pytest.approx(1.0, abs=0.01)
    assert through.start_s == pytest.approx(0.004, abs=0.002)  # its show time: where the clock stood
    assert [m.kind for m in timeline.commands] == ["command"] * 3 + ["command", "skip", "command"]
    assert [m.text.split(" ")[0] for m in timeline.commands] == ["pause", "skip", "resume", "go", "cue", "panic"]
    assert timeline.commands[4].text == "cue 3 'extra' skipped (step 6)"
    go_text, panic_text = (m.text.split(":")[0] for m in timeline.commands[3::2])
    assert go_text.startswith("go ") and go_text.endswith(" from key")
    assert panic_text == "panic from osc udp 127.0.0.1"
    go = timeline.commands[3]
    assert go.drawn_at == pytest.approx(PAUSE_S + FIRST_HOLD_S + 0.1, abs=0.01)
    assert go.show_s == pytest.approx(0.1, abs=0.01)
    assert [m.kind for m in timeline.stands] == ["paused", "held", "held"]
    lines = list(render_text(timeline, 100))
    row = next(line for line in lines if "holds/cmds" in line)
    assert "~" in row and "^" in row and "s" in row
    assert any(line.strip().startswith("0.100 s  held 2.300 s at cue 1 'applause', go from key") for line in lines)


def test_the_png_timeline_draws_a_held_show(held, tmp_path):
    pytest.importorskip("matplotlib")
    assert vmain(["log", "timeline", str(held), "--png", str(tmp_path / "t.png")]) == 0
    assert (tmp_path / "t.png").read_bytes()[:4] == b"\x89PNG"


def test_export_cues_to_csv_from_the_command_line(held, capsys):
    assert vmain(["log", "export", "--cues", "--csv", "-", str(held)]) == 0
    rows = list(csv.DictReader(io.StringIO(capsys.readouterr().out)))
    assert [r["released"] for r in rows] == ["go key", "time", "skipped", "waiting (stopped)"]
    assert rows[1]["late_ms"] == "0.0" and rows[0]["bar_beat"] == ""


# -- hostile clock samples ----------------------------------------------------------------------

def test_a_clock_state_no_choreo_writes_is_refused_as_one_line():
    with pytest.raises(ValueError, match="state"):
        parse("/choreo/clock", b'{"show_s": 1.0, "monotonic_ns": 5, "state": "frozen"}')
    assert parse("/choreo/clock", b'{"show_s": 1.0, "monotonic_ns": 5, "state": "paused"}').state == "paused"


def _fed(samples):  # type: ignore[no-untyped-def]
    times = ShowTimes(0)
    for log_time, record in samples:
        times.see_clock(log_time, record)
    return times


def test_stands_from_states_and_time_during_them():
    s = 1_000_000_000
    times = _fed([(0, ClockRecord(0.0, 0, state="running")), (s, ClockRecord(1.0, s, state="paused")),
                  (3 * s, ClockRecord(1.0, 3 * s, state="running")), (4 * s, ClockRecord(2.0, 4 * s))])
    assert [(x.kind, x.show_s, x.seconds(None)) for x in times.stands] == [("paused", 1.0, 2.0)]
    assert times.seconds(2 * s) == 1.0 and times.seconds(4 * s) == pytest.approx(2.0)
    assert times.elapsed(2 * s) == pytest.approx(2.0) and times.elapsed(4 * s) == pytest.approx(4.0)


def test_an_older_logs_hold_is_found_where_a_sample_falls_behind_and_a_loop_pass_is_no_hold():
    s = 1_000_000_000
    times = _fed([(0, ClockRecord(0.0, 0)), (3 * s, ClockRecord(1.0, 3 * s)), (4 * s, ClockRecord(0.2, 4 * s))])
    assert [(x.kind, x.show_s, x.start_ns, x.end_ns) for x in times.stands] == [("held", 1.0, s, 3 * s)]
    assert times.seconds(2 * s) == 1.0


def test_many_stands_and_a_planned_time_among_them_cost_a_lookup():
    s = 1_000_000_000
    samples = []
    for n in range(20_000):  # a hostile log: the clock held and went on 20,000 times
        samples += [(2 * n * s, ClockRecord(float(n), 2 * n * s, state="held")),
                    (2 * n * s + s, ClockRecord(float(n), 2 * n * s + s, state="running"))]
    times = _fed(samples)
    assert len(times.stands) == 20_000
    assert [times.elapsed_of_show(n + 0.5) for n in range(0, 20_000, 1000)] == [
        pytest.approx(2 * n + 1.5) for n in range(0, 20_000, 1000)]


def test_samples_out_of_order_are_passed_over_at_a_bounded_cost():
    samples = [(n, ClockRecord(n / 1e9, n)) for n in range(200_000, 0, -1)]
    times = _fed(samples)
    assert times.disordered == len(samples) - 1 and len(times.stands) == 0


def _clock_log(path, samples):  # type: ignore[no-untyped-def]
    """A log of clock samples (log time, record) as a recorder writes them, with a step between."""
    from choreo.log.format import StepRecord
    from choreo.log.recorder import Recorder, RunInfo

    recorder = Recorder(path, RunInfo("show.yaml", "x", b"version: 1\n", "sim://", 115200, 10**18, "hth4-2.2"))
    recorder.on_step_record(StepRecord(0, "wait", "start", 0.0), 10**18)
    for log_time, record in samples:
        recorder.on_clock(record, log_time)
    recorder.close({"outcome": "done"})
    return path


REVIEWS = (["summary"], ["timeline"], ["frames"], ["export", "--csv", "-"], ["export", "--cues", "--json", "-"])


@pytest.mark.parametrize("state", ["frozen", "", "x" * 10_000, "HELD", 5, ["held"], {"a": 1}])
def test_a_log_with_a_clock_state_no_choreo_writes_is_one_line_in_every_review(tmp_path, capsys, state):
    good = ClockRecord(0.0, 0, state="running")
    bad = ClockRecord(1.0, 10**9, state=state)  # type: ignore[arg-type]  # a damaged log's value
    log = _clock_log(tmp_path / "bad.mcap", [(10**18, good), (10**18 + 10**9, bad)])
    for review in REVIEWS:
        if review[0] == "export" and "--cues" in review:
            continue  # the cue rows read steps and commands, not the clock
        code = vmain(["log", review[0], str(log), *review[1:]])
        err = capsys.readouterr().err
        assert code == 2 and len(err.strip().splitlines()) == 1 and "'state'" in err, (review, err)
        assert len(err) < 400  # the hostile value is cut, not printed whole


def test_samples_out_of_order_and_states_that_change_are_reviewed_and_counted(tmp_path, capsys):
    s = 10**9
    samples = [(10**18, ClockRecord(0.0, 0, state="running")), (10**18 + s, ClockRecord(1.0, s, state="held")),
               (10**18 + s // 2, ClockRecord(0.5, s // 2, state="running")),  # earlier than the one before
               (10**18 + 2 * s, ClockRecord(1.0, 2 * s, state="paused")),  # held, then paused at once
               (10**18 + 3 * s, ClockRecord(1.0, 3 * s, state="running")),
               (10**18 + 4 * s, ClockRecord(2.0, 4 * s, state="running"))]
    log = _clock_log(tmp_path / "odd.mcap", samples)
    summary = summarize(log)
    assert summary.lengths is not None and summary.clock_disordered == 1
    assert (summary.lengths.held_s, summary.lengths.paused_s) == (1.0, 1.0)
    assert summary.clock is not None and abs(summary.clock.drift_ms) < 1e-6  # ran 2 s of 4, and drifted none
    assert vmain(["log", "summary", str(log)]) == 0
    assert "1 out of order, passed over" in capsys.readouterr().out
    for review in REVIEWS:
        assert vmain(["log", review[0], str(log), *review[1:]]) == 0, review


@pytest.mark.parametrize("source, held_s", [("machine", 2.0), ("music", 0.0)])
def test_an_older_log_without_states_has_its_holds_on_the_machines_clock_only(tmp_path, source, held_s):
    """Before samples said the clock's state, a hold shows where a sample falls behind the one
    before it: on the machine's clock (which never drifts) that is a hold; the music never held."""
    s = 10**9
    samples = [(10**18, ClockRecord(0.0, 0, source)), (10**18 + s, ClockRecord(1.0, s, source)),
               (10**18 + 4 * s, ClockRecord(2.0, 4 * s, source)), (10**18 + 5 * s, ClockRecord(3.0, 5 * s, source))]
    summary = summarize(_clock_log(tmp_path / "old.mcap", samples))
    assert summary.lengths is not None and summary.lengths.held_s == pytest.approx(held_s)
    assert summary.clock is not None
    assert summary.clock.drift_ms == pytest.approx(0.0 if held_s else -2000.0)  # the music: it drifted


def test_a_replay_keeps_the_holds_and_pauses_the_board_saw(held, tmp_path):
    """Replay paces the frames on the recorded show's elapsed time: the gaps the board saw
    across the pause and the holds are in the replay too (paced on show time, the 1.2 s pause
    and the 2.3 s hold would vanish, and the board be driven faster than on the night)."""
    from choreo.run.replay import replay
    from runlog import read_log

    out = tmp_path / "replayed.mcap"
    replay(held, port="sim://", log_path=out, time_source=VirtualTime())

    def plays(path) -> list[int]:  # type: ignore[no-untyped-def]
        return [m["_log_time"] for m in read_log(path).topic("/rcb4/tx") if m["kind"] == "play"]

    recorded, replayed = plays(held), plays(out)
    assert len(recorded) == len(replayed) >= 3
    gaps = [(b - a) / 1e9 for a, b in zip(recorded, recorded[1:], strict=False)]
    again = [(b - a) / 1e9 for a, b in zip(replayed, replayed[1:], strict=False)]
    assert max(gaps) > FIRST_HOLD_S  # the night's frames straddle a hold
    assert again == pytest.approx(gaps, abs=0.005)


def test_the_png_shades_each_hold_and_pause_and_marks_each_command(held, tmp_path, monkeypatch):
    """The figure itself, read back from matplotlib's artists: a shaded span for the pause and
    each hold, at their places on the elapsed axis and of their lengths, and a marker for each
    command (removing the shading or the markers fails this, not only a PNG header check)."""
    pytest.importorskip("matplotlib")
    import matplotlib.colors
    import matplotlib.pyplot as plt

    from choreo.review.timeline import STOOD, render_png

    figures = []
    close = plt.close
    monkeypatch.setattr(plt, "close", lambda fig=None: (figures.append(fig), close(fig)))
    with LogReader(held) as reader:
        timeline = build(reader)
    with open(tmp_path / "t.png", "wb") as out:
        render_png(timeline, out)
    (ax,) = next(fig for fig in figures if not isinstance(fig, str) and fig is not None).axes  # not close("all")
    stood = matplotlib.colors.to_rgba(STOOD)
    spans = sorted((round(float(v[:, 0].min()), 3), round(float(v[:, 0].max() - v[:, 0].min()), 3))
                   for c in ax.collections if len(c.get_facecolor()) and tuple(c.get_facecolor()[0]) == stood
                   for v in (p.vertices for p in c.get_paths()))
    assert [(k.kind) for k in timeline.stands] == ["paused", "held", "held"]
    assert spans == sorted((round(s.drawn_at, 3), round(s.length_s, 3)) for s in timeline.stands)
    assert [length for _, length in sorted(spans)] == pytest.approx([PAUSE_S, FIRST_HOLD_S, SECOND_HOLD_S], abs=0.01)
    row = [label.get_text() for label in ax.get_yticklabels()].index("commands")
    marked = sorted(x for line in ax.lines for x, y in zip(line.get_xdata(), line.get_ydata(), strict=True) if y == row)
    assert marked == pytest.approx(sorted(m.drawn_at for m in timeline.commands))
    assert len(marked) == 6  # pause, skip, resume, GO, the skipped cue passed, panic


FIRST_SKIPPED = """\
version: 1
steps:
  - play: 1
    at: 0
    label: opener
  - play: 2
    at: 2
    label: two
  - play: 3
    at: go
    label: three
"""


@pytest.mark.parametrize("skip", [["skip opener"], []])
def test_a_show_whose_first_cue_is_skipped_ran_from_its_start(tmp_path, skip):
    """The first cue skipped (its step logs `skip`, not `start`): the show clock still ran from
    0 to the second cue at 2 s, and every review says it ran 2 s, not from 2 s."""
    from test_pause import VirtualRun
    run = VirtualRun(tmp_path, FIRST_SKIPPED, before=skip)
    run.curtain()
    run.finish()
    lengths = summarize(run.log_path).lengths
    assert lengths is not None and lengths.start_s == 0.0
    assert lengths.ran_s == pytest.approx(lengths.show_s) and lengths.show_s == pytest.approx(2.0, abs=0.02)
    with LogReader(run.log_path) as reader:
        assert build(reader).lengths == lengths
