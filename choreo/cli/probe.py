"""`choreo probe [--port URL]`: which board answers, at what baud, and what it says."""

from __future__ import annotations

import argparse
from typing import TYPE_CHECKING

from choreo.cli.terminal import print_fitted
from choreo.errors import UsageError
from choreo.wire.protocol import spell_bauds

if TYPE_CHECKING:  # the board layer loads when the probe runs: --help stays light
    from choreo.board.probe import BoardInfo


def register(subparsers: argparse._SubParsersAction) -> None:
    parser = subparsers.add_parser(
        "probe",
        help="find the board's baud and read its version, config word and program counter",
        description=f"Send the ACK check at {spell_bauds('and')} baud (even parity) until the "
        "board answers, then read its version text, config word (decoded) and program counter, and "
        "say what they suggest about its memory layout (a hint, never a fact). It never writes RAM "
        "and never sends a CALL: the robot does not move. Exit 3 if nothing answers, or something "
        "answers the ACK check but none of the questions after it (a line that echoes what is sent).",
    )
    parser.add_argument("--port", help="pyserial URL or device (default: Kondo's USB adapter when "
                        "exactly one is plugged in); sim:// probes the built-in simulator")
    parser.add_argument("--timeout", type=float, metavar="S", default=0.2,
                        help="seconds to wait for each reply, 0 < S <= 10 (default 0.2)")
    parser.add_argument("--json", action="store_true", help="one JSON object on stdout: the baud, what the "
                        "board said, notes and hints (on failure: ok false, exit, error)")
    parser.set_defaults(handler=run)


def run(args: argparse.Namespace) -> int:
    from choreo.board.probe import probe
    from choreo.run.settings import check_timeout

    check_timeout(args.timeout)
    port = args.port if args.port is not None else _kondo_adapter()
    if not port.strip():
        raise UsageError("--port: empty; give a device (/dev/ttyUSB0, COM3) or a URL (sim://)")
    info = probe(port, timeout=args.timeout, time_source=args.time_source)
    if args.json:
        from choreo.cli.jsonout import print_json

        print_json(board_record(info))
        return 0
    for line in info.lines():
        print_fitted(line)
    return 0


def board_record(info: BoardInfo) -> dict:
    """What `probe --json` prints: the readings as numbers, None where the board did not answer."""
    config = info.config
    counter = info.counter
    return {
        "ok": True, "exit": 0, "port": info.port, "baud": info.baud, "version": info.version,
        "config": None if config is None else {
            "word": config.word, **config.flags, "frame_ms": config.frame_ms, "com_baud": config.com_baud,
            "ics_baud": config.ics_baud},
        "counter": None if counter is None else {
            "program_counter": counter.program_counter, "in_call": counter.in_call, "hex": counter.data.hex(" ")},
        "notes": list(info.notes), "hints": info.hints(),
    }


def _kondo_adapter() -> str:
    """The one Kondo adapter plugged in; otherwise the user must say which port."""
    from serial.tools import list_ports

    from choreo.board.usb import KONDO_USB, KONDO_USB_ID

    ports = list_ports.comports()
    kondo = [p.device for p in ports if (p.vid, p.pid) == KONDO_USB]
    if len(kondo) == 1:
        return kondo[0]
    found = ", ".join(sorted(p.device for p in ports)) or "none"
    why = "several Kondo adapters are plugged in" if kondo else f"no Kondo adapter (USB {KONDO_USB_ID}) found"
    raise UsageError(f"probe: {why}: give --port (serial ports: {found}; `choreo ports` lists them, "
                     "sim:// probes the simulator)")
