"""Who decided the stop is who the run's outcome names (issue 22: first reason wins, a panic
always wins), and what a run attaches is gone when it ends, however it ends.

Hostile variants of the wiring defects the issue names: a log whose disk fills after the
operator's panic (or a Ctrl-C) must not claim it stopped the run.
"""

from __future__ import annotations

from pathlib import Path

import pytest

from choreo.events import PANIC, StepEvent, StopRequest
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
    assert any(m["message"].startswith(f"show {reason} at") for m in log.logs)
