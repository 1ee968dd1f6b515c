"""Benchmark 2, drift: 200 steps of `play` + `wait: 0.1`, total run time minus planned time.

Each play's frames take wire time (about 5 ms at 115200 baud through the pty simulator); a
runner that summed sleeps would end 200 x that late. The show clock is absolute, so the run
should end within a millisecond of its planned 20 s. The run's end is the runner's show clock
when the last wait returns; the last play's first byte against its due time is reported too,
to show that lateness does not accumulate along the show.

Goal (PRODUCT.md, issue 6): under 1 ms in all.
"""

from __future__ import annotations

import sys

from common import median, pty_sim, row, run_show, temp_dir, write_show

GOAL_MS = 1.0
STEPS = 200
QUICK_STEPS = 40  # --quick: 4 s of the show
FULL_RUNS = 3
QUICK_RUNS = 1
WAIT_S = 0.1


def drift_show(steps: int) -> str:
    return ("version: 1\nname: bench-drift\nmotions:\n  move: {number: 5, duration: 0.05}\n"
            f"steps:\n  - repeat: {steps}\n    steps:\n      - play: move\n      - wait: {WAIT_S}\n")


def run(quick: bool = False) -> list[dict]:
    runs = QUICK_RUNS if quick else FULL_RUNS
    steps = QUICK_STEPS if quick else STEPS
    drifts, last_plays = [], []
    with temp_dir() as tmp, pty_sim("--motion-s", "0.05") as device:
        show = write_show(tmp, drift_show(steps))
        for i in range(runs):
            result = run_show(show, device, log_path=tmp / f"drift-{i}.mcap")
            planned = steps * WAIT_S
            drifts.append((result.result.show_s - planned) * 1e3)
            last_write = result.capture.writes[-3]  # the last play's stop frame
            last_plays.append((result.show_time_mono(last_write) - (planned - WAIT_S)) * 1e3)
    worst = max(drifts, key=abs)
    typical = median(drifts)
    what = f"{steps} x play + wait {WAIT_S:g}, {runs} run{'s' * (runs > 1)}, pty"
    return [
        row(f"drift: run time - planned, median ({what})", round(typical, 3), "ms", f"< {GOAL_MS:g}",
            abs(typical) < GOAL_MS),
        row("drift: run time - planned, worst run", round(worst, 3), "ms", None, None),
        row("drift: last play's first byte vs its due time, median", round(median(last_plays), 3),
            "ms", f"< {GOAL_MS:g}", median(last_plays) < GOAL_MS),
    ]

if __name__ == "__main__":
    from run import print_table

    sys.exit(print_table(run(quick="--quick" in sys.argv)))
