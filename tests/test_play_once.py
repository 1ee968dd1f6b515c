"""A play whose start frame's reply is lost: the board is asked before anything is sent again,
so a motion never starts twice for one cue (issue 10, item 3)."""

from __future__ import annotations

import pytest

from choreo import protocol as p
from choreo.link import Link, Tag
from choreo.runner import Runner, StopRequest
from choreo.show.load import load_show
from choreo.show.plan import compile_plan
from runlog import write_show
from test_link import ACK_CALL, ACK_MOV, IDLE, RUNNING, Events, ScriptedPort, link_for

BAD_SUM = ACK_MOV[:3] + bytes([(ACK_MOV[3] + 1) & 0xFF])


def kinds(events: Events) -> list[str]:
    return [e.frame.kind.value for e in events.tx]


@pytest.mark.parametrize("lost", [b"", BAD_SUM], ids=["silence", "garbled"])
def test_a_lost_start_reply_with_the_motion_running_is_a_play_done(lost):
    link, port, events = link_for(ACK_MOV, ACK_CALL, lost, RUNNING)
    played = link.play(3, Tag(0))
    assert played.recovered and "'play 3' (restore frame) was lost" in played.recovered
    assert played.tries == 1
    assert kinds(events) == ["stop", "play", "restore", "status"]
    assert kinds(events).count("play") == 1  # one CALL: the motion started once


def test_a_lost_start_reply_with_the_motion_not_running_is_retried_from_the_stop_frame():
    link, port, events = link_for(ACK_MOV, ACK_CALL, b"", IDLE, ACK_MOV, ACK_CALL, ACK_MOV)
    played = link.play(3)
    assert played.recovered is None and played.tries == 2
    assert kinds(events) == ["stop", "play", "restore", "status", "stop", "play", "restore"]


def test_the_state_is_read_one_status_refresh_after_the_start_frame():
    link, port, events = link_for(ACK_MOV, ACK_CALL, b"", RUNNING)
    link.play(3)
    restore = next(e for e in events.tx if e.frame.kind is p.FrameKind.RESTORE)
    status = next(e for e in events.tx if e.frame.kind is p.FrameKind.STATUS)
    assert status.time_ns - restore.time_ns >= 50_000_000


def test_a_nak_to_the_start_frame_is_a_refusal_retried_without_asking():
    link, port, events = link_for(ACK_MOV, ACK_CALL, p.nak(p.CMD_MOV), ACK_MOV, ACK_CALL, ACK_MOV)
    assert link.play(3).tries == 2
    assert "status" not in kinds(events)


def test_the_last_try_still_asks_before_giving_up():
    link, port, events = link_for(ACK_MOV, ACK_CALL, b"", RUNNING, tries=1)
    assert link.play(3).recovered


SHOW = """
    version: 1
    motions:
      home: {number: 0, duration: 0.05}
    on_abort: home
    steps:
      - play: 3
      - wait: 0.05
      - play: 4
      - wait: 0.05
"""


class Stopper(Events):
    def __init__(self, stop: StopRequest) -> None:
        super().__init__()
        self.stop = stop

    def on_tx(self, event) -> None:
        super().on_tx(event)
        if event.frame.motion == 4 and event.frame.kind is p.FrameKind.RESTORE:
            self.stop.request("interrupted (test)")


def test_the_abort_motion_with_a_lost_start_reply_is_played_once_and_said(tmp_path):
    show = load_show(write_show(tmp_path, SHOW))
    stop = StopRequest()
    events = Stopper(stop)
    port = ScriptedPort(*(ACK_MOV, ACK_CALL, ACK_MOV) * 2, ACK_MOV, ACK_CALL, b"", RUNNING)
    logged: list[str] = []

    class Lines:
        def on_step(self, event) -> None:
            pass

        def on_log(self, level, message, time_ns=None) -> None:
            logged.append(message)

    link = Link(port, timeout=0.01, listeners=[events])
    result = Runner(compile_plan(show), link, on_abort=show.on_abort, stop=stop,
                    listeners=[Lines()]).run()
    assert result.outcome == "aborted"
    motions = [e.frame.motion for e in events.tx if e.frame.kind is p.FrameKind.PLAY]
    assert motions == [3, 4, 0]
    assert any(line.startswith("on_abort: the reply to 'play 0' (restore frame) was lost")
               and "not sent again" in line for line in logged)
