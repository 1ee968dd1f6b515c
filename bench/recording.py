"""Benchmark 5, recording cost: the time a frame spends in the Recorder, and a run with the log on.

1. Per frame: real events (a play's three frames and a status query, as the link produced them
   over `sim://`) are fed to a `Recorder` writing a real file: on_tx then on_rx (what the show's
   path pays: a queue append), then on_idle (what the runner's next idle moment pays: the JSON and
   the MCAP append, and now and then a chunk written), each timed alone. p50 and p99.
2. Whole run: the same show of back-to-back plays over `sim://` (wire time emulated, so a run
   looks like a show and not a tight loop) with and without the log, alternately; the median
   difference, per frame.

Goal (PRODUCT.md): under 30 us a frame; a run with the log on not measurably slower.
"""

from __future__ import annotations

import dataclasses
import gc
import sys
import time
from pathlib import Path

from choreo.board.link import Link

from choreo.events import RxEvent, Tag, TxEvent
from choreo.log.recorder import Recorder, RunInfo
from common import Capture, median, percentile, row, run_show, temp_dir, write_show

GOAL_US = 30.0
FULL = (50_000, 7, 200)  # frames timed, runs each way, plays a run
QUICK = (10_000, 3, 100)
SIM = "sim://"


def sample_events() -> list[tuple[TxEvent, RxEvent]]:
    """A play (stop, play, restore) and a status query, as the link reports them."""
    capture = Capture()
    with Link.open("sim://?wire=0", listeners=[capture]) as link:
        link.play(3, Tag(4, "spin"))
        link.query_status(Tag(5, None))
    return list(zip(capture.tx, capture.rx, strict=True))  # no faults: a reply to every frame


def frame_costs_us(path: Path, frames: int) -> tuple[list[float], list[float]]:
    """Per frame, microseconds: reporting it (on_tx + on_rx, on the show's path) and writing it
    (the serialisation and MCAP append the runner's next idle moment does, `on_idle`)."""
    samples = sample_events()
    events = []
    for i in range(frames):
        tx, rx = samples[i % len(samples)]
        t = 1_700_000_000_000_000_000 + i * 1_000_000
        events.append((dataclasses.replace(tx, seq=i + 1, time_ns=t),
                       dataclasses.replace(rx, seq=i + 1, time_ns=t + 500_000)))
    info = RunInfo(str(path), "bench", b"version: 1\n", "sim://", 115200, time.time_ns())
    reporting, writing = [], []
    clock = time.perf_counter_ns
    with Recorder(path, info) as recorder:
        for tx, rx in events:
            began = clock()
            recorder.on_tx(tx)
            recorder.on_rx(rx)
            reported = clock()
            recorder.on_idle()
            reporting.append((reported - began) / 1e3)
            writing.append((clock() - reported) / 1e3)
    return reporting, writing


def run_costs_s(tmp: Path, runs: int, plays: int) -> tuple[list[float], list[float]]:
    """Run times (s) of the same show with and without the log, alternating."""
    show = write_show(tmp, "version: 1\nname: bench-rec\nmotions:\n  m: {number: 2, duration: 0.05}\n"
                           f"steps:\n  - repeat: {plays}\n    steps:\n      - play: m\n")
    with_log, without = [], []
    run_show(show, SIM)  # warm-up
    for i in range(runs):
        without.append(run_show(show, SIM).run_s)
        with_log.append(run_show(show, SIM, log_path=tmp / f"rec-{i}.mcap").run_s)
    return with_log, without


def run(quick: bool = False) -> list[dict]:
    frames, runs, plays = QUICK if quick else FULL
    with temp_dir() as tmp:
        gc.collect()
        reporting, writing = frame_costs_us(tmp / "frames.mcap", frames)
        with_log, without = run_costs_s(tmp, runs, plays)
    total = [a + b for a, b in zip(reporting, writing, strict=True)]
    p50, p99, mean = median(total), percentile(total, 99), sum(total) / len(total)
    per_frame_us = (median(with_log) - median(without)) / (plays * 3) * 1e6
    return [
        row(f"recorder: reporting a frame (on_tx+on_rx, on the show's path), p99 ({frames:,} frames)",
            round(percentile(reporting, 99), 2), "us", None, None),
        row("recorder: writing a frame (at the runner's next idle moment), p50",
            round(median(writing), 2), "us", None, None),
        row("recorder: a frame in all (reporting + writing), p50", round(p50, 2), "us", None, None),
        row("recorder: a frame in all, mean (chunk writes amortised)", round(mean, 2), "us",
            f"< {GOAL_US:g}", mean < GOAL_US),
        row("recorder: a frame in all, p99 (the frames that close a 64 KiB chunk)", round(p99, 2),
            "us", None, None),
        row(f"run of {plays} back-to-back plays over sim://, log off (median of {runs})",
            round(median(without), 4), "s", None, None),
        row(f"run of {plays} back-to-back plays over sim://, log on (median of {runs})",
            round(median(with_log), 4), "s", None, None),
        row("run with log on - off, per frame", round(per_frame_us, 1), "us", f"< {GOAL_US:g}",
            per_frame_us < GOAL_US),
    ]


if __name__ == "__main__":
    from run import print_table

    sys.exit(print_table(run(quick="--quick" in sys.argv)))
