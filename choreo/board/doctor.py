"""`choreo doctor`: what stands between a user and a working show, one finding and one fix a line.

Each check looks at one thing (the serial ports, Kondo's adapter and its driver, permission on
the device, the FTDI latency timer, the board itself) and says it is fine, or what is wrong and
the command that fixes it. Checks read the machine through arguments (the ports pyserial lists,
a sysfs tree, a probe function), so tests give them a machine of their own.
"""

from __future__ import annotations

import grp
import os
import shlex
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from pathlib import Path

from choreo.errors import ChoreoError, UsageError, one_line
from choreo.board.link import NETWORK_URLS
from choreo.board.probe import BoardInfo
from choreo.board.usb import (KONDO_USB, KONDO_USB_ID, LOW_LATENCY_MS, NEW_ID_FIX, SYSFS, latency_cost, latency_fix,
                              latency_timer_ms, usb_devices)
from choreo.show.model import SIM_URL, is_simulator
from choreo.wire.layouts import HTH4_22, SEED, Layout

OK, PROBLEM, NOTE = "ok", "problem", "note"
OTHER_URLS = (*NETWORK_URLS, "loop://")  # pyserial ports that are no device of this machine


@dataclass(frozen=True)
class Finding:
    """One check's verdict: what it found, and the fix when something is wrong."""

    level: str  # ok | problem | note
    check: str
    text: str
    fix: str | None = None
    robot: str | None = None  # a show's robot the check is about (None: the machine, the show)

    @property
    def name(self) -> str:
        """The check as a table names it: `board`, or `board lead` for one robot of several."""
        return self.check if self.robot is None else f"{self.check} {self.robot}"

    @property
    def verdict(self) -> str:
        return {OK: "ok", PROBLEM: "PROBLEM", NOTE: "note"}[self.level]

    def line(self) -> str:
        """One line, whatever a port's name put in it (a line break too)."""
        return one_line(f"{self.verdict:<7} {self.name}: {self.text}" + (f" -> fix: {self.fix}" if self.fix else ""))


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
        findings += device_checks(target, sysfs)
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


def device_checks(device: str, sysfs: Path = SYSFS) -> list[Finding]:
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
        return Finding(PROBLEM, "board", exc.lines()[0], f"choreo probe --port {shlex.quote(port)} says "
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


# --------------------------------------------------------------------------- a show's board


@dataclass(frozen=True)
class BoardWanted:
    """What a show's robot will ask of its board: the run's baud and layout, and whether anyone
    chose that layout (`assumed`: the default, nobody did)."""

    port: str
    baud: int
    layout: Layout
    assumed: bool = False
    robot: str | None = None


def board_checks(info: BoardInfo, wanted: BoardWanted) -> list[Finding]:
    """What the read-only probe says of the board a show will drive: it answers at the show's
    baud, the config word a layout built from it needs was read, the counter's main loop does not
    contradict the show's layout, and no motion is running (a board mid-motion is busy: the
    show's first play would land on it)."""
    return [_answers(info, wanted), _layout_check(info, wanted), _idle(info, wanted)]


def _answers(info: BoardInfo, wanted: BoardWanted) -> Finding:
    version = f", version {info.version!r}" if info.version else ""
    config = f", config 0x{info.config.word:04x}" if info.config is not None else ""
    said = f"a board answers on {wanted.port} at {info.baud} baud{version}{config}"
    if info.baud != wanted.baud:
        fix = (f"robots.{wanted.robot}.baud: {info.baud} in the show" if wanted.robot is not None
               else f"--baud {info.baud} (or robot.baud: {info.baud} in the show)")
        return Finding(PROBLEM, "board", f"{said}, but the show runs at {wanted.baud} baud", fix, wanted.robot)
    if wanted.layout.reads_config and info.config is None:
        return Finding(PROBLEM, "board", f"{said}, but its config word was not read: layout {wanted.layout.name} "
                       f"builds its stop and start frames from it", f"choreo probe --port {shlex.quote(wanted.port)} "
                       "says more; check the cable and the board's firmware", wanted.robot)
    unread = [note.removeprefix("note: ") for note in info.notes]
    if unread:
        return Finding(NOTE, "board", f"{said}; {unread[0]}", None, wanted.robot)
    return Finding(OK, "board", said, None, wanted.robot)


def _layout_check(info: BoardInfo, wanted: BoardWanted) -> Finding:
    """The program counter hints at a layout (docs/hardware.md, Board layouts): HTH4 1.x's main
    loop, which the seed stop frame also writes, contradicts hth4-2.2; HTH4 2.x's fits both
    layouts (2.0/2.1 are seed), so it only says which is whose."""
    layout, robot = wanted.layout, wanted.robot
    where = "robot.layout in the show or --layout" if robot is None else f"robots.{robot}.layout in the show"
    choose = f"{where}; `choreo import PROJECT.h4p` reads it from the project"
    if info.counter is None or info.counter.in_call:
        why = "not read" if info.counter is None else "a motion is running"
        return Finding(NOTE, "layout", f"{layout.name}: the board's program counter cannot tell ({why})", None, robot)
    pc = info.counter.program_counter
    if pc == SEED.main_loop and layout is not SEED:
        return Finding(PROBLEM, "layout", f"the show uses {layout.name} but the board's counter 0x{pc:06x} is "
                       "HTH4 1.x's main loop, which the seed layout's stop frame also writes: the board says seed",
                       f"if HTH4 2.2 or later wrote its motions, power the board off and on and check again; "
                       f"else layout seed ({choose})", robot)
    if pc == HTH4_22.main_loop and (layout is SEED or wanted.assumed):
        said = "assumed (nobody chose it)" if wanted.assumed else "the show's"
        return Finding(NOTE, "layout", f"{layout.name} is {said}; the board's counter 0x{pc:06x} is HTH4 2.x's main "
                       "loop: seed fits motions written by HTH4 2.0/2.1, hth4-2.2 those by 2.2 and later",
                       f"if HTH4 2.2 or later wrote them: layout hth4-2.2 ({choose})", robot)
    if pc in (SEED.main_loop, HTH4_22.main_loop):
        return Finding(OK, "layout", f"{layout.name}: the board's counter 0x{pc:06x} is the main loop it expects",
                       None, robot)
    return Finding(NOTE, "layout", f"{layout.name}: the board's counter 0x{pc:06x} is not a main loop choreo "
                   "knows: no hint", None, robot)


def _idle(info: BoardInfo, wanted: BoardWanted) -> Finding:
    if info.counter is None:
        return Finding(NOTE, "idle", "the program counter was not read: whether a motion runs is unknown",
                       None, wanted.robot)
    pc = info.counter.program_counter
    if info.counter.in_call:
        return Finding(PROBLEM, "idle", f"a motion is running on the board (counter 0x{pc:06x}): the show's "
                       "first play would land on it", "wait until the robot is still (or stop its program), "
                       "then check again", wanted.robot)
    return Finding(OK, "idle", f"no motion is running (counter 0x{pc:06x}, not in a call)", None, wanted.robot)
