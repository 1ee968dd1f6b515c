"""`choreo frames`: the exact bytes on one line, bad arguments exit 2 without a traceback."""

from __future__ import annotations

import re
import subprocess
import sys

import pytest

from choreo.cli import main


@pytest.mark.parametrize(
    "argv,out",
    [
        (["play", "0"], "07 0c b8 0b 00 00 d6"),
        (["play", "119"], "07 0c b8 c3 03 00 91"),
        (["stop"], "13 00 02 00 00 00 21 87 fd 03 00 00 00 00 00 00 00 00 bd"),
        (["restore"], "09 00 02 00 00 00 23 87 b5"),
        (["status"], "0a 00 20 00 00 00 00 00 02 2c"),
    ],
)
def test_frames_prints_hex(argv, out, capsys):
    assert main(["frames", *argv]) == 0
    assert capsys.readouterr().out == out + "\n"


@pytest.mark.parametrize("argv", [["play", "120"], ["play", "-1"], ["play", "x"], ["play"], ["stop", "3"]])
def test_bad_frame_arguments_exit_2_with_one_line(argv):
    done = subprocess.run([sys.executable, "-m", "choreo", "frames", *argv], capture_output=True, text=True)
    assert done.returncode == 2
    assert done.stdout == ""
    assert len(done.stderr.strip().splitlines()) == 1
    assert "Traceback" not in done.stderr


def test_every_commands_baud_help_is_spelt_from_the_protocols_list():
    """The bauds were typed in four help texts; now each is built from protocol.BAUDS."""
    import argparse

    from choreo.cli import build_parser
    from choreo.wire import protocol

    def subparsers(parser: argparse.ArgumentParser) -> dict[str, argparse.ArgumentParser]:
        found = {}
        for action in parser._actions:
            if isinstance(action, argparse._SubParsersAction):
                for name, sub in action.choices.items():
                    found[name] = sub
                    found.update({f"{name} {n}": s for n, s in subparsers(sub).items()})
        return found

    helps = {name: action.help for name, sub in subparsers(build_parser()).items()
             for action in sub._actions if "--baud" in action.option_strings}
    assert {"run", "frames", "sim", "replay"} <= set(helps)
    for name, text in [*helps.items(), ("probe", subparsers(build_parser())["probe"].description)]:
        assert {int(n) for n in re.findall(r"\d{5,}", text)} == set(protocol.BAUDS), (name, text)
        assert re.findall(r"(\d+) \(default\)", text) in ([], [str(protocol.DEFAULT_BAUD)]), (name, text)
