"""OSC control of a running show, in QLab's manner, so that a QLab Network cue (or TouchOSC, Max,
a lighting desk) can give the GO: `/choreo/go`, `/choreo/panic`, `/choreo/start`, `/choreo/stop`
and `/choreo/cue/LABEL/go`, over UDP and over TCP framed with SLIP (OSC 1.1, as QLab sends it),
on one port number.

Every message is answered to its sender as QLab answers: `/reply` + the address, with one JSON
string `{"address", "status": ok|error|denied, "message", "data"}`; the commands themselves are
carried out by `choreo.live.Live`, exactly as the console's keys are, so both are answered and
logged alike. With a notify address, the show's progress goes out as OSC too (steps, GO cues
waiting, commands, warnings and faults) from a thread of its own: a slow or absent receiver
never holds a runner.

Who may command the show: this machine (loopback), and the addresses given with --osc-allow.
A refused sender still gets a `denied` reply, because the operator setting up a desk on another
machine needs to see why nothing happens, and a TCP peer's address is proven by its handshake.
A UDP sender's address is not (it can be forged to make us send replies to a victim, and a
flood of refusals would fill the log, which stops the show when it cannot take more), so
refusals are answered and logged only within a small budget shared by every refused sender
(`REFUSALS_BURST`, then `REFUSALS_PER_S`); the rest are dropped and counted in the next line.

OSC address patterns (`/choreo/*`) are not expanded: a pattern could match GO and panic at once,
which no operator means; a command is taken only at its own address.
"""

from __future__ import annotations

import errno
import ipaddress
import json
import queue
import socket
import socketserver
import threading
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Any

from pythonosc import osc_server, osc_tcp_server, slip
from pythonosc.dispatcher import Dispatcher
from pythonosc.osc_message_builder import build_msg

from choreo.errors import UsageError, did_you_mean
from choreo.live import Answer, Command, CommandEvent, GoCue, Live
from choreo.logformat import ERROR, WARNING

if TYPE_CHECKING:
    from choreo.runner import RunResult, StepEvent

# OSC addresses, not log topics (those are spelled in choreo.logformat), though both start /choreo
ROOT = "/choreo"
COMMANDS = {f"{ROOT}/{name}": name for name in ("go", "panic", "start", "stop")}
CUE_PREFIX, CUE_SUFFIX = f"{ROOT}/cue/", "/go"
NOTIFY = f"{ROOT}/notify"
PATTERN_CHARS = frozenset("*?[]{}")
REFUSALS_BURST, REFUSALS_PER_S = 10, 1.0
SERVE_POLL_S = 0.1  # how soon `close` stops the servers (a message wakes them at once anyway)
MAX_FRAME = 64 * 1024  # a SLIP stream this long without an END is not OSC: the connection is closed

Network = ipaddress.IPv4Network | ipaddress.IPv6Network
Sender = tuple  # (host, port) or, over IPv6, (host, port, flowinfo, scope)


@dataclass(frozen=True)
class Reply:
    """The answer to one OSC message, in QLab's form (its `workspace_id` has no counterpart
    here, and `message` is ours: the same line the console shows)."""

    address: str
    status: str  # ok | error | denied
    message: str = ""
    data: dict = field(default_factory=dict)

    def osc(self) -> tuple[str, str]:
        """(address, JSON argument): what a python-osc handler returns to have it sent back."""
        body = {"address": self.address, "status": self.status, "message": self.message, "data": self.data}
        return "/reply" + self.address, json.dumps(body, ensure_ascii=False)


def command_for(address: str) -> tuple[str, str | None] | None:
    """The `Live` command an address names and its cue label, or None: not one of ours."""
    if address in COMMANDS:
        return COMMANDS[address], None
    if address.startswith(CUE_PREFIX) and address.endswith(CUE_SUFFIX):
        label = address[len(CUE_PREFIX):-len(CUE_SUFFIX)]
        if label and "/" not in label:
            return "cue_go", label
    return None


def unknown_message(address: str) -> str:
    """Why an address is refused, with the nearest command when there is one."""
    if PATTERN_CHARS & set(address):
        return f"unknown command {address}: address patterns are not taken; send the command's own address"
    if address.startswith("/") and command_for(ROOT + address) is not None:  # QLab's /go, /cue/1/go
        hint = f": did you mean '{ROOT}{address}'?"
    else:
        hint = did_you_mean(address, COMMANDS)
    known = ", ".join([*COMMANDS, CUE_PREFIX + "LABEL" + CUE_SUFFIX])
    return f"unknown command {address}{hint or f' (choreo takes {known})'}"


def is_release(args: Sequence[Any]) -> bool:
    """A button's release: TouchOSC and many desks send 1 on press and 0 on release, and a
    release taken as a second GO would skip a cue."""
    return len(args) == 1 and not isinstance(args[0], str) and args[0] in (0, 0.0, False)


def parse_allow(values: Sequence[str]) -> tuple[Network, ...]:
    """--osc-allow's addresses (or networks, 192.168.1.0/24); UsageError on anything else."""
    networks = []
    for value in values:
        try:
            networks.append(ipaddress.ip_network(value.strip(), strict=False))
        except ValueError:
            raise UsageError(f"--osc-allow {value}: give an IP address (192.168.1.20) or a network "
                             "(192.168.1.0/24)") from None
    return tuple(networks)


def sender_allowed(host: str, allow: Sequence[Network] = ()) -> bool:
    """This machine (loopback) or an allowed address."""
    try:
        ip = ipaddress.ip_address(plain_host(host))
    except ValueError:
        return False
    return ip.is_loopback or any(ip in network for network in allow)


def plain_host(host: str) -> str:
    """An IPv4 sender as IPv4 also when a dual-stack socket (`--osc-host ::`) names it as an
    IPv4-mapped IPv6 address (`::ffff:10.0.0.5`), as --osc-allow would be given it."""
    try:
        ip = ipaddress.ip_address(host)
    except ValueError:
        return host
    mapped = ip.ipv4_mapped if isinstance(ip, ipaddress.IPv6Address) else None
    return str(mapped) if mapped is not None else host


def where(sender: Sender) -> str:
    """`127.0.0.1:53001`, `[::1]:53001`: how messages and the log name a sender or an address."""
    host, port = plain_host(sender[0]), sender[1]
    return f"[{host}]:{port}" if ":" in host else f"{host}:{port}"


class Budget:
    """A token bucket: `burst` at once, then `per_s` a second. `take` returns how many were
    refused since the last one taken (None: over budget now)."""

    def __init__(self, burst: int = REFUSALS_BURST, per_s: float = REFUSALS_PER_S,
                 now: Callable[[], float] = time.monotonic) -> None:
        self.burst = burst
        self.per_s = per_s
        self._now = now
        self._tokens = float(burst)
        self._at = now()
        self._skipped = 0
        self._lock = threading.Lock()

    def take(self) -> int | None:
        with self._lock:
            now = self._now()
            self._tokens = min(float(self.burst), self._tokens + (now - self._at) * self.per_s)
            self._at = now
            if self._tokens < 1.0:
                self._skipped += 1
                return None
            self._tokens -= 1.0
            skipped, self._skipped = self._skipped, 0
            return skipped


class SlipStream:
    """OSC packets out of a TCP byte stream framed with SLIP (RFC 1055): double-END framing as
    QLab and OSC 1.1 send it, and END-terminated frames too. A malformed frame is dropped, not
    the connection; a stream without an END for `MAX_FRAME` bytes is not OSC (ValueError)."""

    def __init__(self) -> None:
        self._buffer = b""

    def feed(self, data: bytes) -> list[bytes]:
        *frames, self._buffer = (self._buffer + data).split(slip.END)
        if len(self._buffer) > MAX_FRAME:
            raise ValueError("SLIP frame too long")
        packets = []
        for frame in frames:
            if frame:
                try:
                    packets.append(slip.decode(frame))
                except slip.ProtocolError:
                    continue
        return packets


class _UdpServer(osc_server.BlockingOSCUDPServer):
    """One message at a time, in order of arrival (a GO and a stop keep their order)."""

    def handle_error(self, request: Any, client_address: Any) -> None:
        """socketserver would print a traceback; a bad packet is its sender's problem."""


class _TcpServer(socketserver.ThreadingMixIn, osc_tcp_server.OSCTCPServer):
    """A thread a connection (QLab keeps one open), its packets read by `_SlipConnection`
    rather than python-osc's reader, which takes only double-END frames arriving whole."""

    daemon_threads = True
    allow_reuse_address = True  # a restart right after a run: connections in TIME_WAIT do not block it

    def __init__(self, address: tuple[str, int], dispatcher: Dispatcher) -> None:
        self.connections: set[socket.socket] = set()
        self.connections_lock = threading.Lock()
        super().__init__(address, dispatcher, mode=osc_tcp_server.MODE_1_1)

    def finish_request(self, request: Any, client_address: Any) -> None:
        _SlipConnection(request, client_address, self)

    def handle_error(self, request: Any, client_address: Any) -> None:
        """socketserver would print a traceback; a broken connection is its peer's problem."""

    def close_connections(self) -> None:
        """The peers see the end of the stream; their threads, blocked reading, end."""
        with self.connections_lock:
            connections = list(self.connections)
        for connection in connections:
            try:
                connection.shutdown(socket.SHUT_RDWR)
            except OSError:
                pass


class _SlipConnection(socketserver.BaseRequestHandler):
    """One TCP peer: its packets dispatched as they come, each reply SLIP-framed on the same
    connection."""

    server: _TcpServer

    def handle(self) -> None:
        server, connection = self.server, self.request
        connection.setsockopt(socket.IPPROTO_TCP, socket.TCP_NODELAY, 1)  # a reply is one small write: now
        with server.connections_lock:
            server.connections.add(connection)
        stream = SlipStream()
        try:
            while data := connection.recv(4096):
                for packet in stream.feed(data):
                    for reply in server.dispatcher.call_handlers_for_packet(packet, self.client_address):
                        connection.sendall(slip.encode(build_msg(reply[0], list(reply[1:])).dgram))
        except (OSError, ValueError):
            pass
        finally:
            with server.connections_lock:
                server.connections.discard(connection)


class _Notifier:
    """The show's progress as OSC messages to HOST:PORT (UDP), sent by a thread of its own from
    a queue: the listeners only enqueue, so nothing on a runner's path waits for the network,
    and a message that cannot be sent is dropped."""

    def __init__(self, target: tuple[str, int], live: Live) -> None:
        self.target = target
        self.live = live
        self._queue: queue.SimpleQueue[tuple | None] = queue.SimpleQueue()
        self._socket: socket.socket | None = None
        self._address: Any = None
        self._thread: threading.Thread | None = None

    def start(self) -> None:
        host, port = self.target
        try:
            family, kind, proto, _, address = socket.getaddrinfo(host, port, type=socket.SOCK_DGRAM)[0]
            self._socket = socket.socket(family, kind, proto)
        except OSError as exc:
            raise UsageError(f"--osc-notify {host}:{port}: {exc.strerror or exc}") from None
        self._socket.setblocking(False)
        self._address = address
        self._thread = threading.Thread(target=self._loop, name="choreo-osc-notify", daemon=True)
        self._thread.start()

    def put(self, address: str, *args: Any) -> None:
        self._queue.put((address, args))

    def close(self) -> None:
        if self._thread is not None:
            self._queue.put(None)
            self._thread.join(1.0)
            self._thread = None
        if self._socket is not None:
            self._socket.close()
            self._socket = None

    def _loop(self) -> None:
        while True:
            item = self._queue.get()
            if item is None:
                return
            self._send(*item)

    def _send(self, address: str, args: tuple) -> None:
        try:
            self._socket.sendto(build_msg(address, list(args)).dgram, self._address)  # type: ignore[union-attr]
        except (OSError, ValueError, AttributeError):
            pass  # nobody listening, a full buffer, closed: progress is not worth holding the show


class OscServer:
    """Takes OSC commands for a `Live` on host:port (UDP and TCP), answers each, and (a run and
    command listener) notifies progress; see the module's docstring."""

    def __init__(self, live: Live, port: int, *, host: str = "127.0.0.1", allow: Sequence[str] = (),
                 notify: tuple[str, int] | None = None) -> None:
        self.live = live
        self.host = host
        self.requested_port = port
        self.allow_given = tuple(allow)
        self.allow = parse_allow(allow)
        self.notify = notify
        self._notifier = _Notifier(notify, live) if notify is not None else None
        self._refusals = Budget()
        self._unknowns = Budget()
        self._servers: list[tuple[socketserver.BaseServer, threading.Thread]] = []
        self._port: int | None = None

    # -- serving -----------------------------------------------------------------------------

    @property
    def port(self) -> int:
        """The port it listens on (the one the OS chose, when asked for port 0)."""
        return self._port if self._port is not None else self.requested_port

    def start(self) -> None:
        udp, tcp = self._bind()
        self._port = udp.server_address[1]
        if self._notifier is not None:
            try:
                self._notifier.start()
            except UsageError:
                udp.server_close()
                tcp.server_close()
                raise
        for name, server in (("udp", udp), ("tcp", tcp)):
            thread = threading.Thread(target=server.serve_forever, args=(SERVE_POLL_S,),
                                      name=f"choreo-osc-{name}", daemon=True)
            thread.start()
            self._servers.append((server, thread))

    def _bind(self) -> tuple[_UdpServer, _TcpServer]:
        """UDP and TCP on one port number; with port 0, a number free for both."""
        attempts = 20 if self.requested_port == 0 else 1
        while True:
            attempts -= 1
            udp = self._listen("udp", self.requested_port)
            try:
                return udp, self._listen("tcp", udp.server_address[1])
            except UsageError:
                udp.server_close()
                if attempts == 0:
                    raise

    def _listen(self, transport: str, port: int) -> Any:
        kind = _UdpServer if transport == "udp" else _TcpServer
        try:
            return kind((self.host, port), self._dispatcher(transport))
        except (OSError, OverflowError) as exc:
            why = getattr(exc, "strerror", None) or str(exc)
            if getattr(exc, "errno", None) == errno.EADDRINUSE:
                why += " (another program listens there: choose another port)"
            tcp = " (tcp)" if transport == "tcp" else ""
            raise UsageError(f"--osc {self.requested_port}: cannot listen on {where((self.host, port))}{tcp}: "
                             f"{why}") from None

    def _dispatcher(self, transport: str) -> Dispatcher:
        """Every address goes to `_receive` (no mapping: patterns are not expanded), and a
        bundle's future time tag is not waited for (a sleeping handler would hold the next GO)."""
        dispatcher = Dispatcher(strict_timing=False)

        def receive(sender: Sender, address: str, *args: Any) -> tuple[str, str] | None:
            reply = self._receive(transport, sender, address, args)
            return reply.osc() if reply is not None else None

        dispatcher.set_default_handler(receive, needs_reply_address=True)
        return dispatcher

    def close(self) -> None:
        servers, self._servers = self._servers, []
        # each server notices within SERVE_POLL_S: both told at once, not one after the other
        stopping = [threading.Thread(target=server.shutdown, daemon=True) for server, _ in servers]
        for stopper in stopping:
            stopper.start()
        for stopper in stopping:
            stopper.join()
        for server, thread in servers:
            server.server_close()
            if isinstance(server, _TcpServer):
                server.close_connections()
            thread.join(1.0)
        if self._notifier is not None:
            self._notifier.close()

    @property
    def listening(self) -> str:
        """The start-up line: where, both transports, and who may command the show."""
        others = ", ".join(self.allow_given)
        who = f"commands from this machine and {others}" if others else "commands from this machine only"
        if others and _is_loopback_host(self.host):
            who += f" (but {self.host} is reachable from this machine only: give --osc-host 0.0.0.0)"
        line = f"osc: listening on {where((self.host, self.port))} (udp and tcp/SLIP), {who}"
        if self.notify is not None:
            line += f"; progress to {where(self.notify)}"
        return line

    # -- one message -------------------------------------------------------------------------

    def _receive(self, transport: str, sender: Sender, address: str, args: tuple) -> Reply | None:
        """A message from `sender`: its reply (None: none is sent)."""
        source = f"osc {transport} {where(sender)}"
        if not sender_allowed(sender[0], self.allow):
            return self._refuse(sender, source, address)
        wanted = command_for(address)
        if wanted is None:
            return self._unknown(source, address)
        if is_release(args):
            return Reply(address, "ok", "ignored: a button's release (argument 0) is not a command",
                         {"ignored": True})
        name, label = wanted
        answer = self.live.command(Command(name, source, label))
        return Reply(address, answer.status, answer.message, answer.data)

    def _refuse(self, sender: Sender, source: str, address: str) -> Reply | None:
        skipped = self._refusals.take()
        if skipped is None:
            return None
        host = plain_host(sender[0])
        message = (f"refused: {host} may not command this show (give --osc-allow {host} to let it)"
                   + _more(skipped, "refused"))
        self._report(Command("refused", source, address), Answer("denied", message))
        return Reply(address, "denied", message)

    def _unknown(self, source: str, address: str) -> Reply:
        """Answered always (the sender is trusted); logged within a budget, as a desk that sends
        every fader move would otherwise fill the log."""
        message = unknown_message(address)
        skipped = self._unknowns.take()
        if skipped is not None:
            self._report(Command("unknown", source, address), Answer("error", message + _more(skipped, "unknown")))
        return Reply(address, "error", message)

    def _report(self, command: Command, answer: Answer) -> None:
        """A message `Live.command` has no name for, told to its listeners (the log) as it
        tells them of the commands it carries out."""
        self.live.report(command, answer)

    # -- listening to the show (notifications) -----------------------------------------------

    def on_step(self, event: StepEvent) -> None:
        if self._notifier is not None:
            self._notifier.put(f"{NOTIFY}/step", event.robot or "", event.step.index, event.step.label or "",
                               event.event, round(event.actual_s, 6), event.outcome or "")

    def on_log(self, level: int, message: str, time_ns: int | None = None) -> None:
        if self._notifier is not None and level >= WARNING:
            self._notifier.put(f"{NOTIFY}/fault" if level >= ERROR else f"{NOTIFY}/warning", message)

    def on_waiting(self, cue: GoCue) -> None:
        """The show reached a GO cue (from `Live`, once a cue)."""
        if self._notifier is not None:
            self._notifier.put(f"{NOTIFY}/go", cue.name, cue.step.index, round(cue.reached_s, 6))

    def on_command(self, event: CommandEvent) -> None:
        if self._notifier is not None:
            command, answer = event.command, event.answer
            self._notifier.put(f"{NOTIFY}/command", command.name, command.source, answer.status,
                               answer.message, command.label or "")

    def on_result(self, result: RunResult) -> None:
        """The run is over (`done` or `aborted`): for the caller to tell after `Session.run`."""
        if self._notifier is not None:
            self._notifier.put(f"{NOTIFY}/done", result.outcome, result.steps_run, result.late_steps,
                               round(result.show_s, 6))


def _more(skipped: int, what: str) -> str:
    return f" ({skipped} more {what} not logged)" if skipped else ""


def _is_loopback_host(host: str) -> bool:
    if host == "localhost":
        return True
    try:
        return ipaddress.ip_address(host).is_loopback
    except ValueError:
        return False
