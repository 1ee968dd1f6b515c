"""OSC control attacked as a hostile network would: replies too big for a datagram, text JSON
cannot carry, letters that fold to ASCII (a suggestion offered as "only a difference of case"),
questions from many forged senders, forged subscriptions (their places and what they may be
sent), bundles mixing commands, and cues written every odd way.

Loopback only. Budgets run on a virtual clock that moves only when a test moves it; replies are
waited for with a deadline, never a sleep that decides.
"""

from __future__ import annotations

import json

import pytest

from choreo.clock import VirtualTime
from choreo.live.limits import LIMITS, Limits, Rate
from choreo.live.osc import COMMANDS, EFFECTS, BadAddress, OscServer, Reply, status_reply, suggestion, wanted
from choreo.live.oscnotify import Subscriptions
from choreo.live.oscwire import decode_packet, encode_bundle, encode_message
from choreo.log.format import WARNING
from runlog import wait_for
from test_osc_dictionary import STATUS, Recording, ask, reply, told
from test_osc_dictionary import peers, server  # noqa: F401 - fixtures
from test_osc import POLL_S, Commands
from test_osc_dictionary import real_shows  # noqa: F401 - a fixture
from test_osc_limits import Peer

TIMEOUT_S = 5.0


@pytest.fixture
def clock() -> VirtualTime:
    return VirtualTime()


@pytest.fixture
def live(clock):  # type: ignore[no-untyped-def]
    return Recording(clock)


def strict_json(text: str) -> dict:
    """JSON as any parser reads it: no NaN nor Infinity (Python's own json takes them)."""
    def refuse(word: str) -> None:
        raise ValueError(f"not JSON: {word}")
    return json.loads(text, parse_constant=refuse)


# -- status: a reply larger than a datagram, text JSON cannot carry ---------------------------------


def many_robots(count: int) -> dict:
    row = {"state": "running", "step": 3, "label": "é" * 200, "cue": "12.5", "doing": "play", "next": None}
    return {**STATUS, "robots": {f"robot-{n:03d}-" + "x" * 60: {**row, "robot": str(n)} for n in range(count)}}


class Big(Recording):
    def __init__(self, clock: VirtualTime, status: dict) -> None:
        super().__init__(clock)
        self.said = status

    def status(self) -> dict:
        return self.said


@pytest.mark.parametrize("transport", ["udp", "tcp"])
def test_a_status_too_big_for_a_datagram_is_cut_saying_so_over_udp_and_whole_over_tcp(transport, clock):
    """100 robots with long labels: 60 KB of status. Over UDP it was sent nowhere and said
    nothing (sendto failed, quietly); now it is cut to `Limits.status_datagram` bytes, the
    robots left out counted, the message saying to ask over TCP, where it comes whole."""
    said = many_robots(100)
    osc = OscServer(Big(clock, said), 0, now=clock.now)
    osc.start()
    peer = Peer(transport, osc.port)
    try:
        peer.send(encode_message("/choreo/status"))
        peer.sock.settimeout(TIMEOUT_S)
        packet = peer.sock.recv(65536) if transport == "udp" else _frame(peer)
    finally:
        peer.close()
        osc.close()
    address, body = reply(packet)
    data = body["data"]
    assert address == "/reply/choreo/status" and body["status"] == "ok"
    if transport == "tcp":
        assert data == said and body["message"] == "running"
        return
    assert len(packet) <= LIMITS.status_datagram < len(Reply("/choreo/status", "ok", "running", said).encoded())
    kept = list(data["robots"])
    assert 0 < len(kept) < 100 and kept == list(said["robots"])[:len(kept)]  # the first ones, whole
    assert data["cut"] == {"robots": 100 - len(kept), "waiting": 0, "playhead": False}
    assert body["message"] == (f"running (cut to {LIMITS.status_datagram} bytes: {100 - len(kept)} of 100 robots, "
                               "0 of 0 cues waiting left out; ask over TCP for the whole status)")
    assert len(Reply("/choreo/status", "ok", "", {**said, "robots": dict(list(said["robots"].items())[:len(kept) + 1])})
               .encoded()) > LIMITS.status_datagram - 200  # as many as fit, not a few


def test_a_status_too_big_for_one_message_is_cut_over_tcp_too(clock):
    """300 robots: 175 KB of status over TCP, more than one message choreo takes (and more than
    a connection may leave unsent before it is closed): cut to `OscLimits.max_message`."""
    said = many_robots(300)
    osc = OscServer(Big(clock, said), 0, now=clock.now)
    osc.start()
    peer = Peer("tcp", osc.port)
    try:
        peer.send(encode_message("/choreo/status"))
        peer.sock.settimeout(TIMEOUT_S)
        packet = _frame(peer)
    finally:
        peer.close()
        osc.close()
    body = reply(packet)[1]
    assert len(packet) <= osc.wire_limits.max_message and 0 < len(body["data"]["robots"]) < 300
    assert body["message"].endswith("robots, 0 of 0 cues waiting left out; one message holds no more)")


def _frame(peer: Peer) -> bytes:
    while b"\xc0" not in peer._buffer.lstrip(b"\xc0"):
        chunk = peer.sock.recv(65536)
        assert chunk, "closed"
        peer._buffer += chunk
    frame, _, peer._buffer = peer._buffer.lstrip(b"\xc0").partition(b"\xc0")
    return frame


def test_a_status_cut_leaves_out_robots_then_the_cues_waiting_then_the_playhead():
    cue = {"number": "1", "label": "a", "go": True, "planned_s": 1.0, "robots": [f"r{n}" * 30 for n in range(300)]}
    waiting = [{**cue, "number": str(n), "reached_s": 1.0} for n in range(4)]
    status = {**many_robots(5), "playhead": cue, "waiting": waiting}
    for most in (60_000, 30_000, 2_000):
        packet = status_reply("/choreo/status", status, most).encoded()
        assert len(packet) <= most
        data = strict_json(decoded_text(packet))["data"]
        assert data["robots"] == {} and data["cut"]["robots"] == 5
        assert len(data["waiting"]) + data["cut"]["waiting"] == 4
        assert (data["playhead"] is None) == data["cut"]["playhead"]
    assert reply(status_reply("/choreo/status", status, 2_000).encoded())[1]["data"]["cut"] == {
        "robots": 5, "waiting": 4, "playhead": True}
    assert status_reply("/choreo/status", status, None).data == status  # over TCP: whole


def test_a_reply_is_always_sent_and_always_json():
    """A lone surrogate (no UTF-8 for it) made encoding fail: no reply at all, a fault counted.
    A NaN made Python write `NaN`, which no other JSON parser reads."""
    for data in ({"label": "x\ud800y"}, {"show_s": float("nan")}, {"rows": [{"latency_ms": float("inf")}]}):
        assert strict_json(decoded_text(Reply("/choreo/status", "ok", "running", data).encoded()))["status"] == "ok"
    assert strict_json(decoded_text(Reply("/s", "ok", "", {"label": "x\ud800y"}).encoded()))["data"] == {
        "label": "x\ud800y"}
    assert strict_json(decoded_text(Reply("/s", "ok", "", {"a": [float("nan"), 1.5]}).encoded()))["data"] == {
        "a": [None, 1.5]}
    assert "été" in decoded_text(Reply("/s", "ok", "été").encoded())  # UTF-8 as it is when it can be


def decoded_text(packet: bytes) -> str:
    (message,) = decode_packet(packet).messages
    return str(message.args[0])


# -- suggestions: a letter that folds to ASCII is not a difference of case ---------------------------


def ascii_lookalikes() -> dict[str, str]:
    """Every non-ASCII character that Unicode's case mapping or folding turns into ASCII letters
    (`ſ` s, `K` k, `ﬆ` st, ...): the ASCII it becomes."""
    found = {}
    for code in range(0x80, 0x10000):  # past the BMP no letter folds to ASCII (Unicode 15)
        char = chr(code)
        for folded in (char.casefold(), char.lower(), char.upper()):
            if folded.isascii() and folded.isalpha():
                found[char] = folded.lower()
    return found


def test_a_letter_that_folds_to_ascii_never_reaches_a_command_with_an_effect():
    """`/choreo/ſtop` (a long s) was offered `/choreo/stop` as a mere difference of case: a stop
    for an address no operator meant. Every such letter, in every place of every address with
    a stage effect and its upper-case spelling: nothing with an effect is offered."""
    lookalikes = ascii_lookalikes()
    assert {"ſ", "\u212a", "ﬆ"} <= set(lookalikes)  # a long s, the Kelvin sign, a ligature
    bases = [a for a, name in COMMANDS.items() if name in EFFECTS] + ["/choreo/cue/1/go", "/go", "/cue/1/go"]
    tried = 0
    for base in bases:
        for spelled in (base, base.upper()):
            for char, ascii_text in lookalikes.items():
                at = spelled.lower().find(ascii_text)
                while at >= 0:
                    address = spelled[:at] + char + spelled[at + len(ascii_text):]
                    meant = suggestion(address)
                    assert meant is None or wanted(meant).name not in EFFECTS, (address, meant)  # type: ignore[union-attr]
                    tried += 1
                    at = spelled.lower().find(ascii_text, at + 1)
    assert tried >= 20
    assert suggestion("/CHOREO/STOP") == "/choreo/stop"  # ASCII case still is case


# -- questions from many senders ----------------------------------------------------------------------


def test_status_from_many_forged_senders_is_answered_within_a_total_and_heartbeats_still_are(clock):
    """Each sender had 20 answers of its own and nothing bounded them all: 256 addresses of an
    allowed network, forged, each asking once a burst, had 256 status replies (kilobytes each)
    sent to a victim among them for 24-byte questions. All senders' status answers are bounded
    now; a heartbeat (a reply as small as a command's) is answered within its sender's own."""
    osc = OscServer(Recording(clock), 0, allow=["10.0.0.0/8"], now=clock.now)
    question = encode_message("/choreo/status")
    answered = sum(bool(osc.packet("udp", (f"10.0.{n // 250}.{n % 250 + 1}", 53000), question))
                   for n in range(200))
    assert answered == LIMITS.queries_total.burst
    assert osc.counts["unanswered"] == 200 - LIMITS.queries_total.burst
    assert osc.packet("udp", ("10.9.9.9", 53000), encode_message("/choreo/go"))  # a command still is answered
    clock.sleep(1.0)
    assert sum(bool(osc.packet("udp", (f"10.1.0.{n + 1}", 53000), question)) for n in range(100)) == \
        int(LIMITS.queries_total.per_s)
    thump = encode_message("/choreo/thump")
    assert all(osc.packet("udp", (f"10.2.0.{n + 1}", 53000), thump) for n in range(100))


# -- subscriptions: their places and what a UDP one may be sent ---------------------------------------


def test_a_tcp_subscriber_takes_the_place_of_the_udp_one_least_lately_heard():
    """Four forged UDP subscriptions, renewed by a forged message a minute, kept QLab's TCP
    connection out for good. A TCP sender (proven by its handshake) now takes the place of the
    UDP subscriber least lately heard; UDP never takes a TCP one's; all TCP: refused."""
    clock = VirtualTime()
    table = Subscriptions(most=3, expire_s=61.0, now=clock.now)
    for n in range(3):
        assert table.add(f"u{n}", "udp", ("10.0.0.1", n + 1), f"u{n}") == (True, [])
        clock.sleep(1.0)
    table.heard("u0")
    taken, ended = table.add("t0", "tcp", ("127.0.0.1", 9), "t0")
    assert taken and [(s.source, s.ended) for s in ended] == [
        ("u1", "its place taken by a TCP subscriber (a UDP sender's address can be forged)")]
    assert table.add("u1", "udp", ("10.0.0.1", 2), "u1") == (False, [])
    assert table.add("t1", "tcp", ("127.0.0.1", 10), "t1")[0] and table.add("t2", "tcp", ("127.0.0.1", 11), "t2")[0]
    assert table.add("t3", "tcp", ("127.0.0.1", 12), "t3") == (False, [])
    assert sorted(s.source for s in table.current()[0]) == ["t0", "t1", "t2"]


def test_over_the_network_a_tcp_subscriber_displaces_a_udp_one_and_the_log_says_so(live, clock, peers):  # noqa: F811
    udp = [peers("udp") for _ in range(LIMITS.update_subscribers)]
    for peer in udp:
        assert ask(peer, "/choreo/updates", 1)[1]["status"] == "ok"
    tcp = peers("tcp")
    assert ask(tcp, "/choreo/updates", 1)[1]["status"] == "ok"
    assert ("ok", "updates off: its place taken by a TCP subscriber (a UDP sender's address can be forged)") in \
        [told_[1:] for told_ in told(live)]
    assert ask(peers("udp"), "/choreo/updates", 1)[1]["status"] == "error"  # UDP never takes a place back


def test_a_udp_subscriber_is_sent_within_its_budget_of_bytes_and_renewing_does_not_refill_it(clock):
    """A forged `/choreo/updates 1` sent every notification to its victim for 61 s per datagram,
    renewable by one more: what it may be sent is bounded (`Limits.update_bytes`), the rest
    dropped and counted; renewing keeps the budget spent (a new one would refill it)."""
    live = Recording(clock)
    osc = OscServer(live, 0, now=clock.now, limits=Limits(update_bytes=Rate(1000, 1.0)))
    osc.start()
    live.subscribe(osc)
    peer = Peer("udp", osc.port)
    try:
        assert ask(peer, "/choreo/updates", 1)[1]["status"] == "ok"  # its own notification spends some too
        warning = encode_message("/choreo/notify/warning", ["x" * 300])
        for _ in range(10):
            osc.on_log(WARNING, "x" * 300)
        warnings: list[bytes] = []

        def all_told() -> bool:
            warnings.extend(p for p in peer.replies(0.02) if p.startswith(b"/choreo/notify/warning"))
            return len(warnings) + osc.counts["unsent updates"] == 10

        assert wait_for(all_told, TIMEOUT_S, every=0.0)
        assert 1 <= len(warnings) <= 1000 // len(warning) and set(warnings) == {warning}
        unsent = osc.counts["unsent updates"]
        assert ask(peer, "/choreo/updates", 1)[1]["status"] == "ok"  # renewed: nothing refilled
        osc.on_log(WARNING, "x" * 300)
        assert wait_for(lambda: osc.counts["unsent updates"] >= unsent + 1, TIMEOUT_S, every=0.005)
        clock.sleep(1.0)  # the budget refills at its rate, 1 byte a second here
        osc.on_log(WARNING, "x" * 300)
        assert wait_for(lambda: osc.counts["unsent updates"] >= unsent + 2, TIMEOUT_S, every=0.005)
    finally:
        peer.close()
        osc.close()


def test_a_tcp_subscriber_is_not_bounded_by_the_udp_budget(clock):
    """TCP's own flow control bounds a TCP subscriber (its address is proven): the byte budget
    is the UDP subscribers' alone."""
    table = Subscriptions(now=clock.now)
    table.add("t", "tcp", ("127.0.0.1", 1), "t")
    table.add("u", "udp", ("127.0.0.1", 2), "u")
    (tcp, udp), _ = table.current()
    assert tcp.budget is None and udp.budget is not None and udp.budget.burst == LIMITS.update_bytes.burst


# -- bundles mixing commands ---------------------------------------------------------------------------


@pytest.mark.parametrize("transport", ["udp", "tcp"])
def test_a_bundle_is_carried_out_in_order_each_message_answered(transport, live, peers):  # noqa: F811
    peer = peers(transport)
    bundle = encode_bundle([encode_message("/choreo/pause"), encode_message("/choreo/go"),
                            encode_message("/choreo/status"), encode_message("/choreo/bogus"),
                            encode_message("/choreo/resume")])
    peer.send(bundle)
    got = [reply(packet) for packet in _replies(peer, 5)]
    assert [address for address, _ in got] == ["/reply/choreo/pause", "/reply/choreo/go", "/reply/choreo/status",
                                               "/reply/choreo/bogus", "/reply/choreo/resume"]
    assert [c.name for c in live.given] == ["pause", "go", "resume"]  # the question carries nothing out


def _replies(peer: Peer, count: int) -> list[bytes]:
    got: list[bytes] = []
    assert wait_for(lambda: got.extend(peer.replies(0.05)) or len(got) >= count, TIMEOUT_S, every=0.0)
    return got


# -- cues written every odd way, on a show's own cue list -------------------------------------------

ODD_SHOW = """\
    version: 1
    motions:
      bow: {number: 2, duration: 0.05}
    steps:
      - play: 1
      - play: bow
        at: go
        label: café
      - play: bow
        at: go
        cue: 12.5
        label: next
      - play: bow
        at: go
        label: "1.5"
      - play: bow
        at: go
        label: "*"
    """


def playhead_of(peer: Peer) -> str | None:
    data = ask(peer, "/choreo/status")[1]["data"]
    return data["playhead"]["number"] if data["playhead"] else None


@pytest.mark.parametrize("transport", ["udp", "tcp"])
def test_cues_sent_every_odd_way_reach_their_cue_or_change_nothing(transport, real_shows):  # noqa: F811
    """Cue 1 'café', 12.5 'next', 13 '1.5' (a label that reads as a number), 14 '*' (a pattern's
    character). A number by its value, a label decomposed (NFD, as macOS may send it), `next`
    escaped; every refused reference (overlong UTF-8, a surrogate, %00, a bad escape, 10,000
    characters, a pattern) answered as an error with the playhead where it was."""
    many = Rate(1000, 1.0)  # every reference here is carried out and answered (the budgets are tested elsewhere)
    run = real_shows(ODD_SHOW, limits=Limits(commands_per_sender=many, commands_total=many, replies_per_sender=many,
                                             queries_per_sender=many, queries_total=many))
    peer = Peer(transport, run.server.port)
    try:
        assert wait_for(lambda: run.waiting() == ["café"], POLL_S, every=0.005), run.waiting()
        heard = Commands()
        run.live.subscribe(heard)
        reached = {"12.50": "12.5", "%6Eext": "12.5", "cafe%CC%81": "1", "caf%C3%A9": "1", "café": "1",
                   "1": "1", "13": "13", "1.5": "13", "1%2E5": "13", "%31": "1", "%2A": "14", "*": "14",
                   "12.5": "12.5", "014": "14"}
        for ref, number in reached.items():
            body = ask(peer, f"/choreo/playhead/{ref}")[1]
            assert body["status"] == "ok" and body["data"]["cue"] == number, (ref, body)
        assert ask(peer, "/choreo/playhead/13")[1]["status"] == "ok"
        refused = ["%C0%AF", "%E0%80%AF", "%ED%A0%80", "%F4%90%80%80", "%00", "%", "%%", "a%2", "x" * 10_000,
                   "14.0.0", "1e1", "1.50", "%2B1", "nope", "cafe"]
        for ref in refused:
            got, body = ask(peer, f"/choreo/playhead/{ref}")
            assert body["status"] == "error", (ref, body)
            got, body = ask(peer, f"/choreo/cue/{ref}/go")
            assert body["status"] == "error", (ref, body)
        assert ask(peer, "/choreo/playhead/next")[1]["data"]["cue"] == "14"  # the command, not the label
        assert playhead_of(peer) == "14" and run.waiting() == ["café"]  # nothing refused moved it
        taken = [e.command.name for e in heard.events if e.answer.status == "ok"]
        assert taken == ["playhead"] * (len(reached) + 1) + ["playhead_next"]
    finally:
        peer.close()


@pytest.mark.parametrize("transport", ["udp", "tcp"])
def test_a_bundle_of_pause_and_go_on_a_show(transport, real_shows):  # noqa: F811
    """pause + GO in one bundle: carried out in order (the GO refused: paused), then resume + GO
    in another: the cue released. Each message answered, in order."""
    run = real_shows()  # GO_SHOW: cue 1 'applause' waits
    peer = Peer(transport, run.server.port)
    try:
        assert wait_for(lambda: run.waiting() == ["applause"], POLL_S, every=0.005), run.waiting()
        peer.send(encode_bundle([encode_message("/choreo/pause"), encode_message("/choreo/go")]))
        (pause, pause_body), (go, go_body) = [reply(p) for p in _replies(peer, 2)]
        assert (pause, pause_body["status"]) == ("/reply/choreo/pause", "ok")
        assert (go, go_body["status"], go_body["message"]) == (
            "/reply/choreo/go", "error", "paused: resume first (p or /choreo/resume)")
        assert run.waiting() == ["applause"]
        peer.send(encode_bundle([encode_message("/choreo/resume"), encode_message("/choreo/go")]))
        (_, resume_body), (_, go_body) = [reply(p) for p in _replies(peer, 2)]
        assert resume_body["status"] == "ok" and go_body["message"] == "GO: cue 1 'applause'"
    finally:
        peer.close()


@pytest.mark.parametrize("silent_s, still", [(60.999, True), (61.0, False), (600.0, False)])
def test_a_subscription_silent_61_s_has_ended_whether_or_not_a_notification_went_meanwhile(silent_s, still, live,
                                                                                         clock, peers):  # noqa: F811
    """Expiring was lazy: a subscriber silent for ten minutes, with nothing notified meanwhile,
    was renewed by its next message (its thump said `updates: true`, and the notifications went
    on), while one silent as long in a busier show had ended. The boundary is the same either
    way: 61 s of silence ends it."""
    peer = peers("udp")
    assert ask(peer, "/choreo/updates", 1)[1]["status"] == "ok"
    clock.sleep(silent_s)
    assert ask(peer, "/choreo/thump")[1]["data"] == {"updates": still}
    ended = [m for _, _, m in told(live) if m.startswith("updates off")]
    assert ended == ([] if still else ["updates off: no message for 61 s"])


# -- suggestions: every near miss, exhaustively ------------------------------------------------------

WORDS = ("go", "panic", "start", "stop", "pause", "resume", "skip", "playhead", "next", "previous", "cue", "status",
         "thump", "updates", "1", "bow")


def single_edits(text: str) -> set[str]:
    """Every address one keystroke from `text`: a character left out, added, changed, or two
    swapped (letters, digits, `/`, `%`)."""
    alphabet = "abcdefghijklmnopqrstuvwxyz0123456789/%"
    edits = {text[:i] + text[i + 1:] for i in range(len(text))}
    edits |= {text[:i] + text[i + 1] + text[i] + text[i + 2:] for i in range(len(text) - 1)}
    edits |= {text[:i] + c + text[i:] for i in range(len(text) + 1) for c in alphabet}
    edits |= {text[:i] + c + text[i + 1:] for i in range(len(text)) for c in alphabet}
    return edits


def test_no_address_one_keystroke_or_one_word_away_is_offered_a_command_with_an_effect():
    """Exhaustively (not sampled): every address one keystroke from one of ours (its cue `1` or
    `bow`), and every `/choreo/A/B` and `/choreo/cue/1/A` of the dictionary's words
    (`/choreo/cue/1/skip`, `/choreo/pause/1`, `/choreo/skip/go`): none is offered GO, panic, start,
    stop, pause, resume, skip or a cue's GO unless it is that address but for ASCII case, /choreo
    and a trailing slash; `/playhead` alone (QLab's question) is offered status."""
    ours = [*COMMANDS, "/choreo/cue/1/go", "/choreo/cue/bow/go", "/choreo/playhead/1", "/choreo/status",
            "/choreo/thump", "/choreo/updates", "/go", "/cue/1/go", "/ping"]
    near = set().union(*(single_edits(address) for address in ours))
    near |= {f"/choreo/{a}/{b}" for a in WORDS for b in WORDS} | {f"/choreo/cue/1/{a}" for a in WORDS}
    offered = 0
    for address in sorted(near):
        if not address.startswith("/") or wanted_or_bad(address):
            continue
        meant = suggestion(address)
        if meant is not None and wanted(meant).name in EFFECTS:  # type: ignore[union-attr]  # a suggestion is ours
            assert address.lower().rstrip("/").removeprefix("/choreo") == meant.lower().removeprefix("/choreo"), \
                (address, meant)
            offered += 1
    assert len(near) > 15_000 and offered > 20  # `/GO`, `/choreo/stop/`, ... are offered
    assert suggestion("/choreo/playhead") == suggestion("/choreo/playhead/") == "/choreo/status"


def wanted_or_bad(address: str) -> bool:
    """One of ours (taken as it is), or one of ours badly escaped (answered with how to escape)."""
    try:
        return wanted(address) is not None
    except BadAddress:
        return True
