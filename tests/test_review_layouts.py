"""Every review reads a log's frames with the board layout the log records (issue 21, item 7).

Real runs of an hth4-2.2 show on the simulator (virtual time), one robot and two (both hth4-2.2,
and one of each layout): `log frames`, `log export`, `log summary`, `log timeline` and `replay`
name every frame and reply as the robot's own layout builds and answers them (no "invalid", no
"not a motion slot"), and the ACK check and config read sent when a port opens come first, at
negative show times, in the order they were sent.
"""

from __future__ import annotations

import json
import re
from pathlib import Path

import pytest

from choreo.clock import VirtualTime
from choreo.wire.framewords import describe_frame
from choreo.wire.layouts import HTH4_22, SEED
from choreo.log.format import (ClockRecord, LogLayouts, RxRecord, StepRecord, TxRecord, frame_meaning,
                              reply_meaning)
from choreo.log.reader import LogReader
from choreo.run.replay import replay
from choreo.review.showtime import ShowTimes
from choreo.review.summary import summarize
from choreo.review.timeline import build
from runlog import vmain, write_show

MOTIONS = """\
motions:
  wave: {number: 3, duration: 0.2}
  bow: {number: 7, duration: 0.15}
  last: {number: 119, duration: 0.1}
"""
STEPS = """\
steps:
  - play: wave
  - wait: done
  - play: bow
  - wait: done
  - play: last
  - wait: done
"""
ONE = "version: 1\nname: one\nrobot: {layout: hth4-2.2}\n" + MOTIONS + STEPS
TWO = "version: 1\nname: two\nrobots:\n  left: {layout: hth4-2.2}\n  right: {layout: hth4-2.2}\n" + MOTIONS + STEPS
MIXED = "version: 1\nname: mixed\nrobots:\n  left: {layout: hth4-2.2}\n  right: {layout: seed}\n" + MOTIONS + STEPS
LAYOUT_OF = {"one": {None: "hth4-2.2"}, "two": {"left": "hth4-2.2", "right": "hth4-2.2"},
             "mixed": {"left": "hth4-2.2", "right": "seed"}}
PLAYED = {3, 7, 119}
WRONG = ("invalid", "not a motion slot", "not a frame", "-byte reply", "not hex")


@pytest.fixture(scope="module")
def logs(tmp_path_factory) -> dict[str, Path]:
    folder = tmp_path_factory.mktemp("layouts")
    made = {}
    for name, body in (("one", ONE), ("two", TWO), ("mixed", MIXED)):
        show = write_show(folder, body, f"{name}.yaml")
        made[name] = folder / f"{name}.mcap"
        assert vmain(["run", str(show), "--log", str(made[name]), "-q"]) == 0
    return made


def _export(log: Path, capsys) -> list[dict]:
    capsys.readouterr()
    assert vmain(["log", "export", str(log), "--jsonl", "-"]) == 0
    return [json.loads(line) for line in capsys.readouterr().out.splitlines()]


def _frames(log: Path, capsys) -> list[str]:
    capsys.readouterr()
    assert vmain(["log", "frames", str(log)]) == 0
    return capsys.readouterr().out.splitlines()


@pytest.mark.parametrize("name", ["one", "two", "mixed"])
def test_export_reads_every_frame_with_its_robots_layout(logs, name, capsys):
    rows = _export(logs[name], capsys)
    assert len(rows) > 20
    for row in rows:
        assert not any(word in row["frame_meaning"] for word in WRONG), row
        assert not any(word in row["reply_meaning"] for word in WRONG), row
        assert row["layout"] == LAYOUT_OF[name][row["robot"]], row
        assert row["reply"] in ("ack", "status"), row  # a clean run: the recorded verdicts agree
        if row["frame"] == "play":
            assert row["frame_meaning"].endswith(f": motion {row['motion']}"), row
        if row["frame"] == "status":
            assert row["reply_meaning"].endswith("executing"), row
    assert {row["motion"] for row in rows if row["frame"] == "play"} == PLAYED


def test_the_hth4_frames_are_named_as_the_layout_builds_them(logs, capsys):
    rows = _export(logs["one"], capsys)
    meaning = {row["frame"]: row["frame_meaning"] for row in rows}
    assert meaning["play"].startswith("CALL 0x")
    assert "suspend: config 0x" in meaning["stop"] and "resume: config 0x" in meaning["restore"]
    assert meaning["counter"].endswith("program counter to the main loop 0x00044b")
    assert meaning["read"].endswith("config word read") and meaning["status"].endswith("status query")
    calls = [row for row in rows if row["frame"] == "play"]
    assert [row["frame_meaning"] for row in calls] == [
        f"CALL 0x{HTH4_22.slot_address(row['motion']):06x}: motion {row['motion']}" for row in calls]
    running = [row["reply_meaning"] for row in rows if row["frame"] == "status" and row["executing"]]
    assert running and all(re.match(r"program counter 0x[0-9a-f]{6} \(motion \d+\), return address 0x00044b, "
                                    r"depth 1: executing$", text) for text in running)


@pytest.mark.parametrize("name", ["one", "two", "mixed"])
def test_log_frames_reads_every_frame_with_its_robots_layout(logs, name, capsys):
    lines = _frames(logs[name], capsys)
    body = [line for line in lines[1:] if re.match(r"^ *-?\d+\.\d+  (tx|rx)  #", line)]
    assert len(body) == len(lines) - 1  # no note: the log records every robot's layout
    assert not [line for line in body if any(word in line for word in WRONG)]
    called = {int(m.group(1)) for line in body for m in [re.search(r"CALL 0x[0-9a-f]{6}: motion (\d+)$", line)] if m}
    assert called == PLAYED


@pytest.mark.parametrize("name", ["one", "two", "mixed"])
def test_frames_sent_at_open_come_first_at_negative_show_times(logs, name, capsys):
    rows = _export(logs[name], capsys)
    for robot, layout in LAYOUT_OF[name].items():
        own = [row for row in rows if row["robot"] == robot]
        opening = [row for row in own if row["label"] == "open"]
        show = [row for row in own if row["step"] is not None]
        if layout == "seed":
            assert not opening  # the seed layout reads nothing at open
            continue
        assert [row["frame"] for row in opening] == ["sync", "read"]
        assert own[:2] == opening  # first in the log, in the order sent
        assert opening[0]["tx_show_s"] < opening[1]["tx_show_s"] < 0
        assert all(row["rx_show_s"] <= 0 for row in opening)
        assert max(row["rx_show_s"] for row in opening) <= min(row["tx_show_s"] for row in show)
    lines = _frames(logs[name], capsys)
    opened = [line for line in lines if "ACK check" in line or "config word read" in line]
    assert opened and all(line.lstrip().startswith("-0.") for line in opened)


def test_a_fault_at_open_is_placed_before_the_show_in_the_timeline(tmp_path, capsys):
    show = write_show(tmp_path, ONE)
    log = tmp_path / "junk.mcap"
    # the first ACK check at open gets a junk reply (seeded: the same on every run), the second is fine
    port = "sim://?junk=0.5&faults_on=sync&seed=1"
    assert vmain(["run", str(show), "--port", port, "--log", str(log), "-q"]) == 0
    rows = _export(log, capsys)
    assert [row["reply"] for row in rows[:3]] == ["invalid", "ack", "status"]
    with LogReader(log) as reader:
        timeline = build(reader)
    (fault,) = timeline.faults
    assert fault.show_s < 0 and "INVALID to frame #1" in fault.text
    capsys.readouterr()
    assert vmain(["log", "timeline", str(log)]) == 0
    listed = capsys.readouterr().out.split("faults: 1\n", 1)[1].splitlines()[0]
    assert re.match(r"^ +-0\.\d{3} s  INVALID to frame #1", listed)


def test_summary_places_a_warning_at_open_before_the_show(tmp_path, monkeypatch):
    """A warning the run logs as the port opens (a USB adapter's slow latency timer) is listed
    where it was logged, before the show clock started (on virtual time the clock starts the
    same instant), not at the time the port's frames took after the run was prepared."""
    monkeypatch.setattr("choreo.board.link.usb_latency_note", lambda port: "port X: the latency timer is 16 ms")
    show = write_show(tmp_path, ONE)
    log = tmp_path / "note.mcap"
    assert vmain(["run", str(show), "--log", str(log), "-q"]) == 0
    summary = summarize(log)
    (line,) = summary.log_lines
    assert "latency timer" in line.message and line.show_s <= 0
    assert summary.replies["invalid"] == 0 and summary.replies["status"] > 3
    first_play = min(play.start_s for play in summary.plays)
    assert line.show_s < first_play


def test_replay_says_what_the_recorded_replies_meant(logs, tmp_path):
    """A replay whose board refuses every third status query: the recorded replies it compares
    are named as the hth4-2.2 layout answers them, not called invalid."""
    report = replay(logs["one"], port="sim://?nak=3&faults_on=read", log_path=tmp_path / "r.mcap",
                    time_source=VirtualTime())
    assert report.different > 0
    said = [str(difference) for difference in report.differences]
    assert not [text for text in said if "invalid" in text]
    assert all("recorded program counter 0x" in text and "replay NAK" in text for text in said), said


@pytest.mark.parametrize("name", ["one", "two"])
def test_a_replays_log_reads_right_and_keeps_the_open_frames_before_zero(logs, name, tmp_path, capsys):
    new_log = tmp_path / "replayed.mcap"
    report = replay(logs[name], log_path=new_log, time_source=VirtualTime())
    assert report.frames > 20 and report.board_differences == 0
    rows = _export(new_log, capsys)
    assert not [row for row in rows if any(word in row["frame_meaning"] + row["reply_meaning"] for word in WRONG)]
    opening = [row for row in rows if row["label"] == "open"]
    assert opening and all(row["tx_show_s"] < 0 for row in opening)


# -- the one decoding function, on logs this run did not write -------------------------------


def test_a_log_without_a_recorded_layout_is_read_with_seed_and_says_so():
    layouts = LogLayouts.of({"show": "old"})  # a log from before layouts were recorded
    assert layouts.name(None) == "seed" and layouts.assumed(None)
    call = TxRecord(1, "play", SEED.play_frame(5).hex, motion=5)
    assert frame_meaning(call, layouts) == f"CALL 0x{SEED.slot_address(5):06x}: motion 5"
    (note,) = layouts.notes([])
    assert "does not record a board layout" in note and "seed" in note
    assert LogLayouts.of({"layout": "hth4-2.2"}).notes([]) == []


def test_each_robot_is_read_with_its_own_layout():
    layouts = LogLayouts.of({"robots": "a,b", "layout": "hth4-2.2", "robot.a.layout": "hth4-2.2",
                             "robot.b.layout": "seed"})
    a = TxRecord(1, "play", HTH4_22.play_frame(2).hex, motion=2, robot="a")
    b = TxRecord(1, "play", SEED.play_frame(2).hex, motion=2, robot="b")
    assert frame_meaning(a, layouts).endswith(": motion 2") and frame_meaning(b, layouts).endswith(": motion 2")
    wrong = TxRecord(1, "play", SEED.play_frame(2).hex, motion=2, robot="a")  # a seed CALL sent to an hth4 board
    assert frame_meaning(wrong, layouts).endswith("not a motion slot of the hth4-2.2 layout (motion 2's slot in seed)")


def test_an_unknown_layout_is_said_and_slots_named_by_the_layout_they_fit():
    layouts = LogLayouts.of({"layout": "hth9\x1b[2J"})
    assert layouts.layout(None) is None
    call = TxRecord(1, "play", HTH4_22.play_frame(4).hex, motion=4)
    assert frame_meaning(call, layouts).endswith("motion 4 (a slot of the hth4-2.2 layout)")
    (note,) = layouts.notes([])
    assert "unknown to this choreo" in note and "\x1b" not in note


def test_a_huge_recorded_layout_name_is_cut_in_every_review(logs, tmp_path, capsys):
    # A hostile log's 50 KB layout name was printed whole: in the summary, the frames' notes and
    # every row of an export. A known name is kept whole.
    from test_review_damage import _rewritten

    huge = "hth9" + "\u202e" + "x" * 50_000
    log = tmp_path / "huge.mcap"
    _rewritten(logs["mixed"], log, "/rcb4/tx", "-", None, {"robot.left.layout": huge})
    assert LogLayouts.of({"robot.left.layout": huge, "robots": "left"}).name("left") == huge[:39] + "\u2026"
    assert LogLayouts.of({"layout": "hth4-2.2"}).name(None) == "hth4-2.2"
    for review in (["summary"], ["frames"], ["export", "--csv", "-"]):  # --json: the metadata as stored
        capsys.readouterr()
        assert vmain(["log", review[0], str(log), *review[1:]]) == 0
        out = capsys.readouterr().out
        assert "x" * 40 not in out and len(out) < 20_000, review
        assert "hth9" in out, review


def test_replies_are_read_by_the_frame_they_answer():
    layouts = LogLayouts.of({"layout": "hth4-2.2"})
    status = TxRecord(1, "status", HTH4_22.status.hex)
    over = RxRecord(1, "status", "0d 00 4b 04 00 00 00 00 00 00 00 00 5c")
    assert reply_meaning(over, status, layouts) == ("program counter 0x00044b, return address 0x000000, "
                                                    "depth 0: not executing")
    assert reply_meaning(over, None, layouts) == "13-byte reply: 0d 00 4b 04 00 00 00 00 00 00 00 00 5c"
    assert reply_meaning(RxRecord(1, "status", "0d 00 4b"), status, layouts) == "invalid: 0d 00 4b"
    assert describe_frame(bytes.fromhex("07 0c 00 00 00 00 13"), HTH4_22) == "CALL 0x000000: not a motion slot"


def test_bytes_that_are_not_hex_are_said_so():
    layouts = LogLayouts.of({"layout": "hth4-2.2"})
    assert frame_meaning(TxRecord(1, "play", ["07"]), layouts) == "not hex: ['07']"  # type: ignore[arg-type]
    assert frame_meaning(TxRecord(1, "play", "zz"), layouts) == "not hex: 'zz'"
    assert reply_meaning(RxRecord(1, "ack", {"a": 1}), None, layouts) == "not hex: {'a': 1}"  # type: ignore[arg-type]
    assert reply_meaning(RxRecord(1, "ack", "04 00 06 0a"), TxRecord(1, "stop", 7), layouts) == "ACK"  # type: ignore[arg-type]


# -- a log whose show clock is damaged ----------------------------------------------------------


def _hostile_log(path: Path, show_s: object) -> Path:
    """A log whose first clock sample and first step start carry `show_s`, then a good step."""
    from choreo.log.recorder import Recorder, RunInfo

    recorder = Recorder(path, RunInfo("show.yaml", "x", b"version: 1\n", "sim://", 115200, 10**18, "hth4-2.2"))
    recorder.on_tx(_TxEvent(1, 10**18 + 1_000_000))
    recorder.on_clock(ClockRecord(show_s, 5), 10**18 + 2_000_000)  # type: ignore[arg-type]
    recorder.on_step_record(StepRecord(0, "play", "start", show_s), 10**18 + 3_000_000)  # type: ignore[arg-type]
    recorder.on_step_record(StepRecord(1, "play", "start", 1.0), 10**18 + 4_000_000)
    recorder.close({"outcome": "done"})
    return path


class _TxEvent:
    def __init__(self, seq: int, time_ns: int) -> None:
        from choreo.wire.protocol import sync_frame

        self.seq, self.frame, self.attempt, self.time_ns, self.tag = seq, sync_frame(), 1, time_ns, None


@pytest.mark.parametrize("show_s", [float("inf"), float("nan"), 1e300, "abc", [], None])
def test_a_damaged_show_time_is_one_line_or_skipped_never_a_traceback(tmp_path, show_s, capsys):
    log = _hostile_log(tmp_path / "hostile.mcap", show_s)
    for command in (["summary"], ["frames"], ["timeline"], ["export", "--csv", "-"]):
        code = vmain(["log", command[0], str(log), *command[1:]])
        err = capsys.readouterr().err
        assert code in (0, 2) and "Traceback" not in err, (command, err)
        assert code == 0 or len(err.strip().splitlines()) == 1, (command, err)


def test_the_first_show_time_that_is_a_number_fixes_zero(tmp_path):
    log = _hostile_log(tmp_path / "hostile.mcap", float("nan"))
    with LogReader(log) as reader:
        times = ShowTimes.of(reader)
    assert times.anchored and times.seconds(10**18 + 4_000_000) == pytest.approx(1.0)
    assert times.seconds(10**18 + 1_000_000) == pytest.approx(0.997)  # the frame before: before zero


def test_summary_names_each_robots_layout_and_an_assumed_one(logs, tmp_path, capsys):
    assert vmain(["log", "summary", str(logs["mixed"])]) == 0
    out = capsys.readouterr().out
    assert "robot left: " in out and ", layout hth4-2.2; " in out and ", layout seed; " in out
    old = _hostile_log(tmp_path / "old.mcap", 0.0)
    with LogReader(old) as reader:
        reader.metadata["choreo"].pop("layout")  # as a log from before layouts were recorded
        from choreo.review.summary import summarize_reader
        from choreo.review.summarytext import render

        lines = list(render(summarize_reader(reader)))
    assert any(", layout seed (not recorded: assumed) " in line for line in lines if line.startswith("run "))
