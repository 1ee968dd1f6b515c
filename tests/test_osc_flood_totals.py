"""A UDP flood of commands from other allowed addresses (loopback's many, or an --osc-allow
network's, whose source addresses can be forged) cannot take the operator's commands over TCP
(issue 21, item 3): the commands' total is kept apart per transport. Virtual time, no sockets."""

from __future__ import annotations

import json

from choreo.clock import VirtualTime
from choreo.events import StopRequest
from choreo.live.controls import Live
from choreo.live.limits import LIMITS, SenderKey, SenderLimits
from choreo.live.osc import OscServer
from choreo.live.oscwire import decode_packet, encode_message

IGNORED = "ignored: over the limit of commands"


def _answer(replies) -> str:  # type: ignore[no-untyped-def]
    (reply,) = replies
    return str(json.loads(decode_packet(reply).messages[0].args[0])["message"])


def test_a_udp_flood_from_ten_addresses_leaves_the_tcp_desk_its_commands():
    """Before: ten addresses each sending 100 pauses a second took the whole total (20, then 10
    a second), and every command from the desk's TCP connection was 'ignored' for as long."""
    clock = VirtualTime()
    live = Live(StopRequest(), wait_start=True, lockout_s=0.0, now=clock.now)
    server = OscServer(live, 0, now=clock.now)
    flood = encode_message("/choreo/pause")
    answers = []
    for tick in range(300):  # 3 s of flood, the desk's command every 0.3 s
        for n in range(2, 12):
            server.packet("udp", (f"127.0.0.{n}", 9000), flood)
        if tick % 30 == 29:
            answers.append(_answer(server.packet("tcp", ("127.0.0.1", 5000), encode_message("/choreo/pause"))))
        clock.advance(0.01)
    assert len(answers) == 10 and not any(answer.startswith(IGNORED) for answer in answers), answers
    # ...while the flood itself still spends its own total: ignored, as before
    more = [_answer(server.packet("udp", (f"127.0.1.{n}", 9000), flood)) for n in range(1, 11)]
    assert sum(answer.startswith(IGNORED) for answer in more) >= len(more) // 2, more


def test_each_transport_has_the_whole_total_and_no_more():
    clock = VirtualTime()
    limits = SenderLimits(now=clock.now)
    total = LIMITS.commands_total.burst
    udp = sum(limits.admit(SenderKey(f"10.0.{n // 250}.{n % 250}")) for n in range(1000))
    tcp = sum(limits.admit(SenderKey(f"10.1.{n // 250}.{n % 250}", "tcp")) for n in range(1000))
    assert udp == total and tcp == total


def test_forged_udp_senders_past_the_table_leave_a_tcp_desk_its_budget():
    """Before: the per-sender table (256 senders) was one for both transports. Datagrams from
    more addresses of an allowed network than it holds, each a command every 0.1 s (never
    idle), took all its places, and a desk connecting over TCP then shared the newcomers'
    bucket, which the flood kept empty: one GO, then 'ignored'."""
    clock = VirtualTime()
    limits = SenderLimits(now=clock.now)
    for _ in range(30):
        for n in range(2 * LIMITS.senders_tracked):
            limits.admit(SenderKey(f"192.168.{n // 250 + 2}.{n % 250 + 1}"))
        clock.advance(0.1)
    desk = SenderKey("192.168.1.20", "tcp")
    assert all(limits.admit(desk) for _ in range(3)) and limits.may_reply(desk)


def test_a_udp_status_flood_leaves_a_tcp_desk_its_answers():
    """Before: all senders' status questions shared one total (40, then 20 a second); datagrams
    from many addresses asking for status took it, and a TCP desk's status went unanswered."""
    clock = VirtualTime()
    limits = SenderLimits(now=clock.now)
    for _ in range(20):
        for n in range(100):
            limits.may_query(SenderKey(f"10.0.0.{n}"))
        clock.advance(0.1)
    desk = SenderKey("10.9.9.9", "tcp")
    assert all(limits.may_query(desk) for _ in range(5))
