"""Every error a serial port raises (at open, at a baud it will not take, on a read, a write or a
poll) is one line naming the port and exit 3, never a traceback: pyserial lets termios.error
(not an OSError) and ValueError through besides its own SerialException."""

from __future__ import annotations

import os
import pty
import termios

import pytest
import serial
import serial.serialposix

from choreo.cli import main
from choreo.sim import protocol_sim
from runlog import vmain

REFUSALS = [
    termios.error(22, "Invalid argument"),
    ValueError("Failed to set custom baud rate (625000): [Errno 22] Invalid argument"),
    serial.SerialException("Could not configure port: (5, 'Input/output error')"),
    OSError(5, "Input/output error"),
]


def refuse(monkeypatch, cls, error: Exception, bauds: set[int] | None = None) -> None:
    """`cls`'s ports refuse to be set to `bauds` (every baud if None), raising `error`, as a pty
    or an adapter without that speed does."""
    original = cls._reconfigure_port

    def reconfigure(self, *args, **kwargs):
        if bauds is None or self._baudrate in bauds:
            raise error
        return original(self, *args, **kwargs)

    monkeypatch.setattr(cls, "_reconfigure_port", reconfigure)


@pytest.fixture
def silent_pty():
    """A real pseudo-terminal nobody answers on (a device that says nothing)."""
    master, slave = pty.openpty()
    try:
        yield os.ttyname(slave)
    finally:
        os.close(slave)
        os.close(master)


def one_line_naming(err: str, port: str) -> str:
    lines = err.strip().splitlines()
    assert len(lines) == 1 and "Traceback" not in err, err
    assert f"port {port}" in lines[0]
    return lines[0]


@pytest.mark.parametrize("error", REFUSALS, ids=lambda e: type(e).__name__)
def test_probe_notes_a_refused_baud_and_tries_the_next(monkeypatch, capsys, error):
    refuse(monkeypatch, protocol_sim.Serial, error, {115200})
    assert vmain(["probe", "--port", "sim://?baud=625000"]) == 0
    out = capsys.readouterr().out
    assert "answers on sim://?baud=625000 at 625000 baud" in out
    assert "note: port sim://?baud=625000: cannot open:" in out and "(at 115200 baud, 8E1)" in out


def test_probe_on_a_silent_pty_that_refuses_a_baud_is_exit_3_in_one_line(monkeypatch, capsys, silent_pty):
    refuse(monkeypatch, serial.serialposix.Serial, termios.error(22, "Invalid argument"), {625000})
    assert main(["probe", "--port", silent_pty, "--timeout", "0.02"]) == 3
    line = one_line_naming(capsys.readouterr().err, silent_pty)
    assert "no answer to the ACK check" in line and "115200" in line
    assert "cannot open: Invalid argument (at 625000 baud, 8E1)" in line


def test_probe_of_a_port_that_takes_no_baud_names_the_port(monkeypatch, capsys, silent_pty):
    refuse(monkeypatch, serial.serialposix.Serial, termios.error(22, "Invalid argument"))
    assert main(["probe", "--port", silent_pty, "--timeout", "0.02"]) == 3
    assert "cannot open: Invalid argument" in one_line_naming(capsys.readouterr().err, silent_pty)


@pytest.mark.parametrize("error", REFUSALS, ids=lambda e: type(e).__name__)
def test_run_on_a_pty_whose_settings_cannot_be_applied_is_exit_3(monkeypatch, capsys, silent_pty, error):
    refuse(monkeypatch, serial.serialposix.Serial, error)
    assert main(["run", "shows/minimal.yaml", "--port", silent_pty, "--no-log", "-q"]) == 3
    assert "cannot open" in one_line_naming(capsys.readouterr().err, silent_pty)


def test_doctor_on_a_silent_pty_is_a_problem_line(monkeypatch, capsys, silent_pty):
    refuse(monkeypatch, serial.serialposix.Serial, termios.error(22, "Invalid argument"), {625000, 1250000})
    assert main(["doctor", "--port", silent_pty]) == 1
    captured = capsys.readouterr()
    assert "Traceback" not in captured.err
    assert f"PROBLEM board: port {silent_pty}: no answer to the ACK check" in captured.out


@pytest.mark.parametrize("method", ["read", "write", "in_waiting"])
@pytest.mark.parametrize("error", [termios.error(5, "Input/output error"), ValueError("bad descriptor"),
                                   OSError(5, "Input/output error")], ids=lambda e: type(e).__name__)
def test_a_port_failing_mid_show_is_one_line_and_exit_3(monkeypatch, capsys, method, error):
    def fail(self, *args, **kwargs):
        raise error

    monkeypatch.setattr(protocol_sim.Serial, method, property(fail) if method == "in_waiting" else fail)
    assert vmain(["run", "shows/minimal.yaml", "--port", "sim://", "--no-log", "-q"]) == 3
    one_line_naming(capsys.readouterr().err, "sim://")
