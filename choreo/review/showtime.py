"""Log times (wall-clock ns) to show time, as every review reads them.

A show's zero is not in the metadata (the run's `start_ns` is taken when the run is prepared,
before the ports open), but the log says where the show clock stood from the moment it started:
the run takes a `/choreo/clock` sample then, and every step start carries its show time. The
first of these fixes the zero to the microsecond. It comes after the frames sent when the port
opened (an hth4-2.2 link's ACK check and config read), so `ShowTimes.of` reads ahead to it
before a review places any frame: those frames fall before zero, at negative show times, in the
order they were sent. Only a log with neither (a run stopped before its show started) falls back
on the metadata's start.

Show time does not always move with the wall clock: it stops while a GO cue waits (live
control), and on the music's clock it drifts with the sound card. The clock samples say where
it stood: a sample the mapping so far does not predict (to a millisecond) starts a new piece, so
the pieces are few (a hold's end, a loop's next pass) and memory stays bounded.
"""

from __future__ import annotations

import math
from bisect import bisect_right

from choreo.log.format import CLOCK_TOPIC, STEP_TOPIC, ClockRecord, StepRecord, parse
from choreo.log.reader import LogReader

BREAK_S = 0.001  # a clock sample this far from the mapping's prediction starts a new piece
# How far `ShowTimes.of` reads ahead for the show clock's start: what comes before it is what a
# run sends and says before its show starts (a few frames and log lines a robot), so a log with
# more has no start to find and the reading ahead costs a bounded time.
LOOKAHEAD_MESSAGES = 10_000


def show_zero_ns(reader: LogReader) -> int | None:
    """The run's start as the metadata gives it (wall-clock ns), before a step says better."""
    return reader.info.start_ns


class ShowTimes:
    """Wall-clock log times to show-clock seconds; see the module's docstring."""

    def __init__(self, zero_ns: int | None) -> None:
        self.zero_ns = zero_ns
        self.anchored = False  # the zero comes from the show clock (a sample or a step), not the metadata
        self._break_ns: list[int] = []  # where a piece begins (log time)
        self._break_s: list[float] = []  # and the show time there

    @classmethod
    def of(cls, reader: LogReader) -> ShowTimes:
        """The log's show times, anchored before any frame is placed (see the module's docstring)."""
        times = cls(show_zero_ns(reader))
        times.anchor(reader)
        return times

    def anchor(self, reader: LogReader) -> None:
        """Read ahead to the show clock's first sample or step start and fix the zero by it.

        A message that does not parse, or holds no number, is left for the review's own pass
        to report."""
        messages = reader.messages()
        try:
            for count, (topic, log_time, data) in enumerate(messages):
                if count >= LOOKAHEAD_MESSAGES:
                    return
                if topic != CLOCK_TOPIC and topic != STEP_TOPIC:
                    continue
                try:
                    record = parse(topic, data)
                    if isinstance(record, ClockRecord):
                        self.see_clock(log_time, record)
                    elif isinstance(record, StepRecord):
                        self.see_step(log_time, record)
                except (KeyError, TypeError, ValueError, AttributeError):
                    continue
                if self.anchored:
                    return
        finally:
            messages.close()

    def see_step(self, log_time: int, step: StepRecord) -> None:
        if step.event == "start":
            self.see_start(log_time, step.actual_s)

    def see_start(self, log_time: int, show_s: float) -> None:
        """A step started at `show_s` on the show clock: the first show time that is a number
        (a damaged record's is not), of a step or a clock sample, fixes the zero."""
        if self.anchored or not isinstance(show_s, (int, float)) or not math.isfinite(show_s * 1e9):
            return
        self.zero_ns = log_time - round(show_s * 1e9)
        self.anchored = True

    def see_clock(self, log_time: int, sample: ClockRecord) -> None:
        """A /choreo/clock sample: where show time really stood at `log_time`."""
        self.see_start(log_time, sample.show_s)
        predicted = self.seconds(log_time) if (self._break_ns or self.zero_ns is not None) else None
        if predicted is None or abs(predicted - sample.show_s) > BREAK_S:
            at = bisect_right(self._break_ns, log_time)
            self._break_ns.insert(at, log_time)
            self._break_s.insert(at, sample.show_s)

    def seconds(self, log_time: int | None) -> float | None:
        if log_time is None:
            return None
        piece = bisect_right(self._break_ns, log_time) - 1
        if piece >= 0:
            return self._break_s[piece] + (log_time - self._break_ns[piece]) / 1e9
        if self.zero_ns is None:
            self.zero_ns = log_time  # no metadata, no step, no sample: the first message is zero
        return (log_time - self.zero_ns) / 1e9
