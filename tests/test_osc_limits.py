"""OSC on a hostile network, what a packet may cost (`choreo.live.limits` through `choreo.live.osc`): one
bundle of many GOs carries out and answers only what one sender's budget allows; replies and
notifications sent back to choreo are never answered nor notified; `--osc-notify` pointed at
choreo's own port is refused at start-up, and every target given is notified; `choreo run`
checks every option, and listens, before a log is created or a byte goes to a board.

Loopback only. The servers' budgets run on a virtual clock that does not move, so what a flood
gets is exact; replies are waited for with a deadline, never a sleep that decides.
"""

from __future__ import annotations

import json
import socket
import threading
import time

import pytest
from pythonosc.osc_bundle_builder import IMMEDIATELY, OscBundleBuilder
from pythonosc.osc_message_builder import OscMessageBuilder

from choreo.clock import VirtualTime
from choreo.errors import UsageError
from choreo.live.limits import LIMITS, Limits, Rate
from choreo.log.format import UNLOGGED
from choreo.live.controls import Live
from choreo.events import Command, StopRequest
from choreo.live.osc import OscServer
from runlog import choreo, choreo_here, ended_if_left, read_log, start_choreo, wait_for, write_show
from test_osc import ONE_GO_SHOW, Receiver, free_port, outside_address

TIMEOUT_S = 5.0
EVERY_EVENT = Limits(reported=Rate(1_000_000, 1.0))  # the test hears every command one by one


class Heard:
    def __init__(self) -> None:
        self.events: list = []
        self._lock = threading.Lock()

    def on_command(self, event) -> None:  # type: ignore[no-untyped-def]
        with self._lock:
            self.events.append(event)

    def names(self) -> list[str]:
        with self._lock:
            return [e.command.name for e in self.events]

    def messages(self, name: str) -> list[str]:
        with self._lock:
            return [e.answer.message for e in self.events if e.command.name == name]


@pytest.fixture
def clock() -> VirtualTime:
    return VirtualTime()


@pytest.fixture
def heard() -> Heard:
    return Heard()


@pytest.fixture
def live(clock, heard):  # type: ignore[no-untyped-def]
    live = Live(StopRequest(), wait_start=True, lockout_s=0.0, now=clock.now, limits=EVERY_EVENT)
    live.subscribe(heard)
    return live


@pytest.fixture
def server(live, clock):  # type: ignore[no-untyped-def]
    server = OscServer(live, 0, now=clock.now)
    server.start()
    live.subscribe(server)
    yield server
    server.close()


def message(address: str) -> bytes:
    return OscMessageBuilder(address).build().dgram


def bundle(address: str, count: int) -> bytes:
    builder = OscBundleBuilder(IMMEDIATELY)
    for _ in range(count):
        builder.add_content(OscMessageBuilder(address).build())
    return builder.build().dgram


def slip(packet: bytes) -> bytes:
    return b"\xc0" + packet.replace(b"\xdb", b"\xdb\xdd").replace(b"\xc0", b"\xdb\xdc") + b"\xc0"


class Peer:
    """One sender on loopback, over UDP or TCP (SLIP), counting the replies it gets."""

    def __init__(self, transport: str, port: int, host: str = "127.0.0.1") -> None:
        self.transport = transport
        if transport == "udp":
            self.sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
            self.sock.bind((host, 0))
            self.sock.connect(("127.0.0.1", port))
        else:
            self.sock = socket.create_connection(("127.0.0.1", port), timeout=TIMEOUT_S, source_address=(host, 0))
        self._buffer = b""

    def send(self, packet: bytes) -> None:
        self.sock.sendall(packet if self.transport == "udp" else slip(packet))

    def replies(self, quiet_s: float = 0.3, at_least: int = 0) -> list[bytes]:
        """Every reply until none came for `quiet_s`, once `at_least` came (a server's thread a
        loaded machine put off may send a reply later than a quiet spell: those a test counts
        are waited for up to TIMEOUT_S)."""
        got: list[bytes] = []
        try:
            while True:
                self.sock.settimeout(TIMEOUT_S if len(got) < at_least else quiet_s)
                data = self.sock.recv(65536)
                if not data:
                    break
                if self.transport == "udp":
                    got.append(data)
                else:
                    self._buffer += data
                    *frames, self._buffer = self._buffer.split(b"\xc0")
                    got.extend(frame for frame in frames if frame)
        except (TimeoutError, socket.timeout):
            pass
        return got

    def close(self) -> None:
        self.sock.close()


# -- what one packet may do ----------------------------------------------------------------------


@pytest.mark.parametrize("transport", ["udp", "tcp"])
def test_one_bundle_of_many_gos_is_bounded_by_the_senders_budget(transport, server, heard):
    """Once, one 8 KB UDP bundle of 408 GOs carried out 408 commands and sent 408 replies (8.8
    times the bytes received: a reflector for forged senders)."""
    count = 200
    packet = bundle("/choreo/go", count)
    peer = Peer(transport, server.port)
    try:
        peer.send(packet)
        assert wait_for(lambda: len(heard.names()) >= count, TIMEOUT_S, every=0.005)
        replies = peer.replies(at_least=LIMITS.replies_per_sender.burst)
    finally:
        peer.close()
    carried_out = [m for m in heard.messages("go") if not m.startswith("ignored: over the limit")]
    assert len(carried_out) == LIMITS.commands_per_sender.burst  # the rest not carried out, but counted
    assert heard.names() == ["go"] * count
    assert len(replies) == LIMITS.replies_per_sender.burst
    assert sum(map(len, replies)) < len(packet)  # no longer an amplifier


def test_the_budget_is_the_senders_not_the_packets(server, heard, clock):
    """Messages sent one packet each count as a bundle's do, from any port of the sender's
    address; another sender (address) keeps its own budget."""
    flooder, other = Peer("udp", server.port), Peer("udp", server.port, host="127.0.0.2")
    try:
        for _ in range(15):
            flooder.send(message("/choreo/go"))
        again = Peer("udp", server.port)  # the same sender from another port
        for _ in range(15):
            again.send(message("/choreo/go"))
        assert wait_for(lambda: len(heard.names()) >= 30, TIMEOUT_S, every=0.005)
        assert again.replies() == []  # its budget was spent from the other port
        again.close()
        other.send(message("/choreo/start"))
        assert wait_for(lambda: "start" in heard.names(), TIMEOUT_S, every=0.005)
        flooded, answered = flooder.replies(at_least=LIMITS.replies_per_sender.burst), other.replies(at_least=1)
    finally:
        flooder.close()
        other.close()
    assert len(flooded) == LIMITS.replies_per_sender.burst
    assert heard.messages("start") == ["starting"] and len(answered) == 1


def test_a_desks_other_messages_spend_no_command(server, heard):
    """A desk that sends every fader move to choreo gets them refused (answered within its
    reply budget), but its GO is still carried out."""
    desk = Peer("udp", server.port)
    try:
        desk.send(bundle("/1/fader1", 100))
        desk.send(message("/choreo/start"))
        assert wait_for(lambda: "start" in heard.names(), TIMEOUT_S, every=0.005)
        replies = desk.replies(at_least=LIMITS.replies_per_sender.burst)
    finally:
        desk.close()
    assert heard.names() == ["unknown"] * 100 + ["start"]
    assert heard.messages("start") == ["starting"]
    assert len(replies) == LIMITS.replies_per_sender.burst


@pytest.mark.parametrize("address", ["/" + "x" * 60_000, "/reply/" + "y" * 60_000,
                                     "/choreo/cue/" + "z" * 60_000 + "/go"])
def test_a_long_address_costs_neither_a_long_log_line_nor_a_long_reply(server, heard, address):
    """A 60 KB address once cost a 60 KB log line (10 at once, 2 a second: a disk filled
    fast) and a reply three times the bytes received (the address, in the reply's address,
    its JSON and its message)."""
    peer = Peer("udp", server.port)
    try:
        peer.send(OscMessageBuilder(address).build().dgram)
        assert wait_for(lambda: heard.events, TIMEOUT_S, every=0.005)
        replies = peer.replies()
    finally:
        peer.close()
    (event,) = heard.events
    most = LIMITS.address_shown + 1
    assert len(event.command.label) <= most and len(event.answer.message) < 2 * most
    assert event.command.label == address[:LIMITS.address_shown] + "…"
    assert sum(map(len, replies)) < 4 * most


def test_a_flood_from_a_sender_not_allowed_gets_few_replies_and_few_log_lines(clock):
    """A forged sender's packets: answered within the refusals' shared budget, logged within
    the log's, and every one counted."""
    host = outside_address()
    if host is None:
        pytest.skip("this machine has no address but loopback")
    live = Live(StopRequest(), wait_start=True, now=clock.now)
    heard = Heard()
    live.subscribe(heard)
    server = OscServer(live, 0, host="0.0.0.0", now=clock.now)
    server.start()
    forged = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    forged.bind((host, 0))
    try:
        for _ in range(6):  # in sixes of 50, read before the next: none lost in the socket's buffer
            for _ in range(50):
                forged.sendto(message("/choreo/panic"), (host, server.port))
            assert wait_for(lambda: server_idle(server), TIMEOUT_S, every=0.01)
        replies = Peer.replies(_Wrapped(forged))
        live.close()
    finally:
        forged.close()
        server.close()
    assert not live.stop()  # no panic from a sender not allowed
    assert len(replies) <= LIMITS.refusals.burst
    names = heard.names()
    assert names.count("refused") <= LIMITS.reported.burst
    summary = [e for e in heard.events if e.command.name == UNLOGGED]
    assert names.count("refused") + sum(e.answer.data["counts"].get("refused", 0) for e in summary) == 300


class _Wrapped:
    """A bare UDP socket, read as a `Peer` reads its replies."""

    def __init__(self, sock: socket.socket) -> None:
        self.sock, self.transport, self._buffer = sock, "udp", b""


def test_a_flood_reaches_the_log_and_terminal_as_counts(clock):
    """The listeners (the log, the terminal's lines, notifications) hear a flood within the
    reported budget; the rest come as one `unlogged` count."""
    live = Live(StopRequest(), wait_start=True, now=clock.now)
    heard = Heard()
    live.subscribe(heard)
    server = OscServer(live, 0, now=clock.now)
    server.start()
    peer = Peer("udp", server.port)
    try:
        for _ in range(4):
            peer.send(bundle("/choreo/go", 100))
            assert wait_for(lambda: server_idle(server), TIMEOUT_S, every=0.01)
        clock.advance(LIMITS.summary_every_s)
        live.flush_reports()
    finally:
        peer.close()
        server.close()
    names = heard.names()
    assert len(names) <= LIMITS.reported.burst + 1
    summary = [e for e in heard.events if e.command.name == UNLOGGED]
    assert len(summary) == 1
    counts = summary[0].answer.data["counts"]
    # 256 messages read (a bundle's messages count as packets), the third bundle's other 44
    # counted unread, and the fourth bundle unread whole: one packet, not decoded
    assert counts["unread"] == 400 - LIMITS.packets_per_sender.burst - 100 + 1
    assert names.count("go") + counts["go"] == LIMITS.packets_per_sender.burst  # each GO read is told


def server_idle(server: OscServer) -> bool:
    """The server has read what was sent before: a probe from another address (with budgets of
    its own), sent after it, is answered (a probe that found the socket's buffer full is lost:
    the next one tries again)."""
    probe = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    probe.bind(("127.0.0.3", 0))
    try:
        probe.sendto(message("/choreo/nothing"), ("127.0.0.1", server.port))
        probe.settimeout(0.5)
        return bool(probe.recv(65536))
    except OSError:
        return False
    finally:
        probe.close()


# -- replies and notifications that come back -----------------------------------------------------


@pytest.fixture
def receivers():  # type: ignore[no-untyped-def]
    made = [Receiver(), Receiver()]
    yield made
    for receiver in made:
        receiver.close()


def test_replies_and_notifications_sent_back_are_never_answered_nor_notified(live, clock, heard, receivers):
    receiver = receivers[0]
    server = OscServer(live, 0, now=clock.now, notify=[receiver.address])
    server.start()
    live.subscribe(server)
    peer = Peer("udp", server.port)
    try:
        for address in ("/reply/choreo/go", "/choreo/notify/command", "/choreo/notify/step"):
            peer.send(message(address))
        peer.send(message("/choreo/start"))  # a real one after them: its notification comes last
        assert wait_for(lambda: any(c[0] == "start" for c in receiver.of("command")), TIMEOUT_S, every=0.005)
        replies = peer.replies(at_least=1)
    finally:
        peer.close()
        server.close()
    assert heard.names() == ["echo", "echo", "echo", "start"]
    assert heard.messages("echo")[0].startswith("ignored: /reply/choreo/go is a reply or a notification")
    assert [json.loads(OscReply(r).argument)["address"] for r in replies] == ["/choreo/start"]
    assert [c[0] for c in receiver.of("command")] == ["start"]  # the echoes were not notified


class OscReply:
    """A reply's one string argument."""

    def __init__(self, data: bytes) -> None:
        from pythonosc.osc_message import OscMessage

        self.argument = OscMessage(data).params[0]


def test_every_notify_target_gets_the_notifications(live, clock, receivers):
    server = OscServer(live, 0, now=clock.now, notify=[r.address for r in receivers])
    server.start()
    live.subscribe(server)
    try:
        assert live.command(Command("start", "key")).ok
        assert wait_for(lambda: all(r.of("command") for r in receivers), TIMEOUT_S, every=0.005)
    finally:
        server.close()
    for receiver in receivers:
        assert receiver.of("command") == [("start", "key", "ok", "starting", "")]
    ports = ", ".join(f"127.0.0.1:{r.address[1]}" for r in receivers)
    assert server.listening.endswith(f"; progress to {ports}")


SELF = ["127.0.0.1", "localhost", "127.9.8.7", "0.0.0.0", "::1", "::ffff:127.0.0.1", "::", "outside"]


@pytest.mark.parametrize("host", SELF)
def test_notifying_choreos_own_port_is_refused_at_start_up(live, host):
    """Each notification would come back as an unknown command, notified in turn: a loop."""
    if host == "outside":
        host = outside_address()
        if host is None:
            pytest.skip("this machine has no address but loopback")
    for _ in range(10):  # a port free a moment ago may be taken by another test worker first
        port = free_port()
        server = OscServer(live, port, host="0.0.0.0", notify=[(host, port)])
        with pytest.raises(UsageError) as refused:
            server.start()
        server.close()
        if "in use" not in str(refused.value):
            break
    assert str(refused.value).startswith(f"--osc-notify {host if ':' not in host else f'[{host}]'}:{port}: "
                                         "that is choreo's own --osc port on this machine")
    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as again:
        again.bind(("0.0.0.0", port))  # the port was let go
    OscServer(live, port, notify=[(host, port + 1 if port < 65535 else port - 1)]).close()  # another port is fine


def test_a_notify_target_on_another_machine_and_port_is_taken(live):
    server = OscServer(live, 0, notify=[("192.0.2.1", 53001), ("127.0.0.1", 9)])  # TEST-NET-1: nobody
    server.start()
    server.close()


# -- choreo run: every option checked, every port bound, before anything opens --------------------


ONE_STEP = """\
    version: 1
    steps:
      - play: 1
    """


class Board:
    """A TCP listener standing for a board on `socket://`: did anyone connect (a byte sent)?"""

    def __init__(self) -> None:
        self.sock = socket.socket(socket.AF_INET, socket.SOCK_STREAM)
        self.sock.bind(("127.0.0.1", 0))
        self.sock.listen()
        self.sock.setblocking(False)
        self.url = f"socket://127.0.0.1:{self.sock.getsockname()[1]}"

    def touched(self) -> bool:
        try:
            connection, _ = self.sock.accept()
        except BlockingIOError:
            return False
        connection.close()
        return True

    def close(self) -> None:
        self.sock.close()


@pytest.fixture
def taken_port():  # type: ignore[no-untyped-def]
    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as taken:
        taken.bind(("127.0.0.1", 0))
        yield taken.getsockname()[1]


@pytest.fixture
def tcp_taken_port():  # type: ignore[no-untyped-def]
    """A port whose TCP side another program listens on (on every address), its UDP side free."""
    with socket.socket(socket.AF_INET, socket.SOCK_STREAM) as taken:
        taken.bind(("0.0.0.0", 0))
        taken.listen()
        yield taken.getsockname()[1]


BAD_OPTIONS = {
    "port out of range": (["--osc", "70000"], "--osc 70000: give a port number"),
    "negative port": (["--osc", "-1"], "--osc -1: give a port number"),
    # a port not written in ASCII digits: argparse's int() took ' 5', '+5', '1_000' and the
    # Arabic-Indic '٥' (port 5) and answered 'abc' with nine lines of usage; '²' passed
    # isdigit() and ended --osc-notify in a traceback
    "port not a number": (["--osc", "abc"], "--osc abc: give a port number"),
    "port in hex": (["--osc", "0x10"], "--osc 0x10: give a port number"),
    "port with a space": (["--osc", " 5"], "--osc  5: give a port number"),
    "port with a sign": (["--osc", "+5"], "--osc +5: give a port number"),
    "port with an underscore": (["--osc", "1_000"], "--osc 1_000: give a port number"),
    "port in another script": (["--osc", "\u0665"], "--osc \u0665: give a port number"),
    "port of a thousand digits": (["--osc", "9" * 5000], "--osc 999"),
    "notify port superscript": (["--osc", "0", "--osc-notify", "127.0.0.1:\u00b2"],
                                "--osc-notify 127.0.0.1:\u00b2: give HOST:PORT"),
    "notify port in another script": (["--osc", "0", "--osc-notify", "127.0.0.1:\u0665"],
                                      "--osc-notify 127.0.0.1:\u0665: give HOST:PORT"),
    "port in use": (["--osc", "{taken}"], "--osc {taken}: cannot listen on 127.0.0.1:{taken}"),
    "tcp port in use, udp free": (["--osc", "{tcp_taken}"], "--osc {tcp_taken}: cannot listen on 127.0.0.1:{tcp_taken} "
                                  "(tcp): Address already in use"),
    "tcp port in use, any host": (["--osc", "{tcp_taken}", "--osc-host", "::"],
                                  "--osc {tcp_taken}: cannot listen on [::]:{tcp_taken} (tcp)"),
    "empty host": (["--osc", "0", "--osc-host", ""], "--osc-host '': give the address"),
    "host of another machine": (["--osc", "0", "--osc-host", "192.0.2.1"], "--osc 0: cannot listen on 192.0.2.1:0"),
    "bad allow": (["--osc", "0", "--osc-allow", "qlab.local"], "--osc-allow qlab.local: give an IP address"),
    "bad notify": (["--osc", "0", "--osc-notify", "127.0.0.1"], "--osc-notify 127.0.0.1: give HOST:PORT"),
    "notify port 0": (["--osc", "0", "--osc-notify", "127.0.0.1:0"], "--osc-notify 127.0.0.1:0: give HOST:PORT"),
    "notify twice": (["--osc", "0", "--osc-notify", "127.0.0.1:9", "--osc-notify", "127.0.0.1:9"],
                     "--osc-notify 127.0.0.1:9: given twice"),
    "notify twice, spelt two ways": (["--osc", "0", "--osc-notify", "localhost:9", "--osc-notify", "127.0.0.1:9"],
                                     "--osc-notify 127.0.0.1:9: given twice"),
    "notify nowhere": (["--osc", "0", "--osc-notify", "no-such-host.invalid:9"],
                       "--osc-notify no-such-host.invalid:9: "),
    "notify itself": (["--osc", "{free}", "--osc-notify", "localhost:{free}"], "--osc-notify localhost:{free}: that is "
                      "choreo's own --osc port"),
    "notify itself, the group of all hosts": (["--osc", "{free}", "--osc-host", "0.0.0.0", "--osc-notify",
                                               "224.0.0.1:{free}"],
                                              "--osc-notify 224.0.0.1:{free}: that is choreo's own"),
    "notify twice, mapped": (["--osc", "0", "--osc-notify", "127.0.0.1:9", "--osc-notify", "[::ffff:127.0.0.1]:9"],
                             "--osc-notify [::ffff:127.0.0.1]:9: given twice"),
    "bad timeout": (["--timeout", "nan"], "--timeout nan: "),
    "bad retries": (["--retries", "99"], "--retries 99: "),
    "bad baud": (["--baud", "12"], "baud 12: "),
}


@pytest.mark.parametrize("case", list(BAD_OPTIONS))
def test_a_bad_option_ends_the_run_before_a_log_or_a_board_is_touched(tmp_path, taken_port, tcp_taken_port, case):
    """Once `--osc 70000` or a port in use were noticed only after the log was created and the
    board had had its ACK check and config read."""
    options, expected = BAD_OPTIONS[case]
    free = free_port()
    ports = {"taken": taken_port, "tcp_taken": tcp_taken_port, "free": free}
    options = [o.format(**ports) for o in options]
    show = write_show(tmp_path, ONE_STEP)
    board = Board()
    try:
        done = choreo_here("run", str(show), "--port", board.url, *options, cwd=tmp_path)
        code, stderr = done.returncode, done.stderr
        touched = board.touched()
    finally:
        board.close()
    assert code == 2, stderr
    assert stderr.startswith(expected.format(**ports)), stderr
    assert stderr.count("\n") == 1 and "Traceback" not in stderr
    assert not touched  # no byte went to the board
    assert not (tmp_path / "runs").exists()  # no log was created


# -- a flood through choreo run --------------------------------------------------------------------


def test_a_flood_over_osc_neither_fills_the_log_nor_the_terminal_and_the_review_counts_it(tmp_path):
    """80,000 GOs in 5 s once wrote a 14 MB log and 4.5 MB of stderr, and `log summary` said
    "38201 commands, 19 refused" where 38,188 were."""
    # after the GO, the show goes on till stopped
    show = write_show(tmp_path, ONE_GO_SHOW.rstrip(" ") + "      - wait: 60\n")
    log_path = tmp_path / "run.mcap"
    port = free_port()
    process = start_choreo("run", str(show), "--osc", str(port), "--no-console", "--log", str(log_path))
    sent = 0
    with ended_if_left(process):
        peer = None
        deadline = time.monotonic() + 30
        while peer is None:  # until choreo listens
            assert time.monotonic() < deadline and process.poll() is None, "choreo does not listen"
            try:
                peer = Peer("tcp", port)
            except OSError:
                time.sleep(0.05)
        while not any(b'"status": "ok"' in reply for reply in peer.replies(quiet_s=0.25)):  # until a GO is taken
            assert time.monotonic() < deadline and process.poll() is None, "no GO taken"
            peer.send(message("/choreo/go"))
            sent += 1
        for _ in range(2000):  # 2,000 GOs over TCP, none lost on the way (past the sender's budget
            peer.send(message("/choreo/go"))  # of packets its connection rests: TCP holds the rest)
            sent += 1
        peer.replies(quiet_s=0.5)
        stopped = False
        stops = 0
        deadline = time.monotonic() + 30
        while not stopped:  # a stop, once the sender's budget has come back
            assert time.monotonic() < deadline, "the stop was never taken"
            peer.send(message("/choreo/stop"))
            sent += 1
            stops += 1
            stopped = any(b"stopping" in reply for reply in peer.replies(quiet_s=0.3))
        peer.close()
        _, err = process.communicate(timeout=30)
    assert process.returncode == 130, err
    assert err.count("\n") < 100, err[-2000:]  # the terminal: a few lines, not one a command
    assert log_path.stat().st_size < 200_000
    commands = read_log(log_path).topic("/choreo/command")
    unlogged = [c for c in commands if c["command"] == UNLOGGED]
    assert unlogged and len(commands) < 200
    # every command the run heard is in its log; a stop sent again while the reply to the one taken
    # was on its way (a loaded machine) may come after the log closed: those alone may be missing
    total = sum(c.get("count", 1) for c in commands)
    assert sent - stops < total <= sent, (total, sent, stops)
    review = choreo("log", "summary", str(log_path), cwd=tmp_path)
    assert review.returncode == 0, review.stderr
    assert f"commands  {total} received ({total - 2} refused; " in review.stdout  # a GO and the stop taken
    assert "log export" not in review.stdout


@pytest.mark.parametrize("url", ["socket://", "socket://127.0.0.1", "socket://127.0.0.1:0", "socket://127.0.0.1:70000",
                                 "rfc2217://:4000", "solo=socket://host:x"])
def test_a_network_port_without_host_and_port_is_a_bad_argument_not_a_failed_link(tmp_path, url):
    """Once `--port socket://` created a log and failed as a link (exit 3) with pyserial's
    "'<=' not supported between instances of 'int' and 'NoneType'"."""
    show = write_show(tmp_path, ONE_STEP)
    done = choreo_here("run", str(show), "--port", url, cwd=tmp_path)
    code, stderr = done.returncode, done.stderr
    assert code == 2, stderr
    assert stderr.startswith(f"--port {url}: give ") and stderr.count("\n") == 1
    assert not (tmp_path / "runs").exists()


# -- what a flood may cost: packets past a sender's rate are counted, not read -----------------------


def _decodes(monkeypatch) -> list[int]:  # type: ignore[no-untyped-def]
    """Counts the packets choreo.live.osc decodes."""
    import choreo.live.osc as osc

    calls = [0]
    decode = osc.decode_packet

    def counting(data, limits=osc.WIRE_LIMITS):  # type: ignore[no-untyped-def]
        calls[0] += 1
        return decode(data, limits)

    monkeypatch.setattr(osc, "decode_packet", counting)
    return calls


def _told(heard: Heard, name: str) -> int:
    """How many `name` the listeners were told of, one by one and in summaries."""
    summed = sum(e.answer.data["counts"].get(name, 0) for e in heard.events if e.command.name == UNLOGGED)
    return heard.names().count(name) + summed


def test_a_flood_past_a_senders_rate_of_packets_is_counted_not_read(clock, monkeypatch):
    """A UDP flood that costs choreo more a packet than it costs its sender outruns the socket,
    which then drops the operator's GO from another address too (a flood of 800,000 GOs in 5 s
    from 127.0.0.2 lost 7 of 10 GOs from 127.0.0.9): past its sender's rate a packet is
    counted and not decoded, and the other sender's GO is read and carried out."""
    decodes = _decodes(monkeypatch)
    live = Live(StopRequest(), wait_start=True, now=clock.now)
    heard = Heard()
    live.subscribe(heard)
    server = OscServer(live, 0, now=clock.now)  # not listening: its packets are handed to it
    flood = 1000
    for n in range(flood):
        server.packet("udp", ("127.0.0.2", 40000 + n % 7), message("/choreo/go"))
    assert decodes[0] == LIMITS.packets_per_sender.burst
    assert server.packet("udp", ("127.0.0.9", 53000), message("/choreo/start"))  # answered
    live.close()
    assert heard.messages("start") == ["starting"]
    unread = flood - LIMITS.packets_per_sender.burst
    assert server.counts["unread"] == unread
    assert _told(heard, "unread") == unread and _told(heard, "go") == LIMITS.packets_per_sender.burst


def test_refused_senders_of_many_addresses_cannot_take_an_allowed_senders_packets(clock, monkeypatch):
    """Forged senders of 300 addresses (more than the senders tracked one by one) share one
    budget of packets read: an allowed sender that speaks after them is still read."""
    decodes = _decodes(monkeypatch)
    live = Live(StopRequest(), wait_start=True, now=clock.now)
    heard = Heard()
    live.subscribe(heard)
    server = OscServer(live, 0, host="0.0.0.0", now=clock.now)
    for n in range(300 * 20):
        server.packet("udp", (f"10.9.{n % 300 // 250}.{n % 300 % 250 + 1}", 5000), message("/choreo/panic"))
    assert server.packet("udp", ("127.0.0.9", 53000), message("/choreo/start"))
    live.close()
    assert not live.stop()
    assert heard.messages("start") == ["starting"]
    assert decodes[0] == 1  # a refused sender's packet is never decoded, read or not
    assert _told(heard, "refused") == 300 * 20  # every one counted


def test_a_tcp_sender_over_its_rate_rests_unread_and_another_go_gets_through(server, heard):
    """Eight connections from one address, each sending GOs as fast as TCP takes them, once
    made every select round cost ~100 ms of frames read and counted (a GO from another address
    waited up to 166 ms, choreo used 65% of a core): past its rate a TCP sender is not read for
    a while, its bytes held by TCP's own flow control."""
    sent = 5000
    flooder = Peer("tcp", server.port, host="127.0.0.2")
    other = Peer("tcp", server.port, host="127.0.0.9")
    try:
        flooder.sock.sendall(slip(message("/choreo/go")) * sent)
        assert wait_for(lambda: server.counts["unread"] > 0, TIMEOUT_S, every=0.005)
        other.send(message("/choreo/start"))
        assert wait_for(lambda: "start" in heard.names(), TIMEOUT_S, every=0.005)
        time.sleep(0.3)  # long enough to read the rest, were it read
        handled = server.counts["unread"] + heard.names().count("go")
    finally:
        flooder.close()
        other.close()
    assert heard.messages("start") == ["starting"]
    assert handled < sent / 2  # what the reads before its rest held, not the whole flood


def test_a_udp_flood_in_a_senders_name_does_not_spend_its_tcp_budgets(clock):
    """A UDP sender's address can be forged (an allowed one too: QLab's): a flood of datagrams
    in its name spent the budgets its own TCP connection, whose address the handshake proves,
    needed for its GO. Over TCP a sender has budgets of its own."""
    live = Live(StopRequest(), wait_start=True, now=clock.now)
    heard = Heard()
    live.subscribe(heard)
    server = OscServer(live, 0, now=clock.now)
    for _ in range(500):
        server.packet("udp", ("127.0.0.2", 9), bundle("/choreo/go", 4))
    replies = server.packet("tcp", ("127.0.0.2", 53000), message("/choreo/start"))
    live.close()
    assert len(replies) == 1 and heard.messages("start") == ["starting"]


def test_a_bundles_messages_are_read_within_the_senders_budget_of_packets(clock):
    """One bundle of 200 unknown addresses cost 7.5 ms to read, answer and count, and a sender
    could have 64 such packets read at once: half a second of the thread that reads the
    operator's GO. Each message of a bundle now spends the sender's budget of packets as if it
    came alone; the rest are counted, not read."""
    live = Live(StopRequest(), wait_start=True, now=clock.now, limits=EVERY_EVENT)
    heard = Heard()
    live.subscribe(heard)
    server = OscServer(live, 0, now=clock.now)
    for _ in range(3):
        server.packet("udp", ("127.0.0.2", 9), bundle("/x", 200))
    live.close()
    burst = LIMITS.packets_per_sender.burst
    assert heard.names().count("unknown") == burst
    assert server.counts["unread"] == 2 * 200 - burst + 1  # the second bundle's rest, and the third whole


def test_a_big_packet_spends_more_of_its_senders_budget(clock, monkeypatch):
    """Reading is by the byte: 256 packets of 60 KB at once held the thread that reads the
    operator's GO for seconds. A packet spends a token per 4 KB begun."""
    from choreo.live.osclimits import LIMITS as WIRE

    decodes = _decodes(monkeypatch)
    live = Live(StopRequest(), wait_start=True, now=clock.now)
    server = OscServer(live, 0, now=clock.now)
    big = message("/x" + "x" * 60_000)
    cost = 1 + (len(big) - 1) // WIRE.packet_bytes_per_token
    for _ in range(100):
        server.packet("udp", ("127.0.0.2", 9), big)
    assert decodes[0] == LIMITS.packets_per_sender.burst // cost
    assert server.counts["unread"] == 100 - decodes[0]
