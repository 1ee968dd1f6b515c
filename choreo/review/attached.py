"""The show a run played, as attached to its log: motion names, expected durations, the sim URL.

A log carries the show file itself (application/yaml), so a review can say "wave" rather than
"motion 4", draw each motion's planned length, and replay against a simulator that runs the
motions as long as the show says. The attachment goes through choreo's own show loader (every
check, the YAML-bomb guards included): a log is data from elsewhere, and a show that no longer
loads (an older format, a tampered log) only costs those niceties, never the review.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING

from choreo.log.format import SHOW_FALLBACK_NAME
from choreo.log.reader import LogReader
from choreo.textfit import fit

NAME_SHOWN = 255  # characters of an attached show's file name a review keeps (a file name's most)

if TYPE_CHECKING:  # for the types only: the show loader is imported when a log has a show attached
    from choreo.show.model import Plan, Show


@dataclass(frozen=True)
class AttachedShow:
    """What a review takes from the attached show; empty when the log has none or it fails to load."""

    show: Show | None = None
    plan: Plan | None = None  # with several robots, the first's
    names: dict[int, str] = field(default_factory=dict)  # slot -> first name in `motions:`
    durations: dict[int, float] = field(default_factory=dict)  # slot -> expected seconds
    problem: str | None = None  # why the show could not be used, if it could not
    plans: dict[str, Plan] = field(default_factory=dict)  # robot -> Plan, in a show for several robots
    source: bytes = b""  # the attached file as read (within a show file's size; nothing past it)
    file_name: str = ""  # its name, cut to NAME_SHOWN

    def plan_of(self, robot: str | None) -> Plan | None:
        """The robot's plan (None: the one robot's)."""
        return self.plan if robot is None else self.plans.get(robot)

    def name_of(self, motion: int | None) -> str | None:
        return self.names.get(motion) if motion is not None else None

    def expected_s(self, motion: int) -> float:
        """The motion's expected length: the show's, else the default the plan and simulator use."""
        from choreo.show.model import DEFAULT_MOTION_S

        return self.durations.get(motion, DEFAULT_MOTION_S)


def attached_show(reader: LogReader) -> AttachedShow:
    """Load the show attached to the log, from its bytes: its music file is not looked for
    (the review needs the plan, not the song, and the song may be elsewhere now)."""
    attachment = reader.show_attachment()
    if attachment is None:
        return AttachedShow(problem="the log has no show attached")
    from choreo.show.read import MAX_BYTES

    if attachment.size > MAX_BYTES:  # read whole, a hostile log's gigabyte would be memory
        return AttachedShow(problem=f"the attached show is {attachment.size:,} bytes, over the "
                                    f"{MAX_BYTES // 1024} KiB a show file may be: not read")
    source = reader.attachment_data(attachment)
    try:
        from choreo.errors import ChoreoError
        from choreo.show.load import load_show_bytes
        from choreo.show.plan import compile_plans
    except ImportError as exc:  # pragma: no cover - the loader ships with choreo
        return AttachedShow(problem=f"cannot load shows here: {exc}")
    name = fit(Path(attachment.name).name, NAME_SHOWN) or SHOW_FALLBACK_NAME  # a hostile log's is any length
    try:
        show = load_show_bytes(source, name)
        plans = compile_plans(show)
    except ChoreoError as exc:
        first = str(exc).splitlines()[0] if str(exc) else type(exc).__name__
        return AttachedShow(problem=f"the attached show {name} does not load: {first}", source=source, file_name=name)
    names: dict[int, str] = {}
    durations: dict[int, float] = {}
    for motion in show.motions.values():
        names.setdefault(motion.number, motion.name)
        if motion.duration is not None:
            durations.setdefault(motion.number, motion.duration)
    return AttachedShow(show, next(iter(plans.values())), names, durations,
                        plans=plans if show.ensemble else {}, source=source, file_name=name)
