"""`choreo doctor`: each check on a machine of the test's making (the ports pyserial would list,
a fake sysfs tree, a device file), and on this machine, which has no adapter."""

from __future__ import annotations

from pathlib import Path

import pytest

from choreo.board import doctor
from choreo.cli import main
from choreo.board.doctor import OK, PROBLEM, SerialPort, examine
from choreo.board.usb import latency_timer_ms
from runlog import vmain


def fake_sysfs(tmp_path: Path, *, kondo_plugged: bool = False, timers: dict[str, int] | None = None) -> Path:
    root = tmp_path / "sys"
    (root / "bus/usb/devices").mkdir(parents=True)
    if kondo_plugged:
        device = root / "bus/usb/devices/1-1"
        device.mkdir()
        (device / "idVendor").write_text("165c\n")
        (device / "idProduct").write_text("0008\n")
    for name, ms in (timers or {}).items():
        folder = root / "bus/usb-serial/devices" / name
        folder.mkdir(parents=True)
        (folder / "latency_timer").write_text(f"{ms}\n")
    return root


def by_check(findings) -> dict[str, tuple[str, str, str | None]]:
    return {f.check: (f.level, f.text, f.fix) for f in findings}


def test_no_ports_and_no_adapter_is_a_problem_with_what_to_do(tmp_path):
    found = by_check(examine([], sysfs=fake_sysfs(tmp_path)))
    assert found["adapter"][0] == PROBLEM and "no serial ports" in found["adapter"][1]
    assert found["board"][0] == PROBLEM and "choreo doctor --port" in found["board"][2]


def test_an_adapter_without_a_driver_gets_the_new_id_line(tmp_path):
    found = by_check(examine([SerialPort("/dev/ttyS0")], sysfs=fake_sysfs(tmp_path, kondo_plugged=True)))
    level, text, fix = found["adapter"]
    assert level == PROBLEM and "no driver" in text
    assert fix.startswith("echo 165C 0008 | sudo tee /sys/bus/usb-serial/drivers/ftdi_sio/new_id")


@pytest.mark.parametrize("timer, level", [(16, PROBLEM), (1, OK)])
def test_the_latency_timer_is_read_from_sysfs_and_fixed_by_one_command(tmp_path, timer, level):
    device = tmp_path / "ttyUSB0"
    device.write_text("")
    sysfs = fake_sysfs(tmp_path, timers={"ttyUSB0": timer})
    assert latency_timer_ms(str(device), sysfs) == timer
    found = by_check(examine([SerialPort(str(device), 0x165C, 0x0008)], sysfs=sysfs))
    assert found["adapter"][0] == OK and found["permission"][0] == OK
    assert found["latency"][0] == level
    if level == PROBLEM:
        assert "is 16 ms" in found["latency"][1]
        assert found["latency"][2] == f"echo 1 | sudo tee {sysfs}/bus/usb-serial/devices/ttyUSB0/latency_timer"


def test_a_device_this_user_cannot_open_names_its_group(tmp_path, monkeypatch):
    device = tmp_path / "ttyUSB0"
    device.write_text("")
    monkeypatch.setattr(doctor.os, "access", lambda path, mode: False)
    found = by_check(examine([], str(device), sysfs=fake_sysfs(tmp_path)))
    level, text, fix = found["permission"]
    assert level == PROBLEM and "cannot be opened by this user" in text
    assert fix.startswith("sudo usermod -aG ") and fix.endswith("$USER, then log out and in again")


def test_a_missing_device_is_a_problem(tmp_path):
    found = by_check(examine([], str(tmp_path / "ttyUSB7"), sysfs=fake_sysfs(tmp_path)))
    assert found["device"][0] == PROBLEM and "does not exist" in found["device"][1]


def test_the_board_is_probed_on_a_simulated_port(capsys):
    assert vmain(["doctor", "--port", "sim://"]) == 0
    out = capsys.readouterr().out
    assert "ok      board: a board answers on sim:// at 115200 baud, version 'RCB-4 simulator (choreo)'" in out
    assert vmain(["doctor", "--port", "sim://?drop=1"]) == 1
    out = capsys.readouterr().out
    assert "PROBLEM board: port sim://?drop=1: no answer to the ACK check" in out and "-> fix: " in out


def test_on_this_machine_every_line_is_a_verdict(capsys):
    code = main(["doctor", "--no-probe"])
    lines = capsys.readouterr().out.splitlines()
    assert lines and all(line.split()[0] in ("ok", "PROBLEM", "note") for line in lines)
    assert code == (1 if any(line.startswith("PROBLEM") for line in lines) else 0)


class FakeSerial:
    """A port as pyserial opens a real device: its path, and the low-latency request."""

    def __init__(self, device: str) -> None:
        self.port = device
        self.low_latency: bool | None = None

    def set_low_latency_mode(self, on: bool) -> None:
        self.low_latency = on


def test_a_run_asks_for_low_latency_and_says_once_what_a_slow_timer_costs(monkeypatch):
    from choreo.board import usb
    from choreo.board.link import usb_latency_note

    monkeypatch.setattr(usb, "latency_timer_ms", lambda device, sysfs=usb.SYSFS: 16)
    port = FakeSerial("/dev/ttyUSB0")
    note = usb_latency_note(port)
    assert port.low_latency is True
    assert note.startswith("port /dev/ttyUSB0: the USB adapter's latency timer is 16 ms")
    assert note.endswith("fix: echo 1 | sudo tee /sys/bus/usb-serial/devices/ttyUSB0/latency_timer")
    monkeypatch.setattr(usb, "latency_timer_ms", lambda device, sysfs=usb.SYSFS: 1)
    assert usb_latency_note(FakeSerial("/dev/ttyUSB0")) is None
    sim = FakeSerial("sim://")
    assert usb_latency_note(sim) is None and sim.low_latency is None  # a URL port has no adapter


def test_the_audio_output_is_checked_with_a_fix_when_it_does_not_open():
    from choreo.board.doctor import NOTE, OK, PROBLEM, audio_output
    from choreo.music.player import AudioError

    def will_not_open() -> str:
        raise AudioError("it will not open (failed to init device)")

    assert audio_output(lambda: "ALSA").line() == "ok      audio: the default output opens (ALSA)"
    # no sound output at all: music shows still keep time, silent; a note, with the fix
    quiet = audio_output(will_not_open)
    assert quiet.level == NOTE and "music shows play silent on the null output" in quiet.text
    assert quiet.fix is not None and "aplay -l" in quiet.fix
    # an output the user asked for that does not open is a problem
    asked = audio_output(will_not_open, "USB")
    assert asked.level == PROBLEM and asked.text.startswith("output 'USB': it will not open") and asked.fix
    assert audio_output(lambda: "Null", "null").level == NOTE
    assert audio_output(lambda: "PulseAudio", "2").level == OK


def test_doctor_checks_the_null_output_and_refuses_an_unknown_one(capsys):
    assert main(["doctor", "--no-probe", "--audio-device", "null"]) in (0, 1)
    assert "note    audio: output 'null' is the null output: music shows play silent" in capsys.readouterr().out
    assert main(["doctor", "--no-probe", "--audio-device", "no-such-output-anywhere"]) == 1
    out = capsys.readouterr().out
    assert "PROBLEM audio: --audio-device no-such-output-anywhere: no such output" in out


@pytest.mark.parametrize("ports", [[], [SerialPort("/dev/ttyS0")],
                                   [SerialPort("/dev/ttyUSB0", 0x165C, 0x0008),
                                    SerialPort("/dev/ttyUSB1", 0x165C, 0x0008)]])
def test_no_port_to_run_a_show_on_is_a_problem_and_exit_1(tmp_path, monkeypatch, capsys, ports):
    """No Kondo adapter (or several, and no --port): a show would not start, so doctor fails."""
    from serial.tools import list_ports

    monkeypatch.setattr(list_ports, "comports", lambda: ports)
    found = by_check(examine(ports, sysfs=fake_sysfs(tmp_path)))
    assert found["board"][0] == PROBLEM
    assert main(["doctor", "--no-probe"]) == 1
    assert "PROBLEM board: no port to check" in capsys.readouterr().out


@pytest.mark.parametrize("name", ["/dev/" + "x" * 300, "/dev/tty\0USB0"])
def test_a_device_name_the_system_refuses_is_a_problem_not_a_traceback(tmp_path, name):
    found = by_check(examine([], name, sysfs=fake_sysfs(tmp_path)))
    assert found["device"][0] == PROBLEM
