"""Benchmark 8, unison skew: how far apart several robots' motion-start frames leave for one play.

N robots (2, 4, 8), each on its own `choreo sim` process on its own pseudo-terminal, play a show
of shared steps: every play goes to all of them at once, on a cue. For each play the figure is
the spread of the moments the robots' motion-start frames (the restore that starts the motion)
were handed to their ports' write calls: the last robot's minus the first's. Each robot's link
runs in its own thread (choreo.run.ensemble), so this is what one Python process driving N serial
lines achieves: the threads' spin to the due time and Python's lock between them.

Goal (issue 12): p99 under 1 ms on a quiet machine.
"""

from __future__ import annotations

import time
from contextlib import ExitStack

from common import Capture, median, percentile, pty_sim, row, temp_dir, write_show

from choreo.wire.protocol import FrameKind
from choreo.events import StopRequest
from choreo.run.session import Session
from choreo.run.settings import RunRequest

GOAL_P99_MS = 1.0
FULL = (2, 4, 8), 40  # robot counts, plays a run
QUICK = (2, 4), 15


def unison_show(robots: int, plays: int) -> str:
    names = "\n".join(f"  r{i}: {{}}" for i in range(robots))
    steps = "\n".join(f"  - play: {1 + i % 3}\n    at: {0.3 + i * 0.12:.2f}" for i in range(plays))
    return f"version: 1\nname: bench-skew\nrobots:\n{names}\nsteps:\n{steps}\n"


def skews_ms(robots: int, plays: int) -> list[float]:
    """Per unison play: last robot's motion-start write minus the first's, ms."""
    with temp_dir() as tmp, ExitStack() as stack:
        paths = [stack.enter_context(pty_sim("--motion-s", "0.05")) for _ in range(robots)]
        show = write_show(tmp, unison_show(robots, plays))
        request = RunRequest(str(show), log_path=str(tmp / "skew.mcap"),
                             robot_ports={f"r{i}": path for i, path in enumerate(paths)})
        session = Session.prepare(request)
        captures = {name: Capture() for name in session.settings.links}
        with session:
            for name, link in session.stage.links.items():
                link.subscribe(captures[name])
                captures[name].watch_writes(link.port)
            session.run(stop=StopRequest())
    starts: dict[int, list[int]] = {}
    for capture in captures.values():
        for event, written in zip(capture.tx, capture.writes, strict=True):  # one write a frame
            if event.frame.kind is FrameKind.RESTORE and event.tag is not None and event.tag.step is not None:
                starts.setdefault(event.tag.step, []).append(written)
    return [(max(t) - min(t)) / 1e6 for t in starts.values() if len(t) == robots]


def run(quick: bool = False) -> list[dict]:
    counts, plays = QUICK if quick else FULL
    rows = []
    for robots in counts:
        began = time.perf_counter()
        skews = skews_ms(robots, plays)
        p99 = percentile(skews, 99)
        rows += [
            row(f"unison skew, {robots} robots on {robots} ptys: median ({len(skews)} plays)",
                round(median(skews), 3), "ms", None, None),
            row(f"unison skew, {robots} robots: p99", round(p99, 3), "ms", f"< {GOAL_P99_MS:g}", p99 < GOAL_P99_MS),
            row(f"unison skew, {robots} robots: max", round(max(skews), 3), "ms", None, None),
        ]
        _ = time.perf_counter() - began
    return rows
