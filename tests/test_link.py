"""The link against a scripted port: reply reading, stale replies, retries, messages.

The simulator covers the fault kinds end to end (test_link_sim.py); here a port that answers
from a script pins down the reading rules byte for byte, without timing.
"""

from __future__ import annotations

from collections import deque
from itertools import pairwise

import pytest

from choreo.wire import protocol as p
from choreo.errors import LinkError
from choreo.board.link import Link
from choreo.events import Tag

ACK_MOV = p.ack(p.CMD_MOV)
ACK_CALL = p.ack(p.CMD_CALL)
RUNNING = p.ram_reply(bytes.fromhex("2387"))
SYNC_ACK = p.sync_frame().data  # the board answers the ACK check with the same 4 bytes
IDLE = p.ram_reply(bytes.fromhex("2187"))


class ScriptedPort:
    """Answers the n-th write with the n-th scripted bytes (b"": silence) once it is written."""

    def __init__(self, *answers: bytes) -> None:
        self.answers = deque(answers)
        self.buffer = bytearray()
        self.written: list[bytes] = []
        self.port = "scripted"
        self.baudrate = 115200
        self.flushes = 0

    def write(self, data: bytes) -> int:
        self.written.append(bytes(data))
        self.buffer += self.answers.popleft() if self.answers else b""
        return len(data)

    def read(self, count: int) -> bytes:
        out, self.buffer = bytes(self.buffer[:count]), self.buffer[count:]
        return out

    @property
    def in_waiting(self) -> int:
        return len(self.buffer)

    def reset_input_buffer(self) -> None:
        self.flushes += 1
        self.buffer.clear()

    def close(self) -> None:
        pass


class Events:
    def __init__(self) -> None:
        self.tx, self.rx = [], []

    def on_tx(self, event) -> None:
        self.tx.append(event)

    def on_rx(self, event) -> None:
        self.rx.append(event)


def link_for(*answers: bytes, tries: int = 3) -> tuple[Link, ScriptedPort, Events]:
    port = ScriptedPort(*answers)
    events = Events()
    return Link(port, timeout=0.01, tries=tries, listeners=[events]), port, events


def test_play_sends_three_frames_each_after_its_reply():
    link, port, events = link_for(ACK_MOV, ACK_CALL, ACK_MOV)
    link.play(3, Tag(0, "wave"))
    assert port.written == [f.data for f in p.play_sequence(3)]
    assert [e.reply.kind for e in events.rx] == [p.ReplyKind.ACK] * 3
    assert [e.seq for e in events.tx] == [e.seq for e in events.rx] == [1, 2, 3]
    assert port.flushes == 0  # nothing thrown away: input is only ever read


def test_a_nak_to_a_status_query_is_read_as_four_bytes():
    link, _, events = link_for(p.nak(p.CMD_MOV), RUNNING)
    reply = link.query_status()
    assert reply.executing is True
    assert [e.reply.kind for e in events.rx] == [p.ReplyKind.NAK, p.ReplyKind.STATUS]


def test_a_late_reply_to_an_earlier_frame_is_set_aside_not_taken_for_this_one():
    # The CALL's reply arrives first: the late ACK of the stop frame, then the CALL's own.
    link, _, events = link_for(ACK_MOV, ACK_MOV + ACK_CALL, ACK_MOV)
    link.play(5)
    call = events.rx[1]
    assert call.reply.kind is p.ReplyKind.ACK and call.reply.data == ACK_CALL
    assert call.reply.stale == ACK_MOV


def test_a_late_ack_is_never_taken_for_a_status():
    link, _, events = link_for(ACK_MOV + IDLE)
    reply = link.query_status()
    assert reply.kind is p.ReplyKind.STATUS and reply.executing is False
    assert reply.stale == ACK_MOV


def test_an_ack_alone_to_a_status_query_is_not_an_answer():
    # each ACK is set aside as stale, the read times out, an ACK check clears the line, retry
    link, _, events = link_for(ACK_MOV, SYNC_ACK, ACK_MOV, SYNC_ACK, ACK_MOV)
    with pytest.raises(LinkError, match="no reply to 'status' \\(status frame\\) after 3 tries: "):
        link.query_status()
    assert [e.frame.kind.value for e in events.tx] == ["status", "sync", "status", "sync", "status"]
    assert all(e.reply.stale == ACK_MOV for e in events.rx if e.frame.kind is p.FrameKind.STATUS)


def test_a_failed_play_is_retried_from_its_stop_frame():
    link, port, events = link_for(ACK_MOV, p.nak(p.CMD_CALL), ACK_MOV, ACK_CALL, ACK_MOV)
    link.play(1)
    kinds = [f.kind.value for f in (e.frame for e in events.tx)]
    assert kinds == ["stop", "play", "stop", "play", "restore"]
    assert [e.attempt for e in events.tx] == [1, 1, 2, 2, 2]


def test_junk_before_a_reply_is_invalid_and_retried():
    link, _, events = link_for(b"\xff\x00" + ACK_MOV, ACK_MOV, ACK_CALL, ACK_MOV)
    link.play(2)
    assert events.rx[0].reply.kind is p.ReplyKind.INVALID and "junk" in events.rx[0].reply.error
    assert events.rx[0].reply.data.startswith(b"\xff\x00")


def test_an_echoing_line_fails_with_what_came_back():
    link, _, _ = link_for(*(f.data for f in p.play_sequence(0)), tries=1)  # echoes the frame
    with pytest.raises(LinkError) as failure:
        link.play(0, Tag(2, "bow"))
    message = str(failure.value)
    assert message.startswith("port scripted: step 2 'bow': an invalid reply (13 00 02")
    assert "to 'play 0' (stop frame) after 1 try" in message


def test_no_reply_error_names_frame_and_what_to_check():
    link, _, events = link_for()
    with pytest.raises(LinkError) as failure:
        link.play(3)
    assert str(failure.value) == (
        "port scripted: no reply to 'play 3' (stop frame) after 1 try and 3 unanswered ACK checks: "
        "check baud (115200), even parity, and the adapter (5 V inverted logic without Kondo's USB "
        "adapter)")
    assert [e.frame.kind.value for e in events.tx] == ["stop", "sync", "sync", "sync"]
    assert len(events.rx) == 4


def test_after_a_timeout_an_ack_check_reads_every_late_reply_before_the_retry():
    # The stop frame's ACK is late: it arrives behind the first ACK check and is set aside; the
    # sequence then starts again from its stop frame, never with a CALL alone.
    link, port, events = link_for(b"", ACK_MOV + SYNC_ACK, ACK_MOV, ACK_CALL, ACK_MOV)
    played = link.play(2)
    assert played.tries == 2
    assert [e.frame.kind.value for e in events.tx] == ["stop", "sync", "stop", "play", "restore"]
    assert events.rx[1].reply.kind is p.ReplyKind.ACK and events.rx[1].reply.stale == ACK_MOV


def test_port_lost_is_a_link_error_with_an_rx_for_the_frame():
    class Unplugged(ScriptedPort):
        def read(self, count: int) -> bytes:
            raise OSError(5, "Input/output error")

    port = Unplugged()
    events = Events()
    link = Link(port, timeout=0.01, listeners=[events])
    with pytest.raises(LinkError, match="step 1: lost while sending 'play 4' \\(stop frame\\)"):
        link.play(4, Tag(1))
    assert events.rx[0].reply.error.startswith("port lost")


def test_bytes_waiting_before_a_write_are_read_whole_and_kept_as_stale():
    link, port, events = link_for(RUNNING)
    port.buffer += ACK_MOV  # a late reply that arrived before the query went out
    reply = link.query_status()
    assert reply.executing is True and reply.stale == ACK_MOV
    assert port.flushes == 0


def test_status_queries_are_never_closer_than_50_ms_even_when_retried():
    link, port, events = link_for(p.nak(p.CMD_MOV), p.nak(p.CMD_MOV), IDLE)
    link.query_status()
    times = [e.time_ns for e in events.tx]
    assert len(times) == 3
    assert min(b - a for a, b in pairwise(times)) >= 50_000_000
