"""The `choreo` process itself: signals from its first instant, and closed standard streams.

These run the real console script (and `python -m choreo`) as subprocesses: what is tested is
the process start-up, before any of the CLI's code has run.
"""

from __future__ import annotations

import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest

from runlog import REPO, _env, read_log, write_show

SCRIPT = Path(sys.executable).with_name("choreo")
ENTRIES = {
    "script": [str(SCRIPT)],
    "module": [sys.executable, "-m", "choreo"],
}

LONG_SHOW = """
    version: 1
    name: long
    steps:
      - play: 1
      - wait: 30
"""

pytestmark = pytest.mark.skipif(not Path("/proc/self/status").exists(), reason="needs Linux /proc")


def spawn(entry: str, *args: str, **kwargs) -> subprocess.Popen:
    if entry == "script" and not SCRIPT.exists():
        pytest.skip("the choreo console script is not installed next to this Python")
    kwargs.setdefault("env", _env())
    return subprocess.Popen([*ENTRIES[entry], *args], stdout=subprocess.PIPE, stderr=subprocess.PIPE,
                            text=True, cwd=REPO, **kwargs)


def catches(pid: int, signum: int) -> bool:
    """True once the process has a handler for `signum` (the SigCgt mask in /proc)."""
    try:
        status = Path(f"/proc/{pid}/status").read_text()
    except OSError:
        return False
    mask = next(line.split()[1] for line in status.splitlines() if line.startswith("SigCgt:"))
    return bool(int(mask, 16) >> (signum - 1) & 1)


def wait_for_handler(process: subprocess.Popen, signum: int = signal.SIGTERM) -> None:
    """Poll as fast as we can: the handler should be there long before the CLI has loaded."""
    while not catches(process.pid, signum):
        assert process.poll() is None, "the process ended without ever catching the signal"


# Holds the import of choreo's CLI (which `choreo.__main__` makes once its signal handlers are in)
# until the test writes a byte to the pipe it names: the process is then surely still loading.
GATE = """\
import os
import sys


class Gate:
    def find_spec(self, name, path=None, target=None):
        if name == "choreo.cli":
            sys.meta_path.remove(self)
            os.read(int(os.environ["CHOREO_TEST_GATE_FD"]), 1)
        return None


sys.meta_path.insert(0, Gate())
"""


def spawn_held(tmp_path: Path, entry: str, *args: str) -> tuple[subprocess.Popen, int]:
    """`spawn`, its CLI's import held (`GATE`) until a byte is written to the descriptor returned."""
    (tmp_path / "gate").mkdir()
    (tmp_path / "gate" / "sitecustomize.py").write_text(GATE)
    held, release = os.pipe()
    env = _env()
    env["PYTHONPATH"] = str(tmp_path / "gate") + os.pathsep + env["PYTHONPATH"]
    env["CHOREO_TEST_GATE_FD"] = str(held)
    try:
        return spawn(entry, *args, env=env, pass_fds=(held,)), release
    finally:
        os.close(held)


@pytest.mark.parametrize("entry", ["script", "module"])
@pytest.mark.parametrize("signum", [signal.SIGINT, signal.SIGTERM, signal.SIGHUP])
@pytest.mark.parametrize("command", ["validate", "run"])
def test_a_signal_from_the_first_instant_is_exit_130_in_one_line(tmp_path, entry, signum, command):
    """The signal comes while choreo loads, whatever the machine's speed: the CLI's import is held
    until it has been sent (sent as soon as the handler was seen, a loaded machine could put the
    test off until a quick command was over: `validate` then ended with 0, as it should)."""
    show = write_show(tmp_path, LONG_SHOW)
    log_path = tmp_path / "early.mcap"
    args = [command, str(show)] + (["--log", str(log_path)] if command == "run" else [])
    process, release = spawn_held(tmp_path, entry, *args)
    try:
        wait_for_handler(process)
        process.send_signal(signum)  # choreo is still loading: noted, acted on once it has loaded
        os.write(release, b"x")
    finally:
        os.close(release)
    out, err = process.communicate(timeout=30)
    assert process.returncode == 130, err
    assert err == "interrupted\n"
    assert out == ""
    assert not log_path.exists()  # nothing was opened


@pytest.mark.parametrize("delay_ms", [0, 50, 250])
@pytest.mark.parametrize("signum", [signal.SIGINT, signal.SIGTERM])
def test_a_signal_at_any_point_of_a_run_is_exit_130_without_a_traceback(tmp_path, signum, delay_ms):
    show = write_show(tmp_path, LONG_SHOW)
    log_path = tmp_path / "any.mcap"
    process = spawn("script", "run", str(show), "--log", str(log_path))
    wait_for_handler(process)
    time.sleep(delay_ms / 1000)
    process.send_signal(signum)
    _, err = process.communicate(timeout=30)
    assert process.returncode == 130, err
    assert "Traceback" not in err
    assert "interrupted" in err.splitlines()[-1] or "stopped" in err.splitlines()[-1]
    if log_path.exists():  # the run had begun: its log was closed properly
        assert read_log(log_path).metadata["choreo.result"]["exit_code"] == "130"


# -- closed standard streams ------------------------------------------------------------------

def _closing(*fds: int):
    def close() -> None:
        for fd in fds:
            os.close(fd)
    return close


@pytest.mark.parametrize("entry", ["script", "module"])
@pytest.mark.parametrize("closed", [(2,), (1,), (1, 2), (0, 1, 2)])
def test_a_run_with_closed_standard_streams_runs_and_writes_its_log(tmp_path, entry, closed):
    show = write_show(tmp_path, """
        version: 1
        name: closed
        steps:
          - play: 1
          - wait: done
    """)
    log_path = tmp_path / "closed.mcap"
    if entry == "script" and not SCRIPT.exists():
        pytest.skip("the choreo console script is not installed next to this Python")
    done = subprocess.run([*ENTRIES[entry], "run", str(show), "--log", str(log_path),
                           "--port", "sim://?motion_s=0.05"], cwd=REPO,
                          env=_env(), stdin=subprocess.DEVNULL, stdout=subprocess.DEVNULL,
                          stderr=subprocess.DEVNULL, preexec_fn=_closing(*closed), timeout=60)
    assert done.returncode == 0
    log = read_log(log_path)  # a whole, valid log: nothing else was written into it
    assert log.metadata["choreo.result"]["outcome"] == "done"
    assert [m.get("motion") for m in log.tx if m["kind"] == "play"] == [1]


def test_messages_still_reach_an_open_stderr_when_stdout_is_closed(tmp_path):
    done = subprocess.run([str(SCRIPT), "validate", str(tmp_path / "missing.yaml")], cwd=REPO,
                          env=_env(), stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, text=True,
                          preexec_fn=_closing(1), timeout=60)
    assert done.returncode == 2
    assert "Traceback" not in done.stderr and len(done.stderr.splitlines()) == 1
