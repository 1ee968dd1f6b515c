"""Benchmark 3, poll spacing in `wait: done`: the time between status queries.

The board refreshes its status every 50 ms, so the runner must never poll faster, and should
not poll much slower either (a motion's end is seen up to one spacing late). Plays of a 1 s
motion, each followed by `wait: done`, run against `choreo sim` on a pseudo-terminal; the spacing
is measured between the link's own timestamps of consecutive status frames within one wait, and
the first poll's distance from the restore frame's reply (the runner's reference) is checked too.

Goal (PRODUCT.md): never under 50 ms; p99 under 51 ms.
"""

from __future__ import annotations

import sys

from choreo.events import TxEvent
from choreo.wire.protocol import FrameKind
from common import ShowRun, median, percentile, pty_sim, row, run_show, temp_dir, write_show

POLL_MS = 50.0
GOAL_P99_MS = 51.0
FULL_PLAYS = 12
QUICK_PLAYS = 4
MOTION_S = 1.0
# Timestamps are integer ns, the deadline float seconds: allow their rounding, nothing more.
ROUNDING_MS = 1e-5


def polls_show(plays: int) -> str:
    return ("version: 1\nname: bench-polls\nmotions:\n  long: {number: 9, duration: 1.0}\n"
            f"steps:\n  - repeat: {plays}\n    steps:\n      - play: long\n      - wait: done\n"
            "        timeout: 5\n")


def spacings_ms(run: ShowRun) -> tuple[list[float], list[float]]:
    """(status-to-status spacings within a wait, restore-reply-to-first-poll gaps), in ms."""
    replies = {event.seq: event.time_ns for event in run.capture.rx}
    spacing, first = [], []
    previous: TxEvent | None = None
    for event in run.capture.tx:
        if event.frame.kind is FrameKind.STATUS and previous is not None:
            if previous.frame.kind is FrameKind.STATUS:
                spacing.append((event.time_ns - previous.time_ns) / 1e6)
            elif previous.frame.kind is FrameKind.RESTORE:
                first.append((event.time_ns - replies[previous.seq]) / 1e6)
        previous = event
    return spacing, first


def run(quick: bool = False) -> list[dict]:
    plays = QUICK_PLAYS if quick else FULL_PLAYS
    spacing: list[float] = []
    first: list[float] = []
    with temp_dir() as tmp, pty_sim("--motion-s", str(MOTION_S)) as device:
        show = write_show(tmp, polls_show(plays))
        result = run_show(show, device, log_path=tmp / "polls.mcap")
        spacing, first = spacings_ms(result)
    p99 = percentile(spacing, 99)
    low = min(spacing)
    what = f"{len(spacing)} spacings, {plays} waits of a {MOTION_S:g} s motion, pty"
    return [
        row(f"poll spacing p50 ({what})", round(median(spacing), 3), "ms", None, None),
        row("poll spacing p99", round(p99, 3), "ms", f"< {GOAL_P99_MS:g}", p99 < GOAL_P99_MS),
        row("poll spacing min", round(low, 3), "ms", f">= {POLL_MS:g}", low >= POLL_MS - ROUNDING_MS),
        row("first poll after the restore's reply, min", round(min(first), 3), "ms", f">= {POLL_MS:g}",
            min(first) >= POLL_MS - ROUNDING_MS),
    ]


if __name__ == "__main__":
    from run import print_table

    sys.exit(print_table(run(quick="--quick" in sys.argv)))
