"""A port that is the terminal choreo runs in is refused before it is opened (issue 21, item 6):
`choreo run --port $(tty)` (a mistyped port, `choreo sim`'s path taken from the wrong window) set
the operator's terminal raw at 115200 baud with even parity, wrote the play frames into it and
left it so. Now: one line naming the port, exit 3, the terminal's settings untouched."""

from __future__ import annotations

import os
import pty
import select
import subprocess
import sys
import termios

import pytest

from choreo.board.link import own_terminal
from runlog import REPO, write_show

pytestmark = pytest.mark.skipif(os.name != "posix", reason="terminals as device files are POSIX")


def _output(master: int) -> bytes:
    got = b""
    while select.select([master], [], [], 0.1)[0]:
        try:
            chunk = os.read(master, 4096)
        except OSError:  # the other side closed
            break
        if not chunk:
            break
        got += chunk
    return got


@pytest.mark.parametrize("command", [["run", "SHOW", "--no-log", "-q"], ["probe"]])  # doctor: the probe's way
def test_a_port_that_is_the_terminal_choreo_runs_in_is_refused_and_left_as_it_was(tmp_path, command):
    master, slave = pty.openpty()
    try:
        path = os.ttyname(slave)
        before = termios.tcgetattr(slave)
        show = write_show(tmp_path, "version: 1\nsteps:\n  - play: 1\n")
        argv = [str(show) if part == "SHOW" else part for part in command]
        done = subprocess.run([sys.executable, "-m", "choreo", *argv, "--port", path], stdin=slave, stdout=slave,
                              stderr=slave, cwd=REPO, timeout=60, check=False)
        out = _output(master)
        assert termios.tcgetattr(slave) == before  # not set raw at the board's baud
        assert b"\x13\x00\x02" not in out  # no stop frame written into it
        said = out.decode(errors="replace")
        assert f"port {path}: is the terminal choreo runs in" in said
        assert done.returncode == 3 and len(said.strip().splitlines()) == 1, said
    finally:
        os.close(master)
        os.close(slave)


def test_only_this_processs_terminals_count():
    if os.path.exists("/dev/tty"):
        assert own_terminal("/dev/tty")  # the controlling terminal, whichever it is
    master, slave = pty.openpty()
    try:
        assert not own_terminal(os.ttyname(slave))  # another terminal: `choreo sim`'s, say
    finally:
        os.close(master)
        os.close(slave)
    assert not own_terminal("sim://?drop=1") and not own_terminal("/dev/null")
    assert not own_terminal(__file__) and not own_terminal("/no/such/device")
