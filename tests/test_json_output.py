"""Machine-readable output (issue 11, item 3): `--json` on validate, plan, log summary and run,
`log export --jsonl`, so that scripts never parse the human text on stderr."""

from __future__ import annotations

import json
from pathlib import Path

import pytest

from choreo.cli import main
from runlog import vmain
from choreo.errors import ChoreoError

FAST = "sim://?motion_s=0.05"


def json_of(capsys, *argv: str, code: int = 0):
    assert main(list(argv)) == code
    out = capsys.readouterr().out
    return json.loads(out)


def test_validate_json_lists_every_file_with_its_figures_or_problems(capsys, tmp_path):
    bad = tmp_path / "bad.yaml"
    bad.write_text("version: 1\nsteps:\n  - play: 400\n")
    record = json_of(capsys, "validate", "shows/minimal.yaml", str(bad), "--json", code=2)
    good, broken = record["files"]
    assert record["ok"] is False
    assert good == {"path": "shows/minimal.yaml", "ok": True, "name": "minimal", "layout": "seed",
                    "steps": 2, "motions": [1], "estimated_s": 1.0, "cues": []}
    assert broken["ok"] is False and broken["path"] == str(bad)
    problem = broken["problems"][0]
    assert problem["line"] == 3 and problem["path"].startswith("steps[0]") and "400" in problem["message"]


def test_validate_json_of_good_shows_is_ok_and_exit_0(capsys):
    record = json_of(capsys, "validate", "shows/dance.yaml", "shows/music.yaml", "--json")
    assert record["ok"] is True and [f["ok"] for f in record["files"]] == [True, True]


def test_plan_json_has_every_step_with_its_frames(capsys):
    record = json_of(capsys, "plan", "shows/minimal.yaml", "--json")
    play, wait = record["plan"]
    assert play["kind"] == "play" and play["motion"] == 1 and play["start_s"] == 0.0
    assert play["frames"][1] == "07 0c b8 13 00 00 de"  # the CALL of slot 1 at 0x0bb8 + 0x800
    assert wait["kind"] == "wait_done" and wait["seconds"] == 60.0
    assert record["estimated_s"] == 1.0 and record["steps"] == 2


def test_plan_json_of_a_bad_show_is_a_json_failure_object(capsys, tmp_path):
    bad = tmp_path / "bad.yaml"
    bad.write_text("name: x\nsteps: [{play: nosuchmotion}]\n")
    record = json_of(capsys, "plan", str(bad), "--json", code=2)
    assert record["ok"] is False and record["exit"] == 2 and "nosuchmotion" in record["error"]
    assert record["problems"] and all(p["file"] == str(bad) for p in record["problems"])


@pytest.mark.parametrize("argv, code", [
    (["plan", "/nonexistent.yaml", "--json"], 2),
    (["validate", "/nonexistent.yaml", "--json"], 2),
    (["run", "/nonexistent.yaml", "--json"], 2),
    (["run", "shows/minimal.yaml", "--port", "sim://?nosuch=1", "--json", "-q"], 2),
    (["run", "shows/minimal.yaml", "--port", "/nonexistent-tty", "--json", "-q", "--no-log"], 3),
])
def test_every_json_command_prints_one_json_object_on_failure(capsys, argv, code):
    """A script that asked for JSON reads stdout only: a failure is a JSON object there too,
    with the exit status; stderr says what it says without --json."""
    assert main(argv) == code
    captured = capsys.readouterr()
    record = json.loads(captured.out)
    assert record["ok"] is False and record["exit"] == code
    assert captured.err.strip()


def test_the_failure_object_is_the_same_shape_everywhere(capsys):
    assert main(["plan", "/nonexistent.yaml", "--json"]) == 2
    plan = json.loads(capsys.readouterr().out)
    assert main(["run", "/nonexistent.yaml", "--json"]) == 2
    run = json.loads(capsys.readouterr().out)
    assert {key: plan[key] for key in ("ok", "exit", "error")} == {key: run[key] for key in ("ok", "exit", "error")}


@pytest.fixture(scope="module")
def a_log(tmp_path_factory) -> Path:
    log = tmp_path_factory.mktemp("runs") / "run.mcap"
    assert vmain(["run", "shows/minimal.yaml", "--port", FAST, "--log", str(log), "-q"]) == 0
    return log


def test_run_json_prints_the_result_and_the_log_path(capsys, tmp_path):
    log = tmp_path / "r.mcap"
    record = json_of(capsys, "run", "shows/minimal.yaml", "--port", FAST, "--log", str(log), "--json", "-q")
    assert record["outcome"] == "done" and record["exit"] == 0 and record["log"] == str(log)
    assert record["steps_run"] == 2 and record["show_s"] > 0
    # How many steps were late depends on the machine's load; what JSON must say is the run's own
    # count, the one its log's result records.
    assert json_of(capsys, "log", "summary", str(log), "--json")["result"]["late_steps"] == str(record["late_steps"])
    assert record["layout"] == "seed" and record["port"] == FAST and "error" not in record
    assert log.exists()


def test_run_json_when_the_port_fails_still_names_the_log(capsys, tmp_path):
    log = tmp_path / "r.mcap"
    record = json_of(capsys, "run", "shows/minimal.yaml", "--port", str(tmp_path / "no-such-tty"),
                     "--log", str(log), "--json", code=3)
    assert record["outcome"] == "failed" and record["exit"] == 3 and record["log"] == str(log)
    assert "cannot open" in record["error"] and log.exists()


def test_run_json_of_a_bad_show_has_no_log(capsys):
    record = json_of(capsys, "run", "/nonexistent.yaml", "--json", code=2)
    assert record == {"show": "/nonexistent.yaml", "ok": False, "exit": 2, "log": None, "outcome": "failed",
                      "error": "/nonexistent.yaml: cannot read the show file: No such file or directory"}


def test_log_summary_json_is_one_object_a_log(capsys, a_log):
    assert main(["log", "summary", str(a_log), str(a_log), "--json"]) == 0
    lines = capsys.readouterr().out.splitlines()
    assert len(lines) == 2
    first = json.loads(lines[0])
    assert first["log"] == str(a_log) and first["state"] == "complete"
    assert first["result"]["outcome"] == "done" and first["steps"]["run"] == 2
    assert first["frames"]["play"] == 1 and first["replies"]["ack"] == 3
    assert first["motions"][0]["motion"] == 1 and first["latency"]["count"] == 5


def test_export_jsonl_is_one_object_a_row_like_the_json_array(capsys, a_log, tmp_path):
    lines_file, array_file = tmp_path / "rows.jsonl", tmp_path / "rows.json"
    assert main(["log", "export", str(a_log), "--jsonl", str(lines_file), "--json", str(array_file)]) == 0
    rows = [json.loads(line) for line in lines_file.read_text().splitlines()]
    assert rows == json.loads(array_file.read_text())
    assert [row["frame"] for row in rows] == ["stop", "play", "restore", "status", "status"]
    assert all(row["reply"] for row in rows)


def test_export_jsonl_to_stdout(capsys, a_log):
    assert main(["log", "export", str(a_log), "--jsonl", "-"]) == 0
    lines = capsys.readouterr().out.splitlines()
    assert lines and all(isinstance(json.loads(line), dict) for line in lines)


def test_only_one_export_can_go_to_stdout(a_log):
    with pytest.raises(ChoreoError, match="only one of --csv, --json and --jsonl"):
        from choreo.cli import _command  # the error itself, before main prints it
        _command(["log", "export", str(a_log), "--jsonl", "-", "--csv", "-"], None)


def test_run_json_names_every_robots_port_and_no_first_one_for_the_show(capsys, tmp_path):
    show = tmp_path / "two.yaml"
    show.write_text("version: 1\nrobots:\n  a: {}\n  b: {}\nsteps:\n  - play: 1\n")
    code = vmain(["run", str(show), "--json", "-q", "--no-log", "--port", "a=sim://?motion_s=0.05",
                  "--port", "b=sim://?motion_s=0.07"])
    record = json.loads(capsys.readouterr().out)
    assert code == 0 and set(record["robots"]) == {"a", "b"}
    assert record["robots"]["a"]["port"].startswith("sim://?motion_s=0.05")
    assert record["robots"]["b"]["port"].startswith("sim://?motion_s=0.07")
    assert "port" not in record and "baud" not in record  # the first robot's would pass for the show's


def test_run_json_of_one_robot_has_its_port_both_ways(capsys):
    record = json_of(capsys, "run", "shows/minimal.yaml", "--port", FAST, "--no-log", "--json", "-q")
    assert record["port"] == FAST and list(record["robots"].values()) == [
        {"port": FAST, "baud": 115200, "layout": "seed"}]


def test_probe_json_is_the_readings(capsys):
    assert vmain(["probe", "--port", "sim://?baud=625000", "--json"]) == 0
    record = json.loads(capsys.readouterr().out)
    assert record["ok"] is True and record["port"] == "sim://?baud=625000" and record["baud"] == 625000
    assert record["version"] == "RCB-4 simulator (choreo)"
    config = record["config"]
    assert config["word"] == 2 and config["rom_run"] is True and config["com_baud"] == 115200
    assert len(record["counter"]["hex"].split()) == 10 and record["hints"]


@pytest.mark.parametrize("argv, code", [
    (["probe", "--port", "sim://?drop=1", "--timeout", "0.02", "--json"], 3),
    (["probe", "--port", " ", "--json"], 2),
    (["doctor", "--port", "sim://?drop=1", "--json", "--audio-device", "nosuch"], 1),
])
def test_probe_and_doctor_json_on_failure(capsys, argv, code):
    assert vmain(argv) == code
    record = json.loads(capsys.readouterr().out)
    assert record["ok"] is False and record["exit"] == code


def test_doctor_json_lists_each_finding(capsys):
    assert vmain(["doctor", "--port", "sim://", "--json"]) in (0, 1)
    record = json.loads(capsys.readouterr().out)
    board = next(f for f in record["findings"] if f["check"] == "board")
    assert board == {"level": "ok", "check": "board", "fix": None,
                     "text": "a board answers on sim:// at 115200 baud, version 'RCB-4 simulator (choreo)'"}
    assert record["ok"] is (record["exit"] == 0)
    assert all(f["level"] in ("ok", "problem", "note") for f in record["findings"])


def test_ports_json_marks_kondo_adapters(capsys, monkeypatch):
    from types import SimpleNamespace

    from serial.tools import list_ports

    found = [SimpleNamespace(device="/dev/ttyUSB0", description="Kondo", vid=0x165C, pid=0x0008),
             SimpleNamespace(device="/dev/ttyS0", description=None, vid=None, pid=None)]
    monkeypatch.setattr(list_ports, "comports", lambda: found)
    record = json_of(capsys, "ports", "--json")
    assert record["ports"] == [
        {"device": "/dev/ttyS0", "description": "", "vid": None, "pid": None, "kondo": False},
        {"device": "/dev/ttyUSB0", "description": "Kondo", "vid": 0x165C, "pid": 0x0008, "kondo": True}]


@pytest.mark.parametrize("argv", [
    ["plan", "--json"],
    ["doctor", "--json", "--bogus"],
    ["probe", "--json", "--timeout", "abc"],
    ["run", "shows/minimal.yaml", "--json", "--baud", "x"],
    ["validate", "--json"],
    ["ports", "--json", "extra"],
])
def test_bad_arguments_of_a_json_command_are_a_json_failure_too(capsys, argv):
    with pytest.raises(SystemExit) as ended:
        main(argv)
    assert ended.value.code == 2
    captured = capsys.readouterr()
    record = json.loads(captured.out)
    assert record == {"ok": False, "exit": 2, "error": record["error"]}
    assert record["error"].startswith(f"choreo {argv[0]}: ")
    assert "usage:" in captured.err


def test_bad_arguments_without_json_print_nothing_on_stdout(capsys):
    with pytest.raises(SystemExit):
        main(["log", "export", "x.mcap", "--json"])  # --json FILE: not a request for JSON output
    assert capsys.readouterr().out == ""


def test_an_interrupted_json_command_says_so_in_json(capsys, monkeypatch):
    import choreo.board.probe

    def interrupted(*args, **kwargs):
        raise KeyboardInterrupt

    monkeypatch.setattr(choreo.board.probe, "probe", interrupted)
    assert main(["probe", "--port", "sim://", "--json"]) == 130
    assert json.loads(capsys.readouterr().out) == {"ok": False, "exit": 130, "error": "interrupted"}
