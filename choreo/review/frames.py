"""`choreo log frames`: every frame and its reply, one line each, in the robot's words.

The log keeps a frame (`/rcb4/tx`) and its reply (`/rcb4/rx`, same `seq`) as two messages, the
reply right after its frame. `exchanges()` pairs them back up, streaming (one frame is held
until its reply arrives), and puts both on the show clock; `choreo log export` and the timeline
use the same pairs.
"""

from __future__ import annotations

from collections.abc import Iterator
from dataclasses import dataclass

from choreo.protocol import describe_frame, describe_reply
from choreo.review.reader import LogReader, decode
from choreo.logformat import RX_TOPIC, STEP_TOPIC, TX_TOPIC
from choreo.review.summary import show_zero_ns, stale_replies

class ShowClock:
    """Wall-clock log times to show-clock seconds.

    The show clock's zero is not in the metadata (the run's `start_ns` is taken when the run is
    prepared, before the port opens), but every step start carries its show time: the first
    one fixes the zero to the microsecond. Until one is seen, the metadata's start stands in.
    """

    def __init__(self, reader: LogReader) -> None:
        self.zero_ns = show_zero_ns(reader)
        self.from_step = False

    def see_step(self, log_time: int, message: dict) -> None:
        if message.get("event") == "start":
            self.see_start(log_time, message["actual_s"])

    def see_start(self, log_time: int, actual_s: float) -> None:
        """A step started at `actual_s` on the show clock: the first one fixes the zero."""
        if not self.from_step:
            self.zero_ns = log_time - round(actual_s * 1e9)
            self.from_step = True

    def seconds(self, log_time: int | None) -> float | None:
        if log_time is None:
            return None
        if self.zero_ns is None:
            self.zero_ns = log_time  # no metadata and no step: the first frame is zero
        return (log_time - self.zero_ns) / 1e9


@dataclass(frozen=True, slots=True)
class Exchange:
    """One frame sent and what came back for it (tx or rx may be missing in a cut or odd log)."""

    seq: int
    tx: dict | None
    tx_ns: int | None
    tx_s: float | None  # show clock
    rx: dict | None
    rx_ns: int | None
    rx_s: float | None

    @property
    def step(self) -> int | None:
        return self.tx.get("step") if self.tx else None

    @property
    def frame_kind(self) -> str | None:
        return self.tx.get("kind") if self.tx else None

    @property
    def reply_kind(self) -> str | None:
        return self.rx.get("kind") if self.rx else None


def exchanges(reader: LogReader, clock: ShowClock | None = None) -> Iterator[Exchange]:
    """Frames paired with their replies, in the order they were sent."""
    clock = clock or ShowClock(reader)
    held: tuple[dict, int] | None = None  # a frame whose reply has not come yet
    topic, number = None, 0
    try:
        for topic, log_time, data in reader.messages((TX_TOPIC, RX_TOPIC, STEP_TOPIC)):
            number += 1
            if topic == STEP_TOPIC:
                if not clock.from_step:
                    clock.see_step(log_time, decode(data))
                continue
            message = decode(data)
            if topic == TX_TOPIC:
                if held is not None:
                    yield _pair(clock, held[0], held[1], None, None)
                held = (message, log_time)
            elif held is not None and held[0].get("seq") == message.get("seq"):
                yield _pair(clock, held[0], held[1], message, log_time)
                held = None
            else:  # a reply without its frame in the log
                yield _pair(clock, None, None, message, log_time)
    except (KeyError, TypeError, ValueError, AttributeError) as exc:
        raise reader.not_choreo(topic, number, exc) from None
    if held is not None:
        yield _pair(clock, held[0], held[1], None, None)


def _pair(clock: ShowClock, tx: dict | None, tx_ns: int | None, rx: dict | None, rx_ns: int | None) -> Exchange:
    seq = (tx or rx or {}).get("seq", 0)
    return Exchange(seq, tx, tx_ns, clock.seconds(tx_ns), rx, rx_ns, clock.seconds(rx_ns))


def frame_meaning(tx: dict) -> str:
    """What a sent frame does, from its bytes: `CALL 0x000bb8: motion 0`."""
    try:
        return describe_frame(bytes.fromhex(tx.get("hex", "")))
    except ValueError:
        return f"not hex: {tx.get('hex')!r}"


def reply_meaning(rx: dict) -> str:
    """What came back, in words: `ACK`, `status 0x23: executing`, or why it was refused."""
    kind = rx.get("kind")
    if kind in ("timeout", "invalid"):
        error = rx.get("error") or ("no reply" if kind == "timeout" else "invalid reply")
        return f"{kind}: {error}"
    try:
        return describe_reply(bytes.fromhex(rx.get("hex", "")))
    except ValueError:
        return f"not hex: {rx.get('hex')!r}"


def stale_note(rx: dict) -> str:
    """` (set aside a late reply: 04 00 06 0a)` after a reply that came with late ones, or ``."""
    replies = stale_replies(rx.get("stale"))
    if not replies:
        return ""
    what = "a late reply" if len(replies) == 1 else f"{len(replies)} late replies"
    return f" (set aside {what}: {', '.join(replies)})"


def matches(exchange: Exchange, step: int | None, kind: str | None) -> bool:
    """`--step N` and `--kind K`: K names a frame kind or a reply kind; either side matching
    keeps the pair, so `--kind nak` shows each refused frame with its NAK."""
    if step is not None and exchange.step != step:
        return False
    if kind is not None and kind not in (exchange.frame_kind, exchange.reply_kind):
        return False
    return True


def _time(seconds: float | None) -> str:
    return f"{seconds:10.6f}" if seconds is not None else " " * 10


def lines(exchange: Exchange) -> Iterator[str]:
    """`show_s  tx  seq  kind  hex  meaning` and the same for its reply."""
    tx, rx = exchange.tx, exchange.rx
    if tx is not None:
        step = tx.get("step")
        where = f"step {step}" if step is not None else "abort" if tx.get("label") == "on_abort" else "-"
        retry = f" (try {tx['attempt']})" if tx.get("attempt", 1) > 1 else ""
        yield (f"{_time(exchange.tx_s)}  tx  #{exchange.seq:<6} {where:<9} {tx.get('kind', '?'):<8} "
               f"{tx.get('hex', ''):<56} {frame_meaning(tx)}{retry}")
    if rx is not None:
        latency = f"{rx.get('latency_ms', 0):.3f} ms"
        yield (f"{_time(exchange.rx_s)}  rx  #{exchange.seq:<6} {latency:<9} {rx.get('kind', '?'):<8} "
               f"{rx.get('hex', ''):<56} {reply_meaning(rx)}{stale_note(rx)}")
    elif tx is not None:
        yield f"{'':10}  rx  #{exchange.seq:<6} {'':9} {'-':<8} {'':56} no reply in the log (it ends here)"


HEADER = f"{'show s':>10}  dir {'seq':<7} {'step/lat':<9} {'kind':<8} {'bytes':<56} meaning"


def frame_lines(reader: LogReader, step: int | None = None, kind: str | None = None) -> Iterator[str]:
    """Every line `choreo log frames` prints, header first; a cut log ends with where it stops."""
    yield HEADER
    shown = 0
    for exchange in exchanges(reader):
        if matches(exchange, step, kind):
            shown += 1
            try:
                yield from lines(exchange)
            except (KeyError, TypeError, ValueError, AttributeError) as exc:
                raise reader.not_choreo(TX_TOPIC, exchange.seq, exc) from None
    if reader.cut is not None:
        yield f"log {reader.cut.state}: {reader.cut}"
    if not shown:
        wanted = " and ".join(x for x in (f"step {step}" if step is not None else "",
                                         f"kind {kind}" if kind else "") if x)
        yield f"no frames{' with ' + wanted if wanted else ''} in this log"
