"""What a run opens and must close: its log, then its ports, closed in reverse.

`choreo run` and `choreo replay` both open through the `Stage`, so their logs say the same
things the same way: a port that will not open is an error line in a log that exists, and an
interrupted or failed run is said so with its exit code.
"""

from __future__ import annotations

import sys
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from types import TracebackType

from choreo.board.link import Link
from choreo.clock import RunClock
from choreo.errors import ChoreoError, Interrupted, LinkError
from choreo.log.format import ERROR, INFO, WARNING, Result
from choreo.log.recorder import Recorder, RunInfo
from choreo.run.settings import LinkSettings


@dataclass
class Stage:
    """A run's log, then its ports (each robot's `LinkSettings`); closed in reverse, the log
    finished with the run's outcome in its metadata whatever happened. With several robots
    (`named`), each link's frames go to its robot's topics."""

    info: RunInfo
    log_path: Path | None  # None: no log
    clock: RunClock
    robots: Sequence[LinkSettings]
    unique_log: bool = False
    opening_note: str | None = None  # logged before the port opens (what this run is)
    named: bool = False  # several robots: topics and messages name each robot
    outcome: dict[str, str] | None = None  # the finished run's metadata, set by whoever ran it
    recorder: Recorder | None = None
    links: dict[str, Link] = field(default_factory=dict)
    notes: list[str] = field(default_factory=list)  # what the user should hear once the ports are open
    opened: bool = False  # every port opened
    outcome_extra: dict[str, str] = field(default_factory=dict)  # what the run adds to the outcome (its clock)

    def __enter__(self) -> Stage:
        try:
            self._open()
        except BaseException:
            exc_type, exc, tb = sys.exc_info()
            self.__exit__(exc_type, exc, tb)
            raise
        return self

    def _open(self) -> None:
        if self.log_path is not None:
            self.recorder = Recorder(self.log_path, self.info, unique=self.unique_log)
            self.log_path = self.recorder.path
            if self.opening_note:
                self.recorder.on_log(INFO, self.opening_note, self.clock.wall_ns())
        for robot in self.robots:
            self.links[robot.robot] = self._open_link(robot)
            note = self.links[robot.robot].latency_note
            if note is not None:
                self.notes.append(f"robot {robot.robot}: {note}" if self.named else note)
                if self.recorder is not None:
                    self.recorder.on_log(WARNING, self.notes[-1], self.clock.wall_ns())
        self.opened = True

    def finished(self, outcome: Mapping[str, str]) -> None:
        """The run is over: what it says of itself goes into the log's metadata at close."""
        self.outcome = dict(outcome)

    def add_to_outcome(self, extra: Mapping[str, str]) -> None:
        """What the run adds to the outcome however it ends (its clock, its music)."""
        self.outcome_extra.update(extra)

    def _open_link(self, robot: LinkSettings) -> Link:
        listeners = []
        if self.recorder is not None:
            listeners.append(self.recorder.for_robot(robot.robot) if self.named else self.recorder)
        try:
            return Link.open(robot.port, robot.baud, timeout=robot.timeout, tries=robot.tries, clock=self.clock,
                             listeners=listeners, layout=robot.layout)
        except LinkError as exc:
            if self.named:
                exc = LinkError(f"robot {robot.robot}: {exc}")
            if self.recorder is not None:
                self.recorder.on_log(ERROR, str(exc), self.clock.wall_ns())
            raise exc from None

    def __exit__(self, exc_type: type[BaseException] | None, exc: BaseException | None,
                 tb: TracebackType | None) -> None:
        for link in self.links.values():
            link.close()
        if self.recorder is not None:
            self.recorder.close({**outcome_metadata(self.outcome, exc), **self.outcome_extra})


def outcome_metadata(finished: dict[str, str] | None, exc: BaseException | None) -> dict[str, str]:
    """The log's last word: what the run said when it finished, else why it did not."""
    if finished is not None and exc is None:
        meta = dict(finished)
    elif isinstance(exc, (Interrupted, KeyboardInterrupt)):
        meta = {Result.OUTCOME: "interrupted"}
    else:
        meta = {Result.OUTCOME: "failed"}
    if isinstance(exc, ChoreoError):
        meta[Result.ERROR] = str(exc)
        meta[Result.EXIT_CODE] = str(exc.exit_code)
    elif isinstance(exc, KeyboardInterrupt):
        meta[Result.EXIT_CODE] = str(Interrupted.exit_code)
    elif exc is None:
        meta.setdefault(Result.EXIT_CODE, str(Interrupted.exit_code) if meta[Result.OUTCOME] == "aborted" else "0")
    return meta
