"""The text of `choreo log summary`: a `Summary` (see `summary`) as the lines it prints.

Apart from `summary`, which reads the log into counts and distributions in one pass: that half
is what the JSON output and the tests read; this half is only wording and layout, and changes
without touching how anything is counted.
"""

from __future__ import annotations

from collections.abc import Iterable

from choreo.log.format import COMMAND_TOPIC, ERROR, LATE_MS, Info, LoggedRun, LogLayouts, Result, host_key
from choreo.numtext import whole_number
from choreo.review.showtime import fixed
from choreo.review.summary import FRAME_KINDS, LISTED_PLAYS, MotionStats, Summary
from choreo.review.timeline import link_text, stood_text

def _ms(value: float | None) -> str:
    return "-" if value is None else f"{fixed(value)} ms"


def render(summary: Summary) -> Iterable[str]:
    """The summary as the lines `choreo log summary` prints."""
    yield from _render_run(summary)
    yield from _render_outcome(summary)
    yield from _render_stands(summary)
    yield from _render_wire(summary)
    yield from _render_clock(summary)
    yield from _render_motions(summary)
    yield from _render_robots(summary)
    yield from _render_commands(summary)
    yield from _render_log_lines(summary)
    yield f"messages  {summary.messages}"


def _state(summary: Summary) -> str:
    """Whether the log is whole, and if not, why."""
    if summary.complete:
        return "complete"
    if summary.cut is not None:
        return f"{summary.cut.state.upper()}: {summary.cut}"
    if summary.result is None:
        return "UNFINISHED: the run recorded no result (it did not close its log)"
    return "UNFINISHED: no MCAP footer"


# What ended a play no status query timed (MotionPlay.ended_by), as the summary says it.
ENDED_BY = {
    "state read": "ended by the program state read after a lost reply (over before it)",
    "stop": "ended by the next play's stop",
    "end of log": "running at the log's end",
    "status": "ended by a status query at no known time",
}


def _spread(stats: MotionStats) -> str:
    """A motion slot's measured lengths, and what ended the plays no status query timed."""
    whys = "; ".join(f"{count} {ENDED_BY.get(by, by)}" for by, count in stats.unmeasured.items())
    if not stats.durations or stats.median_s is None:
        return f"not measured ({whys or 'no status query saw it end'})"
    spread = (f"median {fixed(stats.median_s)} s (min {fixed(min(stats.durations))}, "
              f"max {fixed(max(stats.durations))})")
    return spread + (f"; {sum(stats.unmeasured.values())} not measured ({whys})" if whys else "")


def _render_run(summary: Summary) -> Iterable[str]:
    """Which log, which show, and the run that wrote it (where, when, with what)."""
    run = summary.run
    yield f"log       {summary.path}  ({_state(summary)})"
    sha, path = run.get(Info.SHOW_SHA256, ""), run.get(Info.SHOW_PATH)
    where = f" ({path}" + (f", sha256 {sha[:12]}" if sha else "") + ")" if path else ""
    yield f"show      {summary.show_name}{where}"
    made = f"(choreo {run.get(Info.VERSION, '?')}, host {run.get(Info.HOST, '?')})"
    if run and run.get(Info.ROBOTS):
        names = run[Info.ROBOTS].split(",")
        robots = f"{len(names)} robot" + ("s" if len(names) != 1 else "")
        yield (f"run       started {run.get(Info.START_TIME, '?')}, {robots} ({', '.join(names)}; "
               f"ports below) {made}")
    elif run:
        yield (f"run       started {run.get(Info.START_TIME, '?')} on {run.get(Info.PORT, '?')} at "
               f"{run.get(Info.BAUD, '?')} baud, layout {LogLayouts.of(run).describe(None)} {made}")
    else:
        yield "run       no `choreo` metadata: not a log written by choreo run"
    for note in summary.run_notes:
        yield f"          {note}"
    yield from _render_hosts(run)


def _render_hosts(run: dict[str, str]) -> Iterable[str]:
    """A merged log (`choreo log merge`): its hosts, and how each was lined up on the first's time."""
    hosts = LoggedRun(run).hosts
    if not hosts:
        if run.get(Info.SHOW_HOST):  # one host's log (`choreo run --host`): its robots only
            yield (f"host      {run[Info.SHOW_HOST]} of the show's hosts: its robots only; the others' are in "
                   "their hosts' logs (choreo log merge joins them)")
        return
    placed = []
    for host in hosts[1:]:
        shift = run.get(host_key(host, Info.SHIFT_NS), "")
        size, spread = whole_number(shift.removeprefix("-")), whole_number(run.get(host_key(host, Info.SPREAD_NS), ""))
        by = run.get(host_key(host, Info.ALIGNED_BY), "?")
        how = f"spread {fixed(spread / 1e6)} ms" if spread is not None and by == "clock" else f"by {by}"
        moved = "?" if size is None else f"{fixed((-size if shift.startswith('-') else size) / 1e9, 6, sign=True)} s"
        placed.append(f"{host} shifted {moved} ({how})")
    yield f"hosts     {len(hosts)} merged: {hosts[0]} (the time axis, its clock times the show), {', '.join(placed)}"


def _render_outcome(summary: Summary) -> Iterable[str]:
    """How the run ended, and what its steps came to."""
    duration = f"{fixed(summary.duration_s)} s" if summary.duration_s is not None else "-"
    if summary.result:
        outcome = summary.result.get(Result.OUTCOME, "?")
        error = summary.result.get(Result.ERROR)
        code = summary.result.get(Result.EXIT_CODE)
        yield f"outcome   {outcome}" + (f" (exit {code})" if code else "") + f", {duration} on the show clock"
        if error:
            yield f"          {error}"
    else:
        yield f"outcome   unknown (no result recorded): {duration} on the show clock up to the last message"
    by_retries = f" ({summary.steps_late_by_retries} by retries)" if summary.steps_late_by_retries else ""
    steps = (f"steps     {summary.steps_run} run: {summary.steps_done} done, {summary.steps_late} late{by_retries}, "
             f"{summary.steps_failed} failed")
    if summary.steps_aborted:
        steps += f", {summary.steps_aborted} aborted"
    if summary.steps_unfinished:
        steps += f", {summary.steps_unfinished} unfinished"
    if summary.steps_skipped:
        steps += f", {summary.steps_skipped} skipped"
    yield steps


def _render_wire(summary: Summary) -> Iterable[str]:
    """Frames and replies, and the timing figures: reply latency, cue lateness, motion starts."""
    kinds = ", ".join(f"{k} {n}" for k, n in summary.frames.items() if n or k in FRAME_KINDS)
    yield f"frames    {summary.frames_sent} sent ({kinds}); {summary.retries} retries"
    replies = ", ".join(f"{k.upper() if k in ('ack', 'nak') else k} {n}" for k, n in summary.replies.items())
    unanswered = f"; {summary.unanswered} unanswered (log cut)" if summary.unanswered else ""
    yield f"replies   {replies}; stale {summary.stale} (late replies to earlier frames, set aside){unanswered}"
    lat = summary.latency
    yield (f"latency   min {_ms(lat.min)}, median {_ms(lat.median)}, p99 {_ms(lat.p99)}, "
           f"max {_ms(lat.max)} ({len(lat)} replies)")
    lateness = summary.lateness
    yield (f"cues      lateness median {_ms(lateness.median)}, p99 {_ms(lateness.p99)}, max "
           f"{_ms(lateness.max)} ({len(lateness)} plays, {lateness.above(LATE_MS)} over {LATE_MS:g} ms)")
    starts = summary.motion_starts
    if len(starts):
        yield (f"starts    motion start vs cue (start frame written): median {_ms(starts.median)}, p99 "
               f"{_ms(starts.p99)}, max {_ms(starts.max)} ({len(starts)} cued plays, sent early by their lead)")


def _render_stands(summary: Summary) -> Iterable[str]:
    """Each time the show clock stood still: held at a GO cue, paused; hold time is no drift."""
    lengths = summary.lengths
    text = stood_text(lengths)
    if lengths is None or not text:
        return
    yield ("holds     " if lengths.holds or lengths.pauses else "ran       ") + text
    for stand in summary.stands:
        yield f"  {fixed(stand.stand.show_s, 3, 9)} s  {stand.text(summary.end_ns)}"
    listed = len(summary.stands)
    if lengths.holds + lengths.pauses > listed:
        yield f"  ... and {lengths.holds + lengths.pauses - listed} more"


def _render_log_lines(summary: Summary) -> Iterable[str]:
    """The warnings and errors the run logged: counted, the first few listed."""
    yield f"log lines {summary.warnings} warnings, {summary.errors} errors"
    for line in summary.log_lines:
        word = "error  " if line.level >= ERROR else "warning"
        yield f"  {fixed(line.show_s, 3, 9)} s  {word} {line.message}"
    if summary.warnings + summary.errors > len(summary.log_lines):
        yield f"  ... and {summary.warnings + summary.errors - len(summary.log_lines)} more (choreo log frames)"


def _render_clock(summary: Summary) -> Iterable[str]:
    """Which clock kept the show, and how it ran against the machine's."""
    clock, result = summary.clock, summary.result or {}
    if clock is None:
        return
    if clock.source == "music":
        music = f"the music ({result.get(Result.MUSIC_FILE, '?')} from {result.get(Result.MUSIC_START, '0')} s"
        backend = result.get(Result.AUDIO_BACKEND)
        kept = music + (f", on {backend})" if backend else ")")
    elif summary.link is not None:
        kept = link_text(summary.link)
    else:
        kept = "the machine's"
    ran = f" it ran (of {fixed(clock.span_s, 1)} s; the rest held or paused)" if clock.stood_s > 0 else ""
    drift = (f"; show clock minus machine clock {fixed(clock.drift_ms, sign=True)} ms "
             f"over the {fixed(clock.ran_s, 1)} s{ran}"
             if clock.samples > 1 else "")
    disordered = (f"; {summary.clock_disordered} out of order, passed over"
                  if summary.clock_disordered else "")
    yield f"clock     {kept}{'; ' if summary.link is not None else ': '}{clock.samples} samples{drift}{disordered}"


def _render_commands(summary: Summary) -> Iterable[str]:
    """Who pressed what and when: every GO, panic, start and stop, refused ones included, and
    the counts of those the limits kept out of the log one by one. "Received", not "from the
    operator": a flood refused from a stranger's address is counted here too."""
    if not summary.commands_total:
        return
    unlogged = ""
    if summary.commands_unlogged:
        by = ", ".join(f"{n} {name}" for name, n in sorted(summary.commands_by.items(), key=lambda kv: (-kv[1], kv[0])))
        unlogged = f"; {summary.commands_unlogged} of them not logged one by one, over the log's limit): {by}"
    yield f"commands  {summary.commands_total} received ({summary.commands_refused} refused{unlogged or ')'}"
    for command in summary.commands:
        when = f"{fixed(command.show_s, 3, 9)} s" if command.show_s is not None else "   before  "
        what = command.what
        verdict = "" if command.status == "ok" else f" {command.status.upper()}"
        yield f"  {when}  {what:<12} {command.source}{verdict}: {command.message}"
    if summary.command_records > len(summary.commands):
        more = summary.command_records - len(summary.commands)
        yield f"  ... and {more} more (all on the log's {COMMAND_TOPIC} topic: open the log in Foxglove)"


def _render_robots(summary: Summary) -> Iterable[str]:
    """A show for several robots: a line or two per robot, and how together the unison plays began."""
    if not summary.robots:
        return
    if len(summary.skew):
        skew = summary.skew
        yield (f"unison    motion starts apart: median {_ms(skew.median)}, p99 {_ms(skew.p99)}, max "
               f"{_ms(skew.max)} ({len(skew)} plays by several robots; first robot's start to the last's)")
    layouts = LogLayouts.of(summary.run)
    for name, robot in summary.robots.items():
        run = robot.run
        late = f", {robot.steps_late} late" if robot.steps_late else ""
        failed = f", {robot.steps_failed} failed" if robot.steps_failed else ""
        aborted = f", {robot.steps_aborted} aborted" if robot.steps_aborted else ""
        yield (f"robot {name}: {run.get(Info.PORT, '?')} at {run.get(Info.BAUD, '?')} baud, "
               f"layout {layouts.describe(name)}; "
               f"{robot.steps_run} steps{late}{failed}{aborted}, {robot.frames_sent} frames, {robot.retries} retries, "
               f"{robot.plays_total} plays")
        lat, cues = robot.latency, robot.lateness
        yield (f"          latency median {_ms(lat.median)}, p99 {_ms(lat.p99)}; cue lateness median "
               f"{_ms(cues.median)}, max {_ms(cues.max)}")


def _render_motions(summary: Summary) -> Iterable[str]:
    if not summary.plays_total:
        yield "motions   none played"
        return
    yield f"motions   {summary.plays_total} played (measured: restore to the first status not executing)"
    for stats in sorted(summary.motions.values(), key=lambda s: s.motion):
        yield f"  motion {stats.motion:3d}  x{stats.plays:<5d} {_spread(stats)}"
    if summary.plays_total <= LISTED_PLAYS:
        for play in summary.plays:
            label = f" '{play.label}'" if play.label else ""
            where = f"step {play.step}{label}" if play.step is not None else "abort"
            took = (f"{fixed(play.duration_s)} s" if play.duration_s is not None
                    else f"not measured (ended by {play.ended_by})")
            yield f"  {fixed(play.start_s, 3, 9)} s  motion {play.motion:3d}  {where}: {took}"
