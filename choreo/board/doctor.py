"""`choreo doctor`: what stands between a user and a working show, one finding and one fix a line.

Each check looks at one thing (the serial ports, Kondo's adapter and its driver, permission on
the device, the FTDI latency timer, the board itself) and says it is fine, or what is wrong and
the command that fixes it. Checks read the machine through arguments (the ports pyserial lists,
a sysfs tree, a probe function), so tests give them a machine of their own.
"""

from __future__ import annotations

import grp
import os
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from pathlib import Path

from choreo.errors import ChoreoError, UsageError, one_line
from choreo.board.link import NETWORK_URLS
from choreo.board.probe import BoardInfo
from choreo.board.usb import (KONDO_USB, KONDO_USB_ID, LOW_LATENCY_MS, NEW_ID_FIX, SYSFS, latency_cost, latency_fix,
                              latency_timer_ms, usb_devices)
from choreo.show.model import SIM_URL, is_simulator

OK, PROBLEM, NOTE = "ok", "problem", "note"
OTHER_URLS = (*NETWORK_URLS, "loop://")  # pyserial ports that are no device of this machine


@dataclass(frozen=True)
class Finding:
    """One check's verdict: what it found, and the fix when something is wrong."""

    level: str  # ok | problem | note
    check: str
    text: str
    fix: str | None = None

    def line(self) -> str:
        """One line, whatever a port's name put in it (a line break too)."""
        mark = {OK: "ok     ", PROBLEM: "PROBLEM", NOTE: "note   "}[self.level]
        return one_line(f"{mark} {self.check}: {self.text}" + (f" -> fix: {self.fix}" if self.fix else ""))


@dataclass(frozen=True)
class SerialPort:
    """What doctor needs of a port pyserial lists."""

    device: str
    vid: int | None = None
    pid: int | None = None

    @property
    def is_kondo(self) -> bool:
        return (self.vid, self.pid) == KONDO_USB


def examine(ports: Sequence[SerialPort], port: str | None = None, *, sysfs: Path = SYSFS,
            probe: Callable[[str], BoardInfo] | None = None,
            audio: Callable[[], Finding] | None = None) -> list[Finding]:
    """Every check, in the order a user fixes things: adapter, driver, permission, latency,
    the board on `port` (or on the one Kondo adapter found), then the music's output."""
    findings = _adapters(ports, sysfs)
    target = port or _only_kondo(ports)
    if target is not None and not is_simulator(target) and not target.lower().startswith(OTHER_URLS):
        findings += _device(target, sysfs)
    if target is None:  # a show could not run either: a problem, not a note
        several = sum(1 for p in ports if p.is_kondo) > 1
        findings.append(Finding(PROBLEM, "board", "no port to check: no --port given and "
                                f"{'several Kondo adapters' if several else 'no Kondo adapter'} found",
                                f"choreo doctor --port /dev/ttyUSB0 (or {SIM_URL} to try the simulator)"))
    elif probe is not None:
        findings.append(_board(target, probe))
    if audio is not None:
        findings.append(audio())
    return findings


def _only_kondo(ports: Sequence[SerialPort]) -> str | None:
    kondo = [p.device for p in ports if p.is_kondo]
    return kondo[0] if len(kondo) == 1 else None


def _adapters(ports: Sequence[SerialPort], sysfs: Path) -> list[Finding]:
    kondo = [p for p in ports if p.is_kondo]
    listed = ", ".join(sorted(p.device for p in ports)) or "none"
    if kondo:
        return [Finding(OK, "adapter", f"Kondo's USB adapter ({KONDO_USB_ID}) on {', '.join(p.device for p in kondo)}")]
    unbound = [d for d in usb_devices(sysfs) if d.is_kondo]
    if unbound:
        return [Finding(PROBLEM, "adapter", f"Kondo's USB adapter ({KONDO_USB_ID}) is plugged in but no driver "
                        "gives it a serial port (ftdi_sio does not know Kondo's id)", NEW_ID_FIX)]
    if ports:
        return [Finding(NOTE, "adapter", f"no Kondo adapter ({KONDO_USB_ID}) found; serial ports: {listed}",
                        "plug in Kondo's adapter, or give --port for another one")]
    return [Finding(PROBLEM, "adapter", f"no serial ports and no Kondo adapter ({KONDO_USB_ID}) found",
                    f"plug in the adapter (and check `lsusb`); {SIM_URL} runs shows without one")]


def _device(device: str, sysfs: Path) -> list[Finding]:
    """Permission on the device and its latency timer."""
    path = Path(device)
    try:
        exists = path.exists()
    except (OSError, ValueError) as exc:  # a name too long, a NUL in it, a link loop
        return [Finding(PROBLEM, "device", f"{device}: {getattr(exc, 'strerror', None) or exc}",
                        "choreo ports lists the serial ports")]
    if not exists:
        return [Finding(PROBLEM, "device", f"{device} does not exist", "choreo ports lists the serial ports")]
    findings = [_permission(path)]
    timer = latency_timer_ms(device, sysfs)
    if timer is None:
        findings.append(Finding(NOTE, "latency", f"{device} has no FTDI latency timer to read (not an FTDI "
                                "adapter, or not Linux)"))
    elif timer > LOW_LATENCY_MS:
        findings.append(Finding(PROBLEM, "latency", f"{device}'s FTDI latency timer is {timer} ms: "
                                f"{latency_cost(timer)}",
                                latency_fix(device, sysfs)))
    else:
        findings.append(Finding(OK, "latency", f"{device}'s FTDI latency timer is {timer} ms"))
    return findings


def _permission(path: Path) -> Finding:
    if os.access(path, os.R_OK | os.W_OK):
        return Finding(OK, "permission", f"{path} can be read and written")
    try:
        group = grp.getgrgid(path.stat().st_gid).gr_name
    except (KeyError, OSError):
        group = "dialout"
    return Finding(PROBLEM, "permission", f"{path} cannot be opened by this user (it belongs to group {group})",
                   f"sudo usermod -aG {group} $USER, then log out and in again")


def _board(port: str, probe: Callable[[str], BoardInfo]) -> Finding:
    try:
        info = probe(port)
    except ChoreoError as exc:
        return Finding(PROBLEM, "board", exc.lines()[0], f"choreo probe --port {port} says "
                       "more; check the cable, the board's power and its baud")
    version = f", version {info.version!r}" if info.version else ""
    return Finding(OK, "board", f"a board answers on {port} at {info.baud} baud{version}")


def audio_output(try_output: Callable[[], str], asked: str | None = None) -> Finding:
    """Whether the music will be heard: the output `--audio-device` names (a problem if it does
    not open) or the system's default (a note if none opens: a music show then plays silent, on
    the null output, keeping the music's time)."""
    where = f"output {asked!r}" if asked else "the default output"
    try:
        backend = try_output()
    except ChoreoError as exc:
        if asked:
            text = str(exc) if isinstance(exc, UsageError) else f"{where}: {exc}"
            return Finding(PROBLEM, "audio", text, "choreo devices lists the outputs")
        return Finding(NOTE, "audio", f"{where}: {exc}: music shows play silent on the "
                       "null output, keeping the music's time", "connect a sound output (on Linux, `aplay -l` "
                       "lists sound cards); choreo devices lists what choreo finds")
    if backend.lower() == "null":
        return Finding(NOTE, "audio", f"{where} is the null output: music shows play silent")
    return Finding(OK, "audio", f"{where} opens ({backend})")
