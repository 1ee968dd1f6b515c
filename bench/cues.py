"""Benchmark 1, cue accuracy: how late each `at:` cue's first byte leaves, against its due time.

A cued play is due at its cue minus its lead (the expected time of the exchanges before the
frame that starts the motion, so that frame lands on the cue: benchmark 9 measures that).

A show of many plays, each on its own `at:` cue, runs against `choreo sim` on a pseudo-terminal
with the log on (as on stage). A cue's lateness is the moment its first frame (the stop frame)
is handed to the port's write call, minus its due time on the show clock. The link's own tx
timestamp (what the log records, taken before the listeners run) is reported beside it: the
difference is the work done between the two, which is on the cue's critical path. Cue spacing
varies (80 to 139 ms, a fixed pseudo-random sequence) so the cues do not fall in step with the
timer tick or the simulator's own loop.

Goal (PRODUCT.md): p99 under 1 ms.
"""

from __future__ import annotations

import os
import random
import sys

from common import ShowRun, median, percentile, pty_sim, row, run_show, temp_dir, write_show

GOAL_P99_MS = 1.0
FULL = (3, 100)  # runs, cues a run
QUICK = (1, 40)


def cue_times(count: int, seed: int = 6) -> list[float]:
    """Cue times in seconds, 80..139 ms apart, rounded to the millisecond like a show file's."""
    rng = random.Random(seed)
    times, t = [], 0.2
    for _ in range(count):
        times.append(round(t, 3))
        t += rng.randrange(80, 140) / 1000
    return times


def cue_show(times: list[float]) -> str:
    steps = "\n".join(f"  - play: cue\n    at: {t:.3f}" for t in times)
    return ("version: 1\nname: bench-cues\nmotions:\n  cue: {number: 3, duration: 0.05}\n"
            f"steps:\n{steps}\n")


def lateness_ms(run: ShowRun) -> tuple[list[float], list[float]]:
    """Each cue against its time, ms, in show order: (first byte written, first tx timestamp)."""
    first: dict[int, int] = {}
    for i, event in enumerate(run.capture.tx):
        if event.tag is not None and event.tag.step is not None:
            first.setdefault(event.tag.step, i)
    # a cued play's first frame is due at the cue minus its lead (the exchanges before the frame
    # that starts the motion, which is written on the cue): the step's own due time
    due = {event.step.index: event.planned_s for event in run.capture.steps if event.event == "start"}
    written, stamped = [], []
    for event in run.capture.steps:
        step = event.step
        if event.event == "start" and step.at is not None:
            i = first[step.index]
            written.append((run.show_time_mono(run.capture.writes[i]) - due[step.index]) * 1e3)
            stamped.append((run.show_time(run.capture.tx[i].time_ns) - due[step.index]) * 1e3)
    return written, stamped


def run(quick: bool = False) -> list[dict]:
    runs, count = QUICK if quick else FULL
    times = cue_times(count)
    written, stamped = measure(times, runs)
    p99 = percentile(written, 99)
    what = f"{len(written)} cues, {runs} run{'s' * (runs > 1)}, log on, pty"
    rows = [
        row(f"cue first byte written: p50 ({what})", round(median(written), 3), "ms", None, None),
        row("cue first byte written: p99", round(p99, 3), "ms", f"< {GOAL_P99_MS:g}", p99 < GOAL_P99_MS),
        row("cue first byte written: max", round(max(written), 3), "ms", None, None),
        row("cue first byte written: min (never early)", round(min(written), 3), "ms", ">= 0",
            min(written) >= 0),
        row("cue tx timestamp in the log: p50", round(median(stamped), 3), "ms", None, None),
        row("cue tx timestamp in the log: p99", round(percentile(stamped, 99), 3), "ms", None, None),
    ]
    return rows if quick else rows + realtime_rows(times, runs)


def measure(times: list[float], runs: int) -> tuple[list[float], list[float]]:
    written: list[float] = []
    stamped: list[float] = []
    with temp_dir() as tmp, pty_sim("--motion-s", "0.05") as device:
        show = write_show(tmp, cue_show(times))
        for i in range(runs):
            w, s = lateness_ms(run_show(show, device, log_path=tmp / f"cues-{i}.mcap"))
            written += w
            stamped += s
    return written, stamped


def realtime_rows(times: list[float], runs: int) -> list[dict]:
    """The same runs under SCHED_FIFO, where permitted: what is left when nothing in this VM
    can preempt the runner (the host still can). Informational: choreo does not ask for it."""
    if not hasattr(os, "SCHED_FIFO"):
        return []
    try:
        before = os.sched_getscheduler(0), os.sched_getparam(0)
        os.sched_setscheduler(0, os.SCHED_FIFO, os.sched_param(10))
    except (OSError, AttributeError):
        return [row("cue first byte written under SCHED_FIFO: not permitted here", None, "", None, None)]
    try:
        written, _ = measure(times, runs)
    finally:
        os.sched_setscheduler(0, before[0], before[1])
    return [
        row("cue first byte written under SCHED_FIFO: p50", round(median(written), 3), "ms", None, None),
        row("cue first byte written under SCHED_FIFO: p99", round(percentile(written, 99), 3), "ms",
            None, None),
        row("cue first byte written under SCHED_FIFO: max", round(max(written), 3), "ms", None, None),
    ]

if __name__ == "__main__":
    from run import print_table

    sys.exit(print_table(run(quick="--quick" in sys.argv)))
