"""`choreo log timeline`: each motion on the show clock, planned against actual.

Planned: where the compiled plan put the play step (`estimated_s`) and how long the show says
the motion takes. Actual: from the restore frame that started it (once ACKed) to the first status
query that found the board no longer executing, or to the stop frame of the next play, or to
the end of the log. Late cues (a step starting more than 1 ms after it was due) and faults (any
reply other than ACK or status; error lines) are marked where they happened.

Text by default; `--png` draws the same with matplotlib (the optional extra `choreo[plot]`).
"""

from __future__ import annotations

from collections.abc import Iterator
from dataclasses import dataclass, field
from typing import BinaryIO

from choreo.errors import ChoreoError
from choreo.review.attached import AttachedShow, attached_show
from choreo.review.frames import ShowClock
from choreo.review.reader import Cut, LogReader, decode
from choreo.review.summary import LATE_MS, LOG_TOPIC, RX_TOPIC, STEP_TOPIC, TX_TOPIC

ERROR = 4  # foxglove.Log level
BAR_WIDTH = 60


class PlotUnavailable(ChoreoError):
    """`--png` without matplotlib installed."""

    exit_code = 2


@dataclass(frozen=True)
class MotionRun:
    """One play of a motion: planned and actual spans on the show clock (seconds)."""

    motion: int
    name: str | None
    step: int | None
    label: str | None
    planned_s: float | None  # the compiled plan's start for the play step
    expected_s: float  # how long the show says it takes
    due_s: float | None  # when the step was due at run time
    start_s: float | None  # the restore frame that started it (None: the play never started)
    end_s: float | None
    ended_by: str  # status | stop | end of log | not started
    late_ms: float = 0.0

    @property
    def planned_end_s(self) -> float | None:
        return None if self.planned_s is None else self.planned_s + self.expected_s

    @property
    def measured(self) -> bool:
        """A status query saw it end: `end_s` is its end (to within the 50 ms poll)."""
        return self.ended_by == "status"

    @property
    def drawn_end_s(self) -> float | None:
        """Where its actual bar ends: the measured end, else its expected length at most (what
        ended it - the next play's stop frame, the log's end - is only an upper bound)."""
        if self.start_s is None or self.end_s is None or self.measured:
            return self.end_s
        return min(self.end_s, self.start_s + self.expected_s)

    @property
    def actual_s(self) -> float | None:
        if self.start_s is None or self.end_s is None:
            return None
        return self.end_s - self.start_s

    def title(self) -> str:
        named = f" {self.name}" if self.name else ""
        return f"motion {self.motion}{named}"


@dataclass(frozen=True)
class Mark:
    """A moment worth a reviewer's eye: a late cue, a fault on the wire, an error line."""

    show_s: float
    kind: str  # late | fault | error
    text: str


@dataclass
class Timeline:
    show: str
    runs: list[MotionRun] = field(default_factory=list)
    marks: list[Mark] = field(default_factory=list)
    end_s: float = 0.0
    outcome: str | None = None
    cut: Cut | None = None
    show_problem: str | None = None

    @property
    def late(self) -> list[Mark]:
        return [m for m in self.marks if m.kind == "late"]

    @property
    def faults(self) -> list[Mark]:
        return [m for m in self.marks if m.kind != "late"]


@dataclass
class _Playing:
    """A play step in progress, from its step start to the board saying the motion is over."""

    motion: int
    step: int | None
    label: str | None
    planned_s: float | None
    due_s: float | None
    late_ms: float
    start_s: float | None = None


def build(reader: LogReader, show: AttachedShow | None = None) -> Timeline:
    """One pass over the log: the motion runs and the marks."""
    show = show or attached_show(reader)
    timeline = Timeline(reader.run_info.get("show") or reader.path.stem, show_problem=show.problem)
    clock = ShowClock(reader)
    steps: dict[int, dict] = {}  # play steps started and not yet played (index -> step start)
    armed: _Playing | None = None  # CALL sent, restore not yet ACKed
    running: _Playing | None = None
    frames: dict[int, tuple[str, dict]] = {}  # seq -> (frame kind, tx) awaiting its reply
    last_s = 0.0

    def finish(playing: _Playing, end_s: float | None, ended_by: str) -> None:
        timeline.runs.append(MotionRun(
            playing.motion, show.name_of(playing.motion), playing.step, playing.label, playing.planned_s,
            show.expected_s(playing.motion), playing.due_s, playing.start_s, end_s, ended_by,
            playing.late_ms))

    topic, number = None, 0
    try:
        for topic, log_time, data in reader.messages((STEP_TOPIC, TX_TOPIC, RX_TOPIC, LOG_TOPIC)):
            number += 1
            message = decode(data)
            if topic == STEP_TOPIC:
                clock.see_step(log_time, message)
                now = clock.seconds(log_time)
                if message["event"] == "start":
                    late_ms = message.get("late_ms") or 0.0
                    # Only a play's lateness shows on stage (a wait starts when the play is answered).
                    if late_ms > LATE_MS and message.get("kind") == "play":
                        label = f" '{message['label']}'" if message.get("label") else ""
                        timeline.marks.append(Mark(now, "late", f"step {message['index']}{label} started "
                                                                f"{late_ms:.1f} ms late (due {message['planned_s']:.3f} s)"))
                    if message.get("kind") == "play":
                        steps[message["index"]] = message
            elif topic == TX_TOPIC:
                now = clock.seconds(log_time)
                kind = message.get("kind")
                frames[message["seq"]] = (kind, message, now)
                if kind == "play":
                    key = (message.get("step"), message.get("motion"))
                    if armed is not None and (armed.step, armed.motion) == key:
                        armed.start_s = None  # the play sequence tried again from its stop frame
                    else:
                        if armed is not None:
                            finish(armed, None, "not started")
                        step = steps.pop(key[0], None) if key[0] is not None else None
                        armed = _Playing(message.get("motion"), key[0], message.get("label"),
                                         step.get("estimated_s") if step else None,
                                         step.get("planned_s") if step else None,
                                         step.get("late_ms", 0.0) if step else 0.0)
                elif kind == "restore" and armed is not None:
                    armed.start_s = now
                elif kind == "stop" and running is not None:
                    finish(running, now, "stop")
                    running = None
            elif topic == RX_TOPIC:
                now = clock.seconds(log_time)
                kind = message.get("kind")
                frame_kind, tx, sent_s = frames.pop(message.get("seq"), (None, {}, now))
                if kind not in ("ack", "status"):
                    step = tx.get("step")
                    where = f"step {step}: " if step is not None else ""
                    what = message.get("error") or kind
                    timeline.marks.append(Mark(now, "fault", f"{where}{kind.upper()} to {frame_kind or 'a frame'} "
                                                              f"(#{message.get('seq')}): {what}"))
                    if frame_kind == "restore" and armed is not None:
                        armed.start_s = None  # that try did not start it
                elif frame_kind == "restore" and armed is not None and armed.start_s is not None:
                    if running is not None:
                        finish(running, armed.start_s, "stop")
                    running, armed = armed, None
                elif frame_kind == "status" and running is not None and message.get("executing") is False:
                    finish(running, sent_s, "status")  # the query that found it over
                    running = None
            elif topic == LOG_TOPIC and message.get("level", 0) >= ERROR:
                now = clock.seconds(log_time)
                timeline.marks.append(Mark(now, "error", str(message.get("message", ""))))
            else:
                now = clock.seconds(log_time)
            if now is not None:
                last_s = max(last_s, now)
    except (KeyError, TypeError, ValueError, AttributeError) as exc:
        raise reader.not_choreo(topic, number, exc) from None
    if armed is not None:
        finish(armed, None, "not started")
    if running is not None:
        finish(running, last_s, "end of log")
    timeline.runs.sort(key=lambda r: (r.start_s if r.start_s is not None else r.due_s or 0.0))
    timeline.end_s = last_s
    timeline.cut = reader.cut
    timeline.outcome = (reader.result or {}).get("outcome")
    return timeline


# -- text --------------------------------------------------------------------------------------


def _cells(start: float | None, end: float | None, scale: float) -> range:
    if start is None:
        return range(0)
    first = min(BAR_WIDTH - 1, max(0, int(start * scale)))
    last = min(BAR_WIDTH - 1, max(first, int((end if end is not None else start) * scale)))
    return range(first, last + 1)


def render_text(timeline: Timeline) -> Iterator[str]:
    """The timeline as text: a bar a motion (`-` planned, `#` actual, `!` late), then the marks."""
    span = max(timeline.end_s, max((r.planned_end_s or 0.0 for r in timeline.runs), default=0.0), 0.001)
    scale = BAR_WIDTH / span
    outcome = f", {timeline.outcome}" if timeline.outcome else ""
    yield f"timeline of {timeline.show}: {timeline.end_s:.3f} s on the show clock{outcome}"
    yield f"bars: '-' planned, '#' actual, '!' started late; one column = {span / BAR_WIDTH * 1000:.0f} ms"
    if timeline.show_problem:
        yield f"(planned lengths: {timeline.show_problem}; 1 s each assumed)"
    ruler = f"0 s{'':{BAR_WIDTH - 3 - len(f'{span:.1f} s')}}{span:.1f} s"
    yield f"{'step':>5}  {'motion':<22} {'planned':>15} {'actual':>15}  |{ruler}|"
    for run in timeline.runs:
        bar = [" "] * BAR_WIDTH
        for i in _cells(run.planned_s, run.planned_end_s, scale):
            bar[i] = "-"
        for i in _cells(run.start_s, run.end_s, scale):
            bar[i] = "."
        for i in _cells(run.start_s, run.drawn_end_s, scale):
            bar[i] = "#"
        if run.late_ms > LATE_MS and run.start_s is not None:
            bar[_cells(run.start_s, run.start_s, scale)[0]] = "!"
        planned = _span(run.planned_s, run.planned_end_s)
        if run.start_s is None:
            actual = "not started"
        else:
            actual = _span(run.start_s, run.end_s) if run.measured else f"{run.start_s:.3f}-?"
        step = str(run.step) if run.step is not None else "abort"
        yield f"{step:>5}  {run.title()[:22]:<22} {planned:>15} {actual:>15}  |{''.join(bar)}|"
    if not timeline.runs:
        yield "  (no motion played)"
    if any(r.ended_by not in ("status", "not started") for r in timeline.runs):
        yield ("?: no status query saw it end (no `wait: done`): '#' for its expected length, "
               "'.' up to what stopped it (the next play, or the log's end)")
    for title, marks in (("late cues", timeline.late), ("faults", timeline.faults)):
        yield f"{title}: {len(marks) or 'none'}"
        for mark in marks:
            yield f"  {mark.show_s:9.3f} s  {mark.text}"
    if timeline.cut is not None:
        yield f"log {timeline.cut.state}: {timeline.cut}"


def counted(n: int, word: str) -> str:
    """`1 late cue`, `3 faults`."""
    return f"{n} {word}" if n == 1 else f"{n} {word}s"


def _span(start: float | None, end: float | None) -> str:
    if start is None:
        return "-"
    return f"{start:.3f}-{end:.3f}" if end is not None else f"{start:.3f}-"


# -- picture -----------------------------------------------------------------------------------


def require_matplotlib() -> None:
    """PlotUnavailable (exit 2, how to get it) before any file is made or any log read."""
    try:
        import matplotlib

        matplotlib.use("Agg")
        import matplotlib.pyplot  # noqa: F401
    except ImportError:
        raise PlotUnavailable("timeline --png needs matplotlib: pip install 'choreo[plot]' "
                              "(or pip install matplotlib); the text timeline works without it") from None


def render_png(timeline: Timeline, out: BinaryIO) -> None:
    """Draw the timeline as a PNG into `out`: a row a motion slot, planned bars above actual ones.

    Takes an open file, not a path: the command opens its output before it reads the log, so a
    path it cannot write is one line at once, never a long read and then a traceback.
    """
    require_matplotlib()
    import matplotlib.pyplot as plt

    slots = sorted({r.motion for r in timeline.runs})
    row = {motion: i for i, motion in enumerate(slots)}
    names = {r.motion: r.title() for r in timeline.runs}
    height = max(2.5, 0.55 * (len(slots) + 1) + 1.5)
    fig, ax = plt.subplots(figsize=(11, height), dpi=100)
    try:
        for run in timeline.runs:
            y = row[run.motion]
            if run.planned_s is not None:
                ax.broken_barh([(run.planned_s, run.expected_s)], (y - 0.42, 0.34),
                               facecolors="#b8c4d6", edgecolors="#6b7a90", linewidth=0.5)
            if run.start_s is not None and run.end_s is not None:
                colour = "#2f6db5" if run.measured else "#8c6bb1"
                ax.broken_barh([(run.start_s, max(run.drawn_end_s - run.start_s, 0.005))], (y - 0.04, 0.44),
                               facecolors=colour)
                if not run.measured and run.end_s > run.drawn_end_s:
                    ax.hlines(y + 0.18, run.drawn_end_s, run.end_s, colors=colour, linestyles="dotted",
                              linewidth=1.5)
            if run.late_ms > LATE_MS and run.start_s is not None:
                ax.plot([run.start_s], [y - 0.04], marker="v", color="#d62728", markersize=9, linestyle="")
        fault_y = len(slots)
        late = timeline.late
        faults = timeline.faults
        if faults:
            ax.plot([m.show_s for m in faults], [fault_y] * len(faults), marker="x", color="#d62728",
                    markersize=9, markeredgewidth=2, linestyle="")
        ax.set_yticks(list(range(len(slots))) + ([fault_y] if faults else []))
        ax.set_yticklabels([names[m] for m in slots] + (["faults"] if faults else []))
        ax.set_ylim(-0.8, fault_y + (0.8 if faults else -0.2))
        ax.invert_yaxis()
        ax.set_xlim(0, max(timeline.end_s, max((r.planned_end_s or 0 for r in timeline.runs), default=0), 0.1) * 1.02)
        ax.set_xlabel("show clock (s)")
        ax.grid(axis="x", color="#dddddd", linewidth=0.6)
        ax.set_axisbelow(True)
        title = f"{timeline.show}: {timeline.end_s:.2f} s"
        if timeline.outcome:
            title += f", {timeline.outcome}"
        if timeline.cut is not None:
            title += f" (log {timeline.cut.state})"
        title += f"; {counted(len(late), 'late cue')}, {counted(len(faults), 'fault')}"
        ax.set_title(title)
        from matplotlib.lines import Line2D
        from matplotlib.patches import Patch

        handles = [Patch(facecolor="#b8c4d6", edgecolor="#6b7a90", label="planned"),
                   Patch(facecolor="#2f6db5", label="actual (to status: done)"),
                   Patch(facecolor="#8c6bb1", label="actual (end not polled: expected length)"),
                   Line2D([], [], marker="v", color="#d62728", linestyle="", label="late cue"),
                   Line2D([], [], marker="x", color="#d62728", linestyle="", markeredgewidth=2, label="fault")]
        ax.legend(handles=handles, loc="upper center", bbox_to_anchor=(0.5, -0.18), ncol=5, frameon=False,
                  fontsize="small")
        fig.tight_layout()
        fig.savefig(out, format="png")
    finally:
        plt.close(fig)
