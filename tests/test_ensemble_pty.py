"""Several robots over real pseudo-terminals: `choreo sim --boards N` in its own process and
`choreo run` in another, each robot on its own pty, in real time (few and short: the
behaviour is tested on virtual time in test_ensemble.py)."""

from __future__ import annotations

import re
import signal
from textwrap import dedent

from runlog import read_log, start_choreo, wait_for

SHOW = """
    version: 1
    robots:
      a: {}
      b: {}
    on_abort: 0
    motions:
      home: {number: 0, duration: 0.1}
      bow: {number: 1, duration: 0.2}
      wave: {number: 2, duration: 0.1}
    steps:
      - play: bow
      - wait: done
      - play: wave
        robots: [b]
      - wait: done
        robots: [b]
      - play: bow
      - wait: done
      - wait: 20
        label: long
"""


class Boards:
    """`choreo sim --boards N -v`: the paths, then every journal line by board."""

    def __init__(self, count: int, *options: str) -> None:
        self.count = count
        self.options = options

    def __enter__(self) -> list[str]:
        self.process = start_choreo("sim", "--boards", str(self.count), "-v", *self.options)
        self.paths = [self.process.stdout.readline().strip() for _ in range(self.count)]
        assert all(path.startswith("/dev/") for path in self.paths), self.process.stderr.read()
        return self.paths

    def stop(self) -> dict[int, list[str]]:
        """Stop the server; its journal lines per board (1-based), as `-v` printed them."""
        self.process.send_signal(signal.SIGINT)
        _, err = self.process.communicate(timeout=10)
        assert self.process.returncode == 0, err
        lines: dict[int, list[str]] = {}
        for line in err.splitlines():
            if line.startswith("[board "):
                number = int(line[len("[board "):line.index("]")])
                lines.setdefault(number, []).append(line)
        return lines

    def __exit__(self, *exc) -> None:
        if self.process.poll() is None:
            self.process.kill()
            self.process.communicate(timeout=10)


def test_sim_boards_serves_each_robot_its_own_frames(tmp_path):
    show = tmp_path / "two.yaml"
    show.write_text(dedent(SHOW.replace("      - wait: 20\n        label: long\n", "")).lstrip())
    log_path = tmp_path / "two.mcap"
    boards = Boards(2, "--durations", "0:0.1,1:0.2,2:0.1")
    with boards as (first, second):
        run = start_choreo("run", str(show), "--log", str(log_path), "--port", f"a={first}", "--port", f"b={second}")
        _, err = run.communicate(timeout=30)
        journal = boards.stop()
    assert run.returncode == 0, err
    log = read_log(log_path)
    wave = next(m["hex"] for m in log.topic("/rcb4/b/tx") if m.get("motion") == 2 and m["kind"] == "play")
    for number, robot in ((1, "a"), (2, "b")):
        answered = {m["seq"] for m in log.topic(f"/rcb4/{robot}/rx") if m["kind"] in ("ack", "status")}
        sent = [m for m in log.topic(f"/rcb4/{robot}/tx") if m["seq"] in answered]  # reached the board whole
        heard = [line for line in journal[number] if " #" in line]
        # byte for byte, in order (a frame a loaded machine split over the pty's 20 ms gap was
        # dropped by the board and retried: only the answered ones are sure to be journalled whole)
        position = 0
        for message in sent:
            position = next(i for i in range(position, len(heard)) if message["hex"] in heard[i]) + 1
        assert any(wave in line for line in heard) == (robot == "b")  # the wave was b's alone
    started = {n: [line for line in journal[n] if "started, runs" in line] for n in (1, 2)}
    assert len(started[1]) >= 2 and len(started[2]) >= 3  # b's wave was b's alone (a retried start may repeat)


def test_ctrl_c_plays_every_robots_abort_motion_over_ptys(tmp_path):
    show = tmp_path / "long.yaml"
    show.write_text(dedent(SHOW).lstrip())
    log_path = tmp_path / "long.mcap"
    boards = Boards(2, "--durations", "0:0.1,1:0.2,2:0.1")
    with boards as (first, second):
        run = start_choreo("run", str(show), "--log", str(log_path), "--port", f"a={first}", "--port", f"b={second}")
        assert wait_for(lambda: log_path.exists() and _started_long(log_path))
        run.send_signal(signal.SIGINT)
        _, err = run.communicate(timeout=20)
        journal = boards.stop()
    assert run.returncode == 130, err
    for number in (1, 2):
        started = [line for line in journal[number] if "started, runs" in line]
        assert "motion 0 started" in started[-1], journal[number]  # home, the abort motion
    result = read_log(log_path).metadata["choreo.result"]
    assert result["outcome"] == "aborted" and result["exit_code"] == "130"


def _started_long(path) -> bool:
    from runlog import read_log_linear

    log, _ = read_log_linear(path)
    return any(m.get("label") == "long" and m["event"] == "start"
               for name in ("a", "b") for m in log.topic(f"/choreo/{name}/step"))


def _motions_started(journal: list[str]) -> list[int]:
    """The motions a board started, in order, a start repeated back to back counted once: a
    reply a loaded machine delayed past the run's timeout has the play retried, and the board
    starts the same motion again (nothing else may come between, nor any other motion)."""
    started = [int(found.group(1)) for line in journal if (found := re.search(r"motion (\d+) started, runs", line))]
    return [motion for at, motion in enumerate(started) if started[at - 1:at] != [motion]]


def test_sim_boards_refuses_a_count_it_cannot_serve():
    import subprocess
    import sys

    done = subprocess.run([sys.executable, "-m", "choreo", "sim", "--boards", "0"], capture_output=True,
                          text=True, timeout=20)
    assert done.returncode == 2 and done.stderr.strip() == "choreo sim: --boards 0: give 1..16"


def test_tracks_over_ptys_meet_on_a_shared_cue(tmp_path):
    show = tmp_path / "canon.yaml"
    show.write_text(dedent("""
        version: 1
        robots: {lead: {}, follow: {}}
        tracks:
          lead:
            - play: 1
              at: 0.1
            - play: 2
              at: 0.6
          follow:
            - play: 1
              at: 0.3
            - play: 2
              at: 0.6
    """).lstrip())
    log_path = tmp_path / "canon.mcap"
    boards = Boards(2, "--motion-s", "0.1")
    with boards as (first, second):
        run = start_choreo("run", str(show), "--log", str(log_path), "--port", f"lead={first}",
                           "--port", f"follow={second}")
        _, err = run.communicate(timeout=30)
        journal = boards.stop()
    assert run.returncode == 0, err
    for number in (1, 2):
        assert _motions_started(journal[number]) == [1, 2], journal[number]
    log = read_log(log_path)
    cues = {name: [m["cue"] for m in log.topic(f"/choreo/{name}/step") if m["event"] == "start"]
            for name in ("lead", "follow")}
    assert cues == {"lead": [0.1, 0.6], "follow": [0.3, 0.6]}
