"""The runner in-process: stopping between frames, the abort motion, nothing unasked sent."""

from __future__ import annotations

import time

import pytest

from choreo.wire import protocol as p
from choreo.board.link import Link
from choreo.run.runner import Runner
from choreo.events import StopRequest
from choreo.show.load import load_show
from choreo.show.plan import compile_plan
from runlog import write_show

SHOW = """
    version: 1
    name: runner
    motions:
      home: {number: 0, duration: 0.05}
    on_abort: home
    steps:
      - play: 3
      - wait: 0.05
      - play: 4
"""


class Frames:
    """A link listener that keeps what was sent, and can pull the stop cord at a given frame."""

    def __init__(self, stop: StopRequest | None = None, stop_at: int | None = None) -> None:
        self.sent: list[p.Frame] = []
        self.stop, self.stop_at = stop, stop_at

    def on_tx(self, event) -> None:
        self.sent.append(event.frame)
        if self.stop is not None and event.seq == self.stop_at:
            self.stop.request("interrupted (test)")

    def on_rx(self, event) -> None:
        pass


def runner_for(tmp_path, body: str, stop: StopRequest, frames: Frames) -> Runner:
    show = load_show(write_show(tmp_path, body))
    link = Link.open("sim://?durations=0:0.05", listeners=[frames])
    return Runner(compile_plan(show), link, on_abort=show.on_abort, stop=stop)


def test_stop_mid_sequence_finishes_the_sequence_then_sends_only_the_abort_motion(tmp_path):
    stop = StopRequest()
    frames = Frames(stop, stop_at=1)  # Ctrl-C while the first stop frame is on the wire
    runner = runner_for(tmp_path, SHOW, stop, frames)
    result = runner.run()
    assert result.outcome == "aborted"
    # the play in flight is one unit (cut after its stop frame, the board's program would be
    # left halted); then no show frame, only the abort motion
    assert [f.hex for f in frames.sent] == [f.hex for f in p.play_sequence(3) + p.play_sequence(0)]
    board = runner.link.port.board
    assert [e.reply is not None for e in board.journal if e.kind == "frame"] == [True] * 6


def test_a_show_without_abort_motion_sends_nothing_after_the_sequence_in_flight(tmp_path):
    stop = StopRequest()
    frames = Frames(stop, stop_at=4)  # during the second play's stop frame
    body = SHOW.replace("    on_abort: home\n", "") + "      - wait: 0.05\n"
    runner = runner_for(tmp_path, body, stop, frames)
    assert runner.run().outcome == "aborted"
    assert [f.kind.value for f in frames.sent] == ["stop", "play", "restore"] * 2
    board = runner.link.port.board
    assert board.config(time.monotonic()) & 0x02  # the program runs (motion 4): not left halted


def test_a_stop_before_any_step_sends_nothing_at_all(tmp_path):
    stop = StopRequest()
    stop.request("interrupted (test)")
    frames = Frames()
    runner = runner_for(tmp_path, SHOW, stop, frames)
    assert runner.run().outcome == "aborted"
    assert frames.sent == []  # not even the abort motion: the show never moved the robot


def test_the_runner_sends_exactly_the_plan(tmp_path):
    stop = StopRequest()
    frames = Frames()
    runner = runner_for(tmp_path, SHOW, stop, frames)
    result = runner.run()
    assert result.outcome == "done" and result.steps_run == 3
    assert [f.hex for f in frames.sent] == [f.hex for f in p.play_sequence(3) + p.play_sequence(4)]
    assert result.show_s == pytest.approx(0.05, abs=0.05)


FIRST_STEP_CUE = """
    version: 1
    steps:
      - play: 1
        at: 0.3
"""
OPENING_REPEAT_CUE = """
    version: 1
    steps:
      - repeat: 2
        at: 0.3
        steps:
          - play: 1
          - wait: 0.05
"""


@pytest.mark.parametrize("body", [FIRST_STEP_CUE, OPENING_REPEAT_CUE], ids=["step", "repeat"])
def test_a_cue_that_opens_the_show_waits_for_its_time(tmp_path, body):
    # The show clock starts at 0 whatever the first step is: `at: 0.3` on it is 0.3 s away.
    runner = runner_for(tmp_path, body, StopRequest(), Frames())
    board = runner.link.port.board
    started = time.monotonic()
    runner.run()
    first = next(e for e in board.journal if e.kind == "frame")
    start = next(e for e in board.journal if e.kind == "frame" and " started, runs " in e.note)
    assert first.at - started >= 0.3 - 0.02  # early by the exchanges before the start frame, no more
    assert start.at - started >= 0.3 - 0.002  # the motion starts on the cue


def test_a_show_stopped_before_its_first_play_does_not_play_the_abort_motion(tmp_path):
    stop = StopRequest()
    frames = Frames()
    body = """
        version: 1
        motions:
          home: {number: 0, duration: 0.05}
        on_abort: home
        steps:
          - wait: 0.3
          - play: 3
    """
    runner = runner_for(tmp_path, body, stop, frames)
    result = runner.run(on_idle=lambda: stop.request("interrupted (test)"))  # Ctrl-C during the wait
    assert result.outcome == "aborted" and result.steps_run == 1
    assert frames.sent == []  # the robot was never moved: it is left as it is


def test_a_stop_during_retries_ends_them_and_plays_the_abort_motion(tmp_path):
    # The show's play meets silence and is being retried (10 retries); Ctrl-C during the first
    # ACK check: no further try, then the abort motion, which the board answers.
    from test_link import ACK_CALL, ACK_MOV, ScriptedPort

    stop = StopRequest()
    frames = Frames(stop, stop_at=2)  # the ACK check after the first timeout
    show = load_show(write_show(tmp_path, SHOW))
    port = ScriptedPort(b"", b"", ACK_MOV, ACK_CALL, ACK_MOV)
    link = Link(port, timeout=0.01, tries=11, listeners=[frames])
    result = Runner(compile_plan(show), link, on_abort=show.on_abort, stop=stop).run()
    assert result.outcome == "aborted"
    assert [f.kind.value for f in frames.sent] == ["stop", "sync", "stop", "play", "restore"]
    assert frames.sent[-2].motion == 0  # the abort motion, not a retry of motion 3
