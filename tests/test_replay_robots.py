"""`choreo replay` of a show for several robots: `--layout` reaches every robot's simulator (it
was ignored), each robot's recorded layout by default, and the speed note only for a board that
is not a simulator (it said "2 simulators ... runs its motions at their own speed")."""

from __future__ import annotations

from pathlib import Path
from types import SimpleNamespace

import pytest

from choreo.errors import UsageError
from choreo.run.replay import ReplayReport, _recorded_layout
from runlog import read_log, vmain, write_show

MIXED = """
version: 1
name: mixed
robots:
  left: {layout: hth4-2.2}
  right: {layout: seed}
motions:
  wave: {number: 3, duration: 0.2}
steps:
  - play: wave
  - wait: done
  - play: wave
  - wait: done
"""


@pytest.fixture(scope="module")
def mixed_log(tmp_path_factory) -> Path:
    folder = tmp_path_factory.mktemp("mixed")
    path = folder / "mixed.mcap"
    assert vmain(["run", str(write_show(folder, MIXED)), "--log", str(path), "-q"]) == 0
    return path


def _replay(capsys, log: Path, new_log: Path, *options: str) -> tuple[int, str, str]:
    capsys.readouterr()
    code = vmain(["replay", str(log), "--log", str(new_log), *options])
    out, err = capsys.readouterr()
    return code, out, err


def _layouts(log: Path) -> dict[str, str]:
    info = read_log(log).metadata["choreo"]
    return {name: info[f"robot.{name}.layout"] for name in info["robots"].split(",")}


def test_each_robots_simulator_models_its_recorded_layout(mixed_log, capsys, tmp_path):
    code, out, err = _replay(capsys, mixed_log, tmp_path / "r.mcap", "--strict")
    assert code == 0, out + err
    assert _layouts(tmp_path / "r.mcap") == {"left": "hth4-2.2", "right": "seed"}
    assert "2 simulators, one per robot and its layout (left: hth4-2.2, right: seed)" in err


@pytest.mark.parametrize("layout,other", [("seed", "hth4-2.2"), ("hth4-2.2", "seed")])
def test_layout_gives_every_robots_simulator_that_layout(mixed_log, capsys, tmp_path, layout, other):
    code, out, err = _replay(capsys, mixed_log, tmp_path / "r.mcap", "--layout", layout)
    assert code == 0, out + err
    assert _layouts(tmp_path / "r.mcap") == {"left": layout, "right": layout}
    assert f"(left: {layout}, right: {layout})" in err
    # the robot recorded with the other layout: its CALLs start no slot of this board, and it says so
    robot = "left" if other == "hth4-2.2" else "right"
    differs = [line for line in out.splitlines() if line.startswith("differs:")]
    assert differs  # without --layout the replay is clean (--strict passes): this board answered differently
    replayed = read_log(tmp_path / "r.mcap")
    assert len(replayed.topic(f"/rcb4/{robot}/tx")) == len(read_log(mixed_log).topic(f"/rcb4/{robot}/tx"))


@pytest.mark.parametrize("speed", ["2", "0.5"])
def test_simulators_at_another_speed_get_no_speed_note(mixed_log, capsys, tmp_path, speed):
    code, out, err = _replay(capsys, mixed_log, tmp_path / "r.mcap", "--speed", speed)
    assert code == 0, out + err
    assert "note:" not in err and "own speed" not in err


def test_the_speed_note_names_the_boards_that_are_not_simulators():
    def note(port: str, boards: tuple[str, ...], speed: float = 2.0) -> str | None:
        return ReplayReport(Path("run.mcap"), port, speed, None, boards=boards).speed_note

    assert note("2 simulators, one per robot", ("sim://?durations=3:0.1", "sim://")) is None
    assert note("sim://", ("sim://",)) is None
    assert note("/dev/ttyUSB0", ("/dev/ttyUSB0",), 1.0) is None
    said = note("/dev/ttyUSB0", ("/dev/ttyUSB0",))
    assert said == ("/dev/ttyUSB0 runs motions at the robot's own speed, not 2x: status polls near a "
                    "motion's end may differ")
    assert note("/dev/ttyUSB0", ()) == said  # a report without its boards: its port
    assert note("two", ("sim://", "/dev/ttyUSB0", "socket://host:5")).startswith(
        "/dev/ttyUSB0, socket://host:5 run motions at the robot's own speed")


@pytest.mark.parametrize("robot", [None, "left"])
def test_an_unknown_recorded_layout_points_at_layout(robot):
    key = "layout" if robot is None else f"robot.{robot}.layout"
    reader = SimpleNamespace(run_info={"robots": robot or "", key: "hth9-9"}, path=Path("new.mcap"))
    with pytest.raises(UsageError, match=r"board layout 'hth9-9' is unknown to this choreo: replay it with "
                                         r"--layout seed or hth4-2\.2$"):
        _recorded_layout(reader, robot)
