"""A run is recorded or it does not go on: a log disk that is full at the start or fills mid-run.

Two kinds of small disk: an injected one (a file that refuses writes past a capacity, and a
fallocate that refuses to reserve past it), which works everywhere, and a real tmpfs of a few
hundred KiB (mounted by the test: skipped where mounting is not permitted). Every run is
checked against the simulated board's own journal: no frame reaches the board that is not in
the log.
"""

from __future__ import annotations

import ctypes
import errno
import os
import subprocess
import sys
from pathlib import Path

import pytest

from choreo.log import recorder as record
from choreo.cli import main
from choreo.errors import LogError
from choreo.run.session import Session
from choreo.run.settings import RunRequest
from runlog import prepare, REPO, _env, read_log, write_show

MANY_PLAYS = """
    version: 1
    name: many
    motions:
      home: {number: 0, duration: 0.01}
    on_abort: home
    steps:
      - repeat: 1000
        steps:
          - play: 1
          - play: 2
"""
PORT = "sim://?motion_s=0.01"
KIB = 1024


class SmallDisk:
    """Room for `capacity` bytes of one file: writes and reservations past it fail (ENOSPC)."""

    def __init__(self, capacity: int) -> None:
        self.capacity = capacity

    def fallocate(self, fd: int, mode: int, offset: int, length: int) -> int:
        if offset + length > self.capacity:
            ctypes.set_errno(errno.ENOSPC)
            return -1
        return 0

    def install(self, monkeypatch) -> None:
        create = record._create_exclusive

        def create_small(path, unique=False):
            file, path = create(path, unique)
            return _LimitedFile(file, self.capacity), path

        monkeypatch.setattr(record, "_create_exclusive", create_small)
        monkeypatch.setattr(record, "_fallocate_function", lambda: self.fallocate, raising=False)


class _LimitedFile:
    """A log file on a disk that says no to any byte past its capacity."""

    def __init__(self, file, capacity: int) -> None:
        self._file = file
        self._capacity = capacity

    def write(self, data) -> int:
        if self._file.tell() + len(data) > self._capacity:
            raise OSError(errno.ENOSPC, os.strerror(errno.ENOSPC))
        return self._file.write(data)

    def __getattr__(self, name):
        return getattr(self._file, name)


def board_frames(session: Session) -> list[str]:
    return [e.data.hex(" ") for e in session.stage.links["robot"].port.board.journal if e.kind == "frame"]


def run_until_full(show: Path, log_path: Path, real_time: bool = False) -> tuple[Session, LogError]:
    """On real time where the test needs the recorder's background flushes (every 0.25 s of
    the machine's time) to happen while the show still runs."""
    request = RunRequest(str(show), port=PORT, log_path=str(log_path))
    session = Session.prepare(request) if real_time else prepare(request)
    with pytest.raises(LogError) as stopped, session:
        session.run()
    return session, stopped.value


def assert_everything_sent_is_logged(session: Session, log_path: Path) -> None:
    sent = board_frames(session)
    log = read_log(log_path)  # complete: summary and footer fit in the reserve
    assert log.tx_hex() == sent
    assert len(log.rx) == len(log.tx)
    plays = [m.get("motion") for m in log.tx if m["kind"] == "play"]
    assert 10 < len(plays) < 2000  # the run went on, and was stopped
    assert plays[-1] == 0 and log.tx[-2]["label"] == "on_abort"  # the abort motion, logged too
    result = log.metadata["choreo.result"]
    assert result["outcome"] == "failed" and result["exit_code"] == "2"


# -- an injected small disk -------------------------------------------------------------------

def test_a_disk_that_fills_mid_run_stops_it_with_every_frame_sent_logged(tmp_path, monkeypatch):
    SmallDisk(400 * KIB).install(monkeypatch)
    show = write_show(tmp_path, MANY_PLAYS)
    log_path = tmp_path / "full.mcap"
    session, error = run_until_full(show, log_path)
    assert str(error) == (f"log {log_path}: the disk is full (No space left on device): the run "
                          "was stopped; the log holds every frame sent")
    assert_everything_sent_is_logged(session, log_path)


def test_a_disk_too_full_for_the_start_is_exit_2_before_the_port_and_leaves_no_file(
        tmp_path, monkeypatch, capsys):
    SmallDisk(8 * KIB).install(monkeypatch)
    show = write_show(tmp_path, MANY_PLAYS)
    log_path = tmp_path / "start.mcap"
    code = main(["run", str(show), "--port", "/dev/choreo-no-such-port", "--log", str(log_path)])
    err = capsys.readouterr().err
    assert code == 2, err
    assert err.splitlines()[-1].startswith(
        f"log {log_path}: cannot write the start of the run: No space left on device (a run needs about")
    assert "Traceback" not in err and "port" not in err.splitlines()[-1]  # the port was never tried
    assert not log_path.exists()


def test_without_fallocate_a_failed_write_still_stops_the_run_in_one_line(tmp_path, monkeypatch):
    disk = SmallDisk(400 * KIB)
    disk.install(monkeypatch)
    monkeypatch.setattr(record, "_fallocate_function", lambda: None)
    show = write_show(tmp_path, MANY_PLAYS)
    log_path = tmp_path / "plain.mcap"
    session, error = run_until_full(show, log_path, real_time=True)
    assert str(error) == f"log {log_path}: cannot write: No space left on device: the run was stopped"
    assert 10 < sum(1 for f in board_frames(session) if f.startswith("07 0c")) < 2000


def test_closing_a_log_frees_the_rest_of_its_reserve(tmp_path):
    show = write_show(tmp_path, "version: 1\nsteps:\n  - play: 1\n")
    log_path = tmp_path / "small.mcap"
    session = prepare(RunRequest(str(show), port=PORT, log_path=str(log_path)))
    with session:
        if session.recorder._reserve.supported:
            assert os.stat(log_path).st_blocks * 512 > os.stat(log_path).st_size + 100 * KIB
        session.run()
    stat = os.stat(log_path)
    assert stat.st_blocks * 512 < stat.st_size + 64 * KIB  # the reserve is gone with the close


# -- a real small disk: tmpfs -----------------------------------------------------------------

@pytest.fixture
def tmpfs(tmp_path):
    """A 1 MiB tmpfs, or a skip where mounting is not permitted."""
    mount = tmp_path / "disk"
    mount.mkdir()
    done = subprocess.run(["mount", "-t", "tmpfs", "-o", "size=1m", "tmpfs", str(mount)],
                          capture_output=True)
    if done.returncode != 0:
        pytest.skip("cannot mount a tmpfs here (needs root)")
    try:
        yield mount
    finally:
        subprocess.run(["umount", "-l", str(mount)], check=False)


def leave_free(mount: Path, free: int) -> None:
    stat = os.statvfs(mount)
    (mount / "filler").write_bytes(b"\0" * (stat.f_bavail * stat.f_frsize - free))


def test_a_tmpfs_that_fills_mid_run_stops_it_with_every_frame_sent_logged(tmp_path, tmpfs):
    leave_free(tmpfs, 440 * KIB)
    show = write_show(tmp_path, MANY_PLAYS)
    log_path = tmpfs / "full.mcap"
    session, error = run_until_full(show, log_path)
    assert "the disk is full (No space left on device)" in str(error)
    assert_everything_sent_is_logged(session, log_path)


@pytest.mark.parametrize("free_kib", [0, 4, 24])
def test_a_full_tmpfs_at_the_start_is_exit_2_in_one_line_and_leaves_no_file(tmp_path, tmpfs, free_kib):
    leave_free(tmpfs, free_kib * KIB)
    show = write_show(tmp_path, MANY_PLAYS)
    log_path = tmpfs / "start.mcap"
    done = subprocess.run([sys.executable, "-m", "choreo", "run", str(show), "--log", str(log_path),
                           "-q"], capture_output=True, text=True, cwd=REPO, env=_env(), timeout=60)
    assert done.returncode == 2, done.stderr
    (line,) = done.stderr.splitlines()
    assert line.startswith(f"log {log_path}: ")
    assert "No space left on device" in line and "nothing was sent" in line
    assert sorted(p.name for p in tmpfs.iterdir()) == ["filler"]


def test_a_run_on_a_tmpfs_that_fills_is_exit_2_in_one_line(tmp_path, tmpfs):
    leave_free(tmpfs, 440 * KIB)
    show = write_show(tmp_path, MANY_PLAYS)
    log_path = tmpfs / "cli.mcap"
    done = subprocess.run([sys.executable, "-m", "choreo", "run", str(show), "--log", str(log_path),
                           "--port", PORT, "-q"], capture_output=True, text=True, cwd=REPO,
                          env=_env(), timeout=60)
    assert done.returncode == 2, done.stderr
    (line,) = done.stderr.splitlines()
    assert line == (f"log {log_path}: the disk is full (No space left on device): the run was "
                    "stopped; the log holds every frame sent")
    assert read_log(log_path).metadata["choreo.result"]["exit_code"] == "2"
