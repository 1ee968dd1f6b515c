"""A show played by several hosts (issue 25): `hosts:` names each host's robots, and
`choreo run SHOW --host NAME` drives that host's robots only: its links, plans, log and
ensemble hold them and no other. Another host's robots are absent, not dropped out: a shared
step waits for none of them. Run here on the machine's clock (`--clock machine`, a rehearsal),
on virtual time against in-process simulators, one host after the other."""

from __future__ import annotations

import json
import threading
from pathlib import Path

import pytest

from choreo.errors import UsageError
from choreo.run.settings import RunRequest, RunSettings
from runlog import prepare, read_log, vmain, write_show

SHOW = """
    version: 1
    clock: link
    tempo: {bpm: 120}
    robots:
      a: {}
      b: {}
      c: {}
    hosts:
      left: [a, b]
      right: [c]
    on_abort: 0
    motions:
      home: {number: 0, duration: 0.5}
      bow: {number: 1, duration: 1}
      wave: {number: 2, duration: 0.8}
      clap: {number: 3, duration: 3}
    steps:
      - play: bow
      - wait: done
      - play: wave
        robots: [a, c]
      - wait: done
        robots: [a, c]
      - play: clap
        robots: [c]
      - wait: done
        robots: [c]
      - play: bow
        at: {bar: 4}
        label: finale
      - wait: done
"""


def starts(board) -> list[tuple[int, float]]:
    """(motion, board time) of every motion the board started, from its journal."""
    return [(int(entry.note.split("motion ", 1)[1].split()[0]), entry.at) for entry in board.journal
            if entry.kind == "frame" and " started, runs " in entry.note]


def run_host(tmp_path: Path, host: str, **request):
    """One host's run, rehearsed on the machine's clock; a run that waits for a robot that is
    not there would never end, so it runs in a thread that must finish."""
    show = write_show(tmp_path, SHOW)
    session = prepare(RunRequest(str(show), log_path=str(tmp_path / f"{host}.mcap"), host=host, clock="machine",
                                 **request))
    done = threading.Event()

    def play() -> None:
        with session:
            session.run()
        done.set()

    thread = threading.Thread(target=play, daemon=True)
    thread.start()
    thread.join(30)
    assert done.is_set(), f"host {host}'s run did not finish: it waits for another host's robot"
    return session


def boards(session) -> dict:
    return {name: link.port.board for name, link in session.stage.links.items()}


def test_each_host_drives_its_own_robots_and_logs_only_theirs(tmp_path):
    for host, robots in (("left", "ab"), ("right", "c")):
        session = run_host(tmp_path, host)
        assert session.result is not None and session.result.outcome == "done" and session.dropouts == []
        assert sorted(session.settings.links) == sorted(session.settings.plans) == list(robots)
        assert list(boards(session)) == list(robots)
        log = read_log(tmp_path / f"{host}.mcap")
        robot_topics = {topic.split("/")[2] for topic in log.messages if topic.startswith("/rcb4/")}
        assert robot_topics == set(robots)
        assert {m["robot"] for topic, ms in log.messages.items() if topic.startswith("/rcb4/") for m in ms} \
            == set(robots)
        meta = log.metadata["choreo"]
        assert meta["show_host"] == host and meta["robots"] == ",".join(robots)
        assert not any("dropped out" in m["message"] for m in log.logs)


def test_a_shared_step_runs_for_this_hosts_robots_without_waiting_for_the_absent_ones(tmp_path):
    left, right = run_host(tmp_path, "left"), run_host(tmp_path, "right")
    played = {name: starts(board) for session in (left, right) for name, board in boards(session).items()}
    assert [m for m, _ in played["a"]] == [1, 2, 1] and [m for m, _ in played["b"]] == [1, 1]
    assert [m for m, _ in played["c"]] == [1, 2, 3, 1]
    # the wave a and c share starts on each host when its own robots are through the bow, and the
    # finale on its cue: the same show times on both hosts, though neither saw the other's robot
    since = {name: [at - moves[0][1] for _, at in moves] for name, moves in played.items()}
    assert since["a"][1] == pytest.approx(since["c"][1], abs=0.01) == pytest.approx(1.0, abs=0.1)
    assert since["a"][2] == since["b"][1] == pytest.approx(since["c"][3], abs=0.01) == pytest.approx(6.0, abs=0.01)
    # c's clap, its own host's business, once its wave is done
    assert since["c"][2] == pytest.approx(since["c"][1] + 0.8, abs=0.1)


def settle(tmp_path: Path, **request) -> RunSettings:
    return RunSettings.settle(RunRequest(str(write_show(tmp_path, SHOW)), no_log=True, clock="machine", **request))


def test_host_is_required_by_a_show_with_hosts_and_checked(tmp_path, capsys):
    with pytest.raises(UsageError, match=r"^this show is played by several hosts \(left, right\): give --host NAME"):
        settle(tmp_path)
    with pytest.raises(UsageError, match=r"^--host rigth: the show has no host 'rigth': did you mean 'right'\?; "
                                         r"its hosts: left, right$"):
        settle(tmp_path, host="rigth")
    with pytest.raises(UsageError, match=r"^--port c=\.\.\.: robot c is driven by host right, not by this run's "
                                         r"\(--host left: a, b\)$"):
        settle(tmp_path, host="left", robot_ports={"c": "sim://"})
    settings = settle(tmp_path, host="right")
    assert settings.host == "right" and list(settings.links) == ["c"] and settings.link is None
    assert settings.run_info(0).metadata()["show_host"] == "right"
    path = str(tmp_path / "show.yaml")
    assert vmain(["run", path, "--clock", "machine", "--no-log"]) == 2
    assert "give --host NAME for the one this computer drives" in capsys.readouterr().err
    assert vmain(["run", path, "--clock", "machine", "--host", "lfet", "--no-log"]) == 2
    assert "did you mean 'left'?" in capsys.readouterr().err


def test_host_is_refused_by_a_show_without_hosts_and_its_log_names_none(tmp_path, capsys):
    path = write_show(tmp_path, "version: 1\nsteps: [{play: 1}]\n")
    assert vmain(["run", str(path), "--host", "left", "--no-log"]) == 2
    assert "--host left: the show names no `hosts:`" in capsys.readouterr().err
    settings = RunSettings.settle(RunRequest(str(path), no_log=True))
    assert settings.host is None and "show_host" not in settings.run_info(0).metadata()


def test_the_link_clock_of_a_host_run_is_the_shows(tmp_path):
    settings = RunSettings.settle(RunRequest(str(write_show(tmp_path, SHOW)), no_log=True, host="left"))
    assert settings.link is not None and (settings.link.bpm, settings.link.meter) == (120.0, 4)
    assert list(settings.plans) == ["a", "b"] and settings.sections.starts == {"a": 0, "b": 0}


def test_from_a_label_picks_the_same_moment_on_every_host(tmp_path):
    for host in ("left", "right"):
        settings = settle(tmp_path, host=host, from_step="finale")
        assert settings.sections.origin == 6.0 and set(settings.sections.starts) == set(settings.plans)


def test_the_cli_runs_one_host(tmp_path, capsys):
    path = write_show(tmp_path, SHOW)
    log = tmp_path / "right.mcap"
    assert vmain(["run", str(path), "--host", "right", "--clock", "machine", "--log", str(log), "--no-console"]) == 0
    assert "host: right, driving c; other hosts drive a, b" in capsys.readouterr().err
    meta = read_log(log).metadata["choreo"]
    assert meta["show_host"] == "right" and meta["robots"] == "c"


def test_choreo_plan_names_each_robots_host(tmp_path, capsys):
    assert vmain(["plan", str(write_show(tmp_path, SHOW))]) == 0
    robots = [line for line in capsys.readouterr().out.splitlines() if line.startswith("robot ")]
    assert robots == ["robot a (host left): layout seed", "robot b (host left): layout seed",
                      "robot c (host right): layout seed"]
    assert vmain(["plan", str(tmp_path / "show.yaml"), "--json"]) == 0
    record = json.loads(capsys.readouterr().out)
    assert record["hosts"] == {"left": ["a", "b"], "right": ["c"]} and record["link"] == {"bpm": 120.0, "meter": 4}


def test_a_loop_is_refused_on_the_link_clock_with_a_host_and_rehearsed_on_the_machines(tmp_path):
    """Each host would end a --loop pass on its own robots' last motion and start the next on a
    bar line of its own: the hosts would part. On the machine's clock the section rehearses."""
    show = str(write_show(tmp_path, SHOW))
    with pytest.raises(UsageError, match=r"^--loop 0\.\.1: not on the Link clock with --host .*--clock machine"):
        RunSettings.settle(RunRequest(show, no_log=True, host="left", loop="0..1"))
    assert RunSettings.settle(RunRequest(show, no_log=True, host="left", loop="0..1", clock="machine")).link is None


def test_a_plain_port_is_the_one_robot_a_host_drives(tmp_path):
    """A host that drives one robot takes `--port URL` for it, as a one-robot show does; a host
    of several still needs --port NAME=URL."""
    show = write_show(tmp_path, SHOW)
    settings = RunSettings.settle(RunRequest(str(show), no_log=True, host="right", clock="machine", port="sim://?seed=7"))
    assert [(link.robot, link.port.split("&")[0]) for link in settings.links.values()] == [("c", "sim://?seed=7")]
    with pytest.raises(UsageError, match=r"^--port sim://: this show has several robots"):
        RunSettings.settle(RunRequest(str(show), no_log=True, host="left", clock="machine", port="sim://"))
