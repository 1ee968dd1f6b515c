"""`choreo doctor [--port URL]`: check the adapter, driver, permission, latency timer and board.
`choreo doctor SHOW [run's options]`: everything that show needs (`choreo.run.preflight`)."""

from __future__ import annotations

import argparse
import sys
from collections.abc import Sequence
from typing import TYPE_CHECKING

from choreo.board.usb import KONDO_USB_ID
from choreo.errors import UsageError
from choreo.show.model import CLOCKS
from choreo.textfit import char_width, display_width, fit, pad, visible
from choreo.wire.layouts import LAYOUT_NAMES
from choreo.wire.protocol import spell_bauds

if TYPE_CHECKING:  # the checks load when doctor runs: `choreo --help` stays light
    from choreo.board.doctor import Finding


def register(subparsers: argparse._SubParsersAction) -> None:
    parser = subparsers.add_parser(
        "doctor",
        help="check what stands between you and a working show, with the fix for each problem",
        description=f"Check the serial ports and Kondo's USB adapter ({KONDO_USB_ID}), whether a driver "
        "serves it, permission on the device, its FTDI latency timer, whether a board answers "
        "(a read-only probe: the robot does not move), and whether the music's audio output opens. "
        "One line a check; a problem comes with the command that fixes it. Exit 1 if there is a problem. "
        "With SHOW (and the options `choreo run` would get), everything that show needs: the show loads, "
        "each robot's port opens and its board answers (baud, layout, no motion running), the music "
        "decodes and outlasts the last cue, its output opens, the OSC port is free, the log's folder "
        "takes the log; on the Link clock, the Ableton Link session (peers, tempo, whether multicast reaches "
        "them); nothing moves.",
    )
    parser.add_argument("show", nargs="?", help="the show file to check everything for (YAML)")
    parser.add_argument("--port", action="append", metavar="URL|NAME=URL",
                        help="the port to check and probe (default: the one Kondo adapter plugged in; "
                        "with SHOW: the show's robot.port); sim:// probes the built-in simulator; with a "
                        "show of several robots, NAME=URL for one robot (repeatable), as `choreo run`")
    parser.add_argument("--no-probe", action="store_true", help="do not talk to the board")
    parser.add_argument("--json", action="store_true", help="one JSON object on stdout: ok, exit, and the "
                        "findings, each with level (ok, problem, note), check, text and fix")
    parser.add_argument("--audio-device", metavar="OUTPUT", help="the audio output to check (as `choreo run` "
                        "takes it; default: the system's output)")
    _show_options(parser)
    parser.set_defaults(handler=run)


def _show_options(parser: argparse.ArgumentParser) -> None:
    """`choreo run`'s options that change what a show needs (with SHOW only)."""
    show = parser.add_argument_group("with SHOW", "as `choreo run` takes them")
    show.add_argument("--baud", type=int, help=spell_bauds("or", mark_default=True))
    show.add_argument("--layout", choices=LAYOUT_NAMES, help="the board's memory layout (default: the "
                      "show's robot.layout, else seed)")
    logs = show.add_mutually_exclusive_group()
    logs.add_argument("--log", metavar="PATH", help="the log file the run will write (default runs/...)")
    logs.add_argument("--no-log", action="store_true", help="the run records no log")
    show.add_argument("--no-music", action="store_true", help="the run plays no music")
    show.add_argument("--from", dest="from_step", metavar="STEP", help="the run starts at this step")
    show.add_argument("--loop", metavar="FROM..TO", help="the run rehearses this section")
    show.add_argument("--host", metavar="NAME", help="in a show with `hosts:`, the host this computer is (its "
                      "robots are checked, the others' are their hosts' business)")
    show.add_argument("--clock", choices=CLOCKS, help="the show clock, instead of the show's `clock:`; "
                      "on link, the Ableton Link session is joined (for a moment) and reported")
    show.add_argument("--timeout", type=float, metavar="S", help="seconds to wait for a reply (default 0.2)")
    show.add_argument("--retries", type=int, metavar="N", help="retries of a failed frame (default 2)")
    show.add_argument("--osc", metavar="PORT", help="the OSC port the run will listen on (UDP and TCP)")
    show.add_argument("--osc-host", metavar="HOST", default="127.0.0.1", help="the address OSC listens on")
    show.add_argument("--osc-allow", action="append", metavar="ADDRESS", default=[],
                      help="a sender OSC takes commands from (repeatable)")
    show.add_argument("--osc-notify", action="append", metavar="HOST:PORT", default=[],
                      help="where the run sends its progress (repeatable)")


def run(args: argparse.Namespace) -> int:
    if args.show is not None:
        return _show(args)
    _machine_only(args)
    from serial.tools import list_ports

    from choreo.board.doctor import PROBLEM, SerialPort, examine
    from choreo.board.probe import BoardInfo, probe

    ports = [SerialPort(p.device, p.vid, p.pid) for p in list_ports.comports()]

    def probe_port(port: str) -> BoardInfo:
        return probe(port, time_source=args.time_source)

    def audio() -> Finding:
        from choreo.board.doctor import audio_output
        from choreo.music.player import pick_output, try_output

        return audio_output(lambda: try_output(pick_output(args.audio_device)), args.audio_device)

    port = args.port[0] if args.port else None
    findings = examine(ports, port, probe=None if args.no_probe else probe_port, audio=audio)
    code = 1 if any(f.level == PROBLEM for f in findings) else 0
    if args.json:
        from choreo.cli.jsonout import print_json

        print_json({"ok": code == 0, "exit": code, "findings": [_record(f) for f in findings]})
        return code
    from choreo.cli.terminal import columns

    width = columns() if sys.stdout.isatty() else None  # a file or a pipe: one line a check
    for finding in findings:
        for line in _hanging(finding.line(), width):
            print(line)
    return code


def _hanging(line: str, width: int | None) -> list[str]:
    """A check's line within the terminal's `width`: wrapped (never cut: the fix is the point),
    what follows its first line indented under the check's name."""
    indent = len("PROBLEM ")
    if width is None or display_width(line) <= width or width < 2 * indent:
        return wrapped(line, width)
    first, *rest = wrapped(line, width - indent)
    return [first] + [" " * indent + more for more in rest]


SHOW_ONLY = ("baud", "layout", "log", "no_log", "no_music", "from_step", "loop", "timeout", "retries", "osc",
             "osc_allow", "osc_notify", "host", "clock")


def _machine_only(args: argparse.Namespace) -> None:
    """Without SHOW, the options that say what a show needs have nothing to apply to."""
    given = [name for name in SHOW_ONLY if getattr(args, name) not in (None, False, [])]
    if args.osc_host != "127.0.0.1":
        given.append("osc_host")
    if given:
        option = "--" + given[0].replace("_", "-").replace("from-step", "from")
        raise UsageError(f"{option}: it says what a show needs: give the show too (choreo doctor SHOW {option} ...)")
    if args.port and len(args.port) > 1:
        raise UsageError(f"--port {args.port[1]}: one port to check without a show")


def _show(args: argparse.Namespace) -> int:
    """`choreo doctor SHOW`: the table (check, verdict, detail, fix), or one JSON object."""
    from choreo.cli.run import port_arguments
    from choreo.run.preflight import Machine, OscAsk, preflight
    from choreo.run.settings import RunRequest

    port, robot_ports = port_arguments(args.port)
    request = RunRequest(args.show, port=port, baud=args.baud, log_path=args.log, no_log=args.no_log,
                         from_step=args.from_step, timeout=args.timeout, retries=args.retries, layout=args.layout,
                         robot_ports=robot_ports, no_music=args.no_music, audio_device=args.audio_device,
                         loop=args.loop, host=args.host, clock=args.clock)
    osc = OscAsk(args.osc, args.osc_host, tuple(args.osc_allow), tuple(args.osc_notify))
    report = preflight(request, osc, Machine(time_source=args.time_source, talk=not args.no_probe))
    if args.json:
        from choreo.cli.jsonout import print_json

        log = report.log
        print_json({"ok": report.exit_code == 0, "exit": report.exit_code, "show": report.show,
                    "log_estimate_bytes": log.bytes if log is not None else None,
                    "log_room_bytes": log.room if log is not None else None,
                    "findings": [_record(f) | {"robot": f.robot} for f in report.findings]})
        return report.exit_code
    from choreo.cli.terminal import columns

    for line in table(report.findings, columns()):
        print(line)
    return report.exit_code


def _record(finding: Finding) -> dict:
    """A finding in `--json` (`robot` only with a show: the machine's checks have none)."""
    return {"level": finding.level, "check": finding.check, "text": finding.text, "fix": finding.fix}


def table(findings: Sequence[Finding], width: int | None = None) -> list[str]:
    """One row a check: its name, the verdict, what was found and, for a problem, the fix;
    whatever a name from outside (a port, a file, a show) put in it is shown escaped. Given a
    terminal's `width`, a long detail wraps under the detail column (never cut: the fix is the
    point of the line); narrower than the columns and MIN_DETAIL, each row is its check and
    verdict (cut to the width) and its detail wrapped below: no line runs past the edge."""
    names = max([len("check"), *(display_width(visible(f.name)) for f in findings)])
    indent = names + 2 + len("verdict") + 2
    if width is not None and width - indent < MIN_DETAIL:
        return _stacked(findings, width)
    room = width - indent if width is not None else None
    lines = [f"{pad('check', names)}  verdict  detail -> fix"]
    for f in findings:
        detail = visible(f.text + (f" -> fix: {f.fix}" if f.fix else ""))
        first, *rest = wrapped(detail, room)
        lines.append(f"{pad(visible(f.name), names)}  {f.verdict:<7}  {first}")
        lines += [" " * indent + more for more in rest]
    return lines


MIN_DETAIL = 24  # columns the detail needs beside the check and verdict (else it goes below them)


def _stacked(findings: Sequence[Finding], width: int) -> list[str]:
    """The table for a narrow terminal: a check's name and verdict, then its detail indented."""
    indent = "  " if width > 2 * len("  ") else ""
    lines = [fit("check  verdict", width), fit(f"{indent}detail -> fix", width)]
    for f in findings:
        lines.append(fit(f"{f.name}  {f.verdict}", width))
        detail = visible(f.text + (f" -> fix: {f.fix}" if f.fix else ""))
        lines += [indent + line for line in wrapped(detail, max(width - len(indent), 1))]
    return lines


def wrapped(text: str, width: int | None) -> list[str]:
    """`text` in lines of at most `width` columns (by display width), broken at spaces; a word
    longer than a line (a path, a URL) is broken where the line ends."""
    if width is None or display_width(text) <= width:
        return [text]
    lines: list[str] = []
    line = ""
    for word in text.split(" "):
        candidate = f"{line} {word}" if line else word
        if display_width(candidate) <= width:
            line = candidate
            continue
        if line:
            lines.append(line)
        while display_width(word) > width:
            cut = _cut(word, width)
            lines.append(word[:cut])
            word = word[cut:]
        line = word
    return lines + [line] if line else lines


def _cut(word: str, width: int) -> int:
    """How many characters of `word` fit in `width` columns (at least one)."""
    used = 0
    for index, char in enumerate(word):
        used += char_width(char)
        if used > width:
            return max(index, 1)
    return len(word)
