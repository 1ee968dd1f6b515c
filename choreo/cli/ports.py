"""`choreo ports`: the serial ports on this machine, Kondo's adapter marked."""

from __future__ import annotations

import argparse

from choreo.cli.terminal import print_fitted
from choreo.board.usb import FTDI_DRIVER, KONDO_USB, KONDO_USB_ID, NEW_ID


def register(subparsers: argparse._SubParsersAction) -> None:
    parser = subparsers.add_parser("ports", help="list serial ports, marking Kondo adapters",
                                   description="List the serial ports found; Kondo's USB adapter "
                                   f"(USB {KONDO_USB_ID}) is marked.")
    parser.add_argument("--json", action="store_true", help="one JSON object on stdout: ports, each with "
                        "device, description, vid, pid (null when not USB) and kondo")
    parser.set_defaults(handler=run)


def run(args: argparse.Namespace) -> int:
    from serial.tools import list_ports

    ports = sorted(list_ports.comports(), key=lambda p: p.device)
    if args.json:
        from choreo.cli.jsonout import print_json

        print_json({"ok": True, "exit": 0, "ports": [
            {"device": p.device, "description": p.description or "", "vid": p.vid, "pid": p.pid,
             "kondo": (p.vid, p.pid) == KONDO_USB} for p in ports]})
        return 0
    if not ports:
        print("no serial ports found (is the adapter plugged in? on Linux, Kondo's adapter may "
              f"need: modprobe ftdi_sio && echo {NEW_ID} > /sys/{FTDI_DRIVER}/new_id)")
        return 0
    for port in ports:
        print_fitted(describe_port(port))
    return 0


def describe_port(port) -> str:
    usb = f" USB {port.vid:04X}:{port.pid:04X}" if port.vid is not None else ""
    mark = "  <- Kondo adapter" if (port.vid, port.pid) == KONDO_USB else ""
    return f"{port.device}  {port.description or ''}{usb}{mark}".rstrip()
