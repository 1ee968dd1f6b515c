"""The shared robot status (`choreo.live.status`): where each robot is after step events (a
skip included), the link health from replies and retries, and the `/choreo/status` entry."""

from __future__ import annotations

from pathlib import Path

from choreo.events import RxEvent, StepEvent, TxEvent
from choreo.live.status import LATENCIES, ShowStatus
from choreo.run.session import Session
from choreo.run.settings import RunRequest
from choreo.wire.protocol import Reply, ReplyKind
from runlog import write_show

TWO = """\
version: 1
name: two
robots:
  left: {}
  right: {}
steps:
  - play: 1
  - play: 2
    at: go
    label: bow
  - wait: 0.5
"""


def status_of(tmp_path: Path, body: str = TWO) -> tuple[ShowStatus, Session]:
    session = Session.prepare(RunRequest(str(write_show(tmp_path, body)), no_log=True))
    settings = session.settings
    return ShowStatus(settings.plans, settings.sections.starts), session


def event(step, kind: str, robot: str, at_s: float = 0.0) -> StepEvent:  # type: ignore[no-untyped-def]
    return StepEvent(step, kind, at_s, at_s, 0, robot=robot)


def test_steps_move_each_robot_and_a_skip_leaves_it_past_the_step(tmp_path):
    status, session = status_of(tmp_path)
    steps = session.settings.plans["left"].steps
    left, right = status.robots()
    assert (left.robot, left.state, left.step, left.next_step) == ("left", "not_started", None, steps[0])
    status.on_step(event(steps[0], "start", "left", 0.0))
    status.on_step(event(steps[0], "end", "right", 0.0))  # not right's current step: nothing
    left, right = status.robots()
    assert (left.state, left.step, left.next_step, right.state) == ("running", steps[0], steps[1], "not_started")
    status.on_step(event(steps[0], "end", "left"))
    assert status.robots()[0].state == "between"
    status.on_step(event(steps[1], "skip", "left", 1.0))
    left = status.robots()[0]
    assert (left.step, left.ended, left.next_step, left.started_s) == (steps[1], True, steps[2], 1.0)
    status.on_step(event(steps[2], "start", "left", 1.0))
    assert status.robots()[0].due_s == (1.5,)  # the wait's end: the runner wakes then
    status.on_step(event(steps[2], "end", "left", 1.5))
    left = status.robots()[0]
    assert (left.state, left.done, left.next_step) == ("done", True, None)
    assert left.to_json()["state"] == "done"


def test_link_health_is_the_median_of_the_last_replies_with_retries_and_failures(tmp_path):
    status, _ = status_of(tmp_path)
    watch = status.link_listener("right")
    ok, nak = Reply(ReplyKind.ACK, b"\x06"), Reply(ReplyKind.NAK, b"\x15")
    for latency_ms in [100.0] * 5 + [1.0] * LATENCIES:  # the slow ones fall out of the window
        watch.on_rx(RxEvent(1, None, ok, 0, latency_ms / 1e3, None))  # type: ignore[arg-type]
    watch.on_rx(RxEvent(2, None, nak, 0, 0.5, None))  # type: ignore[arg-type]
    watch.on_tx(TxEvent(3, None, 2, 0, None))  # type: ignore[arg-type]
    watch.on_tx(TxEvent(4, None, 1, 0, None))  # type: ignore[arg-type]
    left, right = status.robots()
    assert (left.latency_ms, left.retries, left.failed) == (None, 0, 0)
    assert (round(right.latency_ms or 0, 6), right.retries, right.failed) == (1.0, 1, 1)
    assert right.to_json() == {"robot": "right", "state": "not_started", "step": None, "label": None, "cue": None,
                               "doing": None, "next": {"step": 0, "label": None, "cue": None, "doing": "play 1"},
                               "latency_ms": 1.0, "retries": 1, "failed": 1}
    status.link_listener("nobody").on_tx(TxEvent(5, None, 2, 0, None))  # type: ignore[arg-type]


def test_a_cue_step_carries_its_number_into_the_status(tmp_path):
    status, session = status_of(tmp_path)
    steps = session.settings.plans["left"].steps
    status.on_step(event(steps[1], "start", "right", 2.0))
    row = status.robots()[1].to_json()
    assert (row["step"], row["label"], row["cue"], row["doing"]) == (1, "bow", "1", "play 2")
