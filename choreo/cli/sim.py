"""`choreo sim`: the simulated RCB-4 board on a pseudo-terminal, for any serial program."""

from __future__ import annotations

import argparse
import contextlib
import signal
import sys
import threading
import time
from typing import TYPE_CHECKING

from choreo.cli.parser import ParagraphHelpFormatter
from choreo.cli.terminal import StatusWriter
from choreo.errors import LinkError, UsageError
from choreo.wire.protocol import spell_bauds

if TYPE_CHECKING:  # the simulator loads when `choreo sim` runs: --help stays light
    from choreo.sim.board import JournalEntry
    from choreo.sim.options import SimOptions
    from choreo.sim.pty import PtyServer, ServeEnd

FAULT_HELP = (
    "K (a whole number >= 1): every K-th frame (K, 2K, 3K...; for --lose only frame K); "
    "P (0 < P < 1, with a decimal point): each frame with probability P, seeded by --seed"
)

EPILOG = """\
The first line of standard output is the device path alone (e.g. /dev/pts/4; with --boards N,
the first N lines, one board each); the server then
answers frames there until Ctrl-C (SIGINT) or SIGTERM, and exits 0. Point any serial program at
the path, e.g. `choreo run --port /dev/pts/4 shows/dance.yaml`, at the board's baud, 8 data
bits, even parity, 1 stop bit; a client set otherwise gets no reply, as from a real board.
As on a real board, read each reply before writing the next frame (a frame that arrives while
the board is still replying gets no reply), and poll the status no faster than every 50 ms
(it is refreshed that often: --refresh-ms).

Faults (each K or P, several allowed): --lose closes the pty (the port is lost) and the server
exits 3 with a line on stderr; --drop: no reply (the frame had no effect); --nak: a NAK (no
effect); --badsum: the reply with a wrong checksum; --short: half the reply; --junk: ff 00 aa
before the reply; --late: the reply --late-ms later than due (default 500); a frame sent
before that reply has arrived gets no reply. Examples:
--drop 5 drops frames 5, 10, 15...; --drop 0.2 drops each frame with probability 0.2.
The same options work in a sim:// URL: sim://?motion_s=0.5&drop=5&durations=3:2.5,7:1.2
"""


def register(subparsers: argparse._SubParsersAction) -> None:
    parser = subparsers.add_parser(
        "sim",
        help="run the simulated controller on a pseudo-terminal",
        description="Serve a simulated RCB-4 board on a pseudo-terminal and print its device path.",
        epilog=EPILOG,
        formatter_class=ParagraphHelpFormatter,
    )
    _board_options(parser)
    _fault_options(parser)
    parser.add_argument("--boards", type=int, default=1, metavar="N",
                        help=f"serve N boards (1..{MAX_BOARDS}), each on its own pseudo-terminal, one path "
                        "a line on stdout: one for each robot of a show for several (same options for all)")
    parser.add_argument("-v", "--verbose", action="store_true", help="log every frame and reply to stderr")
    parser.set_defaults(handler=run)


def _board_options(parser: argparse.ArgumentParser) -> None:
    """The board and its line: what a `sim://` URL's settings say."""
    board = parser.add_argument_group("board")
    board.add_argument("--baud", metavar="N", help=f"the board's baud: {spell_bauds(mark_default=True)}")
    board.add_argument("--layout", metavar="L", help="the board's memory layout: seed (default: slots "
                       "at 0x0BB8) or hth4-2.2 (slots at 0x0B80); a CALL elsewhere is a stray call")
    board.add_argument("--config", metavar="WORD", help="the config word at power-on, e.g. 0x821b "
                       "(default 0x0002: only the run bit)")
    board.add_argument("--baud-switch", action="store_const", const="1", help="a config write whose "
                       "COM baud bits name another baud switches the board to it (undocumented by "
                       "Kondo: the worst case)")
    board.add_argument("--motion-s", metavar="S", help="how long each motion runs, seconds (default 1.0)")
    board.add_argument(
        "--durations", metavar="SLOT:S,...", help="per-slot durations, e.g. 3:2.5,7:1.2 (others: --motion-s)"
    )
    board.add_argument("--reply-ms", metavar="MS", help="delay before each reply, ms (default 0.2)")
    board.add_argument(
        "--refresh-ms", metavar="MS",
        help="status refresh period: a status query shows the board as of the last refresh, "
             "every MS ms from start (default 50; 0: live)",
    )
    board.add_argument("--latency-ms", metavar="MS", help="an FTDI USB adapter's latency timer between "
                       "board and client: replies wait for its next tick, every MS ms (1..255; a real "
                       "adapter's default is 16); default 0: none")
    board.add_argument(
        "--no-wire", action="store_true", help="bytes take no time (default: 11 bits a byte at the baud)"
    )
    board.add_argument(
        "--gap-ms", metavar="MS", help="inter-byte gap that drops a partial frame, ms (default 20)"
    )
    board.add_argument(
        "--no-settings-check", action="store_true", help="answer whatever baud/parity the client set"
    )


def _fault_options(parser: argparse.ArgumentParser) -> None:
    """The faults, each K (every K-th frame) or P (a probability): what a `sim://` URL's faults say."""
    faults = parser.add_argument_group("faults", FAULT_HELP)
    for kind, what in (
        ("lose", "lose the port (close the pty, exit 3)"),
        ("drop", "send no reply"),
        ("nak", "reply NAK"),
        ("badsum", "reply with a wrong checksum"),
        ("short", "send half the reply"),
        ("junk", "send garbage bytes before the reply"),
        ("late", "reply --late-ms late"),
        ("lose_start", "no reply to the frame that starts a motion, which still starts "
                       "(counted over motion starts)"),
        ("hold", "the frame reaches the board --hold-ms after it was written, as when the client's OS "
                 "or adapter holds it (counted over writes)"),
    ):
        faults.add_argument(f"--{kind.replace('_', '-')}", dest=kind, metavar="K|P", help=what)
    faults.add_argument("--late-ms", metavar="MS", help="how late a --late reply is, ms (default 500)")
    faults.add_argument("--hold-ms", metavar="MS", help="how long --hold holds a frame, ms (default 40)")
    faults.add_argument("--faults-on", dest="faults_on", metavar="KINDS",
                        help="the frame faults hit (and count) only frames of these kinds, comma-separated: "
                             "stop, counter, play, restore, read, sync, other (default: every frame)")
    faults.add_argument("--seed", metavar="N", help="seed for faults given as a probability (default 0)")


MAX_BOARDS = 16


def options_from_args(args: argparse.Namespace) -> dict[str, str]:
    """The command line as the `name -> text` mapping the sim:// query also produces."""
    from choreo.sim.options import OPTION_NAMES

    values = {name: getattr(args, name) for name in OPTION_NAMES if getattr(args, name, None) is not None}
    if args.no_wire:
        values["wire"] = "0"
    return values


def run(args: argparse.Namespace) -> int:
    from choreo.sim.options import parse_options
    from choreo.sim.pty import ServeEnd

    if not 1 <= args.boards <= MAX_BOARDS:
        raise UsageError(f"choreo sim: --boards {args.boards}: give 1..{MAX_BOARDS}")
    try:
        options = parse_options(options_from_args(args))
    except ValueError as exc:
        raise UsageError(f"choreo sim: {_as_flags(str(exc))}") from None
    start = time.monotonic()
    # stderr is written by a thread of its own: a terminal stopped with Ctrl-S or a pipe nobody
    # reads must hold up neither the board's replies nor its start (the opening line, written
    # before the boards served, held them all; lines past the queue are counted)
    notes = StatusWriter(sys.stderr, fit_lines=sys.stderr.isatty(), what="journal line")
    journal = notes if args.verbose else None
    servers = [_server(options, journal, start, number if args.boards > 1 else None, args)
               for number in range(args.boards)]
    with contextlib.ExitStack() as stack:
        stack.callback(notes.close)
        for server in servers:
            stack.enter_context(server)
        # Handlers first: whoever reads the paths may signal us at once, and must get exit 0.
        def stop_all(*_: object) -> None:
            for server in servers:
                server.stop()

        previous = {sig: signal.signal(sig, stop_all) for sig in (signal.SIGINT, signal.SIGTERM)}
        try:
            for server in servers:
                print(server.path, flush=True)
            paths = ", ".join(str(server.path) for server in servers)  # set once the pty is open
            notes.line(f"choreo sim: simulated RCB-4 on {paths}, {options.describe()}; Ctrl-C to stop")
            ends = _serve_all(servers, notes)
        finally:
            for sig, handler in previous.items():
                signal.signal(sig, handler)
    lost = [f"fault 'lose' at frame {server.board.lost_at_frame}: closed {server.path}"
            for server, end in zip(servers, ends, strict=True) if end is ServeEnd.LOST]
    if lost:
        raise LinkError(f"choreo sim: {'; '.join(lost)} as if the adapter was unplugged")
    return 0


def _server(options: SimOptions, journal: StatusWriter | None, start: float, number: int | None,
            args: argparse.Namespace) -> PtyServer:
    from choreo.sim.pty import PtyServer
    from choreo.sim.line import PTY_GAP_S

    prefix = f"[board {number + 1}] " if number is not None else ""

    def said(entry: JournalEntry) -> None:
        if journal is not None:
            journal.line(prefix + entry.line(start))

    board = options.board(on_entry=said if journal is not None else None, power_on=start)
    return PtyServer(board, gap_s=options.gap_s or PTY_GAP_S, check_settings=not args.no_settings_check,
                     latency_s=options.latency_s)


def _serve_all(servers: list[PtyServer], notes: StatusWriter) -> list[ServeEnd | None]:
    """Each board on its own thread (one stuck client never holds up another board's replies);
    the main thread keeps the signals. A lost board ends alone: the others go on serving."""
    from choreo.sim.pty import ServeEnd

    if len(servers) == 1:
        return [servers[0].serve()]
    ends: list[ServeEnd | None] = [None] * len(servers)

    def serve(index: int) -> None:
        ends[index] = servers[index].serve()
        if ends[index] is ServeEnd.LOST:
            notes.line(f"choreo sim: fault 'lose' at frame {servers[index].board.lost_at_frame}: closed "
                       f"{servers[index].path}; the other boards go on")

    threads = [threading.Thread(target=serve, args=(i,), daemon=True) for i in range(len(servers))]
    for thread in threads:
        thread.start()
    for thread in threads:
        while thread.is_alive():
            thread.join(0.1)
    return ends


def _as_flags(message: str) -> str:
    """Spell option names as the command line does: `option motion_s=` -> `--motion-s `."""
    from choreo.sim.options import OPTION_NAMES

    for name in sorted(OPTION_NAMES, key=len, reverse=True):
        message = message.replace(f"{name}=", f"--{name.replace('_', '-')} ")
    return message
