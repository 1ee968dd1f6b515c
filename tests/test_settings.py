"""A run's settings (choreo.run.settings): settled once from the show and the request, each
value with where it came from, and a simulator's URL built from them (never edited after)."""

from __future__ import annotations

import dataclasses

import pytest

import choreo.run.settings as settings_module
from choreo.errors import UsageError
from choreo.run.replay import replay
from choreo.run.settings import LinkSettings, RunRequest, RunSettings, at_speed
from choreo.wire.layouts import SEED, layout_named
from runlog import prepare, write_show

HTH4 = layout_named("hth4-2.2")

SHOW = """
    version: 1
    name: settled
    robot: {port: 'sim://?drop=50', baud: 625000, layout: hth4-2.2, timeout: 0.5, retries: 1}
    on_abort: 9
    motions:
      wave: {number: 3, duration: 0.2}
      bow: {number: 7, duration: 0.1}
      rest: {number: 9, duration: 0.4}
    steps:
      - play: wave
      - wait: done
      - play: bow
"""

TWO = """
    version: 1
    name: pair
    robots:
      left: {port: 'sim://?seed=1', baud: 625000}
      right: {layout: hth4-2.2}
    motions:
      wave: {number: 3, duration: 0.2}
    steps:
      - play: wave
      - wait: done
"""


def test_a_shows_robot_settings_resolve_with_where_each_came_from(tmp_path):
    link = prepare(RunRequest(str(write_show(tmp_path, SHOW)), no_log=True)).settings.links["robot"]
    assert (link.given_port, link.port_source, link.baud, link.layout, link.layout_source) == (
        "sim://?drop=50", "show", 625000, HTH4, "show")
    assert (link.timeout, link.tries) == (0.5, 2)  # one retry: two tries
    assert not link.assumes_layout


def test_the_command_line_overrides_the_show_setting_by_setting(tmp_path):
    request = RunRequest(str(write_show(tmp_path, SHOW)), port="sim://", baud=1250000, layout="seed", timeout=0.3,
                         retries=0, no_log=True)
    link = prepare(request).settings.links["robot"]
    assert (link.given_port, link.port_source, link.baud, link.layout, link.layout_source) == (
        "sim://", "command line", 1250000, SEED, "command line")
    assert (link.timeout, link.tries) == (0.3, 1)
    rehearsed = prepare(RunRequest(str(write_show(tmp_path, SHOW)), rehearse=True, no_log=True)).settings
    assert (rehearsed.links["robot"].given_port, rehearsed.links["robot"].port_source) == (
        "sim://", "simulator (--rehearse)")


def test_a_real_port_with_no_layout_named_is_an_assumed_layout(tmp_path):
    show = write_show(tmp_path, "version: 1\nsteps:\n  - play: 1\n")
    link = prepare(RunRequest(str(show), port="/dev/ttyUSB9", no_log=True)).settings.links["robot"]
    assert (link.port, link.port_source, link.layout_source, link.assumes_layout) == (
        "/dev/ttyUSB9", "command line", "default", True)
    default = prepare(RunRequest(str(show), no_log=True)).settings.links["robot"]
    assert (default.port_source, default.assumes_layout) == ("simulator", False)


def test_each_robot_of_several_resolves_on_its_own_and_port_name_overrides_one(tmp_path):
    show = str(write_show(tmp_path, TWO))
    links = prepare(RunRequest(show, robot_ports={"right": "sim://?seed=2"}, no_log=True)).settings.links
    assert (links["left"].given_port, links["left"].port_source, links["left"].baud) == (
        "sim://?seed=1", "show", 625000)
    assert (links["right"].given_port, links["right"].port_source, links["right"].layout) == (
        "sim://?seed=2", "command line", HTH4)
    with pytest.raises(UsageError, match="^robot right: --port sim://[?]bogus=1: "):
        prepare(RunRequest(show, robot_ports={"right": "sim://?bogus=1"}, no_log=True))


def test_the_sim_url_carries_the_shows_durations_from_the_settings(tmp_path):
    link = prepare(RunRequest(str(write_show(tmp_path, SHOW)), no_log=True)).settings.links["robot"]
    # the plan's motions and the abort motion, at the run's baud and layout: the given URL kept as said
    assert link.durations == ((3, 0.2), (7, 0.1), (9, 0.4))
    assert link.port == "sim://?drop=50&durations=3:0.2,7:0.1,9:0.4&baud=625000&layout=hth4-2.2"
    assert link.given_port == "sim://?drop=50"  # where it came from stays as the user wrote it
    with pytest.raises(dataclasses.FrozenInstanceError):
        link.baud = 115200  # type: ignore[misc]  # the point: settings are not edited
    with pytest.raises(TypeError):
        LinkSettings("robot", "sim://", "show", 115200, 0.2, 3, port="sim://?motion_s=9")  # type: ignore[call-arg]


def test_the_sim_url_is_built_from_the_settings_it_is_given():
    plain = LinkSettings("robot", "sim://", "simulator", 115200, 0.2, 3)
    assert plain.port == "sim://"
    timed = dataclasses.replace(plain, durations=((3, 0.2),))
    assert timed.port == "sim://?durations=3:0.2" and plain.port == "sim://"
    said = dataclasses.replace(timed, given_port="sim://?motion_s=2")
    assert said.port == "sim://?motion_s=2"  # the URL chose the lengths itself: no durations added
    board = dataclasses.replace(timed, board_layout=HTH4)  # a replay's: the link reads no layout, the board has one
    assert board.port == "sim://?durations=3:0.2&layout=hth4-2.2" and board.layout is SEED
    fast = dataclasses.replace(timed, speed=2)
    assert fast.port == at_speed(timed.port, 2) and "durations=3:0.1" in fast.port and "wire=0" in fast.port
    assert dataclasses.replace(timed, given_port="/dev/ttyUSB0", speed=2).port == "/dev/ttyUSB0"


def test_the_settings_are_settled_once_and_the_run_opens_what_they_say(tmp_path, monkeypatch):
    loads = []
    real = settings_module.load_show
    monkeypatch.setattr(settings_module, "load_show", lambda path: loads.append(path) or real(path))
    settled = []
    real_settle = RunSettings.settle.__func__  # type: ignore[attr-defined]

    def counted(cls, *args, **kwargs):  # type: ignore[no-untyped-def]
        settled.append(1)
        return real_settle(cls, *args, **kwargs)

    monkeypatch.setattr(RunSettings, "settle", classmethod(counted))
    session = prepare(RunRequest(str(write_show(tmp_path, SHOW)), port="sim://", no_log=True))
    with session:
        assert session.run().outcome == "done"
        board = session.stage.links["robot"].port.board
        assert session.stage.links["robot"].name == session.settings.links["robot"].port
    assert (len(loads), len(settled)) == (1, 1)
    assert board.durations == {3: 0.2, 7: 0.1, 9: 0.4}  # the simulator got the show's lengths from the settings


def test_a_replay_builds_its_port_from_link_settings_as_a_run_does(tmp_path):
    log = tmp_path / "run.mcap"
    session = prepare(RunRequest(str(write_show(tmp_path, SHOW)), port="sim://", log_path=str(log)))
    with session:
        session.run()
    from choreo.clock import VirtualTime

    # the replay's simulator: the attached show's durations, the recorded layout, --baud's baud
    report = replay(log, log_path=tmp_path / "replay.mcap", baud=625000, time_source=VirtualTime())
    run_port = session.settings.links["robot"].port
    assert report.port == run_port == "sim://?durations=3:0.2,7:0.1,9:0.4&baud=625000&layout=hth4-2.2"
    assert report.different == 0
    faster = replay(log, log_path=tmp_path / "fast.mcap", baud=625000, speed=2, time_source=VirtualTime())
    assert faster.port == at_speed(run_port, 2)
