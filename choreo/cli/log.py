"""`choreo log summary|frames|timeline|export LOG` and `choreo replay LOG`: reviewing a run.

Everything prints to stdout as it is read, so `choreo log frames LOG | head` answers at once and
a closed pipe ends the command quietly. A log cut short by a killed run is reviewed as far as it
goes and says where it stops (exit 0): that is the run a reviewer most needs to see.
"""

from __future__ import annotations

import argparse
import errno
import json
import os
import stat
import sys
from collections.abc import Iterable, Iterator
from contextlib import ExitStack, contextmanager, suppress
from pathlib import Path
from typing import IO, TYPE_CHECKING, BinaryIO, TextIO, cast

from choreo.cli.jsonout import error_record, print_json
from choreo.cli.terminal import UNKNOWN_COLUMNS, columns, print_fitted
from choreo.errors import ChoreoError, UsageError, did_you_mean
from choreo.log import LOG_DIR, LOG_SUFFIX
from choreo.textfit import fit, visible
from choreo.userfile import folder_problem, same_file
from choreo.wire.layouts import LAYOUT_NAMES
from choreo.wire.protocol import DEFAULT_BAUD, FrameKind, ReplyKind, spell_bauds

if TYPE_CHECKING:  # loaded by the commands that read logs: --help stays light
    from choreo.log.reader import LogReader
    from choreo.run.replay import ReplayReport

# what --kind takes, in the order a run sends them: the wire's names (FrameKind, ReplyKind), not copies
FRAME_AND_REPLY_KINDS = tuple(kind.value for kind in (
    FrameKind.STOP, FrameKind.COUNTER, FrameKind.PLAY, FrameKind.RESTORE, FrameKind.STATUS, FrameKind.READ,
    FrameKind.SYNC, ReplyKind.ACK, ReplyKind.NAK, ReplyKind.TIMEOUT, ReplyKind.INVALID))


def register(subparsers: argparse._SubParsersAction) -> None:
    parser = subparsers.add_parser(
        "log",
        help="review a run's log: summary, frames, timeline, export",
        description="Review the MCAP log of a run (complete, or cut short by a crash).",
    )
    commands = parser.add_subparsers(dest="log_command", metavar="COMMAND")
    commands.required = True
    _summary_parser(commands)
    _latest_parser(commands)
    _frames_parser(commands)
    _timeline_parser(commands)
    _export_parser(commands)
    _merge_parser(commands)
    _replay_parser(subparsers)


def _summary_parser(commands: argparse._SubParsersAction) -> None:
    """`log summary LOG...`: did the show run as planned."""
    summary = commands.add_parser(
        "summary", help="did the show run as planned: steps, frames, replies, latency, lateness, motions",
        description="Summarise a run: show, port, duration; steps done, late and failed; frames and "
        "replies by kind; reply latency and cue lateness; each motion's measured duration; "
        "whether the log is complete.")
    summary.add_argument("log", nargs="+", help="run logs (.mcap), or folders of them (every .mcap in it, "
                         "oldest first)")
    summary.add_argument("--json", action="store_true", help="one JSON object a log, one a line (JSON Lines)")
    summary.set_defaults(handler=run_summary)


def _latest_parser(commands: argparse._SubParsersAction) -> None:
    """`log latest [DIR]`: the newest log's path, for scripts."""
    latest = commands.add_parser(
        "latest", help="print the newest log's path",
        description="Print the path of the newest .mcap log in DIR (default runs/, where `choreo run` "
        "writes them), for scripts: `choreo log summary \"$(choreo log latest)\"`.")
    latest.add_argument("dir", nargs="?", default=LOG_DIR, help=f"the folder (default {LOG_DIR})")
    latest.set_defaults(handler=run_latest)


def _frames_parser(commands: argparse._SubParsersAction) -> None:
    """`log frames LOG`: every frame and reply, one line each."""
    frames = commands.add_parser(
        "frames", help="every frame and reply, one line each, with what it means",
        description="One line a frame or reply: show time, direction, seq, kind, bytes, meaning.")
    frames.add_argument("log", help="the run's .mcap log")
    frames.add_argument("--step", type=int, metavar="N", help="only the frames of step N (index from `choreo plan`)")
    frames.add_argument("--kind", choices=FRAME_AND_REPLY_KINDS, metavar="K",
                        help="only frames of this kind or with replies of this kind: "
                        + ", ".join(FRAME_AND_REPLY_KINDS))
    frames.add_argument("--robot", metavar="NAME", help="only this robot's frames (a show for several robots)")
    frames.add_argument("--json", action="store_true",
                        help="one JSON object: {ok, log, frames: [one object a frame, the fields of "
                        "`log export`], cut: null or {state, reason}}; a failure is {ok: false, exit, error}")
    frames.set_defaults(handler=run_frames)


def _timeline_parser(commands: argparse._SubParsersAction) -> None:
    """`log timeline LOG`: each motion on the show clock, planned against actual."""
    timeline = commands.add_parser(
        "timeline", help="each motion on the show clock, planned against actual",
        description="Each motion as a bar on the show clock, planned against actual (the plan stays "
        "visible, its unplayed rest in grey), with cues, late plays (retries included, as log summary "
        "counts them), faults, failed and aborted steps marked. Text fitted to the terminal by default; "
        "--png draws a picture (needs matplotlib: choreo[plot]).")
    timeline.add_argument("log", help="the run's .mcap log")
    timeline.add_argument("--png", metavar="FILE", help="write a PNG picture to FILE instead of text")
    timeline.set_defaults(handler=run_timeline)


def _export_parser(commands: argparse._SubParsersAction) -> None:
    """`log export LOG`: one row a frame, as CSV or JSON."""
    export = commands.add_parser(
        "export", help="one row a frame with all its fields, as CSV or JSON",
        description="Write one row a frame (the frame's and its reply's fields, times as wall-clock ns "
        "and show-clock s) for spreadsheets and pandas. FILE '-' is stdout.")
    export.add_argument("log", nargs="+", help="the run's .mcap log (--parquet: several logs, or folders of them)")
    export.add_argument("--csv", metavar="FILE", help="write CSV to FILE")
    export.add_argument("--json", metavar="FILE", help="write a JSON array to FILE")
    export.add_argument("--jsonl", metavar="FILE", help="write JSON Lines (one object a row) to FILE")
    export.add_argument("--cues", action="store_true",
                        help="one row a cue a robot instead: number, label, planned and actual show time, "
                        "lateness, how it was released (time, whose GO, skipped, not reached), bar.beat")
    export.add_argument("--parquet", metavar="DIR",
                        help="write each log's frames, steps, cues and commands as Parquet tables into DIR "
                        "(DIR/<log>.frames.parquet ...), every row with its run's id: many runs, one query "
                        "(needs pyarrow: choreo[parquet])")
    export.add_argument("--format", choices=EXPORT_FORMATS,
                        help="the same as --csv, --json, --jsonl or --parquet with -o's PATH (stdout if none; "
                        "parquet needs -o DIR)")
    export.add_argument("-o", "--output", metavar="PATH",
                        help="with --format: where to write (FILE, or DIR for parquet)")
    export.set_defaults(handler=run_export)


def _merge_parser(commands: argparse._SubParsersAction) -> None:
    """`log merge A B... -o SHOW`: the logs of one show's hosts as one log."""
    merge = commands.add_parser(
        "merge", help="join the logs of one show's hosts into one log every review reads",
        description="Join the logs of one show's hosts (each a choreo run with its own robots, on one Link "
        "session) into one MCAP log: every robot on its own topics, each host's log, clock and commands on "
        "topics of its own, the first log's time the axis, each other log lined up on its clock samples.")
    merge.add_argument("logs", nargs="+", metavar="LOG", help="the hosts' .mcap logs, the time axis's first")
    merge.add_argument("-o", "--output", required=True, metavar="FILE", help="the merged log to write (.mcap)")
    merge.set_defaults(handler=run_merge)


def run_merge(args: argparse.Namespace) -> int:
    """Say how each host was lined up (shift and spread) and what was written."""
    from choreo.log.merge import merge_logs
    from choreo.run.settings import check_output_folder

    check_output_folder(Path(args.output), "-o")
    report = merge_logs(args.logs, args.output)
    for alignment in report.alignments:
        print_fitted(alignment.describe())
    for warning in report.warnings:
        print_fitted(f"warning: {warning}", sys.stderr)
    hosts = ", ".join(f"{log.host} ({', '.join(log.robots)})" for log in report.hosts)
    print_fitted(f"merged {len(report.hosts)} logs, {report.messages} messages, hosts {hosts}: {report.output}")
    return 0


def _replay_parser(subparsers: argparse._SubParsersAction) -> None:
    """`replay LOG` (a command of its own, beside `log`): send a run's frames again and compare."""
    replay = subparsers.add_parser(
        "replay", help="send a recorded run's frames again and compare the replies",
        description="Send every frame of a run's log again with its recorded timing (to the built-in "
        "simulator unless --port says otherwise), record a new log, and report where the replies "
        "differ from the recorded ones. Exit 0 when it ran; with --strict, exit 1 if any differ.")
    replay.add_argument("log", help="the recorded run's .mcap log")
    replay.add_argument("--port", help="where to send the frames (default: sim://, set up from the "
                        "show attached to the log; a real robot only if you name its port)")
    replay.add_argument("--speed", type=float, default=1.0, metavar="X",
                        help="timing factor, 0.01..1000: 2 plays twice as fast, and a sim:// board runs its "
                        "motions twice as fast too (default 1, the recorded timing)")
    replay.add_argument("--layout", choices=LAYOUT_NAMES,
                        help="the board layout the simulator models, for every robot of a show for several "
                        "(default: the one the log records for each robot)")
    replay.add_argument("--baud", type=int, help=f"{spell_bauds('or')} (default: the recorded run's "
                        f"for --port, {DEFAULT_BAUD} for the simulator)")
    replay.add_argument("--timeout", type=float, metavar="S",
                        help="seconds to wait for a reply, more than 0 and at most 10 (default 0.2)")
    replay.add_argument("--log", dest="new_log", metavar="PATH",
                        help="the replay's own log (default runs/<show>-replay-<UTC time>.mcap)")
    replay.add_argument("--strict", action="store_true", help="exit 1 if any reply differs")
    replay.add_argument("--quiet", "-q", action="store_true", help="print only the result line")
    replay.add_argument("--json", action="store_true",
                        help="at the end, one JSON object on stdout: the figures of the result line, the "
                        "logs, and every difference; a failure is {ok: false, exit, error}")
    replay.set_defaults(handler=run_replay)


def _print_all(lines: Iterable[str]) -> None:
    """Each line fitted to the terminal (cut with '…'); to a file or a pipe, whole."""
    width = columns()
    for line in lines:
        sys.stdout.write(fit(line, width) + "\n")


def run_summary(args: argparse.Namespace) -> int:
    """One summary a log, a blank line between; a log that cannot be read is one line on stderr
    (with --json, its error object in the stream too) and the others are still summarised
    (exit 2 at the end)."""
    from choreo.review.summary import summarize, summary_record
    from choreo.review.summarytext import render

    failed = 0
    width = columns()
    out = sys.stdout
    for number, path in enumerate(_logs_in(args.log)):
        try:
            summary = summarize(path)
        except ChoreoError as exc:
            failed += 1
            for line in exc.lines():  # escaped, one line, as cli.main prints every error
                print(line, file=sys.stderr)
            if args.json:
                out.write(json.dumps({**error_record(exc), "log": str(path)}, ensure_ascii=False) + "\n")
            continue
        if args.json:
            out.write(json.dumps(summary_record(summary), separators=(",", ":")) + "\n")
        else:
            out.write(("\n" if number else "") + "\n".join(fit(line, width) for line in render(summary)) + "\n")
        out.flush()
    return 2 if failed else 0


def run_latest(args: argparse.Namespace) -> int:
    if _missing(args.dir):  # the usual case on a new machine: say where logs go
        raise UsageError(f"{args.dir}: no such folder (`choreo run` writes its logs to runs/)")
    print(visible(str(_folder_logs(Path(args.dir))[-1])))  # one line, even for a name with a line break
    return 0


def _missing(name: str) -> bool:
    """Nothing is there by that name; a name too long or holding a NUL is not "missing": the
    listing says what it is (os.path.lexists answered False for both)."""
    try:
        os.lstat(name)
    except FileNotFoundError:
        return True
    except (OSError, ValueError):
        return False
    return False


def _logs_in(given: list[str]) -> list[Path]:
    """The logs named, a folder standing for every .mcap in it (oldest first)."""
    logs: list[Path] = []
    for name in given:
        path = Path(name)
        if not _is_folder(path):
            logs.append(path)  # the log reader says what is wrong with anything that is not a log
            continue
        logs += _folder_logs(path)
    return logs


def _is_folder(path: Path) -> bool:
    try:
        return stat.S_ISDIR(os.stat(path).st_mode)
    except (OSError, ValueError):
        return False


def _folder_logs(folder: Path) -> list[Path]:
    """The regular `*.mcap` files in `folder`, oldest first (by modification time, then name);
    a folder without one is a `UsageError`.

    A link to nothing, a loop of links, a pipe or a folder named `x.mcap` is not a log and is
    passed over; a folder that cannot be listed is an `InputError` saying why, never "no logs".
    """
    from choreo.userfile import listing, modified_if_regular

    logs, others = [], 0
    for path in listing(folder, "log folder"):
        if not path.name.endswith(LOG_SUFFIX) or path.name.startswith("."):
            continue
        modified = modified_if_regular(path)
        if modified is None:
            others += 1
        else:
            logs.append((modified, path.name, path))
    if not logs:
        passed = f" ({others} named *.mcap are not regular files)" if others else ""
        raise UsageError(f"{folder}: no .mcap logs in this folder{passed}")
    return [path for _, _, path in sorted(logs)]


def run_frames(args: argparse.Namespace) -> int:
    from choreo.review.frames import frame_lines
    from choreo.log.reader import LogReader

    with LogReader(args.log) as reader:
        robots = reader.robots
        if args.robot is not None and args.robot not in robots:
            known = f"its robots: {', '.join(robots)}" if robots else "it is a one-robot log"
            raise UsageError(f"--robot {args.robot}: not a robot of this log"
                             f"{did_you_mean(args.robot, robots)}; {known}")
        if args.json:
            _print_frames_json(reader, args)
        else:
            _print_all(frame_lines(reader, step=args.step, kind=args.kind, robot=args.robot))
    return 0


def _print_frames_json(reader: LogReader, args: argparse.Namespace) -> None:
    """One object, printed once the whole log is read: a log that turns out not to be choreo's
    half-way is the failure object alone, never half an object and then another."""
    from choreo.log.format import TX_TOPIC, LogLayouts
    from choreo.review.export import row
    from choreo.review.frames import exchanges, matches

    layouts = LogLayouts.of(reader.run_info)
    records = []
    for exchange in exchanges(reader):
        if not matches(exchange, args.step, args.kind, args.robot):
            continue
        try:
            records.append(row(exchange, layouts))
        except (KeyError, TypeError, ValueError, AttributeError) as exc:
            raise reader.not_choreo(TX_TOPIC, exchange.seq, exc) from None
    cut = {"state": reader.cut.state, "reason": str(reader.cut)} if reader.cut is not None else None
    print_json({"ok": True, "log": str(reader.path), "frames": records, "cut": cut})


def run_timeline(args: argparse.Namespace) -> int:
    from choreo.log.reader import LogReader
    from choreo.review.timeline import build, render_text

    if args.png:
        return _timeline_png(args.log, args.png)

    with LogReader(args.log) as reader:
        timeline = build(reader)
    _print_all(render_text(timeline, columns() or UNKNOWN_COLUMNS))
    return 0


def _timeline_png(log: str, png: str) -> int:
    """Check what can fail fast (the log's head, matplotlib, the output file), then read and draw."""
    from choreo.log.reader import LogReader
    from choreo.review.timeline import build, counted, render_png, require_matplotlib

    with LogReader(log) as reader:
        require_matplotlib()
        with _output(png, "timeline --png", log, binary=True) as out:
            timeline = build(reader)
            render_png(timeline, cast(BinaryIO, out))  # _output(binary=True) opens it in binary mode
    cut = f" (log {timeline.cut.state}: {timeline.cut.reason})" if timeline.cut else ""
    _print_all([f"timeline: {png}: {counted(len(timeline.runs), 'motion')}, "
                f"{counted(len(timeline.late), 'late play')}, {counted(len(timeline.faults), 'fault')}{cut}"])
    return 0


EXPORT_FORMATS = ("csv", "json", "jsonl", "parquet")


def _outputs(args: argparse.Namespace) -> dict[str, str | None]:
    """Where each format goes: `--csv FILE` ..., or `--format F -o PATH` (pandas' and most
    exporters' spelling: stdout without -o, but parquet, which needs a folder)."""
    given = {name: getattr(args, name) for name in EXPORT_FORMATS}
    if args.format is None:
        if args.output is not None:
            raise UsageError("log export: -o PATH goes with --format csv|json|jsonl|parquet")
        return given
    named = [name for name, value in given.items() if value]
    if named:
        raise UsageError(f"log export: --format {args.format} or --{named[0]} PATH, not both")
    if args.format == "parquet" and args.output is None:
        raise UsageError("log export --format parquet: say where: -o DIR (an existing folder)")
    return {**given, args.format: args.output if args.output is not None else "-"}


def run_export(args: argparse.Namespace) -> int:
    from choreo.review.export import CUE_COLUMNS, COLUMNS, CsvSink, JsonLinesSink, JsonSink, export, export_cues
    from choreo.log.reader import LogReader

    outputs = _outputs(args)
    targets = [(name, value) for name, value in outputs.items() if value and name != "parquet"]
    parquet = outputs["parquet"]
    if parquet is not None:
        return _export_parquet(args, parquet, bool(targets))
    if len(args.log) > 1:
        raise UsageError("log export: one log at a time with --csv, --json and --jsonl (--parquet DIR takes several)")
    if not targets:
        raise UsageError("log export: say where: --csv, --json and/or --jsonl FILE ('-' for stdout)")
    if sum(1 for _, value in targets if value == "-") > 1:
        raise UsageError("log export: only one of --csv, --json and --jsonl can go to stdout ('-')")
    sink_of: dict[str, type[CsvSink | JsonSink | JsonLinesSink]] = {"csv": CsvSink, "json": JsonSink,
                                                                     "jsonl": JsonLinesSink}
    with LogReader(args.log[0]) as reader, ExitStack() as files:
        sinks: list[CsvSink | JsonSink | JsonLinesSink] = []
        for name, value in targets:
            out = sys.stdout if value == "-" else cast(TextIO, files.enter_context(  # opened in text mode
                _output(value, f"log export --{name}", args.log[0])))
            sinks.append(CsvSink(out, CUE_COLUMNS if args.cues else COLUMNS) if name == "csv" else sink_of[name](out))
        count = export_cues(reader, sinks) if args.cues else export(reader, sinks)
        cut = reader.cut
    written = ", ".join(value for _, value in targets if value != "-")
    if written:
        note = f" (log {cut.state}: {cut.reason})" if cut else ""
        what = "cue rows" if args.cues else "frames"
        print_fitted(f"exported {count} {what} to {written}{note}", sys.stderr)
    return 0


def _export_parquet(args: argparse.Namespace, into: str, other_targets: bool) -> int:
    """`log export LOG... --parquet DIR`: each log's four tables, a line on stderr a log; a log
    that cannot be read is its one line and the others are still exported (exit 2 at the end).
    DIR must exist, as any output folder must; pyarrow is checked before any log is read."""
    from choreo.errors import InputError, LogError
    from choreo.log.reader import LogReader
    from choreo.review.parquet import export_parquet, require_pyarrow, stem

    if other_targets or args.cues:
        raise UsageError("log export --parquet writes every table (frames, steps, cues, commands) on its own: "
                         "leave out --csv, --json, --jsonl and --cues")
    require_pyarrow()
    folder = Path(into)
    if not into:  # Path('') is the current folder: an unset shell variable wrote the tables there
        raise UsageError("log export --parquet '': give the folder the tables go in")
    why = folder_problem(folder)
    if why is not None:
        raise UsageError(f"log export --parquet {into}: {why}")
    logs = _logs_in(args.log)
    named: dict[str, Path] = {}
    for path in logs:
        other = named.setdefault(stem(path), path)
        if other != path:
            raise UsageError(f"log export --parquet: {other} and {path} would write the same tables "
                             f"({stem(path)}.*.parquet): export them to different folders")
    failed = 0
    for path in dict.fromkeys(logs):
        try:
            with LogReader(path) as reader:
                done = export_parquet(reader, folder)
                cut = f" (log {reader.cut.state}: {reader.cut.reason})" if reader.cut else ""
        except (LogError, InputError) as exc:
            failed += 1
            for line in exc.lines():
                print(line, file=sys.stderr)
            continue
        counts = ", ".join(f"{count} {kind if count != 1 else kind[:-1]}" for kind, count in done.counts.items())
        print_fitted(f"exported {path}: {counts} to {folder / stem(path)}.*.parquet{cut}", sys.stderr)
    return 2 if failed else 0


@contextmanager
def _output(path: str, command: str, log: str, binary: bool = False) -> Iterator[IO]:
    """An output file, created before the log is read, every failure one line (exit 2).

    A folder that does not exist is refused, not made: a mistyped folder would otherwise become a
    tree of new folders somewhere the user does not look. A file this command created and could
    not finish (the disk filled, the log turned out not to be choreo's) is removed, never left
    half written; anything that was there before (a device such as /dev/stdout) is left alone.
    """
    from choreo.run.settings import check_output_folder

    target = Path(path)
    check_output_folder(target, command)
    if same_file(target, log):  # opened for writing first, the log would be emptied before it was read
        raise UsageError(f"{command} {path}: that is the log being read ({log}): writing it would destroy the log; "
                         "give another file name")
    created = not os.path.lexists(target)
    try:
        fd = os.open(target, _WRITE_FLAGS, 0o666)  # a named pipe nobody reads: ENXIO, not a hang
        os.set_blocking(fd, True)
        file = os.fdopen(fd, "wb") if binary else os.fdopen(fd, "w", encoding="utf-8", newline="")
    except OSError as exc:
        why = "a named pipe nobody reads" if exc.errno == errno.ENXIO else exc.strerror or exc
        raise UsageError(f"{command} {path}: cannot write: {why}") from None
    finished = False
    try:
        yield file
        file.close()
        finished = True
    except OSError as exc:
        raise UsageError(f"{command} {path}: cannot write: {exc.strerror or exc}") from None
    finally:
        if not finished:
            _discard(file, target if created else None)


_WRITE_FLAGS = (os.O_WRONLY | os.O_CREAT | os.O_TRUNC | getattr(os, "O_NONBLOCK", 0) | getattr(os, "O_NOCTTY", 0)
                | getattr(os, "O_BINARY", 0))


def _discard(file: IO, created: Path | None) -> None:
    """Close an output that failed; remove it if this command made it as a regular file."""
    with suppress(OSError):
        file.close()
    with suppress(OSError):
        if created is not None and stat.S_ISREG(os.lstat(created).st_mode):
            created.unlink()


def run_replay(args: argparse.Namespace) -> int:
    from choreo.review.showtime import fixed
    from choreo.review.timeline import stood_text
    from choreo.run.replay import replay

    say = not args.quiet and not args.json

    def started(report) -> None:
        if not args.quiet:
            note = f" (simulator without the show's durations: {report.show_note})" if report.show_note else ""
            print_fitted(f"replay: {report.source} on {report.port} at speed {report.speed:g}{note}", sys.stderr)
            if report.speed_note:
                print_fitted(f"note: {report.speed_note}", sys.stderr)
            print_fitted(f"log: {report.log_path}", sys.stderr)

    def differs(difference) -> None:
        if say:
            sys.stdout.write(f"differs: {difference}\n")
            sys.stdout.flush()

    report = replay(args.log, port=args.port, speed=args.speed, baud=args.baud, timeout=args.timeout,
                    log_path=args.new_log, on_difference=differs, on_start=started, layout=args.layout,
                    time_source=args.time_source)
    code = 1 if args.strict and report.board_differences else 0
    if args.json:
        print_json(_replay_record(report, code))
        return code
    unmatched = f", {report.unmatched} with no recorded reply" if report.unmatched else ""
    cut = f"; the recorded log is {report.cut.state}: {report.cut.reason}" if report.cut else ""
    late = f", {report.replay_late} sent late by the replay" if report.replay_late else ""
    timing = (f" ({report.excused} of them status polls at a motion's end{late})"
              if report.excused else "")
    print_fitted(f"replayed {report.frames} frames: {report.same} same, {report.different} differ{timing}"
                 f"{unmatched}; frames left up to {report.max_lag_ms:.1f} ms after their recorded time{cut}")
    lengths = report.recorded
    if lengths is not None and lengths.show_s is not None:
        stood = stood_text(lengths)
        print_fitted(f"recorded show: {fixed(lengths.show_s)} s on the show clock" + (f" ({stood})" if stood else ""))
    print_fitted(f"log: {report.log_path}")
    return code


def _replay_record(report: ReplayReport, code: int) -> dict:
    """`replay --json`: the result line's figures, both logs and every difference in words."""
    cut = {"state": report.cut.state, "reason": report.cut.reason} if report.cut else None
    return {"ok": code == 0, "exit": code, "log": str(report.source), "replay_log": str(report.log_path),
            "port": report.port, "speed": report.speed, "frames": report.frames, "same": report.same,
            "different": report.different, "excused": report.excused, "replay_late": report.replay_late,
            "board_differences": report.board_differences, "unmatched": report.unmatched,
            "max_lag_ms": round(report.max_lag_ms, 3), "cut": cut,
            "differences": [str(d) for d in report.differences],
            "recorded": report.recorded.to_json() if report.recorded is not None else None}
