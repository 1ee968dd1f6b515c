"""Who decided the stop is who the run's outcome names (issue 22: first reason wins, a panic
always wins), and what a run attaches is gone when it ends, however it ends.

Hostile variants of the wiring defects the issue names: a log whose disk fills after the
operator's panic (or a Ctrl-C) must not claim it stopped the run.
"""

from __future__ import annotations

from pathlib import Path

import pytest

from choreo.events import PANIC, StepEvent, StopRequest, never
from choreo.log.format import INFO
from choreo.run.session import Session
from choreo.run.settings import RunRequest
from runlog import prepare, read_log, write_show
from test_log_disk import KIB, MANY_PLAYS, PORT, SmallDisk


class StopThenFillTheDisk:
    """Asks the run to stop (`reason`) as its first step starts, then writes log lines until the
    log's disk is full: the disk fills after the stop was decided, never before."""

    def __init__(self, session: Session, stop: StopRequest, reason: str) -> None:
        self.session = session
        self.stop = stop
        self.reason = reason

    def on_step(self, event: StepEvent) -> None:
        recorder = self.session.recorder
        if event.event != "start" or self.stop() or recorder is None:
            return
        assert self.stop.request(self.reason)
        for n in range(100_000):
            if recorder.full is not None:
                return
            recorder.on_log(INFO, f"filler {n:06d} " + "x" * 200, self.session.clock.wall_ns())
            recorder.on_idle()
            recorder.flush()
        raise AssertionError("the small disk never filled")

    def on_log(self, level: int, message: str, time_ns: int) -> None:
        pass


@pytest.mark.parametrize("reason", [PANIC, "interrupted (Ctrl-C)"])
def test_a_log_disk_filling_after_the_stop_leaves_the_stop_its_reason(tmp_path, monkeypatch, reason):
    """Before, the log marked itself as having stopped the run although its request came second
    (and was refused): the run ended as a LogError "the run was stopped" (exit 2) instead of the
    panic (or the Ctrl-C) that stopped it."""
    SmallDisk(400 * KIB).install(monkeypatch)
    log_path = tmp_path / "full.mcap"
    session = prepare(RunRequest(str(write_show(tmp_path, MANY_PLAYS)), port=PORT, log_path=str(log_path)))
    stop = StopRequest()
    with session:
        result = session.run([StopThenFillTheDisk(session, stop, reason)], stop)
        assert session.recorder is not None and session.recorder.full is not None  # it did fill
    assert result.outcome == "aborted" and stop.reason == reason
    log = read_log(Path(log_path))
    assert log.metadata["choreo.result"]["outcome"] == "aborted"
    assert log.metadata["choreo.result"]["stop_reason"] == reason
    assert any(m["message"].startswith(f"show {reason} at") for m in log.logs)


def test_the_logs_metadata_names_the_panic_that_a_link_fault_followed(tmp_path):
    """A panic, then robot right's link fails (its panic stop frame is lost): the run fails with
    the link's error, and the log's metadata still says who stopped the show (before, only the
    error: a review could not tell a panic from a fault that stopped the show by itself)."""
    from choreo.errors import LinkError
    from test_wiring import TWO_ROBOTS, PanicAt

    log_path = tmp_path / "run.mcap"
    ports = {"left": "sim://", "right": "sim://?lose=2&faults_on=stop"}
    session = prepare(RunRequest(str(write_show(tmp_path, TWO_ROBOTS)), robot_ports=ports, log_path=str(log_path)))
    stop = StopRequest()
    with pytest.raises(LinkError, match="robot right"), session:  # the session closes on the error
        session.run([PanicAt(stop, "right", "hold")], stop)
    links = session.stage.links if session.stage is not None else {}
    assert [len(link.listeners) for link in links.values()] == [1, 1]  # a failed run's wiring went too
    assert all(link._should_stop is never for link in links.values())  # and its stop checks
    result = read_log(Path(log_path)).metadata["choreo.result"]
    assert result["outcome"] == "failed" and result["stop_reason"] == PANIC
    assert result["error"].startswith("robot right")


def test_a_run_nobody_stopped_has_no_stop_reason(tmp_path):
    log_path = tmp_path / "run.mcap"
    session = prepare(RunRequest(str(write_show(tmp_path, "version: 1\nsteps:\n  - play: 1\n")),
                                 log_path=str(log_path)))
    with session:
        assert session.run().outcome == "done"
    assert "stop_reason" not in read_log(Path(log_path)).metadata["choreo.result"]


# -- --loop: what each pass attaches goes with it ----------------------------------------------------

LOOP_TWO_ROBOTS_GO = """
    version: 1
    robots:
      left: {}
      right: {}
    steps:
      - play: 1
        label: intro
      - play: 2
        label: a
        at: go
      - wait: 0.1
      - play: 3
        label: b
      - play: 4
"""


class GoAndStopAtPass:
    """Gives each GO cue its GO as it is reached (the operator, at once) and stops the run as
    pass `last + 1` begins."""

    def __init__(self, live, last: int) -> None:  # type: ignore[no-untyped-def]
        self.live = live
        self.last = last
        self.cues = 0

    def on_step(self, event: StepEvent) -> None:
        pass

    def on_log(self, level: int, message: str, time_ns: int) -> None:
        if message.startswith(f"loop: pass {self.last + 1} "):
            self.live.stop.request("interrupted (test)")

    def on_waiting(self, cue) -> None:  # type: ignore[no-untyped-def]
        self.cues += 1
        from choreo.events import Command

        assert self.live.command(Command("go", "test")).ok

    def on_command(self, event) -> None:  # type: ignore[no-untyped-def]
        pass


def test_loop_with_two_robots_a_go_cue_and_the_live_controls_logs_each_failed_try_once(tmp_path):
    """The variant of issue 22's `--loop` defect with several robots, a GO cue each pass and
    the live controls heard by the log: every NAK either robot meets is one warning line, and
    after the run nothing of it is left on the links or the controls."""
    from choreo.live.controls import Live

    show = write_show(tmp_path, LOOP_TWO_ROBOTS_GO)
    log_path = tmp_path / "run.mcap"
    ports = {"left": "sim://?nak=5", "right": "sim://?nak=4"}
    session = prepare(RunRequest(str(show), robot_ports=ports, log_path=str(log_path), loop="a..b"))
    live = Live(StopRequest(), now=session.clock.mono, wall_ns=session.clock.wall_ns, lockout_s=0.0)
    operator = GoAndStopAtPass(live, 3)
    with session, live.subscribe(operator):
        result = session.run([operator], live=live)
        links = session.stage.links if session.stage is not None else {}
        assert [len(link.listeners) for link in links.values()] == [1, 1]  # the log's own, only
    assert result.outcome == "aborted" and operator.cues == 3  # a GO cue in each of the 3 passes
    assert len(live.listeners) == 0  # the log's subscription went with the run, the operator's with its block
    log = read_log(Path(log_path))
    passes = [m["message"] for m in log.logs if m["message"].startswith("loop: pass")]
    assert passes[:2] == ["loop: pass 2 from 'a' to 'b'", "loop: pass 3 from 'a' to 'b'"]
    for robot in ("left", "right"):
        naks = [m for m in log.topic(f"/rcb4/{robot}/rx") if m["kind"] == "nak"]
        warned = [m["message"] for m in log.logs
                  if m["message"].startswith(f"robot {robot}: ") and "NAK" in m["message"]]
        assert len(naks) >= 3 and len(warned) == len(naks), (robot, len(naks), warned)
        assert len(set(warned)) == len(warned)


def test_a_run_given_two_stop_requests_is_refused_before_anything_moves(tmp_path):
    """The signal handler's stop request and the live controls' must be one: given two, the
    run read only the controls', and a Ctrl-C through the other was never seen."""
    from choreo.live.controls import Live

    session = prepare(RunRequest(str(write_show(tmp_path, "version: 1\nsteps:\n  - play: 1\n")), no_log=True))
    signals, controls = StopRequest(), StopRequest()
    with session:
        with pytest.raises(ValueError, match="one stop request"):
            session.run([], signals, Live(controls))
        link = next(iter(session.stage.links.values())) if session.stage is not None else None
        assert link is not None and not link.moved  # refused before a frame
        assert session.run([], controls, Live(controls)).outcome == "done"  # the same one: fine
