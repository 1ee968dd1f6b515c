"""OSC control of a running show, in QLab's manner, so that a QLab Network cue (or TouchOSC, Max,
a lighting desk) can run it as the console's keys do, over UDP and over TCP framed with SLIP (OSC
1.1, as QLab sends it) or with a length prefix (OSC 1.0, as liblo sends it: Pure Data,
SuperCollider), on one port number.

The dictionary (every address exactly so: no patterns, no other case; CUE is a cue's number, `3`
or `12.5`, or its label, percent-escaped as in a URL: `%20` a space, `%2F` a slash, `%25` a
percent sign, other bytes UTF-8; a bad escape, bytes that are not UTF-8 or a control character
such as `%00` are refused with a reply that says how to escape):

    /choreo/go                  GO: the cue under the playhead, if it waits for GO
    /choreo/cue/CUE/go          GO for that cue, if it waits (`/choreo/cue/LABEL/go` as before)
    /choreo/skip                skip the cue under the playhead (again, ahead: the skip undone)
    /choreo/playhead/next       the playhead to the next cue not yet run
    /choreo/playhead/previous   the playhead to the previous cue not yet run
    /choreo/playhead/CUE        the playhead to that cue (a cue labelled `next` or `previous`
                                is reached by its number, or escaped: `%6Eext`)
    /choreo/pause               the show clock stands still; no new step starts
    /choreo/resume              on from where it stood
    /choreo/start               start a show run with --wait-start
    /choreo/stop                stop: the exchange in flight, then the abort motion
    /choreo/panic               no more show frames: stop frames and every robot's abort motion
    /choreo/status              a question: the reply's data is the show's state (`Live.status`;
                                cut to `Limits.status_datagram` bytes over UDP, to the
                                longest message choreo takes over TCP, saying so)
    /choreo/thump               a heartbeat: answered at once (data: whether updates go to you)
    /choreo/updates 1|0         the notifications to you too (1), or no longer (0)

A command with an argument 0 alone is a button's release (TouchOSC) and ignored, but `/updates
0`. The questions (status, thump) are answered at once, carry nothing out and are not logged one
by one (a desk polls them); they spend their sender's packets and a budget of questions of their
own, not its commands nor its replies (`choreo.live.limits`). `/choreo/updates 1` subscribes the
sender, QLab's way: a UDP sender at its address and port, a TCP sender over its own connection
(framed as it frames), to the notifications the `--osc-notify` targets get, sent from the
notifier's thread (`choreo.live.oscnotify`). At most `Limits.update_subscribers` at once (one
more is refused, told why, but a TCP sender, whose address its handshake proves, takes the place
of the UDP subscriber least lately heard, whose address may be forged); a UDP subscriber is sent
at most `Limits.update_bytes` of them (a forged one's victim gets a bounded share). Each ends
after `Limits.update_expire_s` without a message from it (any message renews it:
`/choreo/thump` is the usual), at `/choreo/updates 0`, or when its TCP connection closes. A
sender whose address is our own port is refused (it would loop). Subscribing and its end are
logged as the command `updates`.

An unknown address is answered with the command meant when it differs from one of ours only by
ASCII case (Unicode's folding would take `ſtop`, a long s, for `stop`), a missing `/choreo` or a
trailing slash (`/go`, `/cue/1/go`); otherwise only an address that changes nothing on stage is
suggested (`/ping` and `/heartbeat`: `/choreo/thump`), never a GO, a panic or another command
with an effect: a typo answered with a suggestion is typed again.

Packets are read by choreo's own bounded decoder (`choreo.live.oscwire`), and the sockets served by
`choreo.live.oscnet` (connection caps, timeouts; the sizes and counts are `choreo.live.osclimits`): a
malformed packet (a bad size, a type tag choreo does not know) is refused whole, counted, and
nothing of it is carried out. python-osc does not receive here: its parser loops for ever on a
bundle element of size 0, and it logs through the root logger.

Every message is answered to its sender as QLab answers: `/reply` + the address, with one JSON
string `{"address", "status": ok|error|denied, "message", "data"}`; the commands themselves are
carried out by `choreo.live.controls.Live`, exactly as the console's keys are, so both are answered and
logged alike. With a notify address, the show's progress goes out as OSC too (steps, GO cues
waiting, commands, warnings and faults) from a thread of its own: a slow or absent receiver
never holds a runner.

Who may command the show: this machine (loopback), and the addresses given with --osc-allow.
The sender is checked before a byte of its packet is read. A refused TCP peer is closed at
accept (its refusal logged: the operator setting up a desk on another machine needs to see why
nothing happens; a TCP peer's address is proven by its handshake). A refused UDP sender gets a
`denied` reply, addressed `/reply` (its message is not read). A UDP sender's address is not
proven (it can be forged to make us send replies to a victim, and a
flood of refusals would fill the log, which stops the show when it cannot take more), so what
any message may cost is bounded (`choreo.live.limits`): refusals are answered within a small budget
shared by every refused sender, an allowed sender's commands and replies within its own, and
refused or ignored commands are logged one by one only within a budget, the rest counted.
A reply or notification sent to our port is never answered nor notified (two would loop).

OSC address patterns (`/choreo/*`) are not expanded: a pattern could match GO and panic at once,
which no operator means; a command is taken only at its own address.
"""

from __future__ import annotations

import ipaddress
import json
import math
import socket
import string
import time
import unicodedata
import urllib.parse
from collections import Counter
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from typing import Any


from choreo.errors import UsageError, closest
from choreo.events import Answer, Command, CommandEvent, GoCue, RunResult, StepEvent
from choreo.live.limits import LIMITS, Limits, SenderKey, SenderLimits
from choreo.log.format import UNLOGGED
from choreo.live.controls import Live
from choreo.live.oscnet import NOTHING, Handled, ListenFailed, OscNet
from choreo.live.osclimits import LIMITS as WIRE_LIMITS
from choreo.live.osclimits import OscLimits
from choreo.live.oscnotify import Notifier, Subscriber, Subscriptions, Target, is_this_machine, show_target
from choreo.live.oscwire import Message, decode_packet, encode_message
from choreo.log.format import ERROR, WARNING

# OSC addresses, not log topics (those are spelled in choreo.log.format), though both start /choreo
ROOT = "/choreo"
PATHS = {"go": "go", "panic": "panic", "start": "start", "stop": "stop", "pause": "pause", "resume": "resume",
         "skip": "skip", "playhead/next": "playhead_next", "playhead/previous": "playhead_previous"}
COMMANDS = {f"{ROOT}/{path}": name for path, name in PATHS.items()}  # address: the Live command it gives
STATUS, THUMP, UPDATES = f"{ROOT}/status", f"{ROOT}/thump", f"{ROOT}/updates"
QUERIES = {STATUS: "status", THUMP: "thump"}  # answered at once, nothing carried out, not logged one by one
CUE_PREFIX, CUE_SUFFIX = f"{ROOT}/cue/", "/go"
PLAYHEAD_PREFIX = f"{ROOT}/playhead/"
# the commands with an effect on the stage: never suggested for an address that is not theirs but
# for its case, a missing /choreo or a trailing slash (a typo must not become a GO or a panic)
EFFECTS = frozenset({"go", "panic", "start", "stop", "pause", "resume", "skip", "cue_go"})
SUGGESTED = (STATUS, THUMP, UPDATES, f"{ROOT}/playhead/next", f"{ROOT}/playhead/previous")  # the rest
# a last segment that names a question (QLab's /workspace/ID/thump), or a heartbeat's other names
# (`/playhead` alone is QLab's question for the playhead: status says where it is, never moves it)
ALIASES = {"ping": THUMP, "heartbeat": THUMP, "thump": THUMP, "status": STATUS, "updates": UPDATES,
           "playhead": STATUS}
DICTIONARY = (*COMMANDS, f"{PLAYHEAD_PREFIX}CUE", f"{CUE_PREFIX}CUE{CUE_SUFFIX}", STATUS, THUMP, UPDATES)
KNOWN = "go, panic, start, stop, pause, resume, skip, playhead/next|previous|CUE, cue/CUE/go, status, thump, updates"
NOTIFY = f"{ROOT}/notify"
PATTERN_CHARS = frozenset("*?[]{}")
ASCII_LOWER = str.maketrans(string.ascii_uppercase, string.ascii_lowercase)
HEX = frozenset("0123456789abcdefABCDEF")
ESCAPING = ("a cue's number or label goes percent-escaped, as in a URL: %20 a space, %2F a slash, %25 a "
            "percent sign, other bytes as UTF-8 (/choreo/cue/big%20bow/go)")
ECHOES = ("/reply", NOTIFY)  # replies and notifications: never commands, never answered (two would loop)
ECHO = "echo"  # the command name a reply or notification sent to us is logged under
LOST = "lost"  # the command name datagrams the system dropped before choreo read them are counted under
UNREAD = "unread"  # the command name a packet over its sender's rate is counted under (not read)
UNANSWERED = "unanswered"  # status or thump over the sender's budget of questions: counted, not answered
UNSENT = "unsent updates"  # notifications over a UDP subscriber's budget of bytes: dropped, counted
ASK_TCP = "ask over TCP for the whole status"  # a status reply cut to fit a datagram
CUT = "…"  # ends an address cut to `Limits.address_shown` characters
UPDATES_COMMAND = "updates"  # how the log names /choreo/updates (subscribing, ending, expiring)
SENDERS_KNOWN = 4096  # senders whose verdict is remembered (an address's parse costs more than a refusal)

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

    def encoded(self) -> bytes:
        """The OSC message sent back: `/reply` + the address, the JSON its one argument (always
        sent, always JSON: a text no UTF-8 can carry, a lone surrogate, goes \\u-escaped, and a
        number JSON has no word for, NaN or infinity, as null)."""
        body = {"address": self.address, "status": self.status, "message": self.message, "data": self.data}
        try:
            return encode_message("/reply" + self.address, [json.dumps(body, ensure_ascii=False, allow_nan=False)])
        except ValueError:  # UnicodeEncodeError is one, and so is json's refusal of a NaN
            return encode_message("/reply" + self.address, [json.dumps(_finite(body))])


def _finite(value: Any) -> Any:
    """`value` with every float that is not finite (JSON has no NaN) as None."""
    if isinstance(value, float):
        return value if math.isfinite(value) else None
    if isinstance(value, dict):
        return {key: _finite(item) for key, item in value.items()}
    if isinstance(value, (list, tuple)):
        return [_finite(item) for item in value]
    return value


def status_reply(address: str, status: dict, most: int | None = None, advice: str = ASK_TCP) -> Reply:
    """The `/choreo/status` reply, in at most `most` bytes when given (over UDP: a reply larger
    than its datagram could not be sent at all, and is sent to an address that may be forged;
    over TCP: the longest message choreo takes, so a peer built alike takes it too): whole if
    it fits; else the robots' rows left out from the last, then the cues waiting, then the
    playhead, and `data["cut"]` and the message say what was left out, and `advice`."""
    state = str(status.get("state", ""))
    whole = Reply(address, "ok", state, status)
    if most is None:
        return whole
    robots, waiting = list(status.get("robots", {}).items()), list(status.get("waiting", []))
    at_most = _at_most(robots, most)  # measures the first robots only, as many as could fit
    if at_most == len(robots) and len(whole.encoded()) <= most:
        return whole

    def cut(kept_robots: int, kept_waiting: int, playhead: bool = True) -> Reply:
        left = {"robots": len(robots) - kept_robots, "waiting": len(waiting) - kept_waiting, "playhead": not playhead}
        data = {**status, "robots": dict(robots[:kept_robots]), "waiting": waiting[:kept_waiting], "cut": left}
        if not playhead:
            data["playhead"] = None
        why = (f"{state} (cut to {most} bytes: {left['robots']} of {len(robots)} robots, {left['waiting']} of "
               f"{len(waiting)} cues waiting{', the playhead' if not playhead else ''} left out; {advice})")
        return Reply(address, "ok", why, data)

    def fits(reply: Reply) -> bool:
        return len(reply.encoded()) <= most

    kept = _most_kept(at_most, lambda n: fits(cut(n, len(waiting))))
    if kept is not None:
        return cut(kept, len(waiting))
    kept = _most_kept(len(waiting), lambda n: fits(cut(0, n)))
    return cut(0, kept) if kept is not None else cut(0, 0, playhead=False)


def _at_most(items: list[tuple[str, Any]], most: int) -> int:
    """How many of the first `items` could fit in `most` bytes at best, each measured alone
    once: the search for how many do fit then encodes a reply a few times, each at most `most`
    long, not the whole status each time (1,000 robots: 26 ms a question on the thread that
    reads the operator's GO)."""
    total = 0
    for count, (key, value) in enumerate(items):
        total += len(json.dumps({key: value}, ensure_ascii=False).encode(errors="replace"))
        if total > most:
            return count
    return len(items)


def _most_kept(count: int, fits: Callable[[int], bool]) -> int | None:
    """The most of `count` items kept (the first ones) that `fits`, found in log2(count) tries,
    or None: not even none."""
    if not fits(0):
        return None
    low, high = 0, count  # fits(low); the answer is in low..high
    while low < high:
        middle = (low + high + 1) // 2
        if fits(middle):
            low = middle
        else:
            high = middle - 1
    return low


class BadAddress(ValueError):
    """An address of ours whose cue is not written as choreo reads it (a bad escape, not UTF-8, a
    control character): the message says what is wrong and how to write it."""


@dataclass(frozen=True)
class Wanted:
    """What an address asks: a `Live` command (its cue reference, unescaped, for cue_go, playhead
    and skip), or a question (`status`, `thump`), or `updates`."""

    name: str
    cue: str | None = None


def wanted(address: str) -> Wanted | None:
    """What an address asks, or None: not one of ours. BadAddress for a cue badly escaped."""
    if address in COMMANDS:
        return Wanted(COMMANDS[address])
    if address in QUERIES:
        return Wanted(QUERIES[address])
    if address == UPDATES:
        return Wanted("updates")
    for prefix, suffix, name in ((CUE_PREFIX, CUE_SUFFIX, "cue_go"), (PLAYHEAD_PREFIX, "", "playhead")):
        segment = _segment(address, prefix, suffix)
        if segment is not None:
            return Wanted(name, unescape(address, segment))
    return None


def wanted_or_none(address: str) -> Wanted | None:
    """`wanted`, with a cue badly escaped as None."""
    try:
        return wanted(address)
    except BadAddress:
        return None


def command_for(address: str) -> tuple[str, str | None] | None:
    """The `Live` command an address gives and its cue, or None (not a command; see `wanted`)."""
    asked = wanted(address)
    return None if asked is None or asked.name in (*QUERIES.values(), "updates") else (asked.name, asked.cue)


def _segment(address: str, prefix: str, suffix: str) -> str | None:
    """The one path segment between `prefix` and `suffix` (not empty), or None."""
    if len(address) > len(prefix) + len(suffix) and address.startswith(prefix) and address.endswith(suffix):
        segment = address[len(prefix):len(address) - len(suffix)]
        return None if "/" in segment else segment
    return None


def unescape(address: str, segment: str) -> str:
    """A cue's number or label as sent in an address, percent-escaped (`%2F` a slash, `%20` a
    space, `%25` a percent sign), decoded strictly: a `%` without two hex digits after it, bytes
    that are not UTF-8, or a control character (`%00`: no label holds one) is a BadAddress."""
    if "%" in segment:
        first, *escaped = segment.split("%")
        raw = bytearray(first.encode())
        for part in escaped:
            if len(part) < 2 or not HEX.issuperset(part[:2]):
                raise BadAddress(f"{address}: a '%' without two hex digits after it: {ESCAPING}")
            raw.append(int(part[:2], 16))
            raw += part[2:].encode()
        try:
            segment = raw.decode("utf-8")
        except UnicodeDecodeError:
            raise BadAddress(f"{address}: the escaped bytes are not UTF-8: {ESCAPING}") from None
    if any(unicodedata.category(char) == "Cc" for char in segment):
        raise BadAddress(f"{address}: a control character in a cue's number or label: {ESCAPING}")
    return segment


def escape(cue: str) -> str:
    """A cue's number or label as an address writes it (`unescape`'s inverse): `big%20bow`."""
    return urllib.parse.quote(cue, safe="")


def unknown_message(address: str) -> str:
    """Why an address is refused, with the command meant when there is one (see `suggestion`)."""
    if PATTERN_CHARS & set(address):
        return f"unknown command {address}: address patterns are not taken; send the command's own address"
    meant = _loosely(address)
    if meant is None and (address.startswith(CUE_PREFIX) and address.endswith(CUE_SUFFIX)
                          or address.startswith(PLAYHEAD_PREFIX)):
        return f"unknown command {address}: {ESCAPING}"  # a label's slash sent as it is
    meant = meant or _close(address)
    if meant is not None:
        return f"unknown command {address}: did you mean '{meant}'?"
    return f"unknown command {address} (choreo takes {ROOT}/ followed by {KNOWN})"


def suggestion(address: str) -> str | None:
    """The address meant, from choreo's own: one that differs from it only by case, a missing
    `/choreo` or a trailing slash (any command); else, for the commands that change nothing on
    stage (status, thump, updates, the playhead's moves), a close spelling, or a heartbeat's
    other names (`/ping`). Never a GO, a panic or another command with a stage effect for a
    mistyped address: a typo answered with a suggestion is typed again."""
    return _loosely(address) or _close(address)


def _close(address: str) -> str | None:
    """Of the addresses with no stage effect, the one `address` is a slip for, or None."""
    tail = address.rstrip("/").rsplit("/", 1)[-1].casefold()
    if tail in ALIASES:
        return ALIASES[tail]
    given = address[len(ROOT) + 1:] if address.casefold().startswith(ROOT + "/") else address.lstrip("/")
    meant = closest(given.casefold(), [*PATHS, "cue/CUE/go", *(known[len(ROOT) + 1:] for known in SUGGESTED)])
    # nearer a command that acts on stage than any other (`/choreo/strat`): no suggestion at all
    return f"{ROOT}/{meant}" if meant is not None and f"{ROOT}/{meant}" in SUGGESTED else None


def _loosely(address: str) -> str | None:
    """One of choreo's addresses that `address` is but for its case, a missing `/choreo`, a
    trailing slash (the cue it names kept as written), or None."""
    candidates = [address, address[:-1]] if address.endswith("/") else [address]
    for candidate in candidates:
        if not candidate.startswith("/"):
            continue
        parts = candidate.split("/")[1:]
        if _fold(parts[0]) != ROOT[1:]:
            parts = [ROOT[1:], *parts]
        fixed = _address_of(parts)
        if fixed is not None and fixed != address and wanted_or_none(fixed) is not None:  # its cue read too
            return fixed
    return None


def _address_of(parts: list[str]) -> str | None:
    """`choreo/...` split at its slashes, matched to an address of ours ignoring the case of all
    but the cue, or None."""
    folded = [_fold(part) for part in parts]
    joined = "/".join(folded[1:])
    if folded[0] != ROOT[1:] or not joined:
        return None
    if joined in PATHS or f"{ROOT}/{joined}" in (*QUERIES, UPDATES):
        return f"{ROOT}/{joined}"
    if len(parts) == 3 and folded[1] == "playhead" and parts[2]:
        return PLAYHEAD_PREFIX + parts[2]
    if len(parts) == 4 and folded[1] == "cue" and folded[3] == "go" and parts[2]:
        return CUE_PREFIX + parts[2] + CUE_SUFFIX
    return None


def _fold(text: str) -> str:
    """`text` in lower case, but only its ASCII letters: Unicode's folding would take
    `/choreo/ſtop` (a long s) or `/choreo/ﬆop` (a ligature) for `/choreo/stop`, and offer the
    stop as a mere difference of case."""
    return text.translate(ASCII_LOWER)


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
    return show_target((plain_host(sender[0]), sender[1]))


class OscServer:
    """Takes OSC commands for a `Live` on host:port (UDP and TCP), answers each, and (a run and
    command listener) notifies progress; see the module's docstring."""

    def __init__(self, live: Live, port: int, *, host: str = "127.0.0.1", allow: Sequence[str] = (),
                 notify: Sequence[Target] = (), limits: Limits = LIMITS,
                 now: Callable[[], float] = time.monotonic, wire_limits: OscLimits = WIRE_LIMITS) -> None:
        self.live = live
        self.host = host[1:-1] if host.startswith("[") and host.endswith("]") else host  # [::1], as URLs write it
        self.requested_port = port
        self.allow_given = tuple(allow)
        self.allow = parse_allow(allow)
        self.notify = tuple(notify)
        self._notifier = Notifier(self.notify, self._deliver)
        self._limits = SenderLimits(limits, now)  # what a sender's messages may cost
        self.subscriptions = Subscriptions(limits.update_subscribers, limits.update_expire_s, now, limits.update_bytes)
        self._closing = False
        self.wire_limits = wire_limits
        self.counts: Counter[str] = Counter()  # packets refused as malformed or unread, connections dropped
        self._net: OscNet | None = None
        self._verdicts: dict[str, tuple[str, bool]] = {}  # a sender's host: its plain host, allowed?

    # -- serving -----------------------------------------------------------------------------

    @property
    def port(self) -> int:
        """The port it listens on (the one the OS chose, when asked for port 0)."""
        return self._net.port if self._net is not None else self.requested_port

    def bind(self) -> None:
        """Listen (UDP and TCP), serving nothing yet, and look the notify targets up: a port in
        use or out of range, a target that does not resolve or is this very port, is a
        UsageError before anything else starts. Twice is harmless."""
        if self._net is None:
            net = OscNet(self, self.host, self.requested_port, self.wire_limits)
            try:
                net.bind()
            except ListenFailed as exc:
                raise UsageError(self._cannot_listen(exc)) from None
            try:
                self._notifier.resolve(net.port)
            except UsageError:
                net.close()
                raise
            self._net = net

    def start(self) -> None:
        self.bind()
        assert self._net is not None
        self._notifier.start()
        self._net.serve()

    def _cannot_listen(self, exc: ListenFailed) -> str:
        why = exc.why + (" (another program listens there: choose another port)" if exc.in_use else "")
        tcp = " (tcp)" if exc.transport == "tcp" else ""
        return f"--osc {self.requested_port}: cannot listen on {where(exc.address)}{tcp}: {why}"

    def close(self) -> None:
        """Stop listening; open connections are closed. Twice is harmless."""
        self._closing = True  # the connections it closes end their subscriptions without a word
        if self._net is not None:
            self._net.close()
        self._notifier.close()

    @property
    def bound_host(self) -> str:
        """The address listened on as the system took it (`0` and `localhost` are names for
        0.0.0.0 and 127.0.0.1: the line says which), or as given before binding."""
        return self._net.bound_host if self._net is not None else self.host

    @property
    def listening(self) -> str:
        """The start-up line: where, both transports, and who may command the show."""
        others = ", ".join(self.allow_given)
        who = f"commands from this machine and {others}" if others else "commands from this machine only"
        if others and _is_loopback_host(self.host):
            who += f" (but {self.host} is reachable from this machine only: give --osc-host 0.0.0.0)"
        line = f"osc: listening on {where((self.bound_host, self.port))} (udp and tcp), {who}"
        if self.notify:
            line += f"; progress to {', '.join(show_target(target) for target in self.notify)}"
        return line

    # -- packets (choreo.live.oscnet asks) --------------------------------------------------------

    def admit(self, sender: Sender) -> bool:
        """A TCP peer, at accept: a refused one is closed before a byte of it is read."""
        host, allowed = self._verdict(sender[0])
        if allowed:
            return True
        self._refuse(host, f"osc tcp {show_target((host, sender[1]))}", "")
        return False

    def packet(self, transport: str, sender: Sender, data: bytes) -> Handled:
        """One packet (a datagram, a TCP frame): its encoded replies. The sender is checked
        before the packet is read, and its rate of packets: past it the packet is counted and
        not read, at the least cost (a flood that costs choreo more than its sender outruns the
        socket, which then drops the operator's GO too). A malformed packet is refused whole.
        It was `read` if well-formed, and `spoke` if it carried an address of ours (a command, a
        question)."""
        host, allowed = self._verdict(sender[0])
        budget = budget_key(transport, host)
        cost = 1 + (len(data) - 1) // self.wire_limits.packet_bytes_per_token if data else 1  # reading is by the byte
        if not self._limits.may_read(budget, allowed, cost):
            self.counts[UNREAD] += 1
            self.live.count(UNREAD if allowed else "refused", f"osc {transport} {host}")
            return NOTHING
        spoke = read = False
        source = f"osc {transport} {show_target((host, sender[1]))}"  # `where`, from the remembered host
        if not allowed:
            replies = [self._refuse(host, source, "")]  # its address is not read: the reply is `/reply`
        else:
            origin = Origin(transport, sender, host, budget, source)
            self._tell_expired(self.subscriptions.heard(origin.key))  # any message renews its subscription
            decoded = decode_packet(data, self.wire_limits)
            if decoded.error is not None:
                replies = [self._malformed(budget, source, decoded.error, decoded.address)]
            else:
                replies = self._messages(origin, decoded.messages)
                read = True
                spoke = any(wanted_or_none(self._shown(m.address)) is not None for m in decoded.messages)
        return Handled.of((reply.encoded() for reply in replies if reply is not None), spoke, read)

    def rest_s(self, sender: Sender) -> float:
        """A TCP sender over its rate of packets: how long its connections are not read."""
        host, allowed = self._verdict(sender[0])
        return self._limits.rest_s(budget_key("tcp", host)) if allowed else 0.0

    def lost(self, transport: str, count: int) -> None:
        """Datagrams the system dropped unread (a flood faster than choreo reads): counted,
        so that the log's counts are what was sent (whose they were is not known)."""
        self.counts[LOST] += count
        self.live.count(LOST, f"osc {transport} (dropped by the system, unread)", count)

    def _verdict(self, host: str) -> tuple[str, bool]:
        """A sender's plain host and whether it may command the show, remembered (at most
        `SENDERS_KNOWN` of them: the table starts again when full)."""
        verdict = self._verdicts.get(host)
        if verdict is None:
            if len(self._verdicts) >= SENDERS_KNOWN:
                self._verdicts.clear()
            plain = plain_host(host)
            verdict = self._verdicts[host] = (plain, sender_allowed(plain, self.allow))
        return verdict

    def dropped(self, transport: str, sender: Sender, why: str) -> None:
        """A frame dropped or a connection closed by the transport's limits: counted, told."""
        self.counts["dropped"] += 1
        self._report(Command("dropped", f"osc {transport} {where(sender)}"), Answer("error", why))

    def closed(self, transport: str, sender: Sender) -> None:
        """A TCP connection ended: a subscription over it ends too (told, unless we are closing)."""
        subscriber = self.subscriptions.remove((transport, tuple(sender)))
        if subscriber is not None and not self._closing:
            self._report(Command(UPDATES_COMMAND, subscriber.source),
                         Answer("ok", "updates off: the connection closed"))

    def _messages(self, origin: Origin, messages: Sequence[Message]) -> list[Reply | None]:
        """One packet's messages in order (a bundle's, all in one call): the place to bound
        what one packet may do. Each message after the first is read within the sender's
        budget of packets as if it came alone (one bundle of 200 unknown addresses cost 7.5
        ms, 64 of them half a second of the thread that reads the operator's GO); the rest
        are counted, not read. The sender is allowed: a refused one's packet is not read."""
        replies = []
        for index, message in enumerate(messages):
            if index and not self._limits.may_read(origin.budget, True):
                self.counts[UNREAD] += len(messages) - index
                self.live.count(UNREAD, f"osc {origin.transport} {origin.host}", len(messages) - index)
                break
            replies.append(self._receive(origin, message.address, message.args))
        return replies

    def _malformed(self, budget: SenderKey, source: str, error: str, address: str | None) -> Reply | None:
        """A packet choreo cannot read whole: nothing of it is carried out. Its sender (allowed)
        is answered when the refused message's address could be read."""
        self.counts["malformed"] += 1
        address = self._shown(address) if address else address
        message = f"refused: OSC that choreo cannot read ({error}); nothing in the packet was carried out"
        self._report(Command("malformed", source, address), Answer("error", message))
        return self._answer(budget, Reply(address, "error", message)) if address else None

    # -- one message -------------------------------------------------------------------------

    def _receive(self, origin: Origin, address: str, args: tuple) -> Reply | None:
        """A message from an allowed sender (one of a bundle's, each counted alone): its reply
        (None: none is sent). What it may cost is bounded (`choreo.live.limits`): its commands are
        carried out and answered within its own budgets, and past them ignored (and counted)."""
        budget, source = origin.budget, origin.source
        address = self._shown(address)
        if address.startswith(ECHOES):  # a reply or notification come back: answering it could loop
            self._report(Command(ECHO, source, address), Answer("error", echo_message(address)))
            return None
        if address.endswith(CUT):
            return self._answer(budget, self._unknown(source, address, f"unknown command {address}: longer than any "
                                                                       "address choreo takes"))
        try:
            asked = wanted(address)
        except BadAddress as bad:
            return self._answer(budget, self._unknown(source, address, str(bad)))
        if asked is None:  # costs a reply and a log line, both bounded; a desk's fader moves spend no GO
            return self._answer(budget, self._unknown(source, address))
        if asked.name in QUERIES.values():
            return self._query(origin, address, asked.name)
        if not self._limits.admit(budget):
            message = self._limits.over_rate(origin.host)
            self._report(Command(asked.name, source, asked.cue), Answer("error", message))
            return self._answer(budget, Reply(address, "error", message))
        if asked.name == UPDATES_COMMAND:
            return self._answer(budget, self._updates(origin, address, args))
        if is_release(args):
            release = "ignored: a button's release (argument 0) is not a command"
            return self._answer(budget, Reply(address, "ok", release, {"ignored": True}))
        answer = self.live.command(Command(asked.name, source, asked.cue))
        return self._answer(budget, Reply(address, answer.status, answer.message, answer.data))

    def _query(self, origin: Origin, address: str, name: str) -> Reply | None:
        """`/choreo/status`, `/choreo/thump`: answered at once within the sender's budget of
        questions (past it, counted and not answered), never logged one by one (a desk polls)."""
        self.counts[name] += 1
        if not self._limits.may_query(origin.budget, costly=name == "status"):
            self.counts[UNANSWERED] += 1
            return None
        if name == "thump":
            return Reply(address, "ok", "thump", {"updates": origin.key in self.subscriptions})
        if origin.transport == "udp":
            return status_reply(address, self.live.status(), self._limits.limits.status_datagram)
        return status_reply(address, self.live.status(), self.wire_limits.max_message, "one message holds no more")

    def _updates(self, origin: Origin, address: str, args: tuple) -> Reply:
        """`/choreo/updates 1|0`: the sender gets the notifications (or no longer), logged as
        a command."""
        on = switch(args)
        if on is None:
            answer = Answer("error", "give 1 (send me the show's notifications) or 0 (stop): /choreo/updates 1")
        elif on:
            answer = self._subscribe(origin)
        elif self.subscriptions.remove(origin.key) is not None:
            answer = Answer("ok", "updates off", {"updates": False})
        else:
            answer = Answer("ok", "updates off already", {"updates": False})
        self._report(Command(UPDATES_COMMAND, origin.source), answer)
        return Reply(address, answer.status, answer.message, answer.data)

    def _subscribe(self, origin: Origin) -> Answer:
        expire = self.subscriptions.expire_s
        if origin.transport == "udp" and loops(origin.sender, self.port):
            return Answer("error", f"refused: {where(origin.sender)} is choreo's own port: each notification "
                                   "would come back as a command")
        taken, expired = self.subscriptions.add(origin.key, origin.transport, tuple(origin.sender), origin.source)
        self._tell_expired(expired)
        if not taken:
            most = self.subscriptions.most
            return Answer("error", f"refused: {most} senders get updates already (at most {most}): one must send "
                                   f"{UPDATES} 0, or fall silent for {expire:g} s")
        how = "on this connection" if origin.transport == "tcp" else f"to {where(origin.sender)}"
        return Answer("ok", f"updates on: the show's notifications {how}, until {UPDATES} 0 or {expire:g} s "
                            f"without a message (send {THUMP})", {"updates": True, "expire_s": expire})

    def _deliver(self, packet: bytes) -> None:
        """A notification, encoded, to every subscriber (the notifier's thread calls)."""
        net = self._net
        if net is None or not len(self.subscriptions):
            return
        subscribers, expired = self.subscriptions.current()
        self._tell_expired(expired)
        for subscriber in subscribers:
            if subscriber.may_send(packet):
                net.push(subscriber.transport, subscriber.sender, packet)
            else:
                self.counts[UNSENT] += 1

    def _tell_expired(self, expired: Sequence[Subscriber]) -> None:
        for subscriber in expired:
            self._report(Command(UPDATES_COMMAND, subscriber.source), Answer("ok", f"updates off: {subscriber.ended}"))

    def _answer(self, budget: SenderKey, reply: Reply) -> Reply | None:
        """The reply, if the sender's reply budget allows (one packet can ask for many)."""
        return reply if self._limits.may_reply(budget) else None

    def _refuse(self, host: str, source: str, address: str) -> Reply | None:
        message = f"refused: {host} may not command this show (give --osc-allow {host} to let it)"
        self._report(Command("refused", source, address or None), Answer("denied", message))
        return Reply(address, "denied", message) if self._limits.may_answer_refusal() else None

    def _unknown(self, source: str, address: str, why: str | None = None) -> Reply:
        message = why or unknown_message(address)
        self._report(Command("unknown", source, address), Answer("error", message))
        return Reply(address, "error", message)

    def _shown(self, address: str) -> str:
        """The address as the log, the terminal and a reply show it: cut past
        `Limits.address_shown` characters (no command's address is that long; a 64 KB one
        would cost a 64 KB log line, and a reply three times the bytes received)."""
        most = self._limits.limits.address_shown
        return address if len(address) <= most else address[:most] + CUT

    def _report(self, command: Command, answer: Answer) -> None:
        """A message `Live.command` has no name for, told to its listeners (the log) as it
        tells them of the commands it carries out."""
        self.live.report(command, answer)

    # -- listening to the show (notifications) -----------------------------------------------

    @property
    def _notifying(self) -> bool:
        """Anyone to notify: a target given, or a sender subscribed (read on a runner's path: cheap)."""
        return bool(self.notify) or len(self.subscriptions) > 0

    def on_step(self, event: StepEvent) -> None:
        if self._notifying:
            self._notifier.put(f"{NOTIFY}/step", event.robot or "", event.step.index, event.step.label or "",
                               event.event, round(event.actual_s, 6), event.outcome or "")

    def on_log(self, level: int, message: str, time_ns: int | None = None) -> None:
        if level >= WARNING and self._notifying:
            self._notifier.put(f"{NOTIFY}/fault" if level >= ERROR else f"{NOTIFY}/warning", message)

    def on_waiting(self, cue: GoCue) -> None:
        """The show reached a GO cue (from `Live`, once a cue)."""
        if self._notifying:
            self._notifier.put(f"{NOTIFY}/go", cue.name, cue.step.index, round(cue.reached_s, 6))

    def on_command(self, event: CommandEvent) -> None:
        """Every command but what came back from a notification or reply, and the summaries of
        those held back: notified, either could loop between two programs."""
        if self._notifying and event.command.name not in (ECHO, UNLOGGED):
            command, answer = event.command, event.answer
            self._notifier.put(f"{NOTIFY}/command", command.name, command.source, answer.status,
                               answer.message, command.label or "")

    def on_result(self, result: RunResult) -> None:
        """The run is over (`done` or `aborted`): for the caller to tell after `Session.run`."""
        if self._notifying:
            self._notifier.put(f"{NOTIFY}/done", result.outcome, result.steps_run, result.late_steps,
                               round(result.show_s, 6))


@dataclass(frozen=True)
class Origin:
    """Where a message came from: the transport, the sender's address (as the socket gives it),
    its plain host, whose budgets it spends, and how the log names it."""

    transport: str
    sender: Sender
    host: str
    budget: SenderKey
    source: str

    @property
    def key(self) -> tuple:
        """Its subscription's key: a UDP sender's address, a TCP sender's connection (its address)."""
        return self.transport, tuple(self.sender)


def switch(args: Sequence[Any]) -> bool | None:
    """`/choreo/updates`' one argument: 1 or 0 (an int, a float, true/false, or the text), else None."""
    if len(args) != 1:
        return None
    value = args[0].strip() if isinstance(args[0], str) else args[0]
    if value in (1, "1", True) and not isinstance(value, bytes):
        return True
    if value in (0, "0", False) and not isinstance(value, bytes):
        return False
    return None


def loops(sender: Sender, own_port: int) -> bool:
    """Would notifications sent to this UDP sender come back to us? Its address is our own port
    on this machine (forged: a datagram cannot come from the port it is sent to), or port 0 (no
    sender's: forged too). The checks `--osc-notify` targets get at start-up."""
    family = socket.AF_INET6 if len(sender) == 4 else socket.AF_INET
    return sender[1] == 0 or sender[1] == own_port and is_this_machine(str(sender[0]), family)


def budget_key(transport: str, host: str) -> SenderKey:
    """Whose budgets a packet spends: its sender's, over TCP apart from UDP. A TCP peer's address
    is proven by its handshake, a UDP sender's can be forged: a flood of datagrams forged in
    QLab's name must not spend the budgets of QLab's own TCP connection, nor, from many
    addresses, the places and totals TCP senders have."""
    return SenderKey(host, "tcp" if transport == "tcp" else "udp")


def echo_message(address: str) -> str:
    return (f"ignored: {address} is a reply or a notification, not a command (is a program's --osc-notify "
            "or reply port set to choreo's own?)")


def _is_loopback_host(host: str) -> bool:
    if host == "localhost":
        return True
    try:
        return ipaddress.ip_address(host).is_loopback
    except ValueError:
        return False
