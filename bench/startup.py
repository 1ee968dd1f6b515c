"""Benchmark 7, start-up: `choreo --help` and `choreo validate shows/dance.yaml`, wall time.

Each command runs as a fresh `python -m choreo` process (what the `choreo` script does), so
the figure includes the interpreter's own start (about 30 ms here) and every import. The median
of several runs is reported, after one unmeasured run that warms the OS's file cache.

Goal (PRODUCT.md): under 0.25 s.
"""

from __future__ import annotations

import subprocess
import sys
import time

from common import ROOT, env, median, row

GOAL_S = 0.25
COMMANDS = {
    "choreo --help": ["--help"],
    "choreo validate shows/dance.yaml": ["validate", "shows/dance.yaml"],
}
FULL_RUNS = 11
QUICK_RUNS = 5


def wall_s(args: list[str]) -> float:
    began = time.perf_counter()
    done = subprocess.run([sys.executable, "-m", "choreo", *args], cwd=ROOT, env=env(),
                          capture_output=True)
    elapsed = time.perf_counter() - began
    if done.returncode != 0:
        raise RuntimeError(f"choreo {' '.join(args)} failed: {done.stderr.decode().strip()}")
    return elapsed


def run(quick: bool = False) -> list[dict]:
    runs = QUICK_RUNS if quick else FULL_RUNS
    rows = []
    for name, args in COMMANDS.items():
        wall_s(args)
        times = [wall_s(args) for _ in range(runs)]
        value = median(times)
        rows.append(row(f"start-up: {name} (median of {runs})", round(value, 3), "s",
                        f"< {GOAL_S:g}", value < GOAL_S))
    return rows


if __name__ == "__main__":
    from run import print_table

    sys.exit(print_table(run(quick="--quick" in sys.argv)))
