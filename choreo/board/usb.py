"""The USB side of a serial link: Kondo's adapter, its driver, and the FTDI latency timer.

Kondo's Dual USB Adapter HS is an FTDI chip with Kondo's own USB id, 165C:0008, which Linux's
ftdi_sio driver does not list: it binds only after the id is added (`new_id`). An FTDI chip
holds short replies until its latency timer fires, 16 ms by default, so each exchange of a play
can take up to 16 ms longer; the timer is a file in sysfs, and pyserial can ask the driver for
low latency (1 ms). Everything here reads a sysfs tree given as a path, so tests hand it a fake.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path
from typing import Protocol, runtime_checkable

from choreo.wire.protocol import play_sequence

KONDO_USB = (0x165C, 0x0008)  # Kondo Dual USB Adapter HS (an FTDI chip)
KONDO_USB_ID = f"{KONDO_USB[0]:04X}:{KONDO_USB[1]:04X}"  # `165C:0008`, as lsusb and messages show it
SYSFS = Path("/sys")
FTDI_DRIVER = "bus/usb-serial/drivers/ftdi_sio"
NEW_ID = f"{KONDO_USB[0]:04X} {KONDO_USB[1]:04X}"  # what ftdi_sio's new_id file takes: `165C 0008`
NEW_ID_FIX = f"echo {NEW_ID} | sudo tee /sys/{FTDI_DRIVER}/new_id   (after: sudo modprobe ftdi_sio)"
LOW_LATENCY_MS = 1
PLAY_FRAMES = len(play_sequence(0))  # the replies a play waits for (the document's sequence)


def latency_cost(timer_ms: int) -> str:
    """What a latency timer of `timer_ms` costs: a run says it at open, `choreo doctor` in its
    finding, in the same words."""
    return f"each reply may wait up to {timer_ms} ms, a play up to {PLAY_FRAMES * timer_ms} ms more"


@dataclass(frozen=True)
class UsbDevice:
    """A USB device as sysfs lists it."""

    path: Path
    vid: int
    pid: int

    @property
    def is_kondo(self) -> bool:
        return (self.vid, self.pid) == KONDO_USB


def usb_devices(sysfs: Path = SYSFS) -> list[UsbDevice]:
    """Every USB device with a vendor and product id (none where there is no sysfs)."""
    found = []
    root = sysfs / "bus/usb/devices"
    for device in sorted(root.glob("*")) if root.is_dir() else []:
        try:
            vid = int((device / "idVendor").read_text().strip(), 16)
            pid = int((device / "idProduct").read_text().strip(), 16)
        except (OSError, ValueError):
            continue
        found.append(UsbDevice(device, vid, pid))
    return found


def latency_timer_path(device: str, sysfs: Path = SYSFS) -> Path:
    """`/dev/ttyUSB0` -> its FTDI latency timer file."""
    return sysfs / "bus/usb-serial/devices" / Path(device).name / "latency_timer"


def latency_timer_ms(device: str, sysfs: Path = SYSFS) -> int | None:
    """The FTDI latency timer of a serial device in ms; None where it has none (not FTDI, not
    Linux, a pty) or it cannot be read."""
    try:
        return int(latency_timer_path(device, sysfs).read_text().strip())
    except (OSError, ValueError):
        return None


def latency_fix(device: str, sysfs: Path = SYSFS) -> str:
    """The command that sets the timer to 1 ms (until the adapter is plugged in again)."""
    return f"echo {LOW_LATENCY_MS} | sudo tee {latency_timer_path(device, sysfs)}"


@runtime_checkable
class LowLatencyPort(Protocol):
    """A port whose driver can be asked for low latency: pyserial's on Linux (`serial.Serial`
    there); not its URL ports, nor other platforms'."""

    def set_low_latency_mode(self, low_latency_settings: bool) -> None: ...


def ask_low_latency(port: object) -> bool:
    """Ask the driver for low latency (pyserial, Linux only); False where it cannot be had
    (another platform, a pty, a URL port): nothing is lost by asking."""
    if not isinstance(port, LowLatencyPort):
        return False
    try:
        port.set_low_latency_mode(True)
    except (OSError, ValueError, NotImplementedError, AttributeError):
        return False
    return True
