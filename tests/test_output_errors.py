"""An output that cannot be written (issue 11, item 3): one line and exit 2, never a traceback;
a reader that went away (a closed pipe) ends the command quietly."""

from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

import pytest

from choreo.cli import main
from runlog import vmain

ROOT = Path(__file__).resolve().parent.parent


@pytest.fixture(scope="module")
def run_log(tmp_path_factory) -> Path:
    path = tmp_path_factory.mktemp("output") / "run.mcap"
    assert vmain(["run", str(ROOT / "shows" / "minimal.yaml"), "--port", "sim://?motion_s=0.1",
                 "--log", str(path), "-q"]) == 0
    return path


COMMANDS = [
    ["plan", "shows/dance.yaml"],
    ["validate", "shows/dance.yaml"],
    ["frames", "play", "3"],
    ["ports"],
    ["schema"],
    ["log", "frames", "LOG"],
    ["log", "summary", "LOG"],
    ["log", "timeline", "LOG"],
    ["log", "export", "LOG", "--csv", "-"],
]


@pytest.mark.skipif(not os.path.exists("/dev/full"), reason="no /dev/full here")
@pytest.mark.parametrize("argv", COMMANDS, ids=lambda a: " ".join(a[:2]))
def test_a_full_output_is_one_line_and_exit_2(argv, run_log):
    argv = [str(run_log) if a == "LOG" else a for a in argv]
    with open("/dev/full", "w") as full:
        done = subprocess.run([sys.executable, "-m", "choreo", *argv], stdout=full, stderr=subprocess.PIPE,
                              text=True, cwd=ROOT, timeout=60)
    assert done.returncode == 2, done.stderr
    assert done.stderr == "choreo: cannot write the output: No space left on device\n"


def test_a_closed_pipe_ends_quietly(run_log):
    reader = subprocess.Popen([sys.executable, "-m", "choreo", "log", "frames", str(run_log)],
                              stdout=subprocess.PIPE, stderr=subprocess.PIPE, cwd=ROOT)
    reader.stdout.readline()
    reader.stdout.close()
    _, err = reader.communicate(timeout=60)
    assert reader.returncode == 0 and b"Traceback" not in err
