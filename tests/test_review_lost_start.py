"""The reviews count a play whose start reply was lost as the link counted it (issue 21, item 2's
follow-up): from the logged read of the board's program state, judged by the robot's layout
(`Layout.start_state`), so `log summary`, `log timeline` and `log export` tell the plays the
board started."""

from __future__ import annotations

import json

import pytest

from choreo.wire.layouts import HTH4_22, SEED
from choreo.log.format import MotionTracker, RxRecord, TxRecord
from choreo.log.reader import LogReader
from choreo.review.summary import summarize
from choreo.review.summarytext import render
from choreo.review.timeline import build
from choreo.run.settings import RunRequest
from runlog import prepare, vmain, write_show
from test_play_once import NEVER, OVER, RUNNING, run_short

FAULTS = ("lose_start=2", "lose_start=1", "badsum=2&faults_on=restore", "junk=2&faults_on=restore",
          "drop=2&faults_on=restore", "lose_start=1&badsum=2&faults_on=read")


def _started_runs(log) -> list:
    with LogReader(log) as reader:
        return [run for run in build(reader).runs if run.start_s is not None]


def _export(log, capsys) -> list[dict]:
    capsys.readouterr()
    assert vmain(["log", "export", str(log), "--jsonl", "-"]) == 0
    return [json.loads(line) for line in capsys.readouterr().out.splitlines()]


@pytest.mark.parametrize("faults", FAULTS)
@pytest.mark.parametrize("layout", ["seed", "hth4-2.2"])
def test_summary_timeline_and_export_count_the_starts_the_board_counted(tmp_path, capsys, layout, faults):
    result, board, log = run_short(tmp_path, layout, faults)
    assert result.outcome == "done" and board.starts == 6
    path = tmp_path / "run.mcap"
    summary = summarize(path)
    assert summary.plays_total == board.starts  # was 3 or 0 where start replies were lost
    assert {m: s.plays for m, s in summary.motions.items()} == {1: 2, 2: 2, 3: 2}
    assert [run.motion for run in _started_runs(path)] == [1, 2, 3, 1, 2, 3]
    recovered = [m for m in log.logs if "not sent again" in m["message"]]
    verdicts = [r["reply_meaning"] for r in _export(path, capsys) if r["frame"] == "read" and r["reply"] == "status"
                and r["layout"] == layout and r["motion"] is not None]
    # the export says of each answered state read what the link concluded, with the motion it asked about
    assert verdicts and all(v.endswith(("started and already over", " running", " never started")) for v in verdicts)
    assert len([v for v in verdicts if not v.endswith("never started")]) == len(recovered)


def test_a_play_over_before_the_state_read_ends_at_the_read(tmp_path):
    run_short(tmp_path, "hth4-2.2", "lose_start=2")
    summary = summarize(tmp_path / "run.mcap")
    assert [play.ended_by for play in summary.plays] == ["stop", "state read", "stop", "state read", "stop",
                                                         "state read"]
    assert "not measured (ended by state read)" in "\n".join(render(summary))


MIXED = """
version: 1
robots:
  left: {layout: hth4-2.2}
  right: {layout: seed}
motions:
  short: {number: 1, duration: 0.05}
  longer: {number: 2, duration: 0.1}
steps:
  - play: short
  - wait: 0.3
  - play: longer
  - wait: 0.3
  - play: short
  - wait: 0.3
"""


def test_each_robot_is_judged_by_its_own_layout(tmp_path):
    show = write_show(tmp_path, MIXED)
    ports = {name: "sim://?durations=1:0.05,2:0.1&lose_start=1" for name in ("left", "right")}
    session = prepare(RunRequest(str(show), robot_ports=ports, log_path=str(tmp_path / "two.mcap")))
    with session:
        assert session.run().outcome == "done"
        starts = {name: link.port.board.starts for name, link in session.stage.links.items()}
    assert starts == {"left": 3, "right": 3}
    summary = summarize(tmp_path / "two.mcap")
    assert {name: part.plays_total for name, part in summary.robots.items()} == starts
    assert summary.plays_total == 6
    assert len(_started_runs(tmp_path / "two.mcap")) == 6


# -- the tracker alone: the state read decides ------------------------------------------------


def _lost_start(tracker: MotionTracker, first_seq: int = 1, step: int = 0, t: int = 0) -> None:
    """stop, CALL, restore of motion 3 (step `step`), the restore's reply lost, the state read."""
    for offset, kind in enumerate(("stop", "play", "restore")):
        tracker.tx(TxRecord(first_seq + offset, kind, "", step=step, motion=3), t + offset * 10)
        tracker.rx(RxRecord(first_seq + offset, "ack" if kind != "restore" else "timeout"), t + offset * 10 + 1)


def _read(tracker: MotionTracker, seq: int, answer: bytes, t: int) -> None:
    tracker.tx(TxRecord(seq, "read", "0a 00 20 00 00 00 00 00 0c 36", step=0, motion=3), t)
    tracker.rx(RxRecord(seq, "status", answer.hex(" ")), t + 1)


def test_a_state_read_showing_the_motion_running_starts_it_at_the_restore():
    tracker = MotionTracker(SEED)
    _lost_start(tracker)
    _read(tracker, 4, RUNNING, 80)
    (play,) = tracker.finish(500)
    assert (play.motion, play.start_ns, play.end_ns, play.ended_by) == (3, 20, 500, "end of log")


def test_a_state_read_showing_the_motion_over_ends_it_at_the_read():
    tracker = MotionTracker(SEED)
    _lost_start(tracker)
    _read(tracker, 4, OVER, 80)
    tracker.tx(TxRecord(5, "stop", "", step=2, motion=4), 300)
    (play,) = tracker.finish(500)
    assert (play.start_ns, play.end_ns, play.ended_by) == (20, 80, "state read")


def test_a_state_read_showing_it_never_started_waits_for_the_retry():
    tracker = MotionTracker(SEED)
    _lost_start(tracker)
    _read(tracker, 4, NEVER, 80)
    for seq, kind in enumerate(("stop", "play", "restore"), 5):  # the link's second try
        tracker.tx(TxRecord(seq, kind, "", step=0, motion=3), seq * 100)
        tracker.rx(RxRecord(seq, "ack"), seq * 100 + 1)
    (play,) = tracker.finish(1000)
    assert (play.start_ns, play.ended_by) == (700, "end of log")  # the retry's restore: one play


@pytest.mark.parametrize("then, ended_by", [(RUNNING, "end of log"), (OVER, "state read")], ids=["running", "over"])
def test_a_second_state_read_that_shows_it_started_counts_it_as_the_link_did(then, ended_by):
    # The link believes "never started" only from a second read; a start frame held on its way
    # shows in the second (the link: started, not sent again).
    tracker = MotionTracker(SEED)
    _lost_start(tracker)
    _read(tracker, 4, NEVER, 80)
    _read(tracker, 5, then, 150)
    (play,) = tracker.finish(500)
    assert (play.motion, play.start_ns, play.ended_by) == (3, 20, ended_by)


def test_two_reads_showing_it_never_started_wait_for_the_retry():
    tracker = MotionTracker(SEED)
    _lost_start(tracker)
    _read(tracker, 4, NEVER, 80)
    _read(tracker, 5, NEVER, 150)
    for seq, kind in enumerate(("stop", "play", "restore"), 6):
        tracker.tx(TxRecord(seq, kind, "", step=0, motion=3), seq * 100)
        tracker.rx(RxRecord(seq, "ack"), seq * 100 + 1)
    (play,) = tracker.finish(1000)
    assert (play.start_ns, play.ended_by) == (800, "end of log")


def test_the_layout_judges_the_same_state_differently():
    # RAM that is seed's "never started" for motion 3 is no state the hth4-2.2 sequence leaves
    tracker = MotionTracker(HTH4_22)
    _lost_start(tracker)
    _read(tracker, 4, NEVER, 80)
    (play,) = tracker.finish(500)
    assert play.start_ns == 20  # unclear: counted started, as the link counts it


@pytest.mark.parametrize("then_step,started_at", [(2, 20), (0, 700)], ids=["went-on", "sent-again"])
def test_with_an_unknown_layout_the_links_next_frame_tells(then_step, started_at):
    tracker = MotionTracker(None)  # a layout this choreo does not know cannot judge the state
    _lost_start(tracker)
    _read(tracker, 4, NEVER, 80)
    for seq, kind in enumerate(("stop", "play", "restore"), 5):
        tracker.tx(TxRecord(seq, kind, "", step=then_step, motion=3), seq * 100)
        tracker.rx(RxRecord(seq, "ack"), seq * 100 + 1)
    plays = [p for p in tracker.finish(1000) if p.start_ns is not None]
    assert plays[0].start_ns == started_at
    assert len(plays) == (2 if then_step == 2 else 1)


def test_a_state_read_answered_with_no_hex_counts_as_unclear():
    tracker = MotionTracker(SEED)
    _lost_start(tracker)
    tracker.tx(TxRecord(4, "read", "", step=0, motion=3), 80)
    tracker.rx(RxRecord(4, "status", "zz"), 81)
    (play,) = tracker.finish(500)
    assert play.start_ns == 20


@pytest.mark.parametrize("motion", [1.0, True, -1, 120, "3", None])
def test_a_motion_no_layout_can_judge_is_left_to_the_links_next_frame(motion):
    tracker = MotionTracker(SEED)  # a log another program wrote: never an exception
    for seq, kind in enumerate(("stop", "play", "restore"), 1):
        tracker.tx(TxRecord(seq, kind, "", step=0, motion=motion), seq * 10)
        tracker.rx(RxRecord(seq, "ack" if kind != "restore" else "timeout"), seq * 10 + 1)
    _read(tracker, 4, NEVER, 80)
    tracker.tx(TxRecord(5, "stop", "", step=1), 300)
    (play,) = tracker.finish(500)
    assert play.start_ns == 30


@pytest.mark.parametrize("motion", [1.0, True, 999, "x"])
def test_export_words_of_a_state_read_with_a_motion_no_layout_can_judge(motion):
    from choreo.log.format import LogLayouts, reply_meaning

    tx = TxRecord(4, "read", SEED.start_read.hex, step=0, motion=motion)
    words = reply_meaning(RxRecord(4, "status", NEVER.hex(" ")), tx, LogLayouts({None: "seed"}))
    assert words.startswith("config 0x8721") and "never started" not in words
