"""Log times (wall-clock ns) to show time, as every review reads them.

A show's zero is not in the metadata (the run's `start_ns` is taken when the run is prepared,
before the ports open), but every step start carries its show time: the first one fixes the
zero to the microsecond; until one is seen, the metadata's start stands in. Show time does not
always move with the wall clock: it stops while a GO cue waits (live control), and on the
music's clock it drifts with the sound card. The log's `/choreo/clock` samples say where it
stood: a sample the mapping so far does not predict (to a millisecond) starts a new piece, so
the pieces are few (a hold's end, a loop's next pass) and memory stays bounded.
"""

from __future__ import annotations

from bisect import bisect_right

from choreo.logformat import ClockRecord, StepRecord
from choreo.review.reader import LogReader

BREAK_S = 0.001  # a clock sample this far from the mapping's prediction starts a new piece


def show_zero_ns(reader: LogReader) -> int | None:
    """The run's start as the metadata gives it (wall-clock ns), before a step says better."""
    start = reader.run_info.get("start_ns")
    return int(start) if start and start.isdigit() else None


class ShowTimes:
    """Wall-clock log times to show-clock seconds; see the module's docstring."""

    def __init__(self, zero_ns: int | None) -> None:
        self.zero_ns = zero_ns
        self.from_step = False
        self._break_ns: list[int] = []  # where a piece begins (log time)
        self._break_s: list[float] = []  # and the show time there

    @classmethod
    def of(cls, reader: LogReader) -> ShowTimes:
        return cls(show_zero_ns(reader))

    def see_step(self, log_time: int, step: StepRecord) -> None:
        if step.event == "start":
            self.see_start(log_time, step.actual_s)

    def see_start(self, log_time: int, actual_s: float) -> None:
        """A step started at `actual_s` on the show clock: the first one fixes the zero."""
        if not self.from_step:
            self.zero_ns = log_time - round(actual_s * 1e9)
            self.from_step = True

    def see_clock(self, log_time: int, sample: ClockRecord) -> None:
        """A /choreo/clock sample: where show time really stood at `log_time`."""
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
