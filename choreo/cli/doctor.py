"""`choreo doctor [--port URL]`: check the adapter, driver, permission, latency timer and board."""

from __future__ import annotations

import argparse

from choreo.board.usb import KONDO_USB_ID


def register(subparsers: argparse._SubParsersAction) -> None:
    parser = subparsers.add_parser(
        "doctor",
        help="check what stands between you and a working show, with the fix for each problem",
        description=f"Check the serial ports and Kondo's USB adapter ({KONDO_USB_ID}), whether a driver "
        "serves it, permission on the device, its FTDI latency timer, whether a board answers "
        "(a read-only probe: the robot does not move), and whether the music's audio output opens. "
        "One line a check; a problem comes with the command that fixes it. Exit 1 if there is a problem.",
    )
    parser.add_argument("--port", help="the port to check and probe (default: the one Kondo adapter "
                        "plugged in); sim:// probes the built-in simulator")
    parser.add_argument("--no-probe", action="store_true", help="do not talk to the board")
    parser.add_argument("--json", action="store_true", help="one JSON object on stdout: ok, exit, and the "
                        "findings, each with level (ok, problem, note), check, text and fix")
    parser.add_argument("--audio-device", metavar="OUTPUT", help="the audio output to check (as `choreo run` "
                        "takes it; default: the system's output)")
    parser.set_defaults(handler=run)


def run(args: argparse.Namespace) -> int:
    from serial.tools import list_ports

    from choreo.board.doctor import PROBLEM, Finding, SerialPort, examine
    from choreo.board.probe import BoardInfo, probe

    ports = [SerialPort(p.device, p.vid, p.pid) for p in list_ports.comports()]

    def probe_port(port: str) -> BoardInfo:
        return probe(port, time_source=args.time_source)

    def audio() -> Finding:
        from choreo.board.doctor import audio_output
        from choreo.music.player import pick_output, try_output

        return audio_output(lambda: try_output(pick_output(args.audio_device)), args.audio_device)

    findings = examine(ports, args.port, probe=None if args.no_probe else probe_port, audio=audio)
    code = 1 if any(f.level == PROBLEM for f in findings) else 0
    if args.json:
        from dataclasses import asdict

        from choreo.cli.jsonout import print_json

        print_json({"ok": code == 0, "exit": code, "findings": [asdict(f) for f in findings]})
        return code
    for finding in findings:
        print(finding.line())
    return code
