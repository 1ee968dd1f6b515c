"""Test helpers for `choreo run`: writing small shows, running the CLI, reading logs back.

Logs are read with the mcap library's own readers (not choreo's), so the tests check the file
that Foxglove and the mcap tools will see.
"""

from __future__ import annotations

import io
import json
import os
import signal
import subprocess
import sys
import textwrap
import time
from collections.abc import Iterator
from contextlib import contextmanager, redirect_stderr, redirect_stdout
from dataclasses import dataclass, field
from pathlib import Path

from mcap.reader import NonSeekingReader, make_reader

REPO = Path(__file__).resolve().parent.parent
# A wait for a reply or a state that comes: it returns once it is in, so a long one costs nothing,
# and a loaded machine's scheduler (a server process or thread put off) is no failure.
REPLY_S = 5.0
# Unbounded work on a hostile input takes minutes or forever; choreo's bounds make it milliseconds.
# A bound between the two fails the first and never a loaded machine's stall (speed is bench/'s).
HANG_S = 10.0


def write_show(directory: Path, body: str, name: str = "show.yaml") -> Path:
    path = directory / name
    path.write_text(textwrap.dedent(body).lstrip())
    return path


@dataclass
class RunLog:
    """A log read back: messages by topic (decoded JSON, with log_time), metadata, attachments."""

    messages: dict[str, list[dict]] = field(default_factory=dict)
    metadata: dict[str, dict[str, str]] = field(default_factory=dict)
    attachments: list = field(default_factory=list)
    schemas: dict[str, str] = field(default_factory=dict)  # topic -> schema name

    def topic(self, name: str) -> list[dict]:
        return self.messages.get(name, [])

    @property
    def tx(self) -> list[dict]:
        return self.topic("/rcb4/tx")

    @property
    def rx(self) -> list[dict]:
        return self.topic("/rcb4/rx")

    @property
    def steps(self) -> list[dict]:
        return self.topic("/choreo/step")

    @property
    def logs(self) -> list[dict]:
        return self.topic("/choreo/log")

    def tx_hex(self) -> list[str]:
        return [m["hex"] for m in self.tx]


# How close to its cue a real-time run's motion must start, past the wake-up lateness the run
# logged itself: wide enough for a busy CI machine's scheduler (a thread can be put off tens of ms
# after it woke, between its first frames and the one on the cue), narrow enough for every error
# of the show clock's arithmetic that shows on stage: a lead-in counted twice (250 ms), a GO hold
# counted (400 ms), a beat at 150 bpm (400 ms), --from's offset. The milliseconds on an idle
# machine are measured by bench/motion_start.py and bench/music_clock.py, never asserted here.
ON_CUE_S = 0.1


def off_cue_s(steps: list[dict], end: dict) -> float:
    """How far past its cue a play's motion started, less however late the run itself measured
    the step's start (its thread woke late: a loaded machine's scheduler, which the log says).

    Real-time tests check the show clock's arithmetic with this, not the machine's speed (that
    is bench/'s to measure): a motion the runner put off its cue is off by the same amount
    however idle the machine, while a wake-up the scheduler delayed is excused only as far as
    the run measured and logged it. A motion started early is never excused (negative result)."""
    woke_late_s = 0.0
    for message in steps[:steps.index(end)]:
        if message["event"] == "start" and message["index"] == end["index"]:
            woke_late_s = max(0.0, message["late_ms"] / 1e3)
    offset = end["start_s"] - end["cue"]
    return offset if offset < 0 else max(0.0, offset - woke_late_s)


def started_on_cue(steps: list[dict], end: dict, within_s: float = ON_CUE_S) -> bool:
    """A play's motion started on its cue (`off_cue_s`), never early by more than `within_s`."""
    return abs(off_cue_s(steps, end)) < within_s


def read_log(path: Path) -> RunLog:
    """A complete log, through the indexed (seeking) reader."""
    log = RunLog()
    with open(path, "rb") as f:
        reader = make_reader(f)
        for schema, channel, message in reader.iter_messages(log_time_order=False):
            decoded = json.loads(message.data)
            decoded["_log_time"] = message.log_time
            log.messages.setdefault(channel.topic, []).append(decoded)
            log.schemas[channel.topic] = schema.name
        for record in reader.iter_metadata():
            log.metadata[record.name] = dict(record.metadata)
        log.attachments = list(reader.iter_attachments())
    return log


def read_log_linear(path: Path) -> tuple[RunLog, str | None]:
    """Whatever a linear reader gets out of a possibly cut file, and the error that stopped it."""
    log = RunLog()
    error = None
    with open(path, "rb") as f:
        try:
            for _schema, channel, message in NonSeekingReader(f).iter_messages(log_time_order=False):
                decoded = json.loads(message.data)
                decoded["_log_time"] = message.log_time
                log.messages.setdefault(channel.topic, []).append(decoded)
        except Exception as exc:  # the cut: a truncated record at the end
            error = f"{type(exc).__name__}: {exc}"
    return log, error


def choreo(*args: str, cwd: Path | None = None, timeout: float = 60) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, "-m", "choreo", *args], capture_output=True, text=True,
                          cwd=cwd or REPO, timeout=timeout, env=_env())


def choreo_here(*args: str, cwd: Path | None = None) -> subprocess.CompletedProcess:
    """`choreo ARGS` in this process, in `cwd`, answered as `choreo()` answers: for what is
    refused or reported before anything opens (bad options, unreadable files), where a process
    of its own would only add a Python start-up (a third of a second of CPU) a case."""
    from choreo.cli import main

    before = os.getcwd()
    out, err = io.StringIO(), io.StringIO()
    os.chdir(cwd or REPO)
    try:
        with redirect_stdout(out), redirect_stderr(err):
            code = main(list(args))
    finally:
        os.chdir(before)
    return subprocess.CompletedProcess(["choreo", *args], code, out.getvalue(), err.getvalue())


def start_choreo(*args: str, cwd: Path | None = None) -> subprocess.Popen:
    return subprocess.Popen([sys.executable, "-m", "choreo", *args], stdout=subprocess.PIPE,
                            stderr=subprocess.PIPE, text=True, cwd=cwd or REPO, env=_env())


@contextmanager
def ended_if_left(process: subprocess.Popen) -> Iterator[subprocess.Popen]:
    """A started choreo, killed and reaped if the test leaves before it ended (a failed assert)."""
    try:
        yield process
    finally:
        if process.poll() is None:
            process.kill()
            process.communicate()


def _env() -> dict[str, str]:
    env = dict(os.environ)
    env["PYTHONPATH"] = str(REPO) + os.pathsep + env.get("PYTHONPATH", "")
    return env


def wait_for(predicate, timeout: float = 20.0, every: float = 0.05) -> bool:
    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline:
        if predicate():
            return True
        time.sleep(every)
    return False


def log_has_steps(path: Path, count: int) -> bool:
    """True once a linear reader sees `count` step messages in a running show's log."""
    if not path.exists():
        return False
    log, _ = read_log_linear(path)
    return len(log.steps) >= count


class SimPty:
    """`choreo sim` on a pseudo-terminal for the length of a `with`: its device path, then a clean stop."""

    def __init__(self, *options: str) -> None:
        self.options = options

    def __enter__(self) -> str:
        self.process = start_choreo("sim", *self.options)
        path = self.process.stdout.readline().strip()
        assert path.startswith("/dev/"), self.process.stderr.read()
        return path

    def __exit__(self, *exc_info: object) -> None:
        if self.process.poll() is None:
            self.process.send_signal(signal.SIGTERM)
        self.process.communicate(timeout=10)


def vmain(argv: list[str]) -> int:
    """`choreo ARGV` on virtual time: a run or replay on the in-process simulator takes no real
    time and comes out the same on any machine (a real port is refused)."""
    from choreo.cli import main
    from choreo.clock import VirtualTime

    return main(argv, time_source=VirtualTime())


def prepare(request):  # type: ignore[no-untyped-def]
    """`Session.prepare` on virtual time (see `vmain`)."""
    from choreo.clock import VirtualTime
    from choreo.run.session import Session

    return Session.prepare(request, VirtualTime())


class LiveRun:
    """A show playing in a thread with a `Live`, as `choreo run` plays it with live control:
    the test gives the commands (as the console or OSC would), and `attach(live)` may add
    controls that also listen to the run (an OscServer). Real time, the in-process simulator.

    A test that fails before its run ends leaves the run's thread playing (paused, or at a GO
    cue) in the worker, holding what a run holds for the process (the quick thread switches)
    under the next tests' feet: `stop_leftover_runs` (conftest, after every test) stops it."""

    started: list[LiveRun] = []  # this process's runs not yet seen to end (see stop_leftover_runs)

    def __init__(self, tmp_path: Path, body: str, *, wait_start: bool = False, lockout_s: float | None = None,
                 attach=None, cues: bool = False, opening: bool = False,
                 **request) -> None:  # type: ignore[no-untyped-def]
        import threading

        from choreo.live.controls import Live
        from choreo.events import StopRequest
        from choreo.run.session import Session
        from choreo.run.settings import RunRequest

        show = write_show(tmp_path, body)
        self.log_path = tmp_path / "run.mcap"
        self.session = Session.prepare(RunRequest(str(show), log_path=str(self.log_path), **request))
        timing = {} if lockout_s is None else {"lockout_s": lockout_s}
        if cues:  # the show's cue list, as `choreo run` gives it (playhead, skip, cues by number)
            from choreo.show.cues import cue_list

            timing["cues"] = cue_list(self.session.settings.plans)
        # opening: commands refused until the log hears them, as `choreo run` has it
        self.live = Live(StopRequest(), wait_start=wait_start, opening=opening, **timing)
        self.listeners = attach(self.live) if attach is not None else []
        self.result = None
        self.error: BaseException | None = None
        self.thread = threading.Thread(target=self._run, daemon=True)
        LiveRun.started.append(self)
        self.thread.start()

    def _run(self) -> None:
        try:
            with self.session:
                self.result = self.session.run(self.listeners, live=self.live)
        except BaseException as exc:  # noqa: BLE001 - the test asserts on it
            self.error = exc

    def go(self, name: str = "go", **kwargs):  # type: ignore[no-untyped-def]
        """A command from the test, as from a key or an OSC message."""
        from choreo.events import Command

        return self.live.command(Command(name, "test", **kwargs))

    def until_waiting(self, name: str | None = None, timeout: float = 10.0) -> None:
        """Until the show waits at a GO cue (`name`: that one)."""
        assert wait_for(lambda: bool(self.live.waiting) and name in (None, self.live.waiting[0].name),
                        timeout, every=0.005), f"no GO cue {name or ''} waiting"

    def finish(self, timeout: float = 20.0) -> None:
        self.thread.join(timeout)
        assert not self.thread.is_alive()

    def stop_if_playing(self) -> None:
        """Stop the run if it still plays (a test ended early), and wait for its end."""
        if self.thread.is_alive():
            self.go("panic")  # heard paused, at a GO cue, before the start; a stop would play the abort motion
            self.thread.join(10)

    def log(self) -> RunLog:
        return read_log(self.log_path)


def stop_leftover_runs() -> None:
    """After a test: every LiveRun it started has ended (stopped here if its test did not wait)."""
    while LiveRun.started:
        LiveRun.started.pop().stop_if_playing()
