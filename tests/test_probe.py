"""`choreo probe`: the baud that answers, what the board says, hints marked as hints, and a robot
that is never moved or written to."""

from __future__ import annotations

import pytest

from choreo.wire import protocol as p
from choreo.cli import main
from choreo.errors import LinkError
from choreo.board.probe import ConfigWord, Counter, _counter_hints, probe
from runlog import SimPty, vmain


def test_the_simulator_answers_at_its_own_baud_and_is_only_read():
    info = probe("sim://?baud=625000", timeout=0.05)
    assert info.baud == 625000
    assert info.version == "RCB-4 simulator (choreo)"
    assert info.config == ConfigWord(0x0002)  # power-on: only the run bit
    assert info.counter is not None and len(info.counter.data) == 10


def test_probing_never_writes_ram_nor_calls():
    from choreo.board.link import Link

    seen: list[bytes] = []

    class Spy:
        def on_tx(self, event) -> None:
            seen.append(event.frame.data)

        def on_rx(self, event) -> None:
            pass

    original = Link.open

    def open_with_spy(*args, **kwargs):
        link = original(*args, **kwargs)
        link.subscribe(Spy())
        return link

    Link.open = open_with_spy
    try:
        probe("sim://", timeout=0.05)
    finally:
        Link.open = original
    commands = [p.parse_command(data) for data in seen]
    assert commands and all(c.command != p.CMD_CALL for c in commands)
    assert all(c.move_type != p.MOV_COM_TO_RAM for c in commands)
    assert {c.command for c in commands} == {p.CMD_ACK_CHECK, p.CMD_VERSION, p.CMD_MOV}


def test_a_silent_port_is_a_link_error_naming_every_baud_tried():
    with pytest.raises(LinkError) as failure:
        probe("sim://?drop=1", timeout=0.02)
    message = str(failure.value)
    assert "no answer to the ACK check" in message and "115200, 625000, 1250000" in message
    assert "5 V inverted logic" in message and "parity" in message


def test_probe_command_over_a_pty(capsys):
    """Real time through a real pseudo-terminal: a long timeout, so a loaded machine still passes."""
    with SimPty() as path:
        assert main(["probe", "--port", path, "--timeout", "2"]) == 0
    out = capsys.readouterr().out
    assert f"answers on {path} at 115200 baud" in out
    assert "COM baud             115200 baud" in out and "hint: the config word's COM baud" not in out


def test_probe_finds_a_board_at_another_baud_and_says_its_bits_disagree(capsys):
    assert vmain(["probe", "--port", "sim://?baud=1250000"]) == 0
    out = capsys.readouterr().out
    assert "answers on sim://?baud=1250000 at 1250000 baud" in out
    assert "COM baud             115200 baud" in out
    assert "hint: the config word's COM baud bits say 115200 but the board answered at 1250000" in out


def test_probe_command_on_a_silent_port_is_exit_3(capsys):
    assert main(["probe", "--port", "sim://?drop=1", "--timeout", "0.02"]) == 3
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and err[0].startswith("port sim://?drop=1: no answer to the ACK check")


def test_probe_without_a_port_and_no_adapter_asks_for_one(capsys, monkeypatch):
    from serial.tools import list_ports

    monkeypatch.setattr(list_ports, "comports", lambda: [])
    assert main(["probe"]) == 2
    assert "no Kondo adapter (USB 165C:0008) found: give --port" in capsys.readouterr().err


def test_config_word_decoding():
    word = ConfigWord(0x821B)  # what HTH4 2.2+ saves: ICS on, run, vector jump, 15 ms, LED
    assert word.bit(0) and word.bit(1) and not word.bit(2) and word.bit(3)
    assert word.frame_ms == 15 and word.com_baud == 115200 and word.ics_baud == 115200
    assert word.bit(15)
    assert ConfigWord(0x8761).com_baud == 625000 and ConfigWord(0x87A1).com_baud == 1250000
    assert ConfigWord(0x00C0).com_baud is None  # code 11 is not a baud
    assert ConfigWord(0x2000).ics_baud == 625000


@pytest.mark.parametrize("counter,words", [
    (bytes.fromhex("4b0400") + bytes(7), ["0x00044b", "hth4-2.2"]),
    (bytes.fromhex("fd0300") + bytes(7), ["0x0003fd", "HTH4 1.x", "seed"]),
    (bytes.fromhex("b81b00") + bytes.fromhex("4b0400") + b"\x01" + bytes(3),
     ["a motion is running", "hth4-2.2: slot 2 + 56 bytes", "seed: slot 2 + 0 bytes"]),
    (bytes.fromhex("123456") + bytes(7), ["not a main loop choreo knows"]),
])
def test_layout_hints_from_the_program_counter(counter, words):
    text = " ".join(_counter_hints(Counter(counter)))
    for word in words:
        assert word in text


def test_a_line_that_echoes_is_not_a_board():
    """The ACK check's reply is its own bytes: an echo passes it and answers nothing after it."""
    with pytest.raises(LinkError) as failure:
        probe("loop://", timeout=0.02)
    message = str(failure.value)
    assert message.startswith("port loop://: something answers the ACK check at 115200 baud but no question")
    assert "echoes" in message and "version" in message


def test_probe_and_doctor_of_a_line_that_echoes_fail(capsys):
    assert main(["probe", "--port", "loop://", "--timeout", "0.02"]) == 3
    assert len(capsys.readouterr().err.strip().splitlines()) == 1
    assert main(["doctor", "--port", "loop://"]) == 1
    assert "PROBLEM board: port loop://: something answers the ACK check" in capsys.readouterr().out


def test_a_device_that_naks_every_frame_is_said_to_hear_them_garbled_not_to_echo(capsys):
    # Was: "so it is not a board: a line that echoes what is sent" for a NAK to every frame.
    assert main(["probe", "--port", "sim://?nak=1", "--timeout", "0.02"]) == 3
    (line,) = capsys.readouterr().err.strip().splitlines()
    assert "NAKs the ACK check and answers no question after it" in line and "echoes" not in line
    assert "parity (8E1)" in line and line.startswith("port sim://?nak=1: something at 115200 baud")
