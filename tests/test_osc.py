"""OSC control (`choreo.live.osc`), driven with python-osc's own clients over UDP and TCP (SLIP): every
command and its QLab-style reply, unknown commands, refused senders, notifications, a port in
use, and one run through the CLI.

Shows run in real time on the in-process simulator, in a thread, as `choreo run` runs them; the
OSC server listens on a port the OS chose. Nothing sleeps: replies and notifications are waited
for with a deadline.
"""

from __future__ import annotations

import json
import socket
import subprocess
import threading
import time
from pathlib import Path

import pytest
from pythonosc.dispatcher import Dispatcher
from pythonosc.osc_server import BlockingOSCUDPServer
from pythonosc.tcp_client import SimpleTCPClient
from pythonosc.udp_client import SimpleUDPClient

from choreo.errors import UsageError
from choreo.live.controls import Live
from choreo.log.format import ERROR, WARNING
from choreo.live.limits import LIMITS, Budget
from choreo.live.oscwire import encode_message, slip_encode
from choreo.live.osc import OscServer, command_for, parse_allow, sender_allowed
from choreo.events import PANIC, StopRequest
from runlog import LiveRun, ended_if_left, read_log, start_choreo, wait_for, write_show

GO_SHOW = """\
    version: 1
    motions:
      bow: {number: 2, duration: 0.05}
    steps:
      - play: 1
      - play: bow
        at: go
        label: applause
      - play: 3
        at: go
        label: encore
    """
ONE_GO_SHOW = GO_SHOW.replace("        label: encore\n", "").replace("      - play: 3\n        at: go\n", "")
TIMEOUT_S = 5.0
# a state polled for (a run at its cue, a notification in): long enough for a run's start on a
# loaded machine; a poll returns as soon as the state holds, so only a failure waits this long
POLL_S = 30.0


def wait_until(predicate, timeout: float = POLL_S) -> None:  # type: ignore[no-untyped-def]
    assert wait_for(predicate, timeout, every=0.002), "timed out"


class Commands:
    """A command listener keeping every event (what the log would record)."""

    def __init__(self) -> None:
        self.events: list = []

    def on_command(self, event) -> None:  # type: ignore[no-untyped-def]
        self.events.append(event)

    def seen(self) -> list[tuple]:
        return [(e.command.name, e.command.source, e.command.label, e.answer.status) for e in self.events]


def serve(live: Live, **options) -> OscServer:  # type: ignore[no-untyped-def]
    server = OscServer(live, 0, **options)
    server.start()
    live.subscribe(server)
    return server


def client(transport: str, port: int, host: str = "127.0.0.1"):  # type: ignore[no-untyped-def]
    if transport == "udp":
        return SimpleUDPClient(host, port)
    return SimpleTCPClient(host, port, timeout=TIMEOUT_S)


def ask(osc, address: str, *args) -> tuple[str, dict]:  # type: ignore[no-untyped-def]
    """Send one message, wait for its reply: (reply address, its JSON)."""
    osc.send_message(address, list(args))
    reply = next(osc.get_messages(TIMEOUT_S), None)
    assert reply is not None, f"no reply to {address}"
    assert len(reply.params) == 1
    return reply.address, json.loads(reply.params[0])


def source_of(osc, transport: str) -> str:  # type: ignore[no-untyped-def]
    """How the server names this client: an unbound UDP socket's source is the address it sends
    to (all of them are this machine's)."""
    sock = osc._sock if transport == "udp" else osc.socket
    host, port = sock.getsockname()[:2]
    if host == "0.0.0.0":
        host = osc._address
    return f"osc {transport} {host}:{port}"


class ShowRun(LiveRun):
    """A show playing in a thread with a Live and an OscServer, wired as `choreo run` wires them."""

    def __init__(self, tmp_path: Path, body: str = GO_SHOW, *, wait_start: bool = False, opening: bool = False,
                 **options) -> None:  # type: ignore[no-untyped-def]
        super().__init__(tmp_path, body, wait_start=wait_start, lockout_s=0.0, cues=True, opening=opening,
                         attach=lambda live: [self._serve(live, options)])

    def _serve(self, live: Live, options: dict) -> OscServer:
        self.server = serve(live, **options)
        return self.server

    def waiting(self) -> list[str]:
        return [cue.name for cue in self.live.waiting]

    def join(self) -> None:
        self.thread.join(TIMEOUT_S * 2)
        assert not self.thread.is_alive()
        assert self.error is None

    def close(self) -> None:
        self.server.close()

    def finish(self) -> None:
        self.join()
        self.close()


@pytest.fixture
def shows(tmp_path):  # type: ignore[no-untyped-def]
    """ShowRun(...) for a test; one the test left running (it failed) is stopped and closed."""
    started: list[ShowRun] = []

    def start(body: str = GO_SHOW, **options) -> ShowRun:  # type: ignore[no-untyped-def]
        started.append(ShowRun(tmp_path, body, **options))
        return started[-1]

    yield start
    for run in started:
        run.live.stop.request()
        run.thread.join(TIMEOUT_S)
        run.close()


@pytest.fixture
def live():  # type: ignore[no-untyped-def]
    return Live(StopRequest(), wait_start=True, lockout_s=0.0)


@pytest.fixture
def server(live):  # type: ignore[no-untyped-def]
    server = serve(live)
    yield server
    server.close()


# -- every command and its reply ---------------------------------------------------------------


@pytest.mark.parametrize("transport", ["udp", "tcp"])
def test_every_command_is_answered_in_qlabs_manner(transport, live, server):
    commands = Commands()
    live.subscribe(commands)
    with client(transport, server.port) as osc:
        address, go = ask(osc, "/choreo/go")
        assert address == "/reply/choreo/go"
        # a show loaded with --wait-start starts only on /choreo/start: a GO meant for a cue must not start it
        assert go == {"address": "/choreo/go", "status": "error", "data": {},
                      "message": "nothing waits for GO now (the show waits for its start: /choreo/start)"}
        _, cue = ask(osc, "/choreo/cue/encore/go")
        assert cue["status"] == "error" and cue["message"].startswith("cue 'encore' is not waiting for GO")
        assert ask(osc, "/choreo/start") == ("/reply/choreo/start", {
            "address": "/choreo/start", "status": "ok", "message": "starting", "data": {}})
        assert ask(osc, "/choreo/start")[1]["message"] == "the show has started already"
        assert ask(osc, "/choreo/stop")[1]["status"] == "ok"
        assert ask(osc, "/choreo/stop")[1] == {"address": "/choreo/stop", "status": "error", "data": {},
                                               "message": "refused: the show is stopping (stopped)"}
        assert ask(osc, "/choreo/panic")[1]["status"] == "error"  # a stop under way is not changed
        source = source_of(osc, transport)
    assert not live.panicked and live.stop.reason == "stopped"
    assert commands.seen() == [("go", source, None, "error"), ("cue_go", source, "encore", "error"),
                               ("start", source, None, "ok"), ("start", source, None, "error"),
                               ("stop", source, None, "ok"), ("stop", source, None, "error"),
                               ("panic", source, None, "error")]


@pytest.mark.parametrize("transport", ["udp", "tcp"])
def test_an_unknown_command_is_answered_with_an_error_and_logged(transport, live, server):
    commands = Commands()
    live.subscribe(commands)
    with client(transport, server.port) as osc:
        _, typo = ask(osc, "/choreo/stpo")  # a typo is never answered with a command that acts on stage
        assert typo == {"address": "/choreo/stpo", "status": "error", "data": {},
                        "message": "unknown command /choreo/stpo (choreo takes /choreo/ followed by go, panic, "
                                   "start, stop, pause, resume, skip, playhead/next|previous|CUE, cue/CUE/go, "
                                   "status, thump, updates)"}
        address, qlab = ask(osc, "/cue/1/go")
        assert address == "/reply/cue/1/go"
        assert qlab["message"] == "unknown command /cue/1/go: did you mean '/choreo/cue/1/go'?"
        _, other = ask(osc, "/workspace/x/thump")
        assert other["message"] == "unknown command /workspace/x/thump: did you mean '/choreo/thump'?"
        # a pattern is not expanded: it could reach GO and panic at once
        _, pattern = ask(osc, "/choreo/*")
        assert pattern["status"] == "error" and "address patterns are not taken" in pattern["message"]
        source = source_of(osc, transport)
    assert not live.stop() and not live.panicked
    assert commands.seen() == [("unknown", source, address, "error") for address in
                               ("/choreo/stpo", "/cue/1/go", "/workspace/x/thump", "/choreo/*")]


def test_a_buttons_release_is_not_a_second_command(live, server):
    """TouchOSC sends 1 on press and 0 on release: the release must not be a second GO."""
    commands = Commands()
    live.subscribe(commands)
    with client("udp", server.port) as osc:
        assert ask(osc, "/choreo/start", 1.0)[1]["status"] == "ok"
        release = ask(osc, "/choreo/start", 0.0)[1]
        assert release["status"] == "ok" and release["data"] == {"ignored": True}
    assert [name for name, *_ in commands.seen()] == ["start"]


def test_the_addresses():
    assert command_for("/choreo/go") == ("go", None)
    assert command_for("/choreo/cue/applause/go") == ("cue_go", "applause")
    assert command_for("/choreo/cue/a b/go") == ("cue_go", "a b")
    assert command_for("/choreo/cue/a%2Fb/go") == ("cue_go", "a/b")
    assert command_for("/choreo/playhead/next") == ("playhead_next", None)
    assert command_for("/choreo/playhead/%6Eext") == ("playhead", "next")  # a cue labelled so, escaped
    for address in ("/choreo/cue//go", "/choreo/cue/a/b/go", "/choreo/cue/go", "/go", "/choreo/go/",
                    "/choreo/status", "/choreo/thump", "/choreo/updates", "/choreo/playhead/", "/choreo/playhead/a/b"):
        assert command_for(address) is None


# -- a show commanded over OSC -----------------------------------------------------------------


def test_go_releases_the_waiting_cue_and_the_show_goes_on(shows):
    run = shows()
    with client("tcp", run.server.port) as tcp, client("udp", run.server.port) as udp:
        wait_until(lambda: run.waiting() == ["applause"])
        _, first = ask(tcp, "/choreo/cue/applause/go")
        assert first["status"] == "ok" and first["message"] == "GO: cue 1 'applause'"
        assert first["data"]["cue"] == "1" and first["data"]["label"] == "applause"
        wait_until(lambda: run.waiting() == ["encore"])
        _, second = ask(udp, "/choreo/go")
        assert second["status"] == "ok" and (second["data"]["cue"], second["data"]["label"]) == ("2", "encore")
        sources = [source_of(tcp, "tcp"), source_of(udp, "udp")]
    run.finish()
    assert run.result.outcome == "done" and run.result.steps_run == 3
    log = read_log(run.log_path)
    commands = [(m["command"], m["source"], m["status"], m.get("label"), m.get("cue"))
                for m in log.topic("/choreo/command")]
    # the cue as sent (cue_go; none for go), and the number of the one fired
    assert commands == [("cue_go", sources[0], "ok", "applause", "1"), ("go", sources[1], "ok", None, "2")]


def test_start_begins_a_show_loaded_with_wait_start(shows):
    run = shows(GO_SHOW.replace("        at: go\n", ""), wait_start=True)
    with client("udp", run.server.port) as osc:
        assert ask(osc, "/choreo/cue/x/go")[1]["status"] == "error"
        assert run.result is None
        assert ask(osc, "/choreo/start")[1]["status"] == "ok"
    run.finish()
    assert run.result.outcome == "done" and run.result.steps_run == 3


@pytest.mark.parametrize("command", ["stop", "panic"])
def test_stop_and_panic_end_a_waiting_show(shows, command):
    run = shows()
    with client("udp", run.server.port) as osc:
        wait_until(lambda: run.waiting() == ["applause"])
        assert ask(osc, f"/choreo/{command}")[1]["status"] == "ok"
    run.finish()
    assert run.result.outcome == "aborted"
    assert run.live.stop.reason == (PANIC if command == "panic" else "stopped")


# -- notifications -----------------------------------------------------------------------------


class Receiver:
    """What QLab (or a logger) would receive on --osc-notify's port: python-osc's own UDP server,
    one that handles the datagrams one by one as they came (its threading server handed each one
    to a thread of its own: a test that saw the last notification could miss one sent before it,
    its thread not yet run on a loaded machine)."""

    def __init__(self) -> None:
        self.messages: list[tuple] = []
        dispatcher = Dispatcher()
        dispatcher.map("/choreo/notify/*", lambda address, *args: self.messages.append((address, *args)))
        self.server = BlockingOSCUDPServer(("127.0.0.1", 0), dispatcher)
        self.address = ("127.0.0.1", self.server.server_address[1])
        threading.Thread(target=self.server.serve_forever, args=(0.05,), daemon=True).start()

    def of(self, kind: str) -> list[tuple]:
        return [m[1:] for m in self.messages if m[0] == f"/choreo/notify/{kind}"]

    def close(self) -> None:
        self.server.shutdown()
        self.server.server_close()


@pytest.fixture
def receiver():  # type: ignore[no-untyped-def]
    receiver = Receiver()
    yield receiver
    receiver.close()


def test_the_shows_progress_is_notified(shows, receiver):
    run = shows(notify=[receiver.address])
    assert run.server.listening.endswith(f"; progress to 127.0.0.1:{receiver.address[1]}")
    with client("udp", run.server.port) as osc:
        wait_until(lambda: receiver.of("go"))  # announced as the show reaches it, before any GO
        assert receiver.of("go")[0][:2] == ("applause", 1)
        ask(osc, "/choreo/go")
        wait_until(lambda: [cue[0] for cue in receiver.of("go")] == ["applause", "encore"])
        ask(osc, "/choreo/stop")
        source = source_of(osc, "udp")
    run.join()
    server = run.server
    server.on_log(WARNING, "a warning")
    server.on_log(ERROR, "a fault")
    server.on_log(2, "an info line is not sent")
    server.on_result(run.result)
    wait_until(lambda: receiver.of("done"))
    run.close()
    steps = receiver.of("step")  # robot, index, label, event, show_s, outcome
    assert steps[0][:4] == ("", 0, "", "start") and steps[1][:4] == ("", 0, "", "end") and steps[1][5] == "ok"
    assert [s[:4] for s in steps if s[1] == 1] == [("", 1, "applause", "start"), ("", 1, "applause", "end")]
    assert ("go", source, "ok", "GO: cue 1 'applause'", "") in receiver.of("command")
    stop = ("stop", source, "ok", "stopping: the exchange in flight, then the abort motion", "")
    assert stop in receiver.of("command")
    assert any(w[0].startswith("show stopped at") for w in receiver.of("warning"))  # the runner's own
    assert ("a warning",) in receiver.of("warning") and receiver.of("fault") == [("a fault",)]
    result = run.result  # (its late steps are the machine's pace: the notification says the same number)
    assert receiver.of("done") == [("aborted", 2, result.late_steps, pytest.approx(result.show_s, abs=1e-5))]


def test_a_notify_address_that_does_not_resolve_is_a_usage_error(live):
    server = OscServer(live, 0, notify=[("no-such-host.invalid", 53001)])
    with pytest.raises(UsageError, match=r"^--osc-notify no-such-host.invalid:53001: "):
        server.start()
    server.close()


# -- who may command the show ------------------------------------------------------------------


def outside_address() -> str | None:
    """This machine's address on its network (not loopback), if it has one."""
    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as probe:
        try:
            probe.connect(("10.255.255.255", 9))  # no packet is sent: only a route is chosen
            host = probe.getsockname()[0]
        except OSError:
            return None
    return None if host.startswith("127.") or host == "0.0.0.0" else host


@pytest.mark.parametrize("transport", ["udp", "tcp"])
def test_a_sender_from_elsewhere_is_refused_unless_allowed(transport, live):
    host = outside_address()
    if host is None:
        pytest.skip("this machine has no address but loopback")
    commands = Commands()
    live.subscribe(commands)
    server = serve(live, host="0.0.0.0")
    assert server.listening == (f"osc: listening on 0.0.0.0:{server.port} (udp and tcp), "
                                "commands from this machine only")
    why = f"refused: {host} may not command this show (give --osc-allow {host} to let it)"
    try:
        if transport == "udp":  # sent to our own outside address: it comes from there
            with client(transport, server.port, host) as osc:
                address, refused = ask(osc, "/choreo/start")
                source = source_of(osc, transport)
            # the sender is checked before its packet is read: the reply cannot name the command
            assert (address, refused) == ("/reply", {"address": "", "status": "denied", "data": {}, "message": why})
        else:  # closed at accept, before a byte is read; the refusal is logged
            with socket.create_connection((host, server.port), timeout=TIMEOUT_S) as sock:
                source = f"osc tcp {host}:{sock.getsockname()[1]}"
                sock.sendall(slip_encode(encode_message("/choreo/start")))
                assert read_to_end(sock) == b""
    finally:
        server.close()
    assert commands.seen() == [("refused", source, None, "denied")]

    allowed = serve(live, host="0.0.0.0", allow=[host])
    try:
        with client(transport, allowed.port, host) as osc:
            assert ask(osc, "/choreo/start")[1]["status"] == "ok"  # the refused one did not start it
    finally:
        allowed.close()


def read_to_end(sock: socket.socket) -> bytes:
    """What a peer sends until it closes (a reset counts as closed)."""
    data = b""
    try:
        while chunk := sock.recv(4096):
            data += chunk
    except ConnectionResetError:
        pass
    return data


def test_a_dual_stack_server_names_an_ipv4_sender_as_ipv4(live):
    if not socket.has_ipv6:
        pytest.skip("no IPv6")
    commands = Commands()
    live.subscribe(commands)
    try:
        server = serve(live, host="::")
    except UsageError as exc:
        pytest.skip(str(exc))
    try:
        with client("udp", server.port) as osc:
            assert ask(osc, "/choreo/start")[1]["status"] == "ok"
            source = source_of(osc, "udp")
    finally:
        server.close()
    assert commands.seen() == [("start", source, None, "ok")]
    assert server.listening.startswith(f"osc: listening on [::]:{server.port} ")


def test_the_allow_check():
    allow = parse_allow(["10.0.0.0/24", "192.168.1.20", "fd00::/8"])
    for host in ("127.0.0.1", "127.3.4.5", "::1", "::ffff:127.0.0.1", "10.0.0.77", "192.168.1.20",
                 "::ffff:10.0.0.1", "fd00::2"):
        assert sender_allowed(host, allow), host
    for host in ("10.0.1.1", "192.168.1.21", "fe80::1%eth0", "8.8.8.8", "", "localhost"):
        assert not sender_allowed(host, allow), host
    assert not sender_allowed("192.168.1.20")  # loopback only by default
    with pytest.raises(UsageError, match=r"^--osc-allow qlab.local: give an IP address"):
        parse_allow(["qlab.local"])


def test_refusals_are_answered_and_logged_within_a_budget():
    """A forged UDP sender must not make the server a reflector, nor fill the log."""
    now = [0.0]
    budget = Budget(burst=3, per_s=1.0, now=lambda: now[0])
    assert [budget.take() for _ in range(5)] == [True, True, True, False, False]
    now[0] = 1.0
    assert budget.take() is True and budget.take() is False


def test_the_start_up_line_says_who_may_command(live):
    server = OscServer(live, 53000, allow=["192.168.1.20"])
    assert server.listening == ("osc: listening on 127.0.0.1:53000 (udp and tcp), commands from this machine "
                                "and 192.168.1.20 (but 127.0.0.1 is reachable from this machine only: give "
                                "--osc-host 0.0.0.0)")


# -- transports --------------------------------------------------------------------------------


def test_a_tcp_message_cut_in_pieces_and_end_terminated_is_answered(live, server):
    from pythonosc.osc_message_builder import build_msg

    packet = build_msg("/choreo/start", []).dgram
    with socket.create_connection(("127.0.0.1", server.port), timeout=TIMEOUT_S) as sock:
        sock.sendall(packet[:5])
        time.sleep(0.01)  # a second segment
        sock.sendall(packet[5:] + b"\xc0")
        reply = b""
        while not reply.endswith(b"\xc0") or len(reply) < 2:
            reply += sock.recv(4096)
    assert b"/reply/choreo/start" in reply and b'"status": "ok"' in reply


def test_a_port_in_use_is_a_usage_error(live):
    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as taken:
        taken.bind(("127.0.0.1", 0))
        port = taken.getsockname()[1]
        with pytest.raises(UsageError) as caught:
            OscServer(live, port).start()
    assert str(caught.value) == (f"--osc {port}: cannot listen on 127.0.0.1:{port}: Address already in use "
                                 "(another program listens there: choose another port)")
    with socket.socket(socket.AF_INET, socket.SOCK_STREAM) as taken:
        taken.bind(("127.0.0.1", 0))
        taken.listen()
        port = taken.getsockname()[1]
        with pytest.raises(UsageError, match=rf"^--osc {port}: cannot listen on 127.0.0.1:{port} \(tcp\): "):
            OscServer(live, port).start()
        with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as udp:
            udp.bind(("127.0.0.1", port))  # the UDP half was let go


def test_close_ends_open_connections_and_can_be_called_twice(live):
    server = serve(live)
    with client("tcp", server.port) as osc:
        assert ask(osc, "/choreo/start")[1]["status"] == "ok"
        server.close()
        assert osc.socket.recv(10) == b""  # the connection was closed
    server.close()


# -- through the CLI ---------------------------------------------------------------------------


def free_port() -> int:
    """A port number free for both UDP and TCP right now."""
    while True:
        with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as udp, \
                socket.socket(socket.AF_INET, socket.SOCK_STREAM) as tcp:
            udp.bind(("127.0.0.1", 0))
            port = udp.getsockname()[1]
            try:
                tcp.bind(("127.0.0.1", port))
            except OSError:
                continue
            return port


def go_when_waiting(osc, process: subprocess.Popen) -> None:  # type: ignore[no-untyped-def]
    """A GO sent until one is taken (choreo listens, and its show has reached the GO cue), no
    faster than the sender's budget of commands refills: sent as fast as refusals came back, the
    GOs of a run a loaded machine took 0.6 s to bring from listening to its cue spent that
    budget, and the GOs past it were ignored as a flood (logged so) or their replies not sent."""
    every_s = 1 / LIMITS.commands_per_sender.per_s
    deadline = time.monotonic() + POLL_S
    while True:
        assert time.monotonic() < deadline and process.poll() is None, "no GO taken"
        sent = time.monotonic()
        osc.send_message("/choreo/go", [])
        reply = next(osc.get_messages(every_s), None)
        if reply is not None and json.loads(reply.params[0])["status"] == "ok":
            return
        time.sleep(max(0.0, sent + every_s - time.monotonic()))


def test_choreo_run_takes_go_over_osc(tmp_path):
    show = write_show(tmp_path, ONE_GO_SHOW)
    log_path = tmp_path / "run.mcap"
    port = free_port()
    process = start_choreo("run", str(show), "--osc", str(port), "--log", str(log_path))
    with ended_if_left(process):
        with client("udp", port) as osc:
            go_when_waiting(osc, process)
            source = source_of(osc, "udp")
        _, err = process.communicate(timeout=30)
    assert process.returncode == 0, err
    assert f"osc: listening on 127.0.0.1:{port} (udp and tcp), commands from this machine only" in err
    commands = read_log(log_path).topic("/choreo/command")
    taken = {"command": "go", "source": source, "status": "ok", "message": "GO: cue 1 'applause'"}
    gos = [m for m in commands if m["command"] == "go"]  # (refusals past the log's limit are summed up)
    assert taken.items() <= gos[-1].items()
    assert all(m["message"].startswith("nothing waits for GO now") for m in gos[:-1])
