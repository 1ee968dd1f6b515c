"""Shared pieces of the benchmarks: result rows, percentiles, the simulator on a pty, show runs.

Benchmarks talk to the simulator the way a user's `choreo run --port /dev/pts/N` would: the
`choreo sim` command in its own process on a pseudo-terminal, so the kernel's tty layer and a
second process' scheduling are part of every figure (a real USB adapter adds its own latency on
top, which no benchmark without hardware can show). Runs are driven in-process through the same
`Session` that `choreo run` uses, so a listener can see each frame's own timestamp (taken by the
link just before the write) without parsing the log.
"""

from __future__ import annotations

import math
import os
import signal
import subprocess
import sys
import tempfile
import textwrap
import time
from collections.abc import Iterator, Sequence
from contextlib import contextmanager
from dataclasses import dataclass, field
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
if str(ROOT) not in sys.path:
    sys.path.insert(0, str(ROOT))

from choreo.events import RunResult, RxEvent, StepEvent, TxEvent  # noqa: E402
from choreo.run.runner import Runner  # noqa: E402
from choreo.run.session import Session  # noqa: E402
from choreo.run.settings import RunRequest  # noqa: E402


def row(name: str, value: float | str | None, unit: str, goal: str | None, ok: bool | None) -> dict:
    """One line of the results table; `ok` None means informational (no goal)."""
    return {"name": name, "value": value, "unit": unit, "goal": goal, "ok": ok}


def percentile(values: Sequence[float], q: float) -> float:
    """The q-th percentile (0..100), linear between the closest ranks (numpy's default)."""
    if not values:
        return math.nan
    ordered = sorted(values)
    pos = (len(ordered) - 1) * q / 100
    low = math.floor(pos)
    high = min(low + 1, len(ordered) - 1)
    return ordered[low] + (ordered[high] - ordered[low]) * (pos - low)


def median(values: Sequence[float]) -> float:
    return percentile(values, 50)


def env() -> dict[str, str]:
    """The environment for a `python -m choreo` child: this checkout first on the path."""
    result = dict(os.environ)
    result["PYTHONPATH"] = str(ROOT) + os.pathsep + result.get("PYTHONPATH", "")
    return result


@contextmanager
def pty_sim(*options: str) -> Iterator[str]:
    """`choreo sim OPTIONS` in a child process; yields the pty's device path, stops it after."""
    proc = subprocess.Popen([sys.executable, "-m", "choreo", "sim", *options], stdout=subprocess.PIPE,
                            stderr=subprocess.PIPE, text=True, cwd=ROOT, env=env())
    try:
        path = proc.stdout.readline().strip() if proc.stdout else ""
        if not path.startswith("/dev/"):
            proc.kill()
            _, err = proc.communicate(timeout=5)
            raise RuntimeError(f"choreo sim did not start: {path!r} {err.strip()}")
        yield path
    finally:
        if proc.poll() is None:
            proc.send_signal(signal.SIGINT)
            try:
                proc.wait(timeout=5)
            except subprocess.TimeoutExpired:
                proc.kill()
                proc.wait()


@contextmanager
def temp_dir() -> Iterator[Path]:
    with tempfile.TemporaryDirectory(prefix="choreo-bench-") as tmp:
        yield Path(tmp)


def write_show(directory: Path, body: str, name: str = "show.yaml") -> Path:
    path = directory / name
    path.write_text(textwrap.dedent(body).lstrip())
    return path


@dataclass
class Capture:
    """A link and runner listener that keeps every event, with its own monotonic time."""

    tx: list[TxEvent] = field(default_factory=list)
    rx: list[RxEvent] = field(default_factory=list)
    steps: list[StepEvent] = field(default_factory=list)
    writes: list[int] = field(default_factory=list)  # monotonic ns as each write call began

    def watch_writes(self, port) -> None:  # type: ignore[no-untyped-def]
        """Timestamp the port's real write calls: the tx timestamp comes before the listeners
        (the recorder among them), so only this says when a frame's first byte was handed to
        the OS. One write a frame, so writes[i] belongs to tx[i]."""
        write = port.write
        clock = time.monotonic_ns

        def timed_write(data: bytes) -> int:
            self.writes.append(clock())
            return write(data)

        port.write = timed_write

    def on_tx(self, event: TxEvent) -> None:
        self.tx.append(event)

    def on_rx(self, event: RxEvent) -> None:
        self.rx.append(event)

    def on_step(self, event: StepEvent) -> None:
        self.steps.append(event)

    def on_log(self, level: int, message: str, time_ns: int | None = None) -> None:
        pass


@dataclass
class ShowRun:
    """What one run left behind: the events, the result, and the show clock's zero."""

    capture: Capture
    result: RunResult
    zero_mono_ns: int  # the monotonic instant the show clock reads 0
    wall_to_mono_ns: int  # add to an event's wall-clock time_ns to get its monotonic ns
    run_s: float  # wall time of the run itself (opening and closing excluded)

    def show_time(self, time_ns: int) -> float:
        """An event's wall-clock time as show-clock seconds."""
        return (time_ns + self.wall_to_mono_ns - self.zero_mono_ns) / 1e9

    def show_time_mono(self, mono_ns: int) -> float:
        """A monotonic instant as show-clock seconds."""
        return (mono_ns - self.zero_mono_ns) / 1e9


def run_show(show_path: Path, port: str, *, log_path: Path | None = None) -> ShowRun:
    """Run a show as `choreo run` does (the same Session), capturing every event.

    The Runner is built here as `Session.run` builds it, so that its show-clock zero (the
    reference every cue is due against) can be read: the runner does not publish it.
    """
    request = RunRequest(str(show_path), port=port, log_path=str(log_path) if log_path else None,
                         no_log=log_path is None)
    session = Session.prepare(request)
    capture = Capture()
    with session:
        assert session.stage is not None
        link, settings = session.stage.links["robot"], session.settings
        link.subscribe(capture)
        capture.watch_writes(link.port)
        listeners = ([session.recorder] if session.recorder else []) + [capture]
        runner = Runner(settings.plans["robot"], link, clock=session.clock, listeners=listeners,
                        start=settings.sections.starts["robot"], on_abort=settings.show.on_abort)
        began = time.perf_counter()
        session.result = runner.run()
        run_s = time.perf_counter() - began
    clock = session.clock
    return ShowRun(capture, session.result, round(runner.show.mono_at(0.0) * 1e9),
                   clock.mono_anchor_ns - clock.wall_anchor_ns, run_s)


def run_session_into(session: Session, listeners: list, live: object, errors: list[BaseException]) -> None:
    """`session.run` on a benchmark's own thread: what it raises is kept for the caller to raise,
    after it has stopped what it started (a thread's exception would only be printed)."""
    try:
        session.run(listeners, live=live)
    except BaseException as exc:  # noqa: BLE001 - reported by the caller
        errors.append(exc)
