"""What the outside may cost a running show: the limits on commands, replies, log lines and
printed lines, in one place (docs/live.md, "Limits", lists them), and the token
buckets that keep them. (The network's own limits, connections, sizes and timeouts, are
`choreo.live.osclimits`.)

Why they exist: a command from the network costs the show a log line, a line on the terminal and
a reply. A flood of them (80,000 GOs in 5 s) would fill the disk, which stops the show, and the
terminal; one UDP packet (a bundle of 408 GOs) would have choreo send 408 replies to a sender
whose address may be forged. So:

- each allowed sender (an address: every port of a machine is one sender) may have
  `commands_per_sender` carried out, and all of them together `commands_total`, over UDP apart
  from TCP (a bundle's messages count one by one; an address choreo does not know is no command
  and spends none); the rest are not carried out. Apart, because a UDP sender's address can be
  forged: ten addresses of an allowed network flooding datagrams took the whole total, and the
  operator's GO over TCP, from an address its handshake proves, was 'ignored' for as long;
- each allowed sender's packets are read within `packets_per_sender` (a datagram, a TCP frame;
  one more token per 4 KB past its first, and for each message of a bundle after its first),
  over TCP apart from UDP, and all refused senders' within one such budget: past it a packet is
  counted, not read, at the least cost there is, so that a flood costs choreo less than it costs
  the sender and the operator's GO, from another address, is still read in time (a flood the
  socket cannot keep up with would drop it); a TCP sender past it rests unread;
- each sender gets at most `replies_per_sender` replies, and the senders refused (not allowed)
  `refusals` replies between them (their addresses are the easiest to forge);
- the questions (`/choreo/status`, `/choreo/thump`) are answered within `queries_per_sender`
  of their own, not the commands' nor the replies' (a desk polling status ten times a second
  must not take the answer to its GO); they carry nothing out and are not logged one by one,
  only counted (a log line each at a desk's polling rate would fill the disk); all senders'
  status questions together are answered within `queries_total` (each answer is sent to an address
  that may be forged: a status reply is kilobytes for a question of 24 bytes), and a status
  reply over UDP is at most `status_datagram` bytes (cut, and saying so, past it);
- at most `update_subscribers` senders get the show's notifications at once (`/choreo/updates
  1`: each one multiplies what the show sends), each until `update_expire_s` without a message
  from it; a UDP subscriber (its address may be forged: the notifications would go to a victim)
  is sent at most `update_bytes` of them, the rest dropped, so that one forged datagram costs at
  most its burst plus its rate for `update_expire_s` (about 1 MB), four of them at once;
- a command that is taken (`ok`) is always logged and shown; refused and ignored ones are, one
  by one, only within `reported`: the rest are counted, and every `summary_every_s` one
  `unlogged` record (the log, the terminal) carries their counts, by command, so the log's
  review adds up to the true totals.
"""

from __future__ import annotations

import threading
import time
from collections import Counter
from collections.abc import Callable, Hashable
from dataclasses import dataclass



@dataclass(frozen=True)
class Rate:
    """A token bucket's shape: `burst` at once, then `per_s` a second."""

    burst: int
    per_s: float

    def describe(self) -> str:
        return f"{self.burst} at once, then {self.per_s:g} a second"


@dataclass(frozen=True)
class Limits:
    """Every limit on what commands from outside may cost (docs/live.md, "Limits", lists them)."""

    packets_per_sender: Rate = Rate(256, 128.0)  # packets (a bundle's messages) read for one sender; the rest counted
    commands_per_sender: Rate = Rate(10, 5.0)  # commands carried out for one sender (its host)
    commands_total: Rate = Rate(20, 10.0)  # commands carried out for all allowed senders together
    replies_per_sender: Rate = Rate(10, 5.0)  # replies sent to one sender
    refusals: Rate = Rate(10, 1.0)  # replies to senders not allowed, all of them together
    reported: Rate = Rate(10, 2.0)  # refused/ignored commands logged and printed one by one
    summary_every_s: float = 1.0  # how often the commands not logged one by one are summed up
    address_shown: int = 256  # characters of an OSC address logged, printed or replied; past them, cut
    senders_tracked: int = 256  # senders with a budget of their own; beyond, new ones share one
    notify_targets: int = 8  # --osc-notify given at most this many times
    queries_per_sender: Rate = Rate(20, 10.0)  # /choreo/status and /thump answered for one sender
    queries_total: Rate = Rate(40, 20.0)  # status answered, all senders together (replies may go to forged addresses)
    status_datagram: int = 16384  # bytes of a /choreo/status reply over UDP at most (robots left out past it)
    update_subscribers: int = 4  # senders subscribed to the notifications (/choreo/updates 1) at once
    update_expire_s: float = 61.0  # a subscription ends after this long without a message from it (QLab's)
    update_bytes: Rate = Rate(65536, 16384.0)  # bytes of notifications sent to one UDP subscriber; the rest dropped
    link_events: Rate = Rate(20, 5.0)  # Link session changes logged (a sample, a line) one by one; the rest summed


LIMITS = Limits()


class Budget:
    """A token bucket of `Rate`: `take` says whether the tokens were there (and takes them)."""

    def __init__(self, burst: int, per_s: float, now: Callable[[], float] = time.monotonic) -> None:
        self.burst = burst
        self.per_s = per_s
        self._now = now
        self._tokens = float(burst)
        self._at = now()
        self._lock = threading.Lock()

    @classmethod
    def of(cls, rate: Rate, now: Callable[[], float] = time.monotonic) -> Budget:
        return cls(rate.burst, rate.per_s, now)

    def take(self, tokens: int = 1) -> bool:
        with self._lock:
            self._refill()
            if self._tokens < tokens:
                return False
            self._tokens -= tokens
            return True

    def empty_for_s(self) -> float:
        """0 while a token is left; once spent, the time to refill whole (a sender that
        emptied its bucket is let rest until it may send a burst again, not one at a time)."""
        with self._lock:
            self._refill()
            return 0.0 if self._tokens >= 1.0 else (self.burst - self._tokens) / self.per_s

    @property
    def full(self) -> bool:
        """Nothing taken lately: the bucket has refilled (its owner is idle)."""
        with self._lock:
            self._refill()
            return self._tokens >= self.burst

    def _refill(self) -> None:
        """The lock is held."""
        now = self._now()
        self._tokens = min(float(self.burst), self._tokens + max(0.0, now - self._at) * self.per_s)
        self._at = now


class Budgets:
    """A `Budget` for each key (a sender's host), at most `keys` of them: when the table is full,
    idle senders' buckets go, and if none is idle a new sender shares one overflow bucket (so a
    flood of forged addresses cannot grow the table, nor take a known sender's budget)."""

    _OVERFLOW = object()

    def __init__(self, rate: Rate, keys: int, now: Callable[[], float] = time.monotonic) -> None:
        self.rate = rate
        self.keys = keys
        self._now = now
        self._budgets: dict[object, Budget] = {}
        self._lock = threading.Lock()
        self._swept_at: float | None = None  # when idle buckets were last looked for

    def take(self, key: Hashable, tokens: int = 1) -> bool:
        return self._budget(key).take(tokens)

    def empty_for_s(self, key: Hashable) -> float:
        return self._budget(key).empty_for_s()

    def _budget(self, key: Hashable) -> Budget:
        with self._lock:
            budget = self._budgets.get(key)
            if budget is not None:
                return budget
            if len(self._budgets) >= self.keys:
                self._sweep()
            if len(self._budgets) >= self.keys:
                key = self._OVERFLOW
            budget = self._budgets.get(key)
            if budget is None:
                budget = self._budgets[key] = Budget.of(self.rate, self._now)
            return budget

    def _sweep(self) -> None:
        """The lock is held. Idle buckets go, looked for at most once in the time a bucket
        takes to refill (a bucket cannot become idle sooner): a flood of new addresses would
        otherwise cost a pass over the whole table for each of its packets."""
        now = self._now()
        if self._swept_at is not None and now - self._swept_at < self.rate.burst / self.rate.per_s:
            return
        self._swept_at = now
        for idle in [k for k, b in self._budgets.items() if k is not self._OVERFLOW and b.full]:
            del self._budgets[idle]


@dataclass(frozen=True)
class SenderKey:
    """Whose budgets a packet spends: its sender's host, over TCP apart from UDP (a key that is
    not a SenderKey, a plain host, is a UDP sender's)."""

    host: str
    transport: str = "udp"


def _transport(key: Hashable) -> str:
    return key.transport if isinstance(key, SenderKey) and key.transport == "tcp" else "udp"


class _ByTransport:
    """A `Budgets` for UDP senders and one for TCP senders: a UDP sender's address can be
    forged, and a flood from more addresses than a table holds must neither take the places of
    TCP senders (whose handshake proves their address) nor drain the bucket the newcomers share."""

    def __init__(self, rate: Rate, keys: int, now: Callable[[], float]) -> None:
        self._tables = {transport: Budgets(rate, keys, now) for transport in ("udp", "tcp")}

    def take(self, key: Hashable, tokens: int = 1) -> bool:
        return self._tables[_transport(key)].take(key, tokens)

    def empty_for_s(self, key: Hashable) -> float:
        return self._tables[_transport(key)].empty_for_s(key)


class SenderLimits:
    """The network's side of the limits: whether a sender's command is carried out, and whether
    a reply goes back to it (`Limits` says how many)."""

    def __init__(self, limits: Limits = LIMITS, now: Callable[[], float] = time.monotonic) -> None:
        self.limits = limits
        self._packets = _ByTransport(limits.packets_per_sender, limits.senders_tracked, now)
        self._refused_packets = Budget.of(limits.packets_per_sender, now)
        self._commands = _ByTransport(limits.commands_per_sender, limits.senders_tracked, now)
        self._total = {transport: Budget.of(limits.commands_total, now) for transport in ("udp", "tcp")}
        self._replies = _ByTransport(limits.replies_per_sender, limits.senders_tracked, now)
        self._refusals = Budget.of(limits.refusals, now)
        self._queries = _ByTransport(limits.queries_per_sender, limits.senders_tracked, now)
        self._queries_total = {transport: Budget.of(limits.queries_total, now) for transport in ("udp", "tcp")}

    def may_read(self, host: Hashable, allowed: bool, tokens: int = 1) -> bool:
        """May a packet from `host` be read now (`tokens`: what reading it costs, a big one
        more)? Senders not allowed share one budget (their packets are refused, never read;
        their addresses are the easiest to forge, and many of them must not take the table's
        places from the allowed ones)."""
        if not allowed:
            return self._refused_packets.take(tokens)
        return self._packets.take(host, tokens)

    def rest_s(self, host: Hashable) -> float:
        """How long an allowed TCP sender that has spent its packets' budget is not read (TCP
        holds its bytes meanwhile, at no cost to choreo); 0 while it has some left."""
        return self._packets.empty_for_s(host)

    def admit(self, host: Hashable) -> bool:
        """May a command from `host` (a SenderKey) be carried out now? Its own budget first, so
        a flooding sender spends its own tokens, not the others' share of the total; then the
        total of its transport's senders (UDP's, whose addresses can be forged, cannot take TCP's)."""
        return self._commands.take(host) and self._total[_transport(host)].take()

    def may_reply(self, host: Hashable) -> bool:
        return self._replies.take(host)

    def may_query(self, host: Hashable, costly: bool = True) -> bool:
        """May a question from `host` (status, thump) be answered now? A budget apart from the
        commands' and replies': polling spends neither. Its own budget first, then, for a
        `costly` one (status: kilobytes), all senders' (a heartbeat's reply is as small as a
        command's: a status flood must not silence a desk's heartbeat), its transport's (a flood
        of datagrams from forged addresses must not silence a TCP desk's status either)."""
        return self._queries.take(host) and (not costly or self._queries_total[_transport(host)].take())

    def may_answer_refusal(self) -> bool:
        """A reply to a sender not allowed (shared by all of them: their addresses are forged
        most easily)."""
        return self._refusals.take()

    def over_rate(self, host: str) -> str:
        """Why a command from `host` was not carried out."""
        return (f"ignored: over the limit of commands ({self.limits.commands_per_sender.describe()} from one "
                f"sender, {self.limits.commands_total.describe()} from all): is {host} flooding the show?")


@dataclass(frozen=True)
class Held:
    """Refused or ignored commands not reported one by one since the last summary."""

    counts: dict[str, int]  # by command name
    sources: tuple[str, ...]  # the sources they came from (the first `SOURCES_KEPT`)
    more_sources: bool = False  # and others beyond those

    SOURCES_KEPT = 64

    @property
    def count(self) -> int:
        return sum(self.counts.values())

    def message(self) -> str:
        what = ", ".join(f"{n} {name}" for name, n in sorted(self.counts.items(), key=lambda kv: -kv[1]))
        named = ", ".join(self.sources[:3])
        others = len(self.sources) - 3
        more = f" and {others}{'+' if self.more_sources else ''} more" if others > 0 or self.more_sources else ""
        return (f"refused or ignored: {self.count} commands not logged one by one (over the log's limit): {what}; "
                f"from {named}{more}")

    @property
    def source(self) -> str:
        if len(self.sources) == 1 and not self.more_sources:
            return self.sources[0]
        return f"{len(self.sources)}{'+' if self.more_sources else ''} sources"


class ReportGate:
    """Which command events reach the listeners (the log, the terminal, notifications): every
    one taken; refused and ignored ones within `Limits.reported`, the rest held as counts and
    summed up (`due`) at most every `Limits.summary_every_s`."""

    def __init__(self, limits: Limits = LIMITS, now: Callable[[], float] = time.monotonic) -> None:
        self.every_s = limits.summary_every_s
        self._now = now
        self._budget = Budget.of(limits.reported, now)
        self._counts: Counter[str] = Counter()
        self._sources: dict[str, None] = {}  # an ordered set, of at most Held.SOURCES_KEPT
        self._more_sources = False
        self._last = now()
        self._lock = threading.Lock()

    def passes(self, name: str, source: str, ok: bool) -> bool:
        """Report this one now? If not, it is counted for the next summary."""
        if ok or self._budget.take():
            return True
        self.hold(name, source)
        return False

    def hold(self, name: str, source: str, n: int = 1) -> None:
        """`n` more `name` not reported one by one (packets not even read: no budget spent)."""
        with self._lock:
            self._counts[name] += n
            if source not in self._sources:
                if len(self._sources) < Held.SOURCES_KEPT:
                    self._sources[source] = None
                else:
                    self._more_sources = True

    def due(self, force: bool = False) -> Held | None:
        """The commands held since the last summary, if it is time to sum them up (`force`:
        now, at the end)."""
        with self._lock:
            now = self._now()
            if not self._counts or (not force and now - self._last < self.every_s):
                return None
            held = Held(dict(self._counts), tuple(self._sources), self._more_sources)
            self._counts.clear()
            self._sources.clear()
            self._more_sources = False
            self._last = now
            return held


class Ticker:
    """Calls `tick` every `every_s` from a thread of its own until `close` (the summaries of
    held commands come out even when no other command does)."""

    def __init__(self, tick: Callable[[], object], every_s: float) -> None:
        self._tick = tick
        self._every_s = every_s
        self._done = threading.Event()
        self._thread = threading.Thread(target=self._loop, name="choreo-summaries", daemon=True)

    def start(self) -> Ticker:
        self._thread.start()
        return self

    def _loop(self) -> None:
        while not self._done.wait(self._every_s):
            self._tick()

    def close(self) -> None:
        self._done.set()
        if self._thread.is_alive():
            self._thread.join(1.0)
