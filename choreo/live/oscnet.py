"""The sockets of OSC control: UDP and TCP on one port number, served by one thread around a
selector, not a thread a connection, so that what a peer sends (or does not send) costs bounded
memory, descriptors and time, and the operator's GO still gets through:

- Who sends is checked first: per datagram (UDP), at accept (TCP: a denied peer is closed before
  a byte of it is read). The packet handler decides; this module only asks.
- TCP connections are capped, in total and per sender address (`OscLimits`). When full, a new
  connection takes the place of the oldest one that has not sent a whole message yet (so idle
  sockets cannot lock out a QLab that connects and speaks); with every place taken by
  connections that speak, of the least lately heard one of the address holding the most (so
  a few addresses cannot lock a new one out either). A sender at its own cap of connections
  that all speak gets no more.
- A connection must send a message the handler takes (a command, a question: not junk, a
  malformed packet or an address nobody takes) within `message_timeout_s` of opening, and
  complete every message within `message_timeout_s` of beginning it (a trickle of bytes does
  not keep it open); one that has sent messages is closed after `idle_timeout_s` without one.
  Junk proves nothing: eight connections from the operator's own machine that each sent one bad
  frame held its places for the idle timeout, and QLab there could not connect over TCP.
  Buffered bytes are bounded by the frame limit.
- Out of descriptors (EMFILE: the process's limit is lower than the caps need), the oldest
  connection that has not sent a message is closed to make room; with none, accepting pauses
  for `ACCEPT_PAUSE_S` instead of spinning on a listener that stays readable.
- A TCP sender over its rate of packets (the handler's `rest_s`) is not read for a while: its
  bytes wait in the network, TCP's own flow control holds the sender, and a flood over TCP
  costs nothing while it rests (read, its frames would cost more than any other peer's turn).
  So does a connection whose read was mostly bytes that frame nothing (a stream of SLIP ENDs
  or zero lengths, which spend no packet: 8 of them cost 60% of a core).
- A reply never blocks the thread: what a peer does not read is queued up to `max_unsent`
  bytes, then the connection is closed; a UDP reply that cannot go at once is dropped.
- Any datagram up to 64 KB is read whole (a smaller buffer would cut it without a word).
- Datagrams the system dropped because they came faster than choreo read them are counted
  where the system says how many (Linux's SO_RXQ_OVFL): the log's counts are what was sent.
- Notifications to subscribed senders (`push`, from the notifier's thread) go out on the UDP
  socket at once, or, for a TCP sender, are handed to the serving thread through a bounded
  outbox (a connection's buffers are that thread's alone); one that would take a connection's
  unsent bytes past `max_unsent` is dropped (counted), not queued: a subscriber that does not
  read loses notifications, never its connection nor anyone's time.
"""

from __future__ import annotations

import contextlib
import errno
import platform
import selectors
import socket
import struct
import sys
import threading
import time
from collections import Counter, deque
from collections.abc import Callable, Iterable
from dataclasses import dataclass, field
from collections.abc import Hashable
from typing import Generic, Protocol, TypeVar

from choreo.live.oscwire import Fed, FrameReader
from choreo.live.osclimits import LIMITS, OscLimits

Sender = tuple  # (host, port) or, over IPv6, (host, port, flowinfo, scope)
ACCEPT_PAUSE_S = 0.1  # out of descriptors: try accepting again this much later
ACCEPT_BATCH = 4  # connections accepted a turn: a peer accepted is read before many more can push it out
UDP_BATCH = 64  # datagrams read a wake-up, then TCP peers get their turn
LISTEN_BACKLOG = 128  # connections the OS holds until accepted (accepting is quick)
RECV_BYTES = 16384  # read at once from a TCP peer
FILLER_REST = (RECV_BYTES // 2, 0.1)  # bytes framing nothing in one read, and the rest they cost (s)
UDP_BUFFER = 65536  # larger than any UDP payload: a datagram is never cut
OUT_OF_DESCRIPTORS = frozenset({errno.EMFILE, errno.ENFILE, errno.ENOBUFS, errno.ENOMEM})
# Linux's SO_RXQ_OVFL (not in Python's socket module): each datagram then carries how many the
# socket has dropped so far. 40 but on PA-RISC and SPARC; elsewhere the drops go uncounted.
OUTBOX = 256  # notifications waiting for the serving thread to queue them to TCP subscribers
SO_RXQ_OVFL = 40 if sys.platform.startswith("linux") and not platform.machine().startswith(("parisc", "sparc")) \
    else None
DROPS_DATA = socket.CMSG_SPACE(4) if hasattr(socket, "CMSG_SPACE") else 0


class ListenFailed(Exception):
    """A port that could not be listened on: which transport, where, and the OS's reason."""

    def __init__(self, transport: str, address: Sender, why: str, in_use: bool = False) -> None:
        super().__init__(why)
        self.transport = transport
        self.address = address
        self.why = why
        self.in_use = in_use


class PacketHandler(Protocol):
    """What the sockets ask and tell their user (`choreo.live.osc.OscServer`); called from the
    serving thread."""

    def admit(self, sender: Sender) -> bool:
        """A TCP connection, at accept: False closes it before it is read."""

    def packet(self, transport: str, sender: Sender, data: bytes) -> Handled:
        """One packet (a datagram, a TCP frame): the encoded replies to send back, and whether
        it spoke (a TCP connection that never does is closed in time)."""

    def dropped(self, transport: str, sender: Sender, why: str) -> None:
        """Something was dropped or closed (a bad frame, a cap, a timeout): to count and tell."""

    def rest_s(self, sender: Sender) -> float:
        """How long a TCP sender's connections are to rest unread (0: not at all)."""

    def lost(self, transport: str, count: int) -> None:
        """`count` datagrams the system dropped before they could be read (a flood)."""

    def closed(self, transport: str, sender: Sender) -> None:
        """A TCP connection ended (either side closed it): what was kept for it goes."""


class Handled(tuple[bytes, ...]):
    """A packet's encoded replies, and whether it `spoke`: carried a message its handler takes
    (a command, a question), as a desk's packets do, not junk, a malformed packet or an address
    nobody takes (which would otherwise hold a TCP connection's place for the idle timeout).
    And whether it was `read`: well-formed OSC, taken or not (a desk proven by a command keeps
    its place while it sends fader moves between its GOs, which junk does not). A tuple:
    `NOTHING`, shared, answers every packet refused unread at no cost. `Read` and `Spoke` are
    the verdicts as classes of their own (fixed when the replies are)."""

    spoke = False
    read = False

    @staticmethod
    def of(replies: Iterable[bytes], spoke: bool, read: bool = False) -> Handled:
        return Spoke(replies) if spoke else Read(replies) if read else Handled(replies)


class Read(Handled):
    read = True


class Spoke(Read):
    spoke = True


NOTHING = Handled()  # no reply, nothing said: a packet refused before it was read


# -- the connections' bookkeeping (pure: times are given) -------------------------------------


@dataclass
class _Slot:
    host: str
    due: float
    opened: float
    proven: bool = False  # has sent a whole message
    spoke: float = 0.0  # when it last sent a whole message
    pending: bool = False  # a message begun


K = TypeVar("K", bound=Hashable)  # what the table's user knows a connection by


class ConnectionTable(Generic[K]):
    """Which TCP connections are open, whose, and when each must have spoken: the caps and
    timeouts as decisions, kept apart from the sockets so they can be tested on a given clock."""

    def __init__(self, limits: OscLimits = LIMITS) -> None:
        self.limits = limits
        self._slots: dict[K, _Slot] = {}

    def __len__(self) -> int:
        return len(self._slots)

    def admit(self, key: K, host: str, now: float) -> tuple[bool, list[K]]:
        """Take a new connection? And the connections to close to make room for it."""
        evict: list[K] = []
        same = [k for k, slot in self._slots.items() if slot.host == host]
        if len(same) >= self.limits.max_per_sender:
            silent = self._silent(same)
            if silent is None:  # the address's places are all taken by connections that speak
                return False, []
            evict.append(silent)
        if len(self._slots) - len(evict) >= self.limits.max_connections:
            others = [k for k in self._slots if k not in evict]
            evict.append(self._silent(others) or self._crowded(others))
        for old in evict:
            del self._slots[old]
        self._slots[key] = _Slot(host, now + self.limits.message_timeout_s, now)
        return True, evict

    def make_room(self) -> K | None:
        """The oldest connection that has not sent a whole message, removed (to be closed: the
        process is out of descriptors), or None."""
        key = self._silent(list(self._slots))
        if key is not None:
            del self._slots[key]
        return key

    def _silent(self, keys: list[K]) -> K | None:
        """The oldest of `keys` that has not sent a whole message, if any."""
        silent = [k for k in keys if not self._slots[k].proven]
        return min(silent, key=lambda k: self._slots[k].opened, default=None)

    def _crowded(self, keys: list[K]) -> K:
        """Of `keys` (all speaking), the one that spoke least lately of the address holding
        the most: when every place is taken by connections that speak, a new address still
        gets in (else a few allowed addresses, each with its share of connections sending
        junk now and then, would keep the operator's QLab out), at the cost of the address
        with the most."""
        held = Counter(self._slots[k].host for k in keys)
        return min(keys, key=lambda k: (-held[self._slots[k].host], self._slots[k].spoke))

    def heard(self, key: K, now: float, *, messages: int, pending: bool, frames: int | None = None,
              read: int = 0) -> None:
        """Bytes came: `frames` whole ones (as many as `messages` unless given), `messages` of
        them messages that speak (see `Handled`), `read` of them well-formed, and a message is
        `pending` (begun) after them. A message begun must end within the timeout; only messages
        that speak prove a connection, and well-formed ones keep a proven one open (junk,
        however much, does neither)."""
        slot: _Slot | None = self._slots.get(key)  # the table's own record of the connection
        if slot is None:
            return
        frames = messages if frames is None else frames
        if messages:
            slot.proven = True
        if messages or slot.proven and read:
            slot.spoke = now
        if not slot.proven:
            pass  # the first message is due within the timeout of connecting, however it trickles
        elif pending and (frames or not slot.pending):
            slot.due = now + self.limits.message_timeout_s
        elif not pending:
            slot.due = slot.spoke + self.limits.idle_timeout_s
        slot.pending = pending

    def remove(self, key: K) -> None:
        self._slots.pop(key, None)

    def next_due(self) -> float | None:
        return min((slot.due for slot in self._slots.values()), default=None)

    def expired(self, now: float) -> list[tuple[K, str]]:
        """The connections past their time, removed, with why."""
        late = [(key, slot) for key, slot in self._slots.items() if slot.due <= now]
        for key, _ in late:
            del self._slots[key]
        return [(key, self._why_late(slot)) for key, slot in late]

    def _why_late(self, slot: _Slot) -> str:
        if slot.pending:
            return f"closed: a message unfinished after {self.limits.message_timeout_s:g} s"
        if not slot.proven:
            return f"closed: no command within {self.limits.message_timeout_s:g} s of connecting"
        return f"closed: idle for {self.limits.idle_timeout_s:g} s"


# -- the sockets --------------------------------------------------------------------------------


@dataclass(eq=False)
class _Connection:
    sock: socket.socket
    sender: Sender
    reader: FrameReader
    unsent: bytearray = field(default_factory=bytearray)
    resting_until: float | None = None  # not read until then: its sender is over its rate
    watched: int = 0  # the selector events it is registered for (0: none)


class OscNet:
    """UDP and TCP on host:port, served by one thread (see the module's docstring)."""

    def __init__(self, handler: PacketHandler, host: str, port: int, limits: OscLimits = LIMITS,
                 now: Callable[[], float] = time.monotonic) -> None:
        self.handler = handler
        self.host = host
        self.requested_port = port
        self.limits = limits
        self._now = now
        self._table: ConnectionTable[_Connection] = ConnectionTable(limits)
        self._connections: set[_Connection] = set()
        self._selector: selectors.BaseSelector | None = None
        self._udp: socket.socket | None = None
        self._tcp: socket.socket | None = None
        self._wake: tuple[socket.socket, socket.socket] | None = None
        self._accept_paused_until: float | None = None
        self._closing = threading.Event()
        self._thread: threading.Thread | None = None
        self._port: int | None = None
        self._bound_host: str | None = None  # the address bound, as the system names it
        self._drops_seen = 0  # the socket's count of dropped datagrams, as last told
        self._by_sender: dict[Sender, _Connection] = {}  # the TCP connections, by their peer's address
        self._outbox: deque[tuple[Sender, bytes]] = deque()  # notifications for TCP peers (`push`)
        self._outbox_lock = threading.Lock()
        self.faults = 0  # events whose handling failed (a bug): counted, and serving goes on
        self.unpushed = 0  # notifications dropped: a full outbox, a peer gone or not reading

    @property
    def port(self) -> int:
        """The port bound (the one the OS chose, when asked for 0)."""
        return self._port if self._port is not None else self.requested_port

    @property
    def bound_host(self) -> str:
        """The address bound, as the system names it (the host given, until bound)."""
        return self._bound_host or self.host

    @property
    def connections(self) -> int:
        """TCP connections open now."""
        return len(self._connections)

    def bind(self) -> None:
        """Listen on both transports (ListenFailed), not serving yet: the port's problems are
        known before a show starts."""
        if self._udp is None:
            self._udp, self._tcp = bind(self.host, self.requested_port, self.limits)
            self._port = self._udp.getsockname()[1]
            self._bound_host = _named(self._udp.getsockname())

    def serve(self) -> None:
        """Serve from a thread of its own, until `close`."""
        if self._udp is None or self._thread is not None or self._closing.is_set():
            return
        self._wake = socket.socketpair()
        self._wake[0].setblocking(False)
        self._wake[1].setblocking(False)  # `push` never waits: a full buffer has woken the thread already
        self._selector = selector = selectors.DefaultSelector()
        assert self._tcp is not None  # bound with the UDP socket, always
        selector.register(self._udp, selectors.EVENT_READ, "udp")
        selector.register(self._tcp, selectors.EVENT_READ, "accept")
        selector.register(self._wake[0], selectors.EVENT_READ, "wake")
        self._thread = threading.Thread(target=self._serve, name="choreo-osc", daemon=True)
        self._thread.start()

    def close(self) -> None:
        """Stop serving; the peers see their connections end. Twice is harmless."""
        if self._thread is not None:
            self._closing.set()
            if self._wake is not None:
                with contextlib.suppress(OSError):  # its buffer full: the thread is woken already
                    self._wake[1].send(b"x")
            self._thread.join(2.0)
            self._thread = None
        for connection in list(self._connections):
            self._close(connection)
        self._closing.set()
        for sock in (self._udp, self._tcp, *(self._wake or ())):
            if sock is not None:
                sock.close()
        self._wake = None
        if self._selector is not None:
            self._selector.close()
            self._selector = None

    # -- the loop ---------------------------------------------------------------------------

    def _serve(self) -> None:
        assert self._selector is not None
        while not self._closing.is_set():
            for key, mask in self._selector.select(self._timeout()):
                try:
                    self._ready(key.data, mask)
                except Exception:  # noqa: BLE001 - one event's fault must not end OSC for the show
                    self.faults += 1
            self._expire()

    def _ready(self, what: object, mask: int) -> None:
        if what == "udp":
            self._read_datagrams()
        elif what == "accept":
            self._accept()
        elif what == "wake":
            self._drain_wake()
        elif isinstance(what, _Connection):  # a TCP connection, registered with itself as its data
            if mask & selectors.EVENT_WRITE:
                self._flush(what)
            else:
                self._read(what)

    def _timeout(self) -> float | None:
        resting = (c.resting_until for c in self._connections if c.resting_until is not None)
        dues = [due for due in (self._table.next_due(), self._accept_paused_until, min(resting, default=None))
                if due is not None]
        return max(0.0, min(dues) - self._now()) if dues else None

    def _drain_wake(self) -> None:
        if self._wake is not None:
            with contextlib.suppress(OSError):  # nothing left to read: woken all the same
                self._wake[0].recv(4096)
        self._deliver_outbox()

    # -- notifications to subscribers ------------------------------------------------------------

    def push(self, transport: str, sender: Sender, packet: bytes) -> None:
        """Send `packet` (a notification) to a sender, from any thread, never waiting: over UDP
        from our own port (where the sender's replies come from), over TCP on its connection."""
        if transport == "udp":
            udp = self._udp
            try:
                if udp is not None:
                    udp.sendto(packet, sender)
                    return
            except (OSError, ValueError):  # a full buffer, an unreachable peer, a socket closed
                pass
            self.unpushed += 1
            return
        with self._outbox_lock:
            if len(self._outbox) >= OUTBOX:
                self.unpushed += 1
                return
            self._outbox.append((sender, packet))
        wake = self._wake
        if wake is not None:
            with contextlib.suppress(OSError):  # its buffer full: the thread is woken already
                wake[1].send(b"n")

    def _deliver_outbox(self) -> None:
        """The serving thread: queue the notifications `push` left to their connections."""
        with self._outbox_lock:
            waiting = list(self._outbox)
            self._outbox.clear()
        for sender, packet in waiting:
            connection: _Connection | None = self._by_sender.get(sender)  # this server's own record
            framed = connection.reader.frame(packet) if connection is not None else b""
            if connection is None or len(connection.unsent) + len(framed) > self.limits.max_unsent:
                self.unpushed += 1
                continue
            connection.unsent += framed
            self._flush(connection)

    def _expire(self) -> None:
        now = self._now()
        if self._accept_paused_until is not None and now >= self._accept_paused_until:
            self._accept_paused_until = None
            assert self._selector is not None and self._tcp is not None  # serving: both exist
            self._selector.register(self._tcp, selectors.EVENT_READ, "accept")
        for connection, why in self._table.expired(now):
            self._drop(connection, why)
        rested: list[_Connection] = [c for c in self._connections
                                     if c.resting_until is not None and c.resting_until <= now]
        rester: _Connection  # this server's own record of a connection
        for rester in rested:
            rester.resting_until = None
            self._watch(rester)

    # -- UDP --------------------------------------------------------------------------------

    def _read_datagrams(self) -> None:
        udp = self._udp
        assert udp is not None  # serving: bound
        for _ in range(UDP_BATCH):
            try:
                data, ancillary, _, sender = udp.recvmsg(UDP_BUFFER, DROPS_DATA)
            except BlockingIOError:
                return
            except OSError:  # e.g. an ICMP error about an earlier reply: not this datagram's fault
                continue
            if ancillary:
                self._count_drops(ancillary)
            if len(data) > self.limits.max_datagram:
                self.handler.dropped("udp", sender, f"a datagram of {len(data)} bytes "
                                                    f"(the limit is {self.limits.max_datagram})")
                continue
            for reply in self.handler.packet("udp", sender, data):
                with contextlib.suppress(OSError):  # a full buffer, an unreachable sender: not worth a wait
                    udp.sendto(reply, sender)

    def _count_drops(self, ancillary: list[tuple[int, int, bytes]]) -> None:
        for level, kind, value in ancillary:
            if level == socket.SOL_SOCKET and kind == SO_RXQ_OVFL and len(value) >= 4:
                (drops,) = struct.unpack("=I", value[:4])
                if drops > self._drops_seen:
                    self.handler.lost("udp", drops - self._drops_seen)
                self._drops_seen = drops

    # -- TCP --------------------------------------------------------------------------------

    def _accept(self) -> None:
        tcp = self._tcp
        assert tcp is not None  # serving: bound
        for _ in range(ACCEPT_BATCH):
            try:
                sock, sender = tcp.accept()
            except BlockingIOError:
                return
            except OSError as exc:
                if exc.errno not in OUT_OF_DESCRIPTORS:
                    continue  # a peer gone before it was accepted
                silent = self._table.make_room()
                if silent is None:
                    self._pause_accepting(exc)
                    return
                why = "closed to make room: out of file descriptors, and it had sent no message"
                self._drop(silent, why)
                continue
            self._admit(sock, sender)

    def _pause_accepting(self, exc: OSError) -> None:
        self._accept_paused_until = self._now() + ACCEPT_PAUSE_S
        assert self._selector is not None and self._tcp is not None  # serving: both exist
        self._selector.unregister(self._tcp)
        self.handler.dropped("tcp", (self.host, self.port), f"cannot accept connections now: {exc.strerror}")

    def _admit(self, sock: socket.socket, sender: Sender) -> None:
        if not self.handler.admit(sender):
            sock.close()
            return
        connection = _Connection(sock, sender, FrameReader(self.limits.max_message))
        taken, evicted = self._table.admit(connection, sender[0], self._now())
        for old in evicted:
            self._drop(old, "closed to make room: it had sent no message")
        if not taken:
            sock.close()
            limits = self.limits
            self.handler.dropped("tcp", sender, f"refused: too many connections (at most {limits.max_connections}, "
                                                f"{limits.max_per_sender} from one address, each sending)")
            return
        sock.setblocking(False)
        with contextlib.suppress(OSError):  # replies go out all the same, only later
            sock.setsockopt(socket.IPPROTO_TCP, socket.TCP_NODELAY, 1)  # a reply is one small write: now
        self._connections.add(connection)
        self._by_sender[sender] = connection
        self._watch(connection)
        self._read(connection)  # a message sent with the connection (QLab's GO) proves it at once

    def _read(self, connection: _Connection) -> None:
        try:
            data = connection.sock.recv(RECV_BYTES)
        except BlockingIOError:
            return
        except OSError:
            data = b""
        if not data:
            self._close(connection)
            return
        fed = connection.reader.feed(data)
        for why in fed.bad:
            self.handler.dropped("tcp", connection.sender, why)
        spoke = read = 0
        for packet in fed.packets:
            handled = self.handler.packet("tcp", connection.sender, packet)
            spoke += handled.spoke
            read += handled.read
            for reply in handled:
                connection.unsent += connection.reader.frame(reply)
        self._table.heard(connection, self._now(), messages=spoke, frames=len(fed.packets) + len(fed.bad),
                          pending=connection.reader.pending, read=read)
        if fed.fatal is not None:
            self._drop(connection, f"closed: {fed.fatal}")
            return
        rest = self._rest_s(connection, fed)
        if rest > 0:
            connection.resting_until = self._now() + rest
        if connection.unsent:
            self._flush(connection)
        else:
            self._watch(connection)

    def _rest_s(self, connection: _Connection, fed: Fed) -> float:
        """How long the connection is not read after this: over its sender's rate, or sending
        bytes that frame nothing."""
        rest = self.handler.rest_s(connection.sender) if fed.packets else 0.0
        if fed.filler >= FILLER_REST[0]:
            rest = max(rest, FILLER_REST[1])
            self.handler.dropped("tcp", connection.sender, f"{fed.filler} bytes that frame nothing: not read for "
                                                           f"{FILLER_REST[1]:g} s")
        return rest

    def _flush(self, connection: _Connection) -> None:
        try:
            sent = connection.sock.send(connection.unsent)
        except BlockingIOError:
            sent = 0
        except OSError:
            self._close(connection)
            return
        del connection.unsent[:sent]
        if len(connection.unsent) > self.limits.max_unsent:
            self._drop(connection, f"closed: it does not read its replies ({len(connection.unsent)} bytes unsent)")
            return
        self._watch(connection)

    def _watch(self, connection: _Connection) -> None:
        """Register for what the connection waits for: reading unless it rests, writing while
        replies are unsent."""
        events = (0 if connection.resting_until is not None else selectors.EVENT_READ) | (
            selectors.EVENT_WRITE if connection.unsent else 0)
        if events == connection.watched:
            return
        selector = self._selector
        assert selector is not None
        if not events:
            selector.unregister(connection.sock)
        elif connection.watched:
            selector.modify(connection.sock, events, connection)
        else:
            selector.register(connection.sock, events, connection)
        connection.watched = events

    def _drop(self, connection: _Connection, why: str) -> None:
        self._close(connection)
        self.handler.dropped("tcp", connection.sender, why)

    def _close(self, connection: _Connection) -> None:
        self._table.remove(connection)
        if connection in self._connections:
            self._connections.discard(connection)
            if self._by_sender.get(connection.sender) is connection:
                del self._by_sender[connection.sender]
            if connection.watched and self._selector is not None:
                with contextlib.suppress(KeyError, ValueError):  # the selector no longer knew it
                    self._selector.unregister(connection.sock)
                connection.watched = 0
            self.handler.closed("tcp", connection.sender)
        with contextlib.suppress(OSError):  # the peer went first
            connection.sock.shutdown(socket.SHUT_RDWR)
        connection.sock.close()


# -- binding ------------------------------------------------------------------------------------


def bind(host: str, port: int, limits: OscLimits = LIMITS) -> tuple[socket.socket, socket.socket]:
    """UDP and TCP on one port number; with port 0, a number free for both."""
    attempts = 20 if port == 0 else 1
    while True:
        attempts -= 1
        udp = _listen(host, port, socket.SOCK_DGRAM, limits)
        try:
            return udp, _listen(host, udp.getsockname()[1], socket.SOCK_STREAM, limits)
        except ListenFailed:
            udp.close()
            if attempts == 0:
                raise


def _listen(host: str, port: int, kind: int, limits: OscLimits) -> socket.socket:
    transport = "udp" if kind == socket.SOCK_DGRAM else "tcp"
    try:
        # the port is not given to getaddrinfo: it would wrap 70000 round to 4464
        family, _, _, _, address = socket.getaddrinfo(host, 0, type=kind, flags=socket.AI_PASSIVE)[0]
        sock = socket.socket(family, kind)
    except (OSError, UnicodeError) as exc:
        raise ListenFailed(transport, (host, port), getattr(exc, "strerror", None) or str(exc)) from None
    try:
        if family == socket.AF_INET6:
            _set(sock, socket.IPPROTO_IPV6, socket.IPV6_V6ONLY, 0)  # `::` takes IPv4 senders too
        if kind == socket.SOCK_STREAM:
            _set(sock, socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)  # a restart while old connections wait
        sock.bind((address[0], port, *address[2:]))
        if kind == socket.SOCK_STREAM:
            sock.listen(LISTEN_BACKLOG)
        elif SO_RXQ_OVFL is not None:
            _set(sock, socket.SOL_SOCKET, SO_RXQ_OVFL, 1)  # how many datagrams a flood made it drop
        sock.setblocking(False)
    except (OSError, OverflowError) as exc:
        sock.close()
        raise ListenFailed(transport, (host, port), getattr(exc, "strerror", None) or str(exc),
                           getattr(exc, "errno", None) == errno.EADDRINUSE) from None
    return sock


def _named(address: Sender) -> str:
    """A bound address's host as a person writes it: an IPv6 one with its interface's name
    (`fe80::1%eth0`) when it has a scope."""
    if len(address) < 4 or not address[3]:
        return str(address[0])
    try:
        return f"{address[0]}%{socket.if_indextoname(address[3])}"
    except OSError:  # an interface gone since: its number says where
        return f"{address[0]}%{address[3]}"


def _set(sock: socket.socket, level: int, option: int, value: int) -> None:
    """An option this system may not have: the socket works without it."""
    with contextlib.suppress(OSError):
        sock.setsockopt(level, option, value)
