"""The OSC dictionary (`choreo.live.osc`): every address and what it reaches, cues percent-escaped,
the questions (`/choreo/status`, `/choreo/thump`) answered at once within their own budget and
not logged one by one, subscriptions to the notifications (`/choreo/updates 1|0`: bounded,
expiring, over UDP to the sender's address and over TCP on its connection), and suggestions for
unknown addresses that never offer a command with a stage effect.

Loopback only, over UDP and TCP. The servers' budgets and subscriptions run on a virtual clock
that moves only when a test moves it; replies are waited for with a deadline, never a sleep that
decides.
"""

from __future__ import annotations

import json
import random
import socket
import struct

import pytest

from choreo.clock import VirtualTime
from choreo.events import Answer, Command, StopRequest
from choreo.live.controls import Live
from choreo.live.limits import LIMITS, Limits, Rate
from choreo.live.osc import (COMMANDS, DICTIONARY, EFFECTS, BadAddress, OscServer, escape, loops, suggestion,
                             unknown_message, wanted)
from choreo.live.oscnotify import Subscriptions
from choreo.live.oscwire import decode_packet, encode_message
from choreo.log.format import WARNING
from runlog import ended_if_left, read_log, start_choreo, wait_for, write_show
from test_osc import GO_SHOW, ONE_GO_SHOW, POLL_S, ShowRun, free_port
from test_osc_limits import Peer

TIMEOUT_S = 5.0
EVERY_EVENT = Limits(reported=Rate(1_000_000, 1.0))  # the test hears every command one by one
STATUS = {"state": "running", "show_s": 1.5, "clock": "machine", "playhead": None, "waiting": [],
          "paused": False, "robots": {}}


class Recording(Live):
    """A Live that records the commands it is given (answering each ok) and says `STATUS`: what
    the OSC side sends it, apart from what the Live does with it."""

    def __init__(self, clock: VirtualTime) -> None:
        super().__init__(StopRequest(), lockout_s=0.0, now=clock.now, limits=EVERY_EVENT)
        self.given: list[Command] = []
        self.told: list[tuple[Command, Answer]] = []

    def command(self, command: Command) -> Answer:
        self.given.append(command)
        answer = Answer("ok", f"did {command.name}", {"cue": command.label})
        self.report(command, answer)
        return answer

    def report(self, command: Command, answer: Answer) -> None:
        self.told.append((command, answer))
        super().report(command, answer)

    def status(self) -> dict:
        return dict(STATUS)


@pytest.fixture
def clock() -> VirtualTime:
    return VirtualTime()


@pytest.fixture
def live(clock):  # type: ignore[no-untyped-def]
    return Recording(clock)


@pytest.fixture
def server(live, clock):  # type: ignore[no-untyped-def]
    server = OscServer(live, 0, now=clock.now)
    server.start()
    live.subscribe(server)
    yield server
    server.close()


def decoded(packet: bytes) -> tuple[str, tuple]:
    (message,) = decode_packet(packet).messages
    return message.address, message.args


def reply(packet: bytes) -> tuple[str, dict]:
    address, args = decoded(packet)
    return address, json.loads(args[0])


def ask(peer: Peer, address: str, *args) -> tuple[str, dict]:  # type: ignore[no-untyped-def]
    """One message and its reply (the first packet back that is not a notification, nor a late
    reply to an earlier question: a loaded machine's status reply can come after its asker gave
    up on it, and was read as the next question's)."""
    peer.send(encode_message(address, args))
    while True:
        packet = next_packet(peer)
        if packet.startswith(b"/choreo/notify"):
            continue
        answer = reply(packet)
        if answer[0] == "/reply" + address or not answer[0].startswith("/reply/choreo/status"):
            return answer


def next_packet(peer: Peer) -> bytes:
    """The next packet the peer gets (a reply or a notification), waited for with a deadline."""
    peer.sock.settimeout(TIMEOUT_S)
    if peer.transport == "udp":
        return peer.sock.recv(65536)
    while b"\xc0" not in peer._buffer.lstrip(b"\xc0"):
        chunk = peer.sock.recv(65536)
        assert chunk, "closed"
        peer._buffer += chunk
    frame, _, peer._buffer = peer._buffer.lstrip(b"\xc0").partition(b"\xc0")
    return frame


@pytest.fixture
def peers(server):  # type: ignore[no-untyped-def]
    opened: list[Peer] = []

    def peer(transport: str, host: str = "127.0.0.1") -> Peer:
        opened.append(Peer(transport, server.port, host))
        return opened[-1]

    yield peer
    for each in opened:
        each.close()


# -- the addresses -------------------------------------------------------------------------------


def test_every_address_of_the_dictionary_reaches_its_command():
    expected = {"/choreo/go": ("go", None), "/choreo/panic": ("panic", None), "/choreo/start": ("start", None),
                "/choreo/stop": ("stop", None), "/choreo/pause": ("pause", None), "/choreo/resume": ("resume", None),
                "/choreo/skip": ("skip", None), "/choreo/playhead/next": ("playhead_next", None),
                "/choreo/playhead/previous": ("playhead_previous", None),
                "/choreo/playhead/CUE": ("playhead", "CUE"), "/choreo/cue/CUE/go": ("cue_go", "CUE"),
                "/choreo/status": ("status", None), "/choreo/thump": ("thump", None),
                "/choreo/updates": ("updates", None)}
    assert set(DICTIONARY) == set(expected)
    for address, (name, cue) in expected.items():
        asked = wanted(address)
        assert asked is not None and (asked.name, asked.cue) == (name, cue), address


@pytest.mark.parametrize("address, cue", [
    ("/choreo/cue/3/go", "3"), ("/choreo/cue/12.5/go", "12.5"), ("/choreo/cue/applause/go", "applause"),
    ("/choreo/cue/big%20bow/go", "big bow"), ("/choreo/cue/big bow/go", "big bow"),
    ("/choreo/cue/a%2Fb/go", "a/b"), ("/choreo/cue/a%2fb/go", "a/b"), ("/choreo/cue/100%25/go", "100%"),
    ("/choreo/cue/%C3%A9t%C3%A9/go", "été"), ("/choreo/cue/été/go", "été"), ("/choreo/cue/a*/go", "a*"),
    ("/choreo/cue/+/go", "+"), ("/choreo/playhead/%6Eext", "next"), ("/choreo/playhead/a%2Fb", "a/b"),
])
def test_a_cue_is_read_percent_escaped(address, cue):
    asked = wanted(address)
    assert asked is not None and asked.cue == cue
    assert wanted(f"/choreo/cue/{escape(cue)}/go") == wanted(f"/choreo/cue/{escape(cue)}/go")
    assert wanted(f"/choreo/cue/{escape(cue)}/go").cue == cue  # type: ignore[union-attr]  # found above


@pytest.mark.parametrize("segment, why", [
    ("a%2", "a '%' without two hex digits"), ("a%", "a '%' without two hex digits"),
    ("%zz", "a '%' without two hex digits"), ("%+f", "a '%' without two hex digits"),
    ("% f", "a '%' without two hex digits"), ("%ff", "not UTF-8"), ("%C3", "not UTF-8"),
    ("%ED%A0%80", "not UTF-8"), ("%00", "a control character"), ("a%0Ab", "a control character"),
    ("\x01", "a control character"),
])
def test_a_bad_escape_is_refused_saying_how_to_escape(segment, why):
    for address in (f"/choreo/cue/{segment}/go", f"/choreo/playhead/{segment}"):
        with pytest.raises(BadAddress) as refused:
            wanted(address)
        assert why in str(refused.value)
        assert "%20 a space, %2F a slash, %25 a percent sign" in str(refused.value)


def test_a_label_with_a_slash_sent_unescaped_is_told_how_to_escape():
    assert wanted("/choreo/cue/a/b/go") is None
    assert "%2F a slash" in unknown_message("/choreo/cue/a/b/go")
    assert "%2F a slash" in unknown_message("/choreo/playhead/a/b")


# -- suggestions ---------------------------------------------------------------------------------


def test_suggestions_for_case_prefix_and_slash_and_for_a_heartbeat():
    assert suggestion("/ping") == "/choreo/thump" and suggestion("/heartbeat") == "/choreo/thump"
    assert suggestion("/choreo/ping") == "/choreo/thump"
    assert suggestion("/workspace/0A1B/thump") == "/choreo/thump"  # QLab's own heartbeat
    assert suggestion("/GO") == "/choreo/go" and suggestion("/choreo/go/") == "/choreo/go"
    assert suggestion("/Choreo/Panic/") == "/choreo/panic"
    assert suggestion("/cue/Big%20Bow/GO") == "/choreo/cue/Big%20Bow/go"  # the cue kept as written
    assert suggestion("/playhead/3") == "/choreo/playhead/3"
    assert suggestion("/cue/%zz/go") is None  # not an address that would be taken either
    assert suggestion("/choreo/stauts") == "/choreo/status"
    assert suggestion("/choreo/playhed/next") == "/choreo/playhead/next"
    assert suggestion("/choreo/playhead/nxet/") == "/choreo/playhead/nxet"  # a cue so named, maybe
    for typo in ("/choreo/gp", "/choreo/stpo", "/choreo/pasue", "/choreo/resum", "/choreo/skp", "/go!",
                 "/choreo/paniq", "/choreo/strat", "/choreo/cue/1/og", "/choreo/goo", "/x/go", "/choreo/g"):
        assert suggestion(typo) is None, typo


def _is_effect(address: str) -> bool:
    try:
        asked = wanted(address)
    except BadAddress:
        return False
    return asked is not None and asked.name in EFFECTS


def _loose(address: str) -> str:
    """An address as the loose match sees it: its fixed parts' case, /choreo, a trailing slash."""
    address = address[:-1] if address.endswith("/") else address
    if not address.casefold().startswith("/choreo/"):
        address = "/choreo" + address
    parts = address.split("/")
    return "/".join(part if index == 3 and parts[2].casefold() == "cue" else part.casefold()
                    for index, part in enumerate(parts))


def _edits(text: str, rng: random.Random) -> str:
    alphabet = "abcdefghijklmnopqrstuvwxyz/ABCDEFGHIJKLMNOPQRSTUVWXYZ%0123456789"
    chars = list(text)
    for _ in range(rng.randint(1, 3)):
        at = rng.randrange(len(chars) + 1)
        kind = rng.randrange(4)
        if kind == 0:
            chars.insert(at, rng.choice(alphabet))
        elif kind == 1 and at < len(chars):
            del chars[at]
        elif kind == 2 and at < len(chars):
            chars[at] = rng.choice(alphabet)
        elif at + 1 < len(chars):
            chars[at], chars[at + 1] = chars[at + 1], chars[at]
    return "".join(chars)


def test_no_near_miss_is_ever_answered_with_a_command_that_acts_on_stage():
    """Random edits of every address (the effect commands' and the others'), and of their QLab,
    upper-case and prefixless spellings: an unknown address is offered an effect command only
    when it is that command but for case, /choreo and a trailing slash."""
    rng = random.Random(24)
    bases = [*COMMANDS, "/choreo/cue/3/go", "/choreo/cue/bow/go", "/choreo/playhead/3", "/choreo/status",
             "/choreo/thump", "/choreo/updates", "/go", "/panic", "/cue/1/go", "/ping", "/heartbeat", "/thump"]
    tried = 0
    for base in bases:
        for _ in range(250):
            address = _edits(base, rng)
            if not address.startswith("/") or wanted_safe(address):
                continue
            tried += 1
            meant = suggestion(address)
            if meant is not None and _is_effect(meant):
                assert _loose(address) == _loose(meant), (address, meant)
    assert tried > 2000


def wanted_safe(address: str) -> bool:
    try:
        return wanted(address) is not None
    except BadAddress:
        return True  # one of ours, badly escaped: answered with how to escape


# -- the commands over UDP and TCP ----------------------------------------------------------------


@pytest.mark.parametrize("transport", ["udp", "tcp"])
def test_each_command_reaches_the_live_with_its_cue(transport, live, peers):
    peer = peers(transport)
    sent = {"/choreo/pause": ("pause", None), "/choreo/resume": ("resume", None), "/choreo/skip": ("skip", None),
            "/choreo/playhead/next": ("playhead_next", None), "/choreo/playhead/previous": ("playhead_previous", None),
            "/choreo/playhead/12.5": ("playhead", "12.5"), "/choreo/playhead/big%20bow": ("playhead", "big bow"),
            "/choreo/cue/a%2Fb/go": ("cue_go", "a/b"), "/choreo/cue/3/go": ("cue_go", "3"),
            "/choreo/cue/*/go": ("cue_go", "*")}  # a cue written `*`, not a pattern expanded
    for address, (_, cue) in sent.items():
        got, body = ask(peer, address)
        assert got == "/reply" + address and body["status"] == "ok" and body["data"] == {"cue": cue}
    assert [(c.name, c.label) for c in live.given] == list(sent.values())
    assert all(c.source.startswith(f"osc {transport} 127.0.0.1:") for c in live.given)


@pytest.mark.parametrize("transport", ["udp", "tcp"])
@pytest.mark.parametrize("address", ["/choreo/cue/a%2/go", "/choreo/cue/%00/go", "/choreo/cue/%FF%FE/go",
                                     "/choreo/playhead/%", "/choreo/cue/" + "%41" * 2000 + "/go"])
def test_a_badly_escaped_cue_is_answered_and_nothing_is_carried_out(transport, address, live, peers):
    peer = peers(transport)
    got, body = ask(peer, address)
    shown = address if len(address) <= LIMITS.address_shown else address[:LIMITS.address_shown] + "…"
    assert got == "/reply" + shown and body["status"] == "error"
    if address == shown:
        assert "%20 a space, %2F a slash, %25 a percent sign" in body["message"]
    else:
        assert body["message"] == f"unknown command {shown}: longer than any address choreo takes"
    assert live.given == [] and [c.name for c, _ in live.told] == ["unknown"]


# -- the questions ---------------------------------------------------------------------------------


@pytest.mark.parametrize("transport", ["udp", "tcp"])
def test_status_and_thump_are_answered_at_once_and_not_logged(transport, live, peers):
    peer = peers(transport)
    assert ask(peer, "/choreo/status") == ("/reply/choreo/status", {
        "address": "/choreo/status", "status": "ok", "message": "running", "data": STATUS})
    assert ask(peer, "/choreo/thump") == ("/reply/choreo/thump", {
        "address": "/choreo/thump", "status": "ok", "message": "thump", "data": {"updates": False}})
    assert ask(peer, "/choreo/thump", 0)[1]["message"] == "thump"  # an argument changes nothing
    assert live.given == [] and live.told == []


@pytest.mark.parametrize("transport", ["udp", "tcp"])
def test_polling_spends_its_own_budget_not_the_gos(transport, live, server, peers):
    """A desk polling status faster than its budget: the rest are counted, unanswered; its GO
    is still carried out and answered (the clock does not move: the budgets do not refill)."""
    peer = peers(transport)
    polls = LIMITS.queries_per_sender.burst + 30
    for _ in range(polls):
        peer.send(encode_message("/choreo/status"))
    assert wait_for(lambda: server.counts["status"] == polls, TIMEOUT_S, every=0.005)
    answered = peer.replies(at_least=LIMITS.queries_per_sender.burst)
    assert len(answered) == LIMITS.queries_per_sender.burst
    assert server.counts["unanswered"] == 30
    assert ask(peer, "/choreo/go")[1]["status"] == "ok"
    assert [c.name for c in live.given] == ["go"] and [c.name for c, _ in live.told] == ["go"]


# -- subscriptions ---------------------------------------------------------------------------------


def notified(peer: Peer, address: str, *args) -> bool:
    """The notification comes (others before it are passed over), within the deadline."""
    while True:
        if decoded(next_packet(peer)) == (address, args):
            return True


def notifications(peer: Peer) -> list[tuple[str, tuple]]:
    """The notifications that come within a short quiet time (for a test that none does)."""
    return [decoded(packet) for packet in peer.replies(0.1) if packet.startswith(b"/choreo/notify")]


def told(live: Recording, name: str = "updates") -> list[tuple[str, str, str]]:
    return [(c.source, a.status, a.message) for c, a in live.told if c.name == name]


@pytest.mark.parametrize("transport", ["udp", "tcp"])
def test_a_subscriber_gets_the_notifications_until_it_ends_them(transport, live, server, peers):
    peer, other = peers(transport), peers(transport)
    got, body = ask(peer, "/choreo/updates", 1)
    assert got == "/reply/choreo/updates" and body["status"] == "ok" and body["data"] == {
        "updates": True, "expire_s": LIMITS.update_expire_s}
    assert body["message"].startswith("updates on: the show's notifications " + (
        "on this connection" if transport == "tcp" else "to 127.0.0.1:"))
    assert ask(peer, "/choreo/thump")[1]["data"] == {"updates": True}
    server.on_log(WARNING, "a warning")
    assert notified(peer, "/choreo/notify/warning", "a warning")
    assert notifications(other) == []  # only who asked
    assert ask(peer, "/choreo/updates", 0)[1]["message"] == "updates off"
    assert ask(peer, "/choreo/updates", 0)[1]["message"] == "updates off already"
    server.on_log(WARNING, "another")
    assert notifications(peer) == []
    assert [status for _, status, _ in told(live)] == ["ok", "ok", "ok"]


def test_a_tcp_subscriber_framing_with_a_length_prefix_gets_them_so(server):
    with socket.create_connection(("127.0.0.1", server.port), timeout=TIMEOUT_S) as sock:
        message = encode_message("/choreo/updates", [1])
        sock.sendall(struct.pack(">I", len(message)) + message)
        assert _framed(sock)[0] == "/reply/choreo/updates"
        server.on_log(WARNING, "framed")
        while (got := _framed(sock))[0] == "/choreo/notify/command":  # its own /updates, notified
            pass
        assert got == ("/choreo/notify/warning", ("framed",))


def _framed(sock: socket.socket) -> tuple[str, tuple]:
    (size,) = struct.unpack(">I", _exactly(sock, 4))
    return decoded(_exactly(sock, size))


def _exactly(sock: socket.socket, size: int) -> bytes:
    data = b""
    while len(data) < size:
        chunk = sock.recv(size - len(data))
        assert chunk, "closed"
        data += chunk
    return data


def test_at_most_four_subscribe_and_the_fifth_is_told_why(live, server, peers):
    subscribers = [peers("udp" if n % 2 else "tcp") for n in range(LIMITS.update_subscribers)]
    for peer in subscribers:
        assert ask(peer, "/choreo/updates", 1)[1]["status"] == "ok"
    fifth = peers("udp")
    refused = ask(fifth, "/choreo/updates", 1)[1]
    assert refused["status"] == "error" and refused["message"] == (
        "refused: 4 senders get updates already (at most 4): one must send /choreo/updates 0, or fall silent "
        "for 61 s")
    assert ask(subscribers[0], "/choreo/updates", 1)[1]["status"] == "ok"  # one subscribed renews
    server.on_log(WARNING, "to the four")
    assert all(notified(p, "/choreo/notify/warning", "to the four") for p in subscribers)
    assert notifications(fifth) == []
    subscribers[2].close()  # a TCP subscriber's connection closed: its place is free
    assert wait_for(lambda: len(server.subscriptions) == 3, TIMEOUT_S, every=0.005)
    assert ask(fifth, "/choreo/updates", 1)[1]["status"] == "ok"
    assert ("updates off: the connection closed") in [m for _, _, m in told(live)]


@pytest.mark.parametrize("transport", ["udp", "tcp"])
def test_a_subscription_expires_after_61_s_without_a_message(transport, live, server, peers, clock):
    peer = peers(transport)
    ask(peer, "/choreo/updates", 1)
    clock.sleep(60.0)
    ask(peer, "/choreo/thump")  # any message renews it
    clock.sleep(60.0)
    server.on_log(WARNING, "still")
    assert notified(peer, "/choreo/notify/warning", "still")
    clock.sleep(61.0)
    server.on_log(WARNING, "gone")
    assert wait_for(lambda: len(server.subscriptions) == 0, TIMEOUT_S, every=0.005)
    assert notifications(peer) == []
    assert told(live)[-1][1:] == ("ok", "updates off: no message for 61 s")


@pytest.mark.parametrize("args", [(), (2,), ("yes",), (1, 1), (b"\x01",)])
def test_updates_takes_one_or_zero_only(args, live, peers):
    _, body = ask(peers("udp"), "/choreo/updates", *args)
    assert body["status"] == "error" and body["message"].startswith("give 1 (send me the show's notifications)")


@pytest.mark.parametrize("args", [(1,), (1.0,), (True,), ("1",)])
def test_updates_on_as_desks_send_it(args, live, peers):
    assert ask(peers("udp"), "/choreo/updates", *args)[1]["data"]["updates"] is True


def test_a_subscriber_at_our_own_port_is_refused(live, server):
    """A datagram forged to come from choreo's own port: its notifications would come back."""
    packet = encode_message("/choreo/updates", [1])
    for sender in (("127.0.0.1", server.port), ("127.0.0.1", 0)):
        (answer,) = server.packet("udp", sender, packet)
        body = reply(answer)[1]
        assert body["status"] == "error" and "choreo's own port" in body["message"]
    assert len(server.subscriptions) == 0
    assert loops(("127.0.0.1", server.port), server.port) and not loops(("127.0.0.1", 9), server.port)
    assert not loops(("192.0.2.1", server.port), server.port)  # another machine's


def test_a_slow_tcp_subscriber_loses_notifications_not_the_show(live, server):
    """A subscriber that never reads: what it has not read stays bounded and the notifier's
    thread never waits for it."""
    with socket.create_connection(("127.0.0.1", server.port), timeout=TIMEOUT_S) as sock:
        sock.setsockopt(socket.SOL_SOCKET, socket.SO_RCVBUF, 4096)
        sock.sendall(b"\xc0" + encode_message("/choreo/updates", [1]) + b"\xc0")
        assert wait_for(lambda: len(server.subscriptions) == 1, TIMEOUT_S, every=0.005)
        net = server._net
        assert net is not None

        def flooded() -> bool:  # until notifications are dropped (the peer's buffers and 64 KB queued)
            for n in range(100):
                server.on_log(WARNING, "x" * 16_000 + str(n))  # never waits, whatever the peer does
            return net.unpushed > 0

        assert wait_for(flooded, TIMEOUT_S * 4, every=0.01)
        assert net.connections == 1  # not closed for it
        assert all(len(c.unsent) <= net.limits.max_unsent for c in net._connections)


# -- with the show's own Live: every state, and the cue list's commands ------------------------------

LONG_SHOW = """\
    version: 1
    motions:
      bow: {number: 2, duration: 0.05}
      long: {number: 3, duration: 60}
    steps:
      - play: 1
      - play: bow
        at: go
        label: big bow/2
      - play: long
    """


@pytest.fixture
def real_shows(tmp_path):  # type: ignore[no-untyped-def]
    """ShowRun(...) (a show on the simulator, with the Live and OscServer `choreo run` wires); one
    left running by a failed test is stopped and closed."""
    started: list[ShowRun] = []

    def start(body: str = GO_SHOW, **options) -> ShowRun:  # type: ignore[no-untyped-def]
        started.append(ShowRun(tmp_path, body, **options))
        return started[-1]

    yield start
    for run in started:
        run.live.stop.request()
        run.thread.join(TIMEOUT_S)
        run.close()


def status_of(peer: Peer) -> dict:
    got, body = ask(peer, "/choreo/status")
    assert got == "/reply/choreo/status" and body["status"] == "ok" and body["message"] == body["data"]["state"]
    return body["data"]


def until_state(peer: Peer, state: str) -> dict:
    """Status asked until the show is in `state`, no faster than the budget of questions refills
    in real time: asked every 20 ms, a run a loaded machine opened slowly spent the budget in
    half a second, and the question past it went unanswered (a timeout, not a state)."""
    seen: list[dict] = []
    every_s = 1 / LIMITS.queries_per_sender.per_s
    assert wait_for(lambda: seen.append(status_of(peer)) or seen[-1]["state"] == state, POLL_S, every=every_s), \
        seen[-1:]
    return seen[-1]


@pytest.mark.parametrize("transport", ["udp", "tcp"])
def test_status_says_each_state_of_a_show(transport, real_shows):
    run = real_shows(LONG_SHOW, wait_start=True, opening=True)  # as `choreo run`: OSC serves as the log opens
    peer = Peer(transport, run.server.port)
    try:
        waiting = until_state(peer, "waiting_start")  # "opening" until the log hears the commands
        assert waiting["state"] == "waiting_start" and waiting["show_s"] is None and waiting["clock"] == "machine"
        assert waiting["playhead"] == {"number": "1", "label": "big bow/2", "go": True, "at": None, "bar": None,
                                       "beat": None, "planned_s": waiting["playhead"]["planned_s"],
                                       "robots": ["robot"]}
        assert ask(peer, "/choreo/start")[1]["status"] == "ok"
        held = until_state(peer, "held")
        waits = [(cue["number"], cue["label"], cue["robots"]) for cue in held["waiting"]]
        assert waits == [("1", "big bow/2", ["robot"])]
        assert ask(peer, "/choreo/pause")[1]["status"] == "ok"
        paused = status_of(peer)
        assert paused["state"] == "paused" and paused["paused"] is True
        assert ask(peer, "/choreo/resume")[1]["status"] == "ok"
        assert status_of(peer)["state"] == "held"
        assert ask(peer, "/choreo/cue/big%20bow%2F2/go")[1]["message"] == "GO: cue 1 'big bow/2'"  # its label
        running = until_state(peer, "running")
        assert running["waiting"] == [] and running["show_s"] >= held["show_s"]
        assert ask(peer, "/choreo/stop")[1]["status"] == "ok"
        assert status_of(peer)["state"] == "stopping"
        run.join()
        run.live.close()
        assert status_of(peer)["state"] == "over"
    finally:
        peer.close()
    assert run.result.outcome == "aborted"
    names = [m["command"] for m in run.log().topic("/choreo/command")]
    assert names == ["start", "pause", "resume", "cue_go", "stop"]  # every command carried out; the questions
    # are not in the log


@pytest.mark.parametrize("transport", ["udp", "tcp"])
def test_the_playhead_and_skip_over_osc(transport, real_shows):
    run = real_shows()  # GO_SHOW: cue 1 'applause', cue 2 'encore', both at GO
    peer = Peer(transport, run.server.port)
    try:
        assert wait_for(lambda: run.waiting() == ["applause"], POLL_S, every=0.005), run.waiting()
        assert ask(peer, "/choreo/playhead/previous")[1]["status"] == "error"  # on the first already
        moved = ask(peer, "/choreo/playhead/next")[1]
        assert moved["message"] == "playhead: cue 2 'encore'" and moved["data"]["playhead"] == "2"
        assert ask(peer, "/choreo/playhead/1")[1]["message"] == "playhead: cue 1 'applause'"
        assert ask(peer, "/choreo/playhead/encore")[1]["message"] == "playhead: cue 2 'encore'"
        assert ask(peer, "/choreo/skip")[1]["message"] == "skipped: cue 2 'encore' will not run"
        assert ask(peer, "/choreo/go")[1]["message"] == "GO: cue 1 'applause'"
        run.join()
    finally:
        peer.close()
    assert run.result.outcome == "done" and run.result.steps_run == 2  # encore skipped, never waited for


def test_choreo_run_answers_status_with_its_robots_and_sends_updates_to_a_subscriber(tmp_path):
    """The whole wiring of `choreo run --osc`: the status names each robot's step and link, a
    subscriber gets the show's progress, and the log records the subscription as a command."""
    show = write_show(tmp_path, ONE_GO_SHOW)
    log_path = tmp_path / "run.mcap"
    port = free_port()
    process = start_choreo("run", str(show), "--osc", str(port), "--log", str(log_path))
    with ended_if_left(process):
        peer = Peer("udp", port)
        try:
            held = until_listening_and(peer, "held")
            (row,) = held["robots"].values()
            assert row["robot"] == "robot" and row["state"] == "between" and row["next"]["label"] == "applause"
            assert ask(peer, "/choreo/updates", 1)[1]["status"] == "ok"
            assert ask(peer, "/choreo/go")[1]["message"] == "GO: cue 1 'applause'"
            # done, both steps run (how many were late is the machine's load: a full suite's can make one)
            assert notified(peer, "/choreo/notify/done", "done", 2, AnyCount(), pytest.approx(0.0, abs=60))
        finally:
            peer.close()
        _, err = process.communicate(timeout=30)
    assert process.returncode == 0, err
    commands = [(m["command"], m["status"]) for m in read_log(log_path).topic("/choreo/command")]
    assert commands == [("updates", "ok"), ("go", "ok")]


class AnyCount:
    """Equal to any whole number (a count the test does not pin)."""

    def __eq__(self, other: object) -> bool:
        return isinstance(other, int) and other >= 0

    def __hash__(self) -> int:
        return 0


def until_listening_and(peer: Peer, state: str) -> dict:
    """Status asked until choreo listens and the show is in `state` (a UDP question sent before
    choreo listens is lost: asked again)."""
    seen: list[dict] = []

    def in_state() -> bool:
        peer.send(encode_message("/choreo/status"))
        peer.sock.settimeout(0.1)
        try:
            seen.append(reply(peer.sock.recv(65536))[1]["data"])
        except (TimeoutError, socket.timeout, ConnectionRefusedError):
            return False
        return seen[-1]["state"] == state

    assert wait_for(in_state, 30, every=0.05), seen[-1:]
    return seen[-1]


def test_subscriptions_are_bounded_and_expire_on_the_clock_given():
    clock = VirtualTime()
    table = Subscriptions(most=2, expire_s=61.0, now=clock.now)
    assert table.add("a", "udp", ("127.0.0.1", 1), "a") == (True, [])
    assert table.add("b", "tcp", ("127.0.0.1", 2), "b") == (True, [])
    assert table.add("c", "udp", ("127.0.0.1", 3), "c") == (False, [])
    clock.sleep(60.9)
    table.heard("a")
    assert table.add("a", "udp", ("127.0.0.1", 1), "a")[0]  # one subscribed already: renewed, not refused
    clock.sleep(0.1)
    taken, expired = table.add("c", "udp", ("127.0.0.1", 3), "c")  # b was silent 61 s: its place is free
    assert taken and [s.source for s in expired] == ["b"]
    current, _ = table.current()
    assert sorted(s.source for s in current) == ["a", "c"] and "b" not in table
    assert table.remove("a") is not None and table.remove("a") is None and len(table) == 1
