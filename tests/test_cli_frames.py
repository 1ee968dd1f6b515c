"""`choreo frames`: the exact bytes on one line, bad arguments exit 2 without a traceback."""

from __future__ import annotations

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
