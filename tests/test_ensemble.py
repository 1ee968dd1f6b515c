"""Several robots on one show clock, run on virtual time against in-process simulators:
each board gets exactly its own frames, unison starts land together (by the boards' journals),
tracks meet on shared cues, faults stop or spare the others, a stop plays every abort motion."""

from __future__ import annotations

from pathlib import Path
from textwrap import dedent

import pytest

from choreo.errors import LinkError, UsageError
from choreo.events import StopRequest
from choreo.run.settings import RunRequest
from runlog import prepare, read_log, vmain

UNISON = """
    version: 1
    robots:
      a: {}
      b: {}
      c: {}
    on_abort: 0
    motions:
      home: {number: 0, duration: 0.5}
      bow: {number: 1, duration: 1}
      wave: {number: 2, duration: 0.8}
      clap: {number: 3, duration: 0.4}
    steps:
      - play: bow
        label: bow
      - wait: done
      - play: wave
        robots: [a]
      - wait: done
        robots: [a]
      - repeat: 2
        robots: [b, c]
        steps:
          - play: clap
          - wait: done
      - play: bow
        at: 5
        label: finale
      - wait: done
"""

CANON = """
    version: 1
    robots:
      lead: {}
      follow: {}
    on_abort: 0
    motions:
      home: {number: 0, duration: 0.5}
      phrase: {number: 4, duration: 1.5}
      pose: {number: 9, duration: 1}
    tracks:
      lead:
        - play: phrase
          at: 1
        - wait: done
        - play: pose
          at: 4
          label: together
        - wait: done
      follow:
        - play: phrase
          at: 2
        - wait: done
        - play: pose
          at: 4
        - wait: done
"""


def write(tmp_path: Path, text: str, name: str = "show.yaml") -> Path:
    path = tmp_path / name
    path.write_text(dedent(text).lstrip())
    return path


def run_session(tmp_path: Path, text: str, stop: StopRequest | None = None, **request):
    session = prepare(RunRequest(str(write(tmp_path, text)), log_path=str(tmp_path / "run.mcap"), **request))
    error = None
    try:
        with session:
            session.run(stop=stop)
    except (LinkError, UsageError) as exc:
        error = exc
    return session, error


def boards(session) -> dict:
    return {name: link.port.board for name, link in session.stage.links.items()}


def frames(board) -> list[str]:
    return [entry.data.hex(" ") for entry in board.journal if entry.kind == "frame"]


def starts(board) -> list[tuple[int, float]]:
    """(motion, board time) of every motion the board started, from its journal."""
    found = []
    for entry in board.journal:
        if entry.kind == "frame" and " started, runs " in entry.note:
            motion = int(entry.note.split("motion ", 1)[1].split()[0])
            found.append((motion, entry.at))
    return found


def test_each_board_gets_exactly_its_own_frames_and_unison_starts_land_together(tmp_path):
    session, error = run_session(tmp_path, UNISON)
    assert error is None and session.result.outcome == "done"
    log = read_log(tmp_path / "run.mcap")
    played = {name: starts(board) for name, board in boards(session).items()}
    assert [m for m, _ in played["a"]] == [1, 2, 1]
    assert [m for m, _ in played["b"]] == [1, 3, 3, 1] == [m for m, _ in played["c"]]
    # the shared plays start at one instant on every board (virtual time: exactly)
    assert played["a"][0][1] == played["b"][0][1] == played["c"][0][1]
    assert played["a"][-1][1] == played["b"][-1][1] == played["c"][-1][1]
    assert played["b"][1][1] == played["c"][1][1]
    # b and c clap only after a's wave is over (the shared steps wait for everyone)
    assert played["b"][1][1] > played["a"][1][1] + 0.8
    # what each board heard is what the log says was sent to that robot, in order
    for name, board in boards(session).items():
        sent = [m["hex"] for m in log.topic(f"/rcb4/{name}/tx")]
        assert frames(board) == sent and all(m["robot"] == name for m in log.topic(f"/rcb4/{name}/tx"))


def test_the_log_names_every_robot_and_the_review_reads_it(tmp_path, capsys):
    session, error = run_session(tmp_path, UNISON)
    log = read_log(tmp_path / "run.mcap")
    per_robot = (("rcb4", "tx"), ("rcb4", "rx"), ("choreo", "step"))
    assert set(log.messages) == {f"/{kind}/{name}/{topic}" for name in "abc"
                                 for kind, topic in per_robot} | {"/choreo/clock"}
    meta = log.metadata["choreo"]
    assert meta["robots"] == "a,b,c" and meta["unison"] == "yes" and meta["robot.b.port"].startswith("sim://")
    assert all(m["robot"] == "b" for m in log.topic("/choreo/b/step"))
    assert vmain(["log", "summary", str(tmp_path / "run.mcap")]) == 0
    out = capsys.readouterr().out
    assert "unison    motion starts apart: median 0.000 ms, p99 0.000 ms, max 0.000 ms (4 plays" in out
    assert ", 3 robots (a, b, c; ports below)" in out
    robots = [line.split(":")[0] for line in out.splitlines() if line.startswith("robot ")]
    assert robots == ["robot a", "robot b", "robot c"]
    assert "0 unanswered" not in out and "unanswered" not in out


def test_tracks_advance_on_their_own_and_meet_on_a_shared_cue(tmp_path):
    session, error = run_session(tmp_path, CANON)
    assert error is None
    lead, follow = starts(boards(session)["lead"]), starts(boards(session)["follow"])
    assert [m for m, _ in lead] == [4, 9] == [m for m, _ in follow]
    assert follow[0][1] - lead[0][1] == pytest.approx(1.0, abs=1e-3)  # the canon: one second behind
    assert lead[1][1] == follow[1][1]  # together again on the cue at 4 s
    assert lead[1][1] - lead[0][1] == pytest.approx(3.0, abs=1e-3)  # the first play: a seeded lead


def test_a_fault_on_one_robot_stops_the_show_and_the_others_play_their_abort(tmp_path):
    session, error = run_session(tmp_path, UNISON, robot_ports={"b": "sim://?lose=12"})
    assert isinstance(error, LinkError) and str(error).startswith("robot b: ")
    played = {name: [m for m, _ in starts(board)] for name, board in boards(session).items()}
    assert played["a"][-1] == 0 and played["c"][-1] == 0  # their abort motion, home
    log = read_log(tmp_path / "run.mcap")
    result = log.metadata["choreo.result"]
    assert result["outcome"] == "failed" and result["exit_code"] == "3" and "robot b" in result["error"]
    assert any("robot b's link failed" in m["message"] for m in log.logs)


def test_on_fault_continue_lets_the_others_finish_and_still_fails_the_run(tmp_path):
    text = UNISON.replace("      b: {}", "      b: {on_fault: continue}")
    session, error = run_session(tmp_path, text, robot_ports={"b": "sim://?lose=12"})
    assert isinstance(error, LinkError)
    assert "robot b dropped out at " in str(error) and "the others finished the show" in str(error)
    played = {name: [m for m, _ in starts(board)] for name, board in boards(session).items()}
    assert played["a"] == [1, 2, 1] and played["c"] == [1, 3, 3, 1]  # everything, no abort
    assert session.dropouts and session.dropouts[0].robot == "b"


def test_a_stop_request_plays_every_robots_abort_motion(tmp_path):
    stop = StopRequest()

    class StopAtClap:
        def on_step(self, event):
            if event.step.motion == 3 and event.event == "start":
                stop.request("interrupted (Ctrl-C)")

        def on_log(self, *args):
            pass

    session = prepare(RunRequest(str(write(tmp_path, UNISON)), log_path=str(tmp_path / "run.mcap")))
    with session:
        result = session.run([StopAtClap()], stop)
    assert result.outcome == "aborted"
    for name, board in boards(session).items():
        assert [m for m, _ in starts(board)][-1] == 0, name


def test_cli_runs_a_show_for_several_robots_and_names_them(tmp_path, capsys):
    show = write(tmp_path, UNISON)
    code = vmain(["run", str(show), "--log", str(tmp_path / "r.mcap"), "--port", "b=sim://?reply_ms=0.5"])
    err = capsys.readouterr().err
    assert code == 0, err
    assert "robot b: sim://?reply_ms=0.5" in err and "from --port" in err and "3 robots, shared steps" in err
    assert vmain(["run", str(show), "--port", "sim://", "--no-log"]) == 2
    assert "give --port NAME=URL for each robot" in capsys.readouterr().err
    assert vmain(["run", str(show), "--port", "d=sim://", "--no-log"]) == 2
    assert "the show has no robot 'd'" in capsys.readouterr().err


def test_from_a_label_in_tracks_starts_every_track_at_that_moment(tmp_path):
    session = prepare(RunRequest(str(write(tmp_path, CANON)), no_log=True, from_step="together"))
    assert session.settings.sections.origin == 4.0 and session.settings.sections.starts == {"lead": 2, "follow": 2}
    with session:
        session.run()
    assert [m for m, _ in starts(boards(session)["lead"])] == [9]


def test_a_one_robot_show_logs_as_before(tmp_path):
    run_session(tmp_path, "version: 1\nsteps:\n  - play: 1\n  - wait: done\n")
    log = read_log(tmp_path / "run.mcap")
    assert set(log.messages) == {"/rcb4/tx", "/rcb4/rx", "/choreo/step", "/choreo/clock"}
    assert not any("robot" in m for topic in log.messages.values() for m in topic)
    assert "robots" not in log.metadata["choreo"]


def test_review_commands_read_every_robot(tmp_path, capsys, monkeypatch):
    monkeypatch.setenv("COLUMNS", "100")
    run_session(tmp_path, UNISON)
    log = str(tmp_path / "run.mcap")
    assert vmain(["log", "timeline", log]) == 0
    lines = capsys.readouterr().out.splitlines()
    lanes = [i for i, line in enumerate(lines) if line.startswith("robot ")]
    assert [lines[i] for i in lanes] == ["robot a", "robot b", "robot c"]
    a_rows = lines[lanes[0] + 1:lanes[1]]
    assert [row.split()[1:3] for row in a_rows] == [["motion", "1"], ["motion", "2"], ["motion", "1"]]
    monkeypatch.setenv("COLUMNS", "400")
    assert vmain(["log", "frames", log]) == 0
    frames = capsys.readouterr().out
    assert "no reply in the log" not in frames  # each robot's frames pair with their own replies
    assert frames.count(" a: ") and frames.count(" b: ") and frames.count(" c: ")
    assert vmain(["log", "export", log, "--jsonl", "-"]) == 0
    rows = [__import__("json").loads(line) for line in capsys.readouterr().out.splitlines()]
    assert {row["robot"] for row in rows} == {"a", "b", "c"} and all(row["reply"] for row in rows)
    assert vmain(["log", "summary", "--json", log]) == 0
    summary = __import__("json").loads(capsys.readouterr().out)
    assert list(summary["robots"]) == ["a", "b", "c"] and summary["unison_skew"]["count"] == 4
    assert summary["robots"]["b"]["steps"]["run"] == 8


def test_replay_replays_every_robot_on_its_own_simulator(tmp_path, capsys):
    run_session(tmp_path, UNISON)
    assert vmain(["replay", str(tmp_path / "run.mcap"), "--log", str(tmp_path / "replay.mcap"), "--strict"]) == 0
    out = capsys.readouterr().out
    recorded, replayed = read_log(tmp_path / "run.mcap"), read_log(tmp_path / "replay.mcap")
    for name in "abc":
        assert ([m["hex"] for m in replayed.topic(f"/rcb4/{name}/tx")]
                == [m["hex"] for m in recorded.topic(f"/rcb4/{name}/tx")])
    frames = sum(len(recorded.topic(f"/rcb4/{name}/tx")) for name in "abc")
    assert f"replayed {frames} frames: {frames} same, 0 differ" in out
    assert vmain(["replay", str(tmp_path / "run.mcap"), "--port", "sim://"]) == 2
    assert "runs each on its own simulator" in capsys.readouterr().err


@pytest.mark.parametrize("lose", [3, 5, 6, 11, 13])
def test_a_robot_dropping_out_anywhere_never_holds_up_the_others(tmp_path, lose):
    """Frame K of b's is lost: in a play sequence, before or at its start frame, or in a poll;
    the others, waiting for b at a shared step or a unison start, go on without it."""
    text = UNISON.replace("      b: {}", "      b: {on_fault: continue}")
    session, error = run_session(tmp_path, text, robot_ports={"b": f"sim://?lose={lose}"})
    assert isinstance(error, LinkError) and "robot b dropped out at " in str(error)
    played = {name: [m for m, _ in starts(board)] for name, board in boards(session).items()}
    assert played["a"] == [1, 2, 1] and played["c"] == [1, 3, 3, 1]


def test_run_json_names_every_robot_and_who_dropped_out(tmp_path, capsys):
    text = UNISON.replace("      b: {}", "      b: {on_fault: continue}")
    show = write(tmp_path, text)
    code = vmain(["run", str(show), "--json", "-q", "--log", str(tmp_path / "r.mcap"), "--port", "b=sim://?lose=5"])
    record = __import__("json").loads(capsys.readouterr().out)
    assert code == 3 and record["exit"] == 3 and list(record["robots"]) == ["a", "b", "c"]
    assert record["robots"]["b"]["port"].startswith("sim://?lose=5")
    assert [d["robot"] for d in record["dropouts"]] == ["b"] and "robot b dropped out" in record["error"]


def test_log_frames_shows_one_robot_on_request(tmp_path, capsys, monkeypatch):
    monkeypatch.setenv("COLUMNS", "400")
    run_session(tmp_path, UNISON)
    log = str(tmp_path / "run.mcap")
    assert vmain(["log", "frames", log, "--robot", "b"]) == 0
    lines = capsys.readouterr().out.splitlines()[1:]
    assert lines and all(" b: " in line for line in lines)
    assert vmain(["log", "frames", log, "--robot", "d"]) == 2
    assert "--robot d: not a robot of this log; its robots: a, b, c" in capsys.readouterr().err


def test_robots_left_keep_the_shows_timing_when_the_robot_of_a_step_dropped_out(tmp_path):
    """a drops out during the first `wait: done`; its wave (0.8 s, steps 2-3) is not danced,
    but b and c still clap when the plan says, after it, not 0.8 s early."""
    text = UNISON.replace("      a: {}", "      a: {on_fault: continue}")
    session, error = run_session(tmp_path, text, robot_ports={"a": "sim://?lose=12"})
    assert isinstance(error, LinkError) and "robot a dropped out" in str(error)
    b = starts(boards(session)["b"])
    assert [m for m, _ in b] == [1, 3, 3, 1]
    bow, clap = b[0][1], b[1][1]
    assert clap - bow >= 1.0 + 0.8  # the bow's second, then the wave's planned 0.8 s


def test_a_robots_show_port_given_to_another_robot_is_refused_before_any_port_opens(tmp_path, capsys):
    show = write(tmp_path, UNISON.replace("      a: {}", "      a: {port: /dev/ttyS9}"))
    assert vmain(["run", str(show), "--port", "b=/dev/ttyS9", "--no-log"]) == 2
    assert "robot b's port /dev/ttyS9 (command line) is robot a's too (show)" in capsys.readouterr().err


def test_the_log_is_named_when_a_later_robots_port_fails(tmp_path, capsys):
    show = write(tmp_path, UNISON)
    code = vmain(["run", str(show), "--log", str(tmp_path / "k.mcap"), "--port", f"c={tmp_path / 'no-tty'}"])
    err = capsys.readouterr().err
    assert code == 3 and f"log: {tmp_path / 'k.mcap'}" in err and "robot c: port " in err
