"""The run log's metadata, written and read through log/format: the names and order logs have
always had on disk, and typed values back (what an old, cut or damaged log lacks reads as empty)."""

from __future__ import annotations

from choreo.events import RunResult
from choreo.log.format import LoggedRun, result_metadata
from choreo.log.recorder import RobotInfo, RunInfo


def _info(robots: tuple[RobotInfo, ...] = (), unison: bool = False) -> RunInfo:
    return RunInfo("shows/hello.yaml", "hello", b"version: 1\n", "sim://", 625000, 1_790_000_000_123_456_789,
                   "hth4-2.2", robots, unison)


def test_the_run_info_keys_are_written_in_the_order_logs_always_had():
    solo = ["version", "show", "show_path", "show_sha256", "port", "baud", "layout", "start_time", "start_ns", "host",
            "python", "platform"]
    assert list(_info().metadata()) == solo
    two = _info((RobotInfo("left", "sim://a", 115200), RobotInfo("right", "sim://b", 1250000, "hth4-2.2")), True)
    assert list(two.metadata()) == solo + ["robots", "unison", "robot.left.port", "robot.left.baud",
                                           "robot.left.layout", "robot.right.port", "robot.right.baud",
                                           "robot.right.layout"]
    assert two.metadata()["unison"] == "yes" and two.metadata()["robot.right.baud"] == "1250000"
    assert _info().metadata()["start_time"] == "2026-09-21T14:13:20.123Z"


def test_the_result_is_written_as_it_always_was():
    assert result_metadata(RunResult("done", 12, 1, 3.5)) == {
        "outcome": "done", "steps_run": "12", "late_steps": "1", "show_s": "3.500000"}


def test_the_run_info_reads_back_typed():
    two = _info((RobotInfo("left", "sim://a", 115200), RobotInfo("right", "sim://b", 1250000)), True)
    run = LoggedRun(two.metadata())
    assert (run.show, run.show_path, run.robots, run.unison) == ("hello", "shows/hello.yaml", ["left", "right"], True)
    assert (run.start_ns, run.baud(), run.baud("left"), run.baud("right")) == (
        1_790_000_000_123_456_789, 625000, 115200, 1250000)
    assert LoggedRun(_info().metadata()).robots == [] and not LoggedRun(_info().metadata()).unison


def test_an_old_or_damaged_run_info_reads_as_empty_not_as_an_error():
    empty = LoggedRun({})
    assert (empty.show, empty.show_path, empty.robots, empty.unison, empty.start_ns, empty.baud(),
            empty.baud("left")) == ("", "", [], False, None, None, None)
    damaged = LoggedRun({"start_ns": "12x", "baud": "-5", "robots": ",,a,", "unison": "YES", "robot.a.baud": "9" * 30})
    assert (damaged.start_ns, damaged.baud(), damaged.robots, damaged.unison, damaged.baud("a")) == (
        None, None, ["a"], False, None)
