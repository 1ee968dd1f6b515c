"""Benchmark 4, play latency against the wire: stop + play + restore, each reply awaited.

A play is three exchanges: 35 bytes out (19 + 7 + 9) and 12 back (three 4-byte ACKs), each byte
11 bits (start, 8 data, even parity, stop), plus the board's reply delay three times. That is the
physical minimum no software can beat; the benchmark measures how far above it choreo's link
is, from the stop frame's timestamp (just before its write) to the restore reply's completion.

Two transports, both with the simulator emulating wire time and a 0.2 ms reply delay:
- `pty`: `choreo sim --baud B` in its own process on a pseudo-terminal, through real pyserial
  (the kernel's tty layer and two processes' scheduling included, as with a USB adapter);
- `sim://`: the in-process simulated port (only choreo's own overhead and the OS's sleeps).

Goal (issue 6): within 1 ms of the minimum plus the board's delay.
"""

from __future__ import annotations

import sys
import time

from choreo.clock import RunClock
from choreo.board.link import Link
from choreo.wire.protocol import BAUDS, play_sequence
from choreo.sim.board import BITS_PER_BYTE
from common import Capture, median, percentile, pty_sim, row

GOAL_EXCESS_MS = 1.0
REPLY_MS = 0.2
FULL_PLAYS = 200
QUICK_PLAYS = 40
PAUSE_S = 0.01  # between plays: each exchange starts on a quiet line, as in a show


def physical_minimum_s(baud: int, reply_s: float = REPLY_MS / 1e3) -> float:
    """Bytes out and back times 11 bits at `baud`, plus the board's reply delay per frame."""
    frames = play_sequence(0)
    sent = sum(len(frame.data) for frame in frames)
    received = sum(min(frame.reply_sizes) for frame in frames)
    return (sent + received) * BITS_PER_BYTE / baud + len(frames) * reply_s


def play_latencies_ms(url: str, baud: int, plays: int) -> list[float]:
    """Stop-frame write to restore-reply completion, ms, for `plays` plays over one link."""
    capture = Capture()
    with Link.open(url, baud, clock=RunClock(), listeners=[capture]) as link:
        link.play(1)  # warm-up: the first exchange pays for first-use code paths
        capture.tx.clear()
        capture.rx.clear()
        for _ in range(plays):
            time.sleep(PAUSE_S)
            link.play(1)
    starts = capture.tx[0::3]
    ends = capture.rx[2::3]
    # a cut last sequence (a start with no end): left out
    return [(end.time_ns - start.time_ns) / 1e6 for start, end in zip(starts, ends, strict=False)]


def rows_for(transport: str, baud: int, latencies: list[float]) -> list[dict]:
    floor_ms = physical_minimum_s(baud) * 1e3
    goal = floor_ms + GOAL_EXCESS_MS
    p50, p99 = median(latencies), percentile(latencies, 99)
    label = f"play latency {transport} {baud} baud"
    return [
        row(f"{label}: p50 (minimum {floor_ms:.3f} ms)", round(p50, 3), "ms", f"< {goal:.3f}", p50 < goal),
        row(f"{label}: p99", round(p99, 3), "ms", f"< {goal:.3f}", p99 < goal),
    ]


def run(quick: bool = False) -> list[dict]:
    plays = QUICK_PLAYS if quick else FULL_PLAYS
    rows = []
    for baud in BAUDS:
        with pty_sim("--baud", str(baud), "--reply-ms", str(REPLY_MS)) as device:
            rows += rows_for("pty", baud, play_latencies_ms(device, baud, plays))
    for baud in BAUDS:
        url = f"sim://?baud={baud}&reply_ms={REPLY_MS}"
        rows += rows_for("sim://", baud, play_latencies_ms(url, baud, plays))
    return rows


if __name__ == "__main__":
    from run import print_table

    sys.exit(print_table(run(quick="--quick" in sys.argv)))
