"""The link's recovery rules under review: stopping between tries, status spacing measured from
the write, and a board that answers an ACK check with anything is alive (issue 9)."""

from __future__ import annotations

import time

import pytest

from choreo.wire import protocol as p
from choreo.errors import Interrupted, LinkError
from choreo.board.link import Link
from choreo.events import StopRequest, Tag
from test_link import ACK_CALL, ACK_MOV, IDLE, SYNC_ACK, Events, ScriptedPort, link_for

SYNC_NAK = p.nak(p.CMD_ACK_CHECK)
BAD_SUM = ACK_MOV[:3] + bytes([(ACK_MOV[3] + 1) & 0xFF])


# -- a stop request ends the retries ----------------------------------------------------------

class StopAfter(Events):
    """Pulls the stop cord when the n-th frame goes out (as a Ctrl-C during a retry would)."""

    def __init__(self, stop: StopRequest, at_seq: int) -> None:
        super().__init__()
        self.stop, self.at_seq = stop, at_seq

    def on_tx(self, event) -> None:
        super().on_tx(event)
        if event.seq == self.at_seq:
            self.stop.request("interrupted (test)")


@pytest.mark.parametrize("at_seq,sent", [
    (1, ["stop"]),  # during the first try: no ACK check, no retry
    (2, ["stop", "sync"]),  # during the first ACK check: no second check, no retry
])
def test_a_stop_request_ends_the_retries_after_the_exchange_in_flight(at_seq, sent):
    port = ScriptedPort()  # silence: every try and every ACK check times out
    stop = StopRequest()
    events = StopAfter(stop, at_seq)
    link = Link(port, timeout=0.01, tries=10, listeners=[events])
    with link.stopping_on(stop), pytest.raises(Interrupted):
        link.play(3, Tag(0))
    assert [e.frame.kind.value for e in events.tx] == sent


def test_a_stop_request_between_nak_retries_sends_no_further_frame():
    port = ScriptedPort(p.nak(p.CMD_MOV), ACK_MOV, ACK_CALL, ACK_MOV)
    stop = StopRequest()
    events = StopAfter(stop, 1)
    link = Link(port, timeout=0.01, tries=3, listeners=[events])
    with link.stopping_on(stop), pytest.raises(Interrupted):
        link.play(3)
    assert len(port.written) == 1
    assert link.moved  # the stop frame reached the board: the show did touch the robot


def test_a_link_that_sent_nothing_has_not_moved_the_robot():
    link, _, _ = link_for(IDLE)
    link.query_status()
    assert not link.moved


# -- status spacing is measured from the write ------------------------------------------------

class SlowFirstWrite(ScriptedPort):
    """A write that a loaded machine delays before the bytes reach the board."""

    def __init__(self, *answers: bytes, delay_s: float) -> None:
        super().__init__(*answers)
        self.delay_s = delay_s
        self.arrived: list[float] = []  # when each frame reached the board

    def write(self, data: bytes) -> int:
        if not self.arrived:
            time.sleep(self.delay_s)
        self.arrived.append(time.monotonic())
        return super().write(data)


def test_status_queries_reach_the_board_50_ms_apart_when_a_write_is_delayed():
    port = SlowFirstWrite(IDLE, IDLE, delay_s=0.03)
    link = Link(port, timeout=0.01)
    link.query_status()
    link.query_status()
    assert port.arrived[1] - port.arrived[0] >= 0.05


# -- any answer to an ACK check proves the line alive -----------------------------------------

@pytest.mark.parametrize("answer", [SYNC_NAK, BAD_SUM, SYNC_ACK], ids=["nak", "badsum", "ack"])
def test_an_answered_ack_check_lets_the_play_be_retried(answer):
    link, port, events = link_for(b"", answer, ACK_MOV, ACK_CALL, ACK_MOV)
    played = link.play(2)
    assert played.tries == 2
    assert [e.frame.kind.value for e in events.tx] == ["stop", "sync", "stop", "play", "restore"]


def test_silence_to_every_ack_check_is_a_dead_line_and_says_so():
    link, _, events = link_for()
    with pytest.raises(LinkError, match="after 1 try and 3 unanswered ACK checks: check baud"):
        link.play(3)


def test_a_retry_warning_says_no_reply_not_nothing(tmp_path):
    from choreo.run.runner import _RetryReporter

    lines: list[str] = []

    class Runner:
        def _log(self, level, message):
            lines.append(message)

    link, _, _ = link_for(b"", SYNC_ACK, ACK_MOV, ACK_CALL, ACK_MOV)
    link.subscribe(_RetryReporter(Runner()))
    link.play(1, Tag(0))
    assert lines and lines[0].startswith("step 0: no reply to 'stop' (stop frame, seq 1)")
    assert "nothing" not in lines[0]


def test_a_late_reply_during_the_tries_turns_the_hint_to_the_timeout():
    # try 1 times out; the ACK check reads the late ACK (set aside) then its own answer; try 2
    # gets a NAK at the CALL: the final line names the late replies and --timeout.
    link, _, _ = link_for(b"", ACK_MOV + SYNC_ACK, ACK_MOV, p.nak(p.CMD_CALL), tries=2)
    with pytest.raises(LinkError) as failure:
        link.play(0)
    message = str(failure.value)
    assert "replies came too late (1 set aside" in message and "--timeout" in message
    assert "check baud" not in message
