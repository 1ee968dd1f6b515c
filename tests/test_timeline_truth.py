"""Timelines that tell the truth (issue 11, item 4) from one log format and one motion tracker
(item 2): late plays by the summary's rule, retries included; cues; failure and abort marks;
the unplayed rest of the plan; the plan visible under the actual bars; every width."""

from __future__ import annotations

import pytest

from choreo.cli import main
from choreo.log.format import MotionTracker, RxRecord, TxRecord, parse
from choreo.log.reader import LogReader
from choreo.review.summary import summarize
from choreo.review.timeline import build, render_text
from choreo.events import StopRequest
from choreo.run.settings import RunRequest
from runlog import prepare, vmain, write_show

SHOW = """
    version: 1
    name: truth
    motions:
      wave: {number: 3, duration: 0.4}
      bow: {number: 5, duration: 0.3}
    steps:
      - play: wave
      - wait: done
      - play: bow
        at: 1.0
        label: bow-cue
      - wait: done
      - play: wave
        at: 2.0
      - wait: done
      - play: bow
      - wait: done
"""


def timeline_of(path):
    with LogReader(path) as reader:
        return build(reader)


def test_a_play_retries_delayed_is_late_in_the_timeline_as_in_the_summary(tmp_path):
    log = tmp_path / "retries.mcap"
    show = write_show(tmp_path, SHOW)
    assert vmain(["run", str(show), "--port", "sim://?drop=9", "--timeout", "0.05", "--log", str(log), "-q"]) == 0
    timeline, summary = timeline_of(log), summarize(log)
    assert summary.steps_late_by_retries >= 1
    assert len(timeline.late) == summary.steps_late  # the same rule, the same count
    retried = [m for m in timeline.late if "(retries)" in m.text]
    assert len(retried) == summary.steps_late_by_retries
    assert all(float(m.text.split(" started ")[1].split(" ms")[0]) > 1.0 for m in retried)
    late_rows = [r for r in timeline.runs if r.late_ms > 1.0]
    assert len(late_rows) == summary.steps_late
    text = "\n".join(render_text(timeline, 100))
    assert "late plays: " + str(summary.steps_late) in text and "ms late (retries)" in text


def test_cues_are_drawn_and_listed(tmp_path):
    log = tmp_path / "cues.mcap"
    assert vmain(["run", str(write_show(tmp_path, SHOW)), "--log", str(log), "-q"]) == 0
    timeline = timeline_of(log)
    assert [(c.show_s, c.name) for c in timeline.cues] == [(1.0, "cue 1 'bow-cue'"), (2.0, "cue 2")]
    lines = list(render_text(timeline, 100))
    cue_row = next(line for line in lines if line.split()[0] == "cues")
    assert cue_row.count("v") == 2
    assert "cues: cue 1 'bow-cue' at 1 s, cue 2 at 2 s" in lines


def test_the_plan_stays_visible_under_the_actual_bars(tmp_path):
    log = tmp_path / "plan.mcap"
    assert vmain(["run", str(write_show(tmp_path, SHOW)), "--log", str(log), "-q"]) == 0
    rows = [line for line in render_text(timeline_of(log), 120) if line[:5].strip().isdigit()]
    assert rows and all("=" in row.split("|")[1] for row in rows)  # planned and actual overlap


def test_a_failed_run_marks_the_failure_and_greys_the_rest_of_the_plan(tmp_path):
    log = tmp_path / "failed.mcap"
    assert vmain(["run", str(write_show(tmp_path, SHOW)), "--port", "sim://?lose=6", "--log", str(log), "-q"]) == 3
    timeline = timeline_of(log)
    assert [m.kind for m in timeline.marks if m.kind == "failure"] == ["failure"]
    assert [r.step for r in timeline.unplayed] == [2, 4, 6]  # lost while polling the first wave
    text = list(render_text(timeline, 100))
    unplayed_rows = [line for line in text if "not played" in line and "|" in line]
    assert len(unplayed_rows) == 3 and all(":" in row.split("|")[1] for row in unplayed_rows)
    assert "not played: 3 plays of the plan that the run never reached" in text


class StopAfter:
    """Asks the run to stop once a step has ended, as Ctrl-C would."""

    def __init__(self, index: int) -> None:
        self.index = index
        self.stop = StopRequest()

    def on_step(self, event) -> None:
        if event.step.index == self.index and event.event == "end":
            self.stop.request("stopped")

    def on_log(self, *args) -> None:
        pass


def run_stopped_after_step_2(show, log):
    stopper = StopAfter(2)
    with prepare(RunRequest(str(show), log_path=str(log))) as session:
        return session.run([stopper], stopper.stop)


def test_a_stopped_run_marks_the_abort(tmp_path):
    show = write_show(tmp_path, SHOW)
    log = tmp_path / "stopped.mcap"
    result = run_stopped_after_step_2(show, log)
    assert result.outcome == "aborted"
    timeline = timeline_of(log)
    assert timeline.outcome == "aborted"
    assert [r.step for r in timeline.unplayed] == [4, 6]
    (abort,) = [m for m in timeline.marks if m.kind == "abort"]
    assert abort.text == "show aborted" and abort.show_s == timeline.end_s  # no on_abort motion


def test_an_abort_motion_is_marked_where_it_was_played(tmp_path):
    show = write_show(tmp_path, SHOW.replace("    steps:", "    on_abort: bow\n    steps:", 1))
    log = tmp_path / "abort.mcap"
    run_stopped_after_step_2(show, log)
    (abort,) = [m for m in timeline_of(log).marks if m.kind == "abort"]
    assert abort.text == "show stopped: abort motion 5 played"
    assert "show stopped: abort motion 5 played" in "\n".join(render_text(timeline_of(log), 100))


@pytest.mark.parametrize("columns", [40, 60, 80, 132])
def test_the_text_timeline_fits_any_width(tmp_path, columns):
    log = tmp_path / "w.mcap"
    assert vmain(["run", str(write_show(tmp_path, SHOW)), "--port", "sim://?lose=6", "--log", str(log), "-q"]) == 3
    lines = list(render_text(timeline_of(log), columns))
    assert max(len(line) for line in lines) <= columns
    assert any("|" in line for line in lines[4:])  # bars at every width


@pytest.mark.parametrize("argv", [["plan", "shows/dance.yaml"], ["log", "summary", "LOG"],
                                  ["log", "frames", "LOG"], ["log", "timeline", "LOG"]])
def test_every_human_output_fits_the_terminal_width(tmp_path, monkeypatch, capsys, argv):
    log = tmp_path / "x.mcap"
    assert vmain(["run", "shows/minimal.yaml", "--log", str(log), "-q"]) == 0
    capsys.readouterr()
    monkeypatch.setenv("COLUMNS", "60")
    assert main([str(log) if a == "LOG" else a for a in argv]) == 0
    out = capsys.readouterr().out.splitlines()
    assert out and max(len(line) for line in out) <= 60
    assert any(line.endswith("…") for line in out) or max(len(line) for line in out) <= 60


def test_to_a_pipe_lines_stay_whole(tmp_path, monkeypatch, capsys):
    monkeypatch.delenv("COLUMNS", raising=False)
    assert main(["plan", "shows/dance.yaml"]) == 0
    assert max(len(line) for line in capsys.readouterr().out.splitlines()) > 100


# -- the motion tracker, alone ------------------------------------------------------------------

def tx(seq, kind, step=0, motion=3):
    return TxRecord(seq, kind, "", step=step, motion=motion)


def test_a_restore_acked_starts_the_motion_and_a_status_not_executing_ends_it():
    tracker = MotionTracker()
    for seq, kind in enumerate(("stop", "play", "restore"), 1):
        tracker.tx(tx(seq, kind), seq * 10)
        tracker.rx(RxRecord(seq, "ack"), seq * 10 + 1)
    tracker.tx(tx(4, "status"), 100)
    tracker.rx(RxRecord(4, "status", executing=True), 101)
    tracker.tx(tx(5, "status"), 150)
    tracker.rx(RxRecord(5, "status", executing=False), 151)
    (play,) = tracker.finish(200)
    assert (play.motion, play.start_ns, play.end_ns, play.ended_by) == (3, 30, 150, "status")


def test_a_lost_restore_reply_with_the_board_executing_is_a_started_motion():
    tracker = MotionTracker()
    for seq, kind in enumerate(("stop", "play"), 1):
        tracker.tx(tx(seq, kind), seq)
        tracker.rx(RxRecord(seq, "ack"), seq)
    tracker.tx(tx(3, "restore"), 30)
    tracker.rx(RxRecord(3, "timeout"), 40)
    tracker.tx(tx(4, "status"), 90)
    tracker.rx(RxRecord(4, "status", executing=True), 91)
    (play,) = tracker.finish(500)
    assert (play.start_ns, play.ended_by) == (30, "end of log")


def test_a_play_whose_restore_never_got_an_ack_did_not_start():
    tracker = MotionTracker()
    tracker.tx(tx(1, "play"), 1)
    tracker.tx(tx(2, "restore"), 2)
    tracker.rx(RxRecord(2, "nak"), 3)
    tracker.tx(tx(3, "play", step=2, motion=5), 4)
    plays = tracker.finish(10)
    assert [(p.motion, p.ended_by) for p in plays] == [(3, "not started"), (5, "not started")]


def test_a_record_a_log_did_not_write_names_the_missing_field():
    with pytest.raises(KeyError, match="kind"):
        parse("/rcb4/tx", b'{"seq": 1, "hex": ""}')
    assert parse("/rcb4/rx", b'{"seq": 2, "kind": "ack", "future_field": 1}') == RxRecord(2, "ack")


def test_a_cut_line_is_exactly_the_width_with_an_ellipsis():
    from choreo.textfit import fit

    assert fit("abcdef", 4) == "abc…" and fit("abcdef", 1) == "…" and fit("abc", 3) == "abc"
    assert fit("a" * 500, None) == "a" * 500  # no width (a pipe): whole


SPIN = """\
version: 1
motions:
  spin: {number: 3, duration: 3.0}
steps:
  - play: spin
  - wait: 1.0
  - wait: done
  - play: 5
    at: go
    label: curtain
"""


def test_a_motion_running_through_a_pause_is_as_long_in_the_timeline_as_in_the_summary(tmp_path):
    """A 3 s spin paused 1 s in, resumed 6 s later: the status query that finds its end comes
    after the pause, at the show time the pause stood at. Its length is from log times (when it
    started and ended), in the summary, the drawing and the timeline's `actual` column alike."""
    from test_pause import VirtualRun
    run = VirtualRun(tmp_path, SPIN, at={(1, "end"): ["pause"]})  # the runner's own thread: 1.0 s in
    run.held()
    run.source.advance(6.0)
    assert run.say("resume").ok
    run.curtain()
    run.finish()
    played = next(p for p in summarize(run.log_path).plays if p.motion == 3)
    assert played.duration_s is not None and played.duration_s > 6.0  # ran on through the pause
    timeline = timeline_of(run.log_path)
    spin = next(r for r in timeline.runs if r.motion == 3)
    assert spin.end_s == pytest.approx(1.0, abs=0.01)  # the show time its end was seen at: the pause's
    assert spin.actual_s == pytest.approx(played.duration_s, abs=1e-6)
    assert spin.start_at is not None and spin.drawn_end_at == pytest.approx(spin.start_at + played.duration_s)
    row = next(line for line in render_text(timeline, 120) if "motion 3 spin" in line)
    assert f"{spin.start_s:.3f}-{spin.start_s + played.duration_s:.3f}" in row, row
