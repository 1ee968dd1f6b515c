"""Benchmark 16, a GO in one track against another track's timed cues (issue 21, item 5).

On the machine's clock a GO cue holds the one show clock for every track: while robot `a`
waits at its GO cue, robot `b`'s later timed cues wait too, and when the GO comes the clock goes
on and each of them falls due that much later. A runner asleep towards such a cue must wake when
the clock goes on, not at the end of a sleep slice (it was ~20 ms late before).

Two robots, each on its own `choreo sim` on a pseudo-terminal, log on: `a` plays GO cues, `b`
plays timed cues placed 1 to 30 ms (show time) after each of `a`'s GO cues. The benchmark gives
each GO (`Live.command`, as a key or OSC message does) a random 40-120 ms after `a` waits. The
figure is how late each of `b`'s cues after a GO started by the runner's own reckoning (its
step's start on the show clock, which the GO moved, against its due time), beside the same for
`b`'s cues that no GO moved.

Goal (issue 21): a GO delays another track's cue by at most 1 ms (p99 of `b`'s cues after a GO).
"""

from __future__ import annotations

import random
import sys
import threading
import time

from common import Capture, median, percentile, pty_sim, row, run_session_into, temp_dir, write_show

from choreo.events import Command, StopRequest
from choreo.live.controls import Live
from choreo.run.session import Session
from choreo.run.settings import RunRequest

GOAL_MS = 1.0
FULL, QUICK = 40, 12  # GO cues a run
GAP_S = 0.4  # show time between `a`'s GO cues
AFTER_S = (0.001, 0.003, 0.010, 0.030)  # `b`'s cue after each GO cue, in turn
TIMEOUT_S = 10.0


def tracks_show(gos: int) -> str:
    """`a`: a GO cue every GAP_S; `b`: a timed cue AFTER_S after each, and one between."""
    a = "".join(f"    - wait: {GAP_S}\n    - play: fast\n      at: go\n" for _ in range(gos))
    b_times = []
    for k in range(gos):
        held = GAP_S * (k + 1)  # the show time `a`'s k-th GO cue holds the clock at
        b_times += [round(held - GAP_S / 2, 3), round(held + AFTER_S[k % len(AFTER_S)], 3)]
    b = "".join(f"    - play: fast\n      at: {t:.3f}\n" for t in b_times)
    return ("version: 1\nname: bench-go-tracks\nrobots:\n  a: {}\n  b: {}\n"
            "motions:\n  fast: {number: 2, duration: 0.02}\n"
            f"tracks:\n  a:\n{a}  b:\n{b}")


def measure(gos: int, seed: int = 21) -> tuple[list[float], list[float], list[float]]:
    """`b`'s cues' lateness (ms), those after a GO and the others, and the holds' lengths (s)."""
    rng = random.Random(seed)
    with temp_dir() as tmp, pty_sim("--motion-s", "0.02") as port_a, pty_sim("--motion-s", "0.02") as port_b:
        show = write_show(tmp, tracks_show(gos))
        session = Session.prepare(RunRequest(str(show), robot_ports={"a": port_a, "b": port_b},
                                             log_path=str(tmp / "go-tracks.mcap")))
        live = Live(StopRequest(), lockout_s=0.0)
        capture = Capture()
        holds: list[float] = []
        errors: list[BaseException] = []
        with session:
            runner = threading.Thread(target=run_session_into, args=(session, [capture], live, errors), daemon=True)
            runner.start()
            try:
                for _ in range(gos):
                    holds.append(_one_go(live, rng))
                runner.join(TIMEOUT_S)  # `b`'s last cue comes after the last GO
            finally:
                live.stop.request("benchmark over")
                runner.join(TIMEOUT_S)
            if errors:
                raise errors[0]
    return *_lateness(capture), holds


def _one_go(live: Live, rng: random.Random) -> float:
    deadline = time.monotonic() + TIMEOUT_S
    while not live.waiting:
        if time.monotonic() > deadline:
            raise RuntimeError("timed out waiting for `a` to reach a GO cue")
        time.sleep(0.0005)
    hold = rng.uniform(0.04, 0.12)
    time.sleep(hold)
    answer = live.command(Command("go", "bench"))
    if not answer.ok:
        raise RuntimeError(f"GO not taken: {answer.message}")
    return hold



def _lateness(capture: Capture) -> tuple[list[float], list[float]]:
    """`b`'s timed cues as its runner started them: after a GO (a cue AFTER_S past a multiple
    of GAP_S) and between GOs."""
    after, between = [], []
    for event in capture.steps:
        if event.robot != "b" or event.event != "start" or event.step.at is None:
            continue
        late = (event.actual_s - event.planned_s) * 1e3
        offset = round(event.step.at % GAP_S, 3)
        (after if offset in AFTER_S else between).append(late)
    return after, between


def run(quick: bool = False) -> list[dict]:
    gos = QUICK if quick else FULL
    after, between, holds = measure(gos)
    p99 = percentile(after, 99)
    what = f"{len(after)} cues 1-30 ms after a GO held {min(holds) * 1e3:.0f}-{max(holds) * 1e3:.0f} ms, log on, pty"
    return [
        row(f"another track's cue after a GO, as its runner started it: median ({what})",
            round(median(after), 3), "ms", None, None),
        row("another track's cue after a GO: p99", round(p99, 3), "ms", f"< {GOAL_MS:g}", p99 < GOAL_MS),
        row("another track's cue after a GO: max", round(max(after), 3), "ms", None, None),
        row(f"the same track's cues no GO moved: median / max ({len(between)} cues)",
            f"{median(between):.3f} / {max(between):.3f}", "ms", None, None),
    ]


if __name__ == "__main__":
    from run import print_table

    sys.exit(print_table(run(quick="--quick" in sys.argv)))
