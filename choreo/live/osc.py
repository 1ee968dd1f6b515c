"""OSC control of a running show, in QLab's manner, so that a QLab Network cue (or TouchOSC, Max,
a lighting desk) can give the GO: `/choreo/go`, `/choreo/panic`, `/choreo/start`, `/choreo/stop`
and `/choreo/cue/LABEL/go`, over UDP and over TCP framed with SLIP (OSC 1.1, as QLab sends it)
or with a length prefix (OSC 1.0, as liblo sends it: Pure Data, SuperCollider), on one port number.

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
import time
from collections import Counter
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from typing import Any


from choreo.errors import UsageError, did_you_mean
from choreo.events import Answer, Command, CommandEvent, GoCue, RunResult, StepEvent
from choreo.live.limits import LIMITS, Limits, SenderLimits
from choreo.log.format import UNLOGGED
from choreo.live.controls import Live
from choreo.live.oscnet import ListenFailed, OscNet
from choreo.live.osclimits import LIMITS as WIRE_LIMITS
from choreo.live.osclimits import OscLimits
from choreo.live.oscnotify import Notifier, Target, show_target
from choreo.live.oscwire import Message, decode_packet, encode_message
from choreo.log.format import ERROR, WARNING

# OSC addresses, not log topics (those are spelled in choreo.log.format), though both start /choreo
ROOT = "/choreo"
COMMANDS = {f"{ROOT}/{name}": name for name in ("go", "panic", "start", "stop")}
CUE_PREFIX, CUE_SUFFIX = f"{ROOT}/cue/", "/go"
NOTIFY = f"{ROOT}/notify"
PATTERN_CHARS = frozenset("*?[]{}")
ECHOES = ("/reply", NOTIFY)  # replies and notifications: never commands, never answered (two would loop)
ECHO = "echo"  # the command name a reply or notification sent to us is logged under
LOST = "lost"  # the command name datagrams the system dropped before choreo read them are counted under
UNREAD = "unread"  # the command name a packet over its sender's rate is counted under (not read)
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
        """The OSC message sent back: `/reply` + the address, the JSON its one argument."""
        body = {"address": self.address, "status": self.status, "message": self.message, "data": self.data}
        return encode_message("/reply" + self.address, [json.dumps(body, ensure_ascii=False)])


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
    return show_target((plain_host(sender[0]), sender[1]))


class OscServer:
    """Takes OSC commands for a `Live` on host:port (UDP and TCP), answers each, and (a run and
    command listener) notifies progress; see the module's docstring."""

    def __init__(self, live: Live, port: int, *, host: str = "127.0.0.1", allow: Sequence[str] = (),
                 notify: Sequence[Target] = (), limits: Limits = LIMITS,
                 now: Callable[[], float] = time.monotonic, wire_limits: OscLimits = WIRE_LIMITS) -> None:
        self.live = live
        self.host = host
        self.requested_port = port
        self.allow_given = tuple(allow)
        self.allow = parse_allow(allow)
        self.notify = tuple(notify)
        self._notifier = Notifier(self.notify) if self.notify else None
        self._limits = SenderLimits(limits, now)  # what a sender's messages may cost
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
            if self._notifier is not None:
                try:
                    self._notifier.resolve(net.port)
                except UsageError:
                    net.close()
                    raise
            self._net = net

    def start(self) -> None:
        self.bind()
        assert self._net is not None
        if self._notifier is not None:
            self._notifier.start()
        self._net.serve()

    def _cannot_listen(self, exc: ListenFailed) -> str:
        why = exc.why + (" (another program listens there: choose another port)" if exc.in_use else "")
        tcp = " (tcp)" if exc.transport == "tcp" else ""
        return f"--osc {self.requested_port}: cannot listen on {where(exc.address)}{tcp}: {why}"

    def close(self) -> None:
        """Stop listening; open connections are closed. Twice is harmless."""
        if self._net is not None:
            self._net.close()
        if self._notifier is not None:
            self._notifier.close()

    @property
    def listening(self) -> str:
        """The start-up line: where, both transports, and who may command the show."""
        others = ", ".join(self.allow_given)
        who = f"commands from this machine and {others}" if others else "commands from this machine only"
        if others and _is_loopback_host(self.host):
            who += f" (but {self.host} is reachable from this machine only: give --osc-host 0.0.0.0)"
        line = f"osc: listening on {where((self.host, self.port))} (udp and tcp), {who}"
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

    def packet(self, transport: str, sender: Sender, data: bytes) -> list[bytes]:
        """One packet (a datagram, a TCP frame): its encoded replies. The sender is checked
        before the packet is read, and its rate of packets: past it the packet is counted and
        not read, at the least cost (a flood that costs choreo more than its sender outruns the
        socket, which then drops the operator's GO too). A malformed packet is refused whole."""
        host, allowed = self._verdict(sender[0])
        budget = budget_key(transport, host)
        cost = 1 + (len(data) - 1) // self.wire_limits.packet_bytes_per_token if data else 1  # reading is by the byte
        if not self._limits.may_read(budget, allowed, cost):
            self.counts[UNREAD] += 1
            self.live.count(UNREAD if allowed else "refused", f"osc {transport} {host}")
            return []
        source = f"osc {transport} {show_target((host, sender[1]))}"  # `where`, from the remembered host
        if not allowed:
            replies = [self._refuse(host, source, "")]  # its address is not read: the reply is `/reply`
        else:
            decoded = decode_packet(data, self.wire_limits)
            if decoded.error is not None:
                replies = [self._malformed(budget, source, decoded.error, decoded.address)]
            else:
                replies = self._messages(transport, host, budget, source, decoded.messages)
        return [reply.encoded() for reply in replies if reply is not None]

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

    def _messages(self, transport: str, host: str, budget: str, source: str,
                  messages: Sequence[Message]) -> list[Reply | None]:
        """One packet's messages in order (a bundle's, all in one call): the place to bound
        what one packet may do. Each message after the first is read within the sender's
        budget of packets as if it came alone (one bundle of 200 unknown addresses cost 7.5
        ms, 64 of them half a second of the thread that reads the operator's GO); the rest
        are counted, not read. The sender is allowed: a refused one's packet is not read."""
        replies = []
        for index, message in enumerate(messages):
            if index and not self._limits.may_read(budget, True):
                self.counts[UNREAD] += len(messages) - index
                self.live.count(UNREAD, f"osc {transport} {host}", len(messages) - index)
                break
            replies.append(self._receive(host, budget, source, message.address, message.args))
        return replies

    def _malformed(self, budget: str, source: str, error: str, address: str | None) -> Reply | None:
        """A packet choreo cannot read whole: nothing of it is carried out. Its sender (allowed)
        is answered when the refused message's address could be read."""
        self.counts["malformed"] += 1
        address = self._shown(address) if address else address
        message = f"refused: OSC that choreo cannot read ({error}); nothing in the packet was carried out"
        self._report(Command("malformed", source, address), Answer("error", message))
        return self._answer(budget, Reply(address, "error", message)) if address else None

    # -- one message -------------------------------------------------------------------------

    def _receive(self, host: str, budget: str, source: str, address: str, args: tuple) -> Reply | None:
        """A message from an allowed sender (one of a bundle's, each counted alone): its reply
        (None: none is sent). What it may cost is bounded (`choreo.live.limits`): its commands are
        carried out and answered within its own budgets, and past them ignored (and counted)."""
        address = self._shown(address)
        if address.startswith(ECHOES):  # a reply or notification come back: answering it could loop
            self._report(Command(ECHO, source, address), Answer("error", echo_message(address)))
            return None
        wanted = command_for(address)
        if wanted is None:  # costs a reply and a log line, both bounded; a desk's fader moves spend no GO
            return self._answer(budget, self._unknown(source, address))
        name, label = wanted
        if not self._limits.admit(budget):
            message = self._limits.over_rate(host)
            self._report(Command(name, source, label), Answer("error", message))
            return self._answer(budget, Reply(address, "error", message))
        if is_release(args):
            release = "ignored: a button's release (argument 0) is not a command"
            return self._answer(budget, Reply(address, "ok", release, {"ignored": True}))
        answer = self.live.command(Command(name, source, label))
        return self._answer(budget, Reply(address, answer.status, answer.message, answer.data))

    def _answer(self, budget: str, reply: Reply) -> Reply | None:
        """The reply, if the sender's reply budget allows (one packet can ask for many)."""
        return reply if self._limits.may_reply(budget) else None

    def _refuse(self, host: str, source: str, address: str) -> Reply | None:
        message = f"refused: {host} may not command this show (give --osc-allow {host} to let it)"
        self._report(Command("refused", source, address or None), Answer("denied", message))
        return Reply(address, "denied", message) if self._limits.may_answer_refusal() else None

    def _unknown(self, source: str, address: str) -> Reply:
        message = unknown_message(address)
        self._report(Command("unknown", source, address), Answer("error", message))
        return Reply(address, "error", message)

    def _shown(self, address: str) -> str:
        """The address as the log, the terminal and a reply show it: cut past
        `Limits.address_shown` characters (no command's address is that long; a 64 KB one
        would cost a 64 KB log line, and a reply three times the bytes received)."""
        most = self._limits.limits.address_shown
        return address if len(address) <= most else address[:most] + "…"

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
        """Every command but what came back from a notification or reply, and the summaries of
        those held back: notified, either could loop between two programs."""
        if self._notifier is not None and event.command.name not in (ECHO, UNLOGGED):
            command, answer = event.command, event.answer
            self._notifier.put(f"{NOTIFY}/command", command.name, command.source, answer.status,
                               answer.message, command.label or "")

    def on_result(self, result: RunResult) -> None:
        """The run is over (`done` or `aborted`): for the caller to tell after `Session.run`."""
        if self._notifier is not None:
            self._notifier.put(f"{NOTIFY}/done", result.outcome, result.steps_run, result.late_steps,
                               round(result.show_s, 6))


def budget_key(transport: str, host: str) -> str:
    """Whose budgets a packet spends: its sender's, over TCP apart from UDP. A TCP peer's address
    is proven by its handshake, a UDP sender's can be forged: a flood of datagrams forged in
    QLab's name must not spend the budgets of QLab's own TCP connection."""
    return host if transport == "udp" else f"{host} (tcp)"


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
