"""`--osc-notify HOST:PORT` (repeatable): the show's progress as OSC messages over UDP to every
target given, sent by a thread of its own from a bounded queue, so nothing on a runner's path
waits for the network and a message that cannot be sent (or queued) is dropped.

A target that is choreo's own `--osc` port on this machine would loop (each notification
comes back as an unknown command, which is notified again), so it is refused at start-up:
loopback, the unspecified address, every address of this machine's interfaces, and a multicast
group or the broadcast address at that port (a datagram sent there is delivered to this
machine's own sockets too: `ff02::1%eth0` reached `--osc-host ::` and looped).

A sender may ask for the same notifications with `/choreo/updates 1` (QLab's `/updates`):
`Subscriptions` keeps who (at most `Limits.update_subscribers`, each until it has been silent
`Limits.update_expire_s`; a TCP sender, proven by its handshake, may take a UDP one's place,
and a UDP one, whose address may be forged, is sent at most `Limits.update_bytes`), and the
notifier's thread hands each notification to them too (`Notifier(deliver=)`), never a runner.
"""

from __future__ import annotations

import contextlib
import ipaddress
import queue
import socket
import threading
import time
from collections.abc import Callable, Hashable, Sequence
from dataclasses import dataclass, replace
from typing import Any


from choreo.errors import UsageError
from choreo.live.limits import LIMITS, Budget, Rate
from choreo.numtext import whole_number
from choreo.live.oscwire import encode_message

QUEUED = 1000  # notifications waiting to be sent; past this they are dropped

Target = tuple[str, int]


def port_number(text: str, lowest: int = 1) -> int | None:
    """A port number as typed: ASCII digits (`choreo.numtext`: `int` would also take '+5', '1_000'
    and the Arabic-Indic '٥'), no blank around them (' 5' is a slip, not a port), `lowest`..65535;
    else None."""
    number = whole_number(text) if text == text.strip() else None
    return number if number is not None and lowest <= number <= 65535 else None


def parse_target(text: str, option: str = "--osc-notify") -> Target:
    """HOST:PORT (`[::1]:53001` for IPv6); UsageError on anything else."""
    host, _, port_text = text.rpartition(":")
    host = host.strip()
    if host.startswith("[") and host.endswith("]"):
        host = host[1:-1]
    port = port_number(port_text)
    if not host or port is None:
        raise UsageError(f"{option} {text}: give HOST:PORT, e.g. 127.0.0.1:53001")
    return host, port


def parse_targets(texts: Sequence[str]) -> tuple[Target, ...]:
    """Every --osc-notify given (each one gets the notifications), none twice."""
    if len(texts) > LIMITS.notify_targets:
        raise UsageError(f"--osc-notify {texts[LIMITS.notify_targets]}: at most {LIMITS.notify_targets} "
                         "notify targets")
    targets: list[Target] = []
    for text in texts:
        target = parse_target(text)
        if target in targets:
            raise UsageError(f"--osc-notify {text}: given twice")
        targets.append(target)
    return tuple(targets)


def show_target(target: Target) -> str:
    host, port = target
    return f"[{host}]:{port}" if ":" in host else f"{host}:{port}"


def is_this_machine(ip: str, family: int) -> bool:
    """Does a packet sent to `ip` stay on this machine? Loopback and unspecified addresses do,
    and so does any address a socket can be bound to (an interface's own)."""
    try:
        address = ipaddress.ip_address(ip.split("%")[0])
    except ValueError:
        return False
    mapped = address.ipv4_mapped if isinstance(address, ipaddress.IPv6Address) else None
    if mapped is not None:
        return is_this_machine(str(mapped), socket.AF_INET)
    if address.is_loopback or address.is_unspecified:
        return True
    try:
        with socket.socket(family, socket.SOCK_DGRAM) as probe:
            probe.bind((ip, 0))
    except OSError:
        return False
    return True


def comes_back(ip: str, family: int) -> bool:
    """Would a datagram sent to `ip` reach this machine's own sockets? This machine's own
    addresses do (`is_this_machine`), and so do a multicast group (sent with the loop that is
    every system's default on: any socket on the port may take it) and the broadcast address."""
    try:
        address = ipaddress.ip_address(ip.split("%")[0])
    except ValueError:
        return False
    mapped = address.ipv4_mapped if isinstance(address, ipaddress.IPv6Address) else None
    shared = (mapped or address).is_multicast or (mapped or address) == ipaddress.IPv4Address("255.255.255.255")
    return shared or is_this_machine(ip, family)


def receiver(family: int, address: tuple) -> tuple:
    """Who a looked-up target reaches, however it was spelt: an IPv4-mapped IPv6 address
    (`[::ffff:127.0.0.1]:9`) reaches the IPv4 receiver (`127.0.0.1:9`); IPv6's flow label
    does not change the receiver, its scope does."""
    host, port = str(address[0]), address[1]
    try:
        ip = ipaddress.ip_address(host.split("%")[0])
    except ValueError:
        return family, address
    mapped = ip.ipv4_mapped if isinstance(ip, ipaddress.IPv6Address) else None
    if mapped is not None:
        return socket.AF_INET, (str(mapped), port)
    return (family, (str(ip), port, address[3])) if len(address) == 4 else (family, (str(ip), port))


class Notifier:
    """Sends each notification to every target (see the module's docstring)."""

    def __init__(self, targets: Sequence[Target], deliver: Callable[[bytes], object] | None = None) -> None:
        self.targets = tuple(targets)
        self._deliver = deliver  # each notification encoded, to the subscribers (from this thread)
        self._queue: queue.Queue[tuple | None] = queue.Queue(QUEUED)
        self._sockets: dict[int, socket.socket] = {}
        self._addresses: list[tuple[int, Any]] = []  # (family, address) of each target
        self._receivers: list[tuple] = []  # who each target reaches (`receiver`)
        self._thread: threading.Thread | None = None

    def resolve(self, own_port: int) -> None:
        """Look every target up and open the sockets; UsageError for a target that does not
        resolve, or that is choreo's own port on this machine (it would loop)."""
        for target in self.targets:
            host, port = target
            try:
                found = socket.getaddrinfo(host, port, type=socket.SOCK_DGRAM)
            except (OSError, UnicodeError) as exc:
                self.close()
                raise UsageError(f"--osc-notify {show_target(target)}: {getattr(exc, 'strerror', None) or exc}") \
                    from None
            if port == own_port and any(comes_back(str(info[4][0]), info[0]) for info in found):
                self.close()
                raise UsageError(f"--osc-notify {show_target(target)}: that is choreo's own --osc port on this "
                                 "machine: each notification would come back as a command (give the port "
                                 "the receiver listens on)")
            family, kind, proto, _, address = found[0]
            if receiver(family, address) in self._receivers:  # localhost:9000 and 127.0.0.1:9000: one receiver
                self.close()
                raise UsageError(f"--osc-notify {show_target(target)}: given twice (another spelling of a "
                                 "target given before): each notification would be sent to it twice")
            if family not in self._sockets:
                self._sockets[family] = socket.socket(family, kind, proto)
                self._sockets[family].setblocking(False)
            self._addresses.append((family, address))
            self._receivers.append(receiver(family, address))

    def start(self) -> None:
        self._thread = threading.Thread(target=self._loop, name="choreo-osc-notify", daemon=True)
        self._thread.start()

    def put(self, address: str, *args: Any) -> None:
        with contextlib.suppress(queue.Full):  # progress is not worth holding the show, nor memory
            self._queue.put_nowait((address, args))

    def close(self) -> None:
        if self._thread is not None:
            with contextlib.suppress(queue.Full):  # a stuck sender: the join below gives up too
                self._queue.put((None), timeout=1.0)
            self._thread.join(1.0)
            self._thread = None
        for sock in self._sockets.values():
            sock.close()
        self._sockets.clear()

    def _loop(self) -> None:
        while True:
            item = self._queue.get()
            if item is None:
                return
            self._send(*item)

    def _send(self, address: str, args: tuple) -> None:
        try:
            data = encode_message(address, args)
        except (ValueError, TypeError):
            return
        for family, target in self._addresses:
            # nobody listening, a full buffer, closed: progress is not worth holding the show
            with contextlib.suppress(OSError, KeyError):
                self._sockets[family].sendto(data, target)
        if self._deliver is not None:
            with contextlib.suppress(Exception):  # a subscriber's fault must not end the targets' notifications
                self._deliver(data)


@dataclass
class Subscriber:
    """A sender that asked for the notifications: how to reach it (its transport and address:
    a TCP sender's is its connection), how the log names it, and when it was last heard."""

    transport: str
    sender: tuple
    source: str
    heard: float
    ended: str = ""  # why it ended, once it has (the log says)
    budget: Budget | None = None  # the bytes it may be sent (a UDP subscriber's: its address may be forged)

    def may_send(self, packet: bytes) -> bool:
        """May this notification go to it (within its budget of bytes, if it has one)?"""
        return self.budget is None or self.budget.take(len(packet))


class Subscriptions:
    """Who gets the notifications besides the --osc-notify targets (`/choreo/updates 1`): at
    most `most`, each until `expire_s` without a message from it. Thread-safe: the OSC thread
    adds and renews, the notifier's thread reads."""

    def __init__(self, most: int = LIMITS.update_subscribers, expire_s: float = LIMITS.update_expire_s,
                 now: Callable[[], float] = time.monotonic, udp_bytes: Rate | None = LIMITS.update_bytes) -> None:
        self.most = most
        self.expire_s = expire_s
        self.udp_bytes = udp_bytes  # what a UDP subscriber may be sent (None: unbounded)
        self._now = now
        self._lock = threading.Lock()
        self._subscribers: dict[Hashable, Subscriber] = {}

    def __len__(self) -> int:
        return len(self._subscribers)

    def __contains__(self, key: Hashable) -> bool:
        return key in self._subscribers

    def add(self, key: Hashable, transport: str, sender: tuple, source: str) -> tuple[bool, list[Subscriber]]:
        """Subscribe (or renew); False when `most` others are subscribed, unless a TCP sender
        (its address proven by its handshake) may take the place of the UDP subscriber least
        lately heard: a UDP sender's address can be forged, and four forged subscriptions, each
        renewed by a forged message a minute, must not keep a desk's TCP connection out. And
        the ones ended on the way, each saying why (the caller tells of them)."""
        with self._lock:
            ended = self._expire()
            known: Subscriber | None = self._subscribers.get(key)  # the table's own record
            if known is not None:  # renewed: its budget goes on (a new one would refill it)
                known.heard = self._now()
                return True, ended
            if len(self._subscribers) >= self.most:
                displaced = self._displace() if transport == "tcp" else None
                if displaced is None:
                    return False, ended
                ended.append(displaced)
            budget = Budget.of(self.udp_bytes, self._now) if transport == "udp" and self.udp_bytes else None
            self._subscribers[key] = Subscriber(transport, sender, source, self._now(), budget=budget)
            return True, ended

    def remove(self, key: Hashable) -> Subscriber | None:
        with self._lock:
            return self._subscribers.pop(key, None)

    def heard(self, key: Hashable) -> list[Subscriber]:
        """A message from `key`: its subscription (if any) goes on, unless it has been silent
        `expire_s` already: then it has ended (returned, for the caller to tell), whether or not
        a notification found it ended first (expiring is lazy: the answer must not depend on
        whether the show happened to notify meanwhile)."""
        if key not in self._subscribers:  # most senders are not subscribed: no lock for them
            return []
        with self._lock:
            subscriber: Subscriber | None = self._subscribers.get(key)  # the table's own record
            if subscriber is None:
                return []
            now = self._now()
            if now - subscriber.heard >= self.expire_s:
                return [self._ended(key, f"no message for {self.expire_s:g} s")]
            subscriber.heard = now
            return []

    def current(self) -> tuple[list[Subscriber], list[Subscriber]]:
        """The subscribers now, and those that have just expired (removed)."""
        with self._lock:
            expired = self._expire()
            return list(self._subscribers.values()), expired

    def _expire(self) -> list[Subscriber]:
        """The lock is held."""
        now = self._now()
        late = [key for key, subscriber in self._subscribers.items() if now - subscriber.heard >= self.expire_s]
        return [self._ended(key, f"no message for {self.expire_s:g} s") for key in late]

    def _displace(self) -> Subscriber | None:
        """The lock is held. The UDP subscriber least lately heard, removed, or None."""
        udp = [key for key, subscriber in self._subscribers.items() if subscriber.transport == "udp"]
        if not udp:
            return None
        key = min(udp, key=lambda each: self._subscribers[each].heard)
        return self._ended(key, "its place taken by a TCP subscriber (a UDP sender's address can be forged)")

    def _ended(self, key: Hashable, why: str) -> Subscriber:
        """The lock is held."""
        return replace(self._subscribers.pop(key), ended=why)
