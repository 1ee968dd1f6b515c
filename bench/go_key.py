"""Benchmark 6, the key half: a GO given by a key press on the console, to the first frame of the
step it releases.

`choreo run` runs as an operator runs it, in its own process with the console up: its stdin and
stderr on a pseudo-terminal this benchmark opens (80x24), its port a `choreo sim` pseudo-terminal.
The show is a row of plays, each waiting for GO (`at: go`, labelled cue-N). For each, once the
console shows "GO fires cue M 'cue-N': press Space or Enter" (and at least Live's 0.5 s lockout
after the last press, plus a few pseudo-random milliseconds so that presses do not fall in step
with anything), a space is written to the terminal and the monotonic clock read just before that
write.

The first frame's time is the log's: the `/rcb4/tx` log time of the first frame tagged with the
step, which the link takes just before handing the frame to the port's write call. It is a
wall-clock time derived from the monotonic clock with a fixed offset, which the log's metadata
gives (`show_zero_monotonic_ns`, `show_zero_wall_ns`), so it is taken back to the monotonic
clock that this process read (one clock for both processes: no wall-clock steps or slewing in
the figure).

So the figure includes the terminal's line discipline, the console's key thread waking and
telling a space from the start of an escape sequence (a space needs no wait), `Live.command`
releasing the cue, the runner thread waking from its wait, the step's start being logged, and
the play's first frame being built; it excludes the write call itself and the bytes' time on
the (simulated) wire. The console does not redraw while a GO cue waits (the show clock holds,
nothing on screen changes), so a press never queues behind a redraw.

Goal (issue 14): under 5 ms, median and p99.
"""

from __future__ import annotations

import fcntl
import json
import os
import random
import signal
import struct
import subprocess
import sys
import termios
import threading
import time
from pathlib import Path

from common import ROOT, env, median, percentile, pty_sim, row, temp_dir, write_show

GOAL_MS = 5.0
FULL, QUICK = 25, 8  # GO presses a run
LOCKOUT_S = 0.5  # choreo.live.controls.LOCKOUT_S: a second GO sooner is refused as a double press
JITTER_S = (0.05, 0.15)  # the extra wait before a press, seeded


def go_show(cues: int) -> str:
    steps = "\n".join(f"  - play: 1\n    at: go\n    label: cue-{i}" for i in range(cues))
    return f"version: 1\nname: bench-go-key\nsteps:\n{steps}\n"


class Terminal:
    """A program on a pseudo-terminal of ours: stdin and stderr on its secondary side, the
    screen read off the primary side by a thread (a screen nobody reads would block its writes)."""

    def __init__(self, args: list[str], columns: int = 80, lines: int = 24) -> None:
        self.primary, secondary = os.openpty()
        fcntl.ioctl(secondary, termios.TIOCSWINSZ, struct.pack("HHHH", lines, columns, 0, 0))
        child_env = {k: v for k, v in env().items() if k not in ("COLUMNS", "LINES")}
        self.proc = subprocess.Popen(args, stdin=secondary, stdout=subprocess.DEVNULL, stderr=secondary,
                                     cwd=ROOT, env=child_env, start_new_session=True)
        os.close(secondary)
        self.output = bytearray()
        self._seen = 0  # where the next wait_for starts looking
        self._changed = threading.Condition()
        self._reader = threading.Thread(target=self._read, daemon=True)
        self._reader.start()

    def _read(self) -> None:
        while True:
            try:
                data = os.read(self.primary, 65536)
            except OSError:  # EIO: the program has exited and closed the terminal
                data = b""
            with self._changed:
                self.output += data
                self._changed.notify_all()
            if not data:
                return

    def wait_for(self, text: bytes, timeout: float = 10.0) -> None:
        deadline = time.monotonic() + timeout
        with self._changed:
            while (found := self.output.find(text, self._seen)) < 0:
                left = deadline - time.monotonic()
                if left <= 0 or self.proc.poll() is not None:
                    raise RuntimeError(f"{text.decode()!r} never came; the screen's end: {self.tail()!r}")
                self._changed.wait(min(left, 0.05))
            self._seen = found + len(text)

    def press(self, key: bytes) -> int:
        """Write a key; the monotonic ns just before the write."""
        now = time.monotonic_ns()
        os.write(self.primary, key)
        return now

    def tail(self, size: int = 600) -> str:
        return bytes(self.output[-size:]).decode("utf-8", "replace")

    def close(self, timeout: float = 15.0) -> int:
        """The program's exit status, once it has exited (interrupted if it will not)."""
        try:
            return self.proc.wait(timeout)
        except subprocess.TimeoutExpired:
            self.proc.send_signal(signal.SIGINT)
            try:
                return self.proc.wait(5)
            except subprocess.TimeoutExpired:
                self.proc.kill()
                return self.proc.wait()
        finally:
            self._reader.join(2)
            os.close(self.primary)


def first_frames_mono_ns(log_path: Path) -> dict[int, int]:
    """Each step's first /rcb4/tx frame, as monotonic ns (see the docstring)."""
    from mcap.reader import make_reader

    first: dict[int, int] = {}
    with open(log_path, "rb") as f:
        reader = make_reader(f)
        result = next(dict(m.metadata) for m in reader.iter_metadata() if m.name == "choreo.result")
        wall_minus_mono = int(result["show_zero_wall_ns"]) - int(result["show_zero_monotonic_ns"])
        for _, _channel, message in reader.iter_messages(topics=["/rcb4/tx"]):
            step = json.loads(message.data).get("step")
            if step is not None:
                first[step] = min(first.get(step, message.log_time), message.log_time)
    return {step: log_time - wall_minus_mono for step, log_time in first.items()}


def presses_ms(cues: int, seed: int = 14) -> list[float]:
    """For each GO press, its release's first frame minus the press, ms."""
    rng = random.Random(seed)
    with temp_dir() as tmp, pty_sim("--motion-s", "0.05") as port:
        show = write_show(tmp, go_show(cues))
        log = tmp / "run.mcap"
        terminal = Terminal([sys.executable, "-m", "choreo", "run", str(show), "--port", port, "--log", str(log)])
        pressed: list[int] = []
        try:
            for i in range(cues):
                terminal.wait_for(f"'cue-{i}': press Space".encode())  # GO fires cue N 'cue-i': press ...
                ready = (pressed[-1] / 1e9 + LOCKOUT_S) if pressed else 0.0
                time.sleep(max(0.0, ready - time.monotonic()) + rng.uniform(*JITTER_S))
                pressed.append(terminal.press(b" "))
        finally:
            code = terminal.close()
        if code != 0:
            raise RuntimeError(f"choreo run exited {code}; the screen's end: {terminal.tail()!r}")
        frames = first_frames_mono_ns(log)
    return [(frames[i] - at) / 1e6 for i, at in enumerate(pressed)]


def run(quick: bool = False) -> list[dict]:
    values = presses_ms(QUICK if quick else FULL)
    p50, p99 = median(values), percentile(values, 99)
    return [row(f"GO by a key (console, pty) -> first frame written: median / p99 of {len(values)} presses",
                f"{p50:.2f} / {p99:.2f}", "ms", f"both < {GOAL_MS:g}", p50 < GOAL_MS and p99 < GOAL_MS),
            row("GO by a key -> first frame written: max", round(max(values), 2), "ms", None, None)]


if __name__ == "__main__":
    from run import print_table

    sys.exit(print_table(run(quick="--quick" in sys.argv)))
