"""`--osc-notify` targets attacked again (issue 21, item 3): a target that reaches choreo's own
`--osc` port loops, whatever its spelling, and a target given twice gets each notification
twice. Start-up checks only: no show runs, no packet is waited for."""

from __future__ import annotations

import socket

import pytest

from choreo.errors import UsageError
from choreo.events import StopRequest
from choreo.live.controls import Live
from choreo.live.osc import OscServer
from choreo.live.oscnotify import Notifier, comes_back, receiver


def _interface() -> str:
    """A network interface of this machine, by name (a link-local group needs one)."""
    names = [name for _, name in socket.if_nameindex()]
    return next((name for name in names if not name.startswith("lo")), names[0])


def _resolves(host: str) -> bool:
    try:
        socket.getaddrinfo(host, 9, type=socket.SOCK_DGRAM)
    except (OSError, UnicodeError):
        return False
    return True


OWN_PORT = 53200


@pytest.mark.parametrize("host", ["224.0.0.1", "239.255.0.1", "255.255.255.255", "ff02::1%{iface}", "ff05::1",
                                  "::ffff:224.0.0.1"])
def test_a_group_or_broadcast_at_our_own_port_is_refused(host):
    """Before: `--osc-notify [ff02::1%eth0]:PORT` with `--osc-host ::` passed the start-up check
    (a multicast group is no address of this machine) and every notification came back to
    choreo's own port, was refused as a command from this machine's link-local address, and
    was notified again. A group or the broadcast address at our port reaches our own sockets."""
    host = host.format(iface=_interface())
    if not _resolves(host):
        pytest.skip(f"{host} does not resolve here")
    family = socket.AF_INET6 if ":" in host else socket.AF_INET
    assert comes_back(host, family)
    notifier = Notifier([(host, OWN_PORT)])
    with pytest.raises(UsageError, match="choreo's own --osc port"):
        notifier.resolve(OWN_PORT)
    Notifier([(host, OWN_PORT + 1)]).close()  # another port of the group: a receiver's, taken


def test_a_machine_elsewhere_does_not_come_back():
    assert not comes_back("192.0.2.77", socket.AF_INET)  # TEST-NET: no address of this machine
    assert not comes_back("not an address", socket.AF_INET)


@pytest.mark.parametrize("first, second", [("127.0.0.1", "::ffff:127.0.0.1"), ("127.0.0.1", "127.1"),
                                           ("::1", "0:0:0:0:0:0:0:1")])
def test_one_receiver_spelt_two_ways_is_given_twice(first, second):
    """Before: 127.0.0.1:9 and [::ffff:127.0.0.1]:9 (an IPv4-mapped address reaches the IPv4
    receiver) were two targets, and the receiver got every notification twice."""
    notifier = Notifier([(first, 9), (second, 9)])
    with pytest.raises(UsageError, match="given twice"):
        notifier.resolve(OWN_PORT)


def test_receivers_apart_are_apart():
    v4 = receiver(socket.AF_INET, ("127.0.0.1", 9))
    assert v4 == receiver(socket.AF_INET6, ("::ffff:127.0.0.1", 9, 0, 0))
    assert v4 != receiver(socket.AF_INET, ("127.0.0.1", 10))
    assert receiver(socket.AF_INET6, ("::1", 9, 0, 0)) != v4
    notifier = Notifier([("127.0.0.1", 9), ("127.0.0.1", 10), ("::1", 9)])
    notifier.resolve(OWN_PORT)  # three receivers: each gets the notifications
    notifier.close()


@pytest.mark.parametrize("host, shown", [("0", "0.0.0.0"), ("localhost", "127.0.0.1"), ("[::1]", "[::1]"),
                                         ("::1", "[::1]")])
def test_the_start_up_line_names_the_address_listened_on(host, shown):
    """Before: `--osc-host 0` listened on every network and said 'listening on 0:PORT', and
    `--osc-host [::1]` (as a URL writes it) was 'cannot listen on [[::1]]:0'."""
    plain = shown.strip("[]")
    try:
        with socket.socket(socket.AF_INET6 if ":" in plain else socket.AF_INET, socket.SOCK_DGRAM) as probe:
            probe.bind((plain, 0))
    except OSError:
        pytest.skip(f"no {plain} on this machine")
    server = OscServer(Live(StopRequest()), 0, host=host)
    server.bind()
    try:
        assert server.listening.startswith(f"osc: listening on {shown}:{server.port} (udp and tcp)"), server.listening
    finally:
        server.close()
