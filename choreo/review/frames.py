"""`choreo log frames`: every frame and its reply, one line each, in the robot's words.

The log keeps a frame (`/rcb4/tx`) and its reply (`/rcb4/rx`, same `seq`) as two messages, the
reply right after its frame. `exchanges()` pairs them back up, streaming (one frame is held
until its reply arrives), and puts both on the show clock; `choreo log export` and the timeline
use the same pairs.
"""

from __future__ import annotations

from collections.abc import Iterator
from dataclasses import dataclass

from choreo.log.format import (ABORT_LABEL, CLOCK_TOPIC, RX_TOPIC, STEP_TOPIC, TX_TOPIC, ClockRecord, LogLayouts,
                               Record, RxRecord, StepRecord, TxRecord, frame_meaning, parse, reply_meaning)
from choreo.log.reader import LogReader
from choreo.review.showtime import ShowTimes, fixed
from choreo.review.summary import stale_replies


@dataclass(frozen=True, slots=True)
class Exchange:
    """One frame sent and what came back for it (tx or rx may be missing in a cut or odd log)."""

    seq: int
    tx: TxRecord | None
    tx_ns: int | None
    tx_s: float | None  # show clock
    rx: RxRecord | None
    rx_ns: int | None
    rx_s: float | None

    @property
    def step(self) -> int | None:
        return self.tx.step if self.tx else None

    @property
    def robot(self) -> str | None:
        """Whose frame, in a show for several robots."""
        either = self.tx if self.tx is not None else self.rx
        return either.robot if either is not None else None

    @property
    def frame_kind(self) -> str | None:
        return self.tx.kind if self.tx else None

    @property
    def reply_kind(self) -> str | None:
        return self.rx.kind if self.rx else None


def exchanges(reader: LogReader, clock: ShowTimes | None = None) -> Iterator[Exchange]:
    """Frames paired with their replies, in the order they were sent."""
    clock = clock or ShowTimes.of(reader)
    held: dict[str | None, tuple[TxRecord, int]] = {}  # by robot: a frame whose reply has not come yet
    topic, number = None, 0
    try:
        for topic, log_time, data in reader.messages((TX_TOPIC, RX_TOPIC, STEP_TOPIC, CLOCK_TOPIC)):
            number += 1
            if topic == CLOCK_TOPIC or (topic == STEP_TOPIC and not clock.anchored):
                _see_time(clock, parse(topic, data), log_time)
            elif topic != STEP_TOPIC:  # shown as it is, whoever wrote it
                yield from _paired(clock, held, parse(topic, data, partial=True), log_time)
    except (KeyError, TypeError, ValueError, AttributeError) as exc:
        raise reader.not_choreo(topic, number, exc) from None
    for frame, sent_ns in held.values():
        yield _pair(clock, frame, sent_ns, None, None)


def _see_time(clock: ShowTimes, record: Record, log_time: int) -> None:
    """The show clock's anchor (the first step events) and its samples (/choreo/clock)."""
    if isinstance(record, StepRecord):
        clock.see_step(log_time, record)
    elif isinstance(record, ClockRecord):
        clock.see_clock(log_time, record)


def _paired(clock: ShowTimes, held: dict[str | None, tuple[TxRecord, int]], message: Record,
            log_time: int) -> Iterator[Exchange]:
    """The pairs a frame or reply completes: a frame is held (in `held`) until its reply comes;
    a frame that a second frame follows, or a reply without its frame, goes out alone."""
    if not isinstance(message, (TxRecord, RxRecord)):
        return
    waiting = held.pop(message.robot, None)
    if isinstance(message, TxRecord):
        if waiting is not None:
            yield _pair(clock, waiting[0], waiting[1], None, None)
        held[message.robot] = (message, log_time)
    elif waiting is not None and waiting[0].seq == message.seq:
        yield _pair(clock, waiting[0], waiting[1], message, log_time)
    else:  # a reply without its frame in the log
        if waiting is not None:
            yield _pair(clock, waiting[0], waiting[1], None, None)
        yield _pair(clock, None, None, message, log_time)


def _pair(clock: ShowTimes, tx: TxRecord | None, tx_ns: int | None, rx: RxRecord | None,
          rx_ns: int | None) -> Exchange:
    either = tx if tx is not None else rx
    assert either is not None, "a pair holds a frame, its reply or both"
    return Exchange(either.seq, tx, tx_ns, clock.seconds(tx_ns), rx, rx_ns, clock.seconds(rx_ns))


def stale_note(rx: RxRecord) -> str:
    """` (set aside a late reply: 04 00 06 0a)` after a reply that came with late ones, or ``."""
    replies = stale_replies(rx.stale)
    if not replies:
        return ""
    what = "a late reply" if len(replies) == 1 else f"{len(replies)} late replies"
    return f" (set aside {what}: {', '.join(replies)})"


def matches(exchange: Exchange, step: int | None, kind: str | None, robot: str | None = None) -> bool:
    """`--step N`, `--kind K` and `--robot NAME`: K names a frame kind or a reply kind; either
    side matching keeps the pair, so `--kind nak` shows each refused frame with its NAK."""
    if step is not None and exchange.step != step:
        return False
    if robot is not None and exchange.robot != robot:
        return False
    return kind is None or kind in (exchange.frame_kind, exchange.reply_kind)


def _time(seconds: float | None) -> str:
    return fixed(seconds, 6, 10) if seconds is not None else " " * 10


def lines(exchange: Exchange, layouts: LogLayouts) -> Iterator[str]:
    """`show_s  tx  seq  kind  hex  meaning` and the same for its reply, the bytes read with the
    layout the log records for the robot."""
    tx, rx = exchange.tx, exchange.rx
    robot = f"{exchange.robot}: " if exchange.robot else ""
    if tx is not None:
        where = f"step {tx.step}" if tx.step is not None else "abort" if tx.label == ABORT_LABEL else "-"
        retry = f" (try {tx.attempt})" if tx.attempt > 1 else ""
        yield (f"{_time(exchange.tx_s)}  tx  #{exchange.seq:<6} {where:<9} {tx.kind:<8} "
               f"{tx.hex:<56} {robot}{frame_meaning(tx, layouts)}{retry}")
    if rx is not None:
        latency = f"{fixed(rx.latency_ms)} ms"
        yield (f"{_time(exchange.rx_s)}  rx  #{exchange.seq:<6} {latency:<9} {rx.kind:<8} "
               f"{rx.hex:<56} {robot}{reply_meaning(rx, tx, layouts)}{stale_note(rx)}")
    elif tx is not None:
        yield f"{'':10}  rx  #{exchange.seq:<6} {'':9} {'-':<8} {'':56} no reply in the log (it ends here)"


HEADER = f"{'show s':>10}  dir {'seq':<7} {'step/lat':<9} {'kind':<8} {'bytes':<56} meaning"


def frame_lines(reader: LogReader, step: int | None = None, kind: str | None = None,
                robot: str | None = None) -> Iterator[str]:
    """Every line `choreo log frames` prints, header first; a cut log ends with where it stops."""
    yield HEADER
    shown = 0
    layouts = LogLayouts.of(reader.run_info)
    for exchange in exchanges(reader):
        if matches(exchange, step, kind, robot):
            shown += 1
            try:
                yield from lines(exchange, layouts)
            except (KeyError, TypeError, ValueError, AttributeError) as exc:
                raise reader.not_choreo(TX_TOPIC, exchange.seq, exc) from None
    if reader.cut is not None:
        yield f"log {reader.cut.state}: {reader.cut}"
    if shown:
        yield from layouts.notes([robot] if robot is not None else reader.robots)
    else:
        wanted = " and ".join(x for x in (f"step {step}" if step is not None else "",
                                         f"kind {kind}" if kind else "",
                                         f"robot {robot}" if robot else "") if x)
        yield f"no frames{' with ' + wanted if wanted else ''} in this log"
    yield from reader.run_notes
