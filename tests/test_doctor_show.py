"""`choreo doctor SHOW`: a show's preflight against the simulator, each failure injected on its
own (a dead port, a board that does not answer, a wrong layout, a missing or short song, an OSC
port in use, a full or unwritable log folder, a port that hangs), the all-clear, and the CLI's
table, JSON and exit codes."""

from __future__ import annotations

import re

import json
import os
import shlex
import shutil
import socket
import subprocess
import sys
import threading
import wave
from pathlib import Path
from typing import Any

import pytest

from choreo.board.doctor import NOTE, OK, PROBLEM, BoardWanted, board_checks
from choreo.board.probe import BoardInfo, Counter
from choreo.clock import VirtualTime
from choreo.run.preflight import Machine, OscAsk, preflight, run_log_estimate
from choreo.run.settings import RunRequest, RunSettings
from choreo.wire.layouts import HTH4_22, SEED
from runlog import REPO, LiveRun, read_log, vmain, write_show

SHOW = """
    version: 1
    name: Doctor
    robot: {layout: LAYOUT}
    motions:
      bow: {number: 1, duration: 1.0}
    steps:
      - play: bow
        label: start
      - wait: done
      - play: bow
        at: 3
        label: late
      - wait: done
"""


def show(tmp_path: Path, layout: str = "seed", music: str | None = None) -> str:
    body = SHOW.replace("LAYOUT", layout)
    if music is not None:
        body = body.replace("    robot:", f"    music: {{file: {music}}}\n    robot:")
    return str(write_show(tmp_path, body))


def song(path: Path, seconds: float) -> Path:
    with wave.open(str(path), "wb") as out:
        out.setnchannels(1)
        out.setsampwidth(2)
        out.setframerate(8000)
        out.writeframes(b"\0\0" * round(8000 * seconds))
    return path


def checks(tmp_path: Path, request: RunRequest, osc: OscAsk | None = None, **machine: Any) -> dict:
    """The findings by check name (and `exit`), on virtual time and a silent output unless told."""
    machine.setdefault("time_source", VirtualTime())
    machine.setdefault("audio", lambda asked: "Null")
    report = preflight(request, osc or OscAsk(), Machine(**machine))
    return {f.name: f for f in report.findings} | {"exit": report.exit_code}


def request(tmp_path: Path, path: str, **given: Any) -> RunRequest:
    given.setdefault("log_path", str(tmp_path / "show.mcap"))
    return RunRequest(path, **given)


def free_port() -> int:
    """A port nothing listens on just now (UDP and TCP)."""
    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as probe:
        probe.bind(("127.0.0.1", 0))
        return probe.getsockname()[1]


def test_all_clear_on_the_simulator(tmp_path):
    song(tmp_path / "song.wav", 6.0)
    found = checks(tmp_path, request(tmp_path, show(tmp_path, music="song.wav")), OscAsk(str(free_port())))
    assert found["exit"] == 0
    for name in ("show", "port", "board", "layout", "idle", "line", "music", "osc", "log", "log space"):
        assert found[name].level == OK, found[name]
    assert found["audio"].level == NOTE  # the null output: silent
    assert "ends at 6.000 s" in found["music"].text and "cue 1 'late' at 3.000 s" in found["music"].text
    assert "the log will take about" in found["log space"].text and "free on" in found["log space"].text
    assert not (tmp_path / "show.mcap").exists()  # the folder was tried with a file of its own, removed
    assert not [p for p in tmp_path.iterdir() if p.name.startswith(".choreo-doctor")]


def test_a_port_that_does_not_exist_is_a_problem_and_not_opened(tmp_path):
    found = checks(tmp_path, request(tmp_path, show(tmp_path), port=str(tmp_path / "ttyUSB9")))
    assert found["exit"] == 1
    assert found["device"].level == PROBLEM and "does not exist" in found["device"].text
    assert "port" not in found and "board" not in found


def test_a_board_that_does_not_answer_is_a_problem(tmp_path):
    found = checks(tmp_path, request(tmp_path, show(tmp_path), port="sim://?drop=1"))
    assert found["exit"] == 1 and found["port"].level == OK
    assert found["board"].level == PROBLEM and "no answer to the ACK check" in found["board"].text
    assert found["board"].fix.startswith("choreo probe --port 'sim://?drop=1' says more")  # a command to paste


def test_a_wrong_layout_is_a_problem(tmp_path):
    found = checks(tmp_path, request(tmp_path, show(tmp_path, "hth4-2.2"), port="sim://?layout=seed"))
    assert found["exit"] == 1
    assert found["layout"].level == PROBLEM and "the show uses hth4-2.2" in found["layout"].text
    assert found["board"].level == OK and found["idle"].level == OK
    # the same board with a seed show: all clear
    assert checks(tmp_path, request(tmp_path, show(tmp_path), port="sim://?layout=seed"))["layout"].level == OK


def test_a_board_at_another_baud_and_a_board_mid_motion(tmp_path):
    found = checks(tmp_path, request(tmp_path, show(tmp_path), port="sim://?baud=625000"))
    assert found["board"].level == PROBLEM and "the show runs at 115200" in found["board"].text
    assert found["board"].fix.startswith("--baud 625000")
    running = BoardInfo("sim://", 115200, "v", None, Counter(bytes.fromhex("b80b00" "4b0400" "0100000000")))
    assert running.counter is not None and running.counter.in_call
    idle = {f.check: f for f in board_checks(running, BoardWanted("sim://", 115200, HTH4_22))}["idle"]
    assert idle.level == PROBLEM and "a motion is running" in idle.text and idle.fix
    seed_main = BoardInfo("x", 115200, "v", None, Counter(SEED.main_loop.to_bytes(3, "little") + bytes(7)))
    layout = {f.check: f for f in board_checks(seed_main, BoardWanted("x", 115200, SEED))}["layout"]
    assert layout.level == OK
    hth4_main = BoardInfo("x", 115200, "v", None, Counter(HTH4_22.main_loop.to_bytes(3, "little") + bytes(7)))
    layout = {f.check: f for f in board_checks(hth4_main, BoardWanted("x", 115200, SEED, assumed=True))}["layout"]
    assert layout.level == NOTE and "assumed" in layout.text  # HTH4 2.0/2.1 boards are seed: a note


def test_a_missing_music_file_is_a_problem(tmp_path):
    found = checks(tmp_path, request(tmp_path, show(tmp_path, music="gone.wav")))
    assert found["exit"] == 1 and found["music"].level == PROBLEM and "gone.wav" in found["music"].text
    assert "audio" not in found


def test_a_song_shorter_than_the_last_cue_is_a_problem_and_one_ending_before_the_show_a_note(tmp_path):
    song(tmp_path / "short.wav", 2.0)
    found = checks(tmp_path, request(tmp_path, show(tmp_path, music="short.wav")))
    assert found["exit"] == 1 and found["music"].level == PROBLEM
    assert "ends at 2.000 s" in found["music"].text and "before cue 1 'late' at 3.000 s" in found["music"].text
    song(tmp_path / "short.wav", 3.5)  # past the cue at 3 s, before the show's end at 4 s
    found = checks(tmp_path, request(tmp_path, show(tmp_path, music="short.wav")))
    assert found["exit"] == 0 and found["music"].level == NOTE and "in silence" in found["music"].text


def test_an_osc_port_in_use_and_an_allow_list_that_does_not_parse(tmp_path):
    path = show(tmp_path)
    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as taken:
        taken.bind(("127.0.0.1", 0))
        port = taken.getsockname()[1]
        found = checks(tmp_path, request(tmp_path, path), OscAsk(str(port)))
    assert found["exit"] == 1 and found["osc"].level == PROBLEM and str(port) in found["osc"].text
    assert "another --osc port" in found["osc"].fix
    found = checks(tmp_path, request(tmp_path, path), OscAsk("0", allow=("192.168.1.0/24", "not-an-address")))
    assert found["exit"] == 1 and found["osc-allow"].level == PROBLEM and "not-an-address" in found["osc-allow"].text
    found = checks(tmp_path, request(tmp_path, path), OscAsk(None, allow=("10.0.0.1",)))
    assert found["osc"].level == PROBLEM and "give --osc PORT" in found["osc"].fix


def test_a_full_log_folder_is_a_problem_with_the_figures(tmp_path):
    found = checks(tmp_path, request(tmp_path, show(tmp_path)), free_bytes=lambda folder: 1000)
    assert found["exit"] == 1 and found["log"].level == OK
    space = found["log space"]
    assert space.level == PROBLEM and "1.0 kB free" in space.text and "frames and replies" in space.text
    estimate = run_log_estimate(RunSettings.settle(RunRequest(show(tmp_path), port="sim://", no_log=True)))
    # room for the finished log is not enough: the recorder holds its chunk, what a stopping run
    # still reports and the summary beyond it as it writes (a run on that disk would stop)
    assert estimate.room > 3 * estimate.bytes
    short = checks(tmp_path, request(tmp_path, show(tmp_path)), free_bytes=lambda folder: 2 * estimate.bytes)
    assert short["exit"] == 1 and short["log space"].level == PROBLEM and "would stop" in short["log space"].text
    tight = checks(tmp_path, request(tmp_path, show(tmp_path)), free_bytes=lambda folder: estimate.room + 1)
    assert tight["exit"] == 0 and tight["log space"].level == NOTE


def test_an_unwritable_log_folder_is_a_problem(tmp_path):
    (tmp_path / "afile").write_text("")
    for log in (tmp_path / "afile" / "show.mcap", tmp_path / "nowhere" / "show.mcap"):
        found = checks(tmp_path, request(tmp_path, show(tmp_path), log_path=str(log)))
        assert found["exit"] == 1 and found["log"].level == PROBLEM and "log space" not in found
    (tmp_path / "taken.mcap").write_text("")
    found = checks(tmp_path, request(tmp_path, show(tmp_path), log_path=str(tmp_path / "taken.mcap")))
    assert found["log"].level == PROBLEM and "never overwrites" in found["log"].text
    # the default folder under a regular file: it could not be made
    found = checks(tmp_path, RunRequest(show(tmp_path), log_dir=str(tmp_path / "afile" / "runs")))
    assert found["log"].level == PROBLEM and "not a folder" in found["log"].text


def test_a_port_that_hangs_cannot_hang_the_preflight(tmp_path):
    release = threading.Event()

    def hangs(url: str, baud: int, timeout: float, time_source: object) -> None:
        release.wait(60)

    try:
        found = checks(tmp_path, request(tmp_path, show(tmp_path)), time_source=None, open_port=hangs, deadline_s=0.05)
    finally:
        release.set()
    assert found["exit"] == 1 and found["port"].level == PROBLEM and "no answer within 0.05 s" in found["port"].text


def test_a_show_that_does_not_load_is_one_problem_and_the_rest_is_still_checked(tmp_path):
    bad = write_show(tmp_path, "version: 1\nname: x\nsteps: [{play: nothing}]\n")
    found = checks(tmp_path, request(tmp_path, str(bad)))
    assert found["exit"] == 1 and found["show"].level == PROBLEM and "choreo validate" in found["show"].fix
    assert found["log"].level == OK and "not estimated" in found["log space"].text


def test_the_estimate_covers_the_log_a_run_writes(tmp_path):
    repo = Path(__file__).resolve().parent.parent
    for name in ("dance.yaml", "canon.yaml"):
        log = tmp_path / f"{name}.mcap"
        assert vmain(["run", str(repo / "shows" / name), "--log", str(log), "-q"]) == 0
        estimate = run_log_estimate(RunSettings.settle(RunRequest(str(repo / "shows" / name), no_log=True)))
        assert log.stat().st_size <= estimate.bytes <= 1.5 * log.stat().st_size, (name, estimate)
        assert len(read_log(log).topic("/choreo/clock")) <= estimate.clock_samples


# --------------------------------------------------------------------------- the CLI


def test_the_cli_table_json_and_exit_codes(tmp_path, capsys, monkeypatch):
    monkeypatch.chdir(tmp_path)
    path = show(tmp_path)
    assert vmain(["doctor", path, "--port", "sim://"]) == 0
    lines = capsys.readouterr().out.splitlines()
    assert lines[0].split() == ["check", "verdict", "detail", "->", "fix"]
    width = lines[0].index("verdict")
    rows = {line[:width].strip(): line[width:].split()[0] for line in lines[1:]}
    assert rows == {"show": "ok", "port": "ok", "board": "ok", "layout": "ok", "idle": "ok", "line": "ok", "log": "ok",
                    "log space": "ok", "simulator": "note"}  # all clear, on a simulator: said, exit 0
    assert not (tmp_path / "runs").exists()  # the default folder is not made by the check
    assert vmain(["doctor", path, "--port", "sim://?drop=1", "--json"]) == 1
    record = json.loads(capsys.readouterr().out)
    assert record["ok"] is False and record["exit"] == 1 and record["show"] == path
    assert isinstance(record["log_estimate_bytes"], int)
    board = next(f for f in record["findings"] if f["check"] == "board")
    assert set(board) == {"level", "check", "robot", "text", "fix"} and board["level"] == "problem" and board["fix"]


def test_the_cli_escapes_names_from_outside_and_keeps_plain_doctor(tmp_path, capsys):
    path = show(tmp_path)
    assert vmain(["doctor", path, "--port", str(tmp_path / "tty\x1b[31mUSB\n0"), "--no-log"]) == 1
    out = capsys.readouterr().out
    assert "\x1b" not in out and all(line for line in out.splitlines())
    assert "\\x1b[31mUSB\\x0a0 does not exist" in out
    # without SHOW, doctor is the machine's check as before; a show's options need a show
    assert vmain(["doctor", "--port", "sim://"]) == 0
    assert "ok      board: a board answers on sim://" in capsys.readouterr().out
    assert vmain(["doctor", "--osc", "53200"]) == 2
    assert "--osc: it says what a show needs" in capsys.readouterr().err


@pytest.mark.parametrize("ensemble_port", ["lead=sim://?layout=seed"])
def test_a_show_of_several_robots_names_each_robots_checks(capsys, ensemble_port, tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    canon = str(Path(__file__).resolve().parent.parent / "shows" / "canon.yaml")
    assert vmain(["doctor", canon, "--port", ensemble_port, "--no-log"]) == 1
    out = capsys.readouterr().out
    assert re.search(r"layout lead +PROBLEM +the show uses hth4-2.2", out) and re.search(r"layout follow +ok", out)


def test_an_audio_device_for_a_show_without_music_is_its_own_problem(tmp_path):
    found = checks(tmp_path, request(tmp_path, show(tmp_path), audio_device="null"))
    assert found["exit"] == 1 and found["audio"].level == PROBLEM and "has no `music:`" in found["audio"].text
    assert found["show"].level == OK and found["board"].level == OK  # the rest is still checked


def test_a_port_that_will_not_open_on_the_machines_time(tmp_path, capsys, monkeypatch):
    """Real time: each port is checked on a thread of its own; a file that is no serial device
    (it exists, this user may open it) does not open as a port."""
    from choreo.cli import main

    monkeypatch.chdir(tmp_path)
    not_a_port = tmp_path / "ttyFAKE0"
    not_a_port.write_text("")
    assert main(["doctor", show(tmp_path), "--port", str(not_a_port), "--no-log", "--json"]) == 1
    found = {f["check"]: f for f in json.loads(capsys.readouterr().out)["findings"]}
    assert found["permission"]["level"] == "ok" and found["port"]["level"] == "problem"
    assert "cannot open" in found["port"]["text"] and "board" not in found


@pytest.mark.skipif(not sys.platform.startswith("linux") or os.geteuid() != 0 or shutil.which("unshare") is None,
                    reason="a tmpfs in a mount namespace of its own needs root on Linux")
def test_a_really_full_log_folder_in_a_tiny_tmpfs(tmp_path):
    """The free space as the machine measures it: a 200 KiB tmpfs, mounted in a mount namespace
    of this test's own (the machine's mounts are left alone), holds the finished log of the
    show three times over but not what the recorder holds as it writes: doctor says so, and the
    run on that disk indeed does not go."""
    folder = tmp_path / "tiny"
    folder.mkdir()
    common = [show(tmp_path), "--port", "sim://", "--log", str(folder / "show.mcap")]
    doctor = shlex.join([sys.executable, "-m", "choreo", "doctor", *common, "--json"])
    run = shlex.join([sys.executable, "-m", "choreo", "run", *common, "-q"])
    mount = f"mount -t tmpfs -o size=200k tmpfs {shlex.quote(str(folder))} && {doctor}; {run}; echo \"run $?\""
    done = subprocess.run(["unshare", "-m", "sh", "-c", mount], capture_output=True, text=True, timeout=60,
                          cwd=REPO)
    if not done.stdout.startswith("{"):
        pytest.skip(f"no mount namespace here: {done.stderr.strip()[:200]}")
    record = json.loads(done.stdout[:done.stdout.rindex("}") + 1])
    space = next(f for f in record["findings"] if f["check"] == "log space")
    assert record["exit"] == 1 and space["level"] == "problem" and "kB free" in space["text"], space
    assert 3 * record["log_estimate_bytes"] < 200 * 1024 < record["log_room_bytes"]
    assert done.stdout.rstrip().endswith("run 2") and "cannot write the start of the run" in done.stderr


def test_nothing_but_the_read_only_probe_reaches_the_boards(tmp_path, monkeypatch):
    """Every frame each simulated board heard (its journal) is an ACK check, the version query or
    a RAM read: no write, no CALL; with two robots, one at another baud, one dead."""
    from choreo.sim import protocol_sim
    from choreo.sim.faults import frame_kind
    from choreo.wire import protocol

    opened: list[protocol_sim.Serial] = []
    real_open = protocol_sim.Serial.open

    def kept(port: protocol_sim.Serial) -> None:
        real_open(port)
        opened.append(port)

    monkeypatch.setattr(protocol_sim.Serial, "open", kept)
    canon = str(REPO / "shows" / "canon.yaml")
    ports = {"lead": "sim://?baud=625000", "follow": "sim://?drop=1"}
    found = checks(tmp_path, RunRequest(canon, robot_ports=ports, no_log=True))
    assert found["board lead"].level == PROBLEM and found["board follow"].level == PROBLEM
    heard = [entry.data for port in opened if port.board is not None for entry in port.board.journal if entry.data]
    assert len(opened) >= 4 and heard
    version = protocol.version_frame().data
    assert all(frame_kind(data) in ("sync", "read") or data == version for data in heard), \
        sorted({data.hex(" ") for data in heard})
    assert any(frame_kind(data) == "read" for data in heard)  # the lead's board answered its reads


def test_a_held_show_logs_no_more_than_its_estimate(tmp_path):
    """Real time: a GO cue held a while adds no clock samples (they are taken on show time), so
    the log of a held show is still within the estimate, a sample forced at each GO included."""
    body = """
    version: 1
    name: Held
    motions:
      bow: {number: 1, duration: 0.3}
    steps:
      - play: bow
        label: start
      - wait: done
      - play: bow
        at: go
        label: applause
      - wait: done
      - play: bow
        at: go
        label: encore
      - wait: done
"""
    run = LiveRun(tmp_path, body, lockout_s=0.0, port="sim://")
    run.until_waiting("applause")
    threading.Event().wait(1.0)  # held: show time stands
    assert run.go().ok
    run.until_waiting("encore")
    assert run.go().ok
    run.finish()
    assert run.error is None
    estimate = run_log_estimate(run.session.settings)
    assert run.log_path.stat().st_size <= estimate.bytes
    assert len(run.log().topic("/choreo/clock")) <= estimate.clock_samples


def test_each_osc_problem_has_the_fix_for_its_cause(tmp_path):
    path = show(tmp_path)
    found = checks(tmp_path, request(tmp_path, path), OscAsk("65536"))
    assert found["osc"].level == PROBLEM and "stop what holds it" not in found["osc"].fix
    assert "--osc with a number" in found["osc"].fix
    found = checks(tmp_path, request(tmp_path, path), OscAsk(str(free_port()), host="no.such.host.invalid"))
    assert found["osc"].level == PROBLEM and found["osc"].fix.startswith("--osc-host")
    found = checks(tmp_path, request(tmp_path, path), OscAsk(str(free_port()), notify=("garbage",)))
    assert found["osc-notify"].level == PROBLEM and "HOST:PORT" in found["osc-notify"].fix
    with socket.socket(socket.AF_INET, socket.SOCK_STREAM) as taken:  # TCP only: the run binds both
        taken.bind(("127.0.0.1", 0))
        taken.listen()
        found = checks(tmp_path, request(tmp_path, path), OscAsk(str(taken.getsockname()[1])))
    assert found["osc"].level == PROBLEM and "(tcp)" in found["osc"].text and "another --osc port" in found["osc"].fix
    # --osc 0 takes any free port: QLab cannot be told it, a note (the run still goes)
    found = checks(tmp_path, request(tmp_path, path), OscAsk("0"))
    assert found["exit"] == 0 and found["osc"].level == NOTE and "--osc 53200" in found["osc"].fix


def test_log_names_the_run_could_not_create(tmp_path, monkeypatch):
    path = show(tmp_path)
    (tmp_path / "dangling.mcap").symlink_to(tmp_path / "nowhere" / "x.mcap")
    for name, said in (("dangling.mcap", "exists already"), ("a" * 300 + ".mcap", "too long")):
        found = checks(tmp_path, request(tmp_path, path, log_path=str(tmp_path / name)))
        assert found["exit"] == 1 and found["log"].level == PROBLEM and said in found["log"].text, found["log"]
    monkeypatch.chdir(tmp_path)  # `--log ''` is the run's default name in runs/, which the run makes
    found = checks(tmp_path, RunRequest(path, log_path=""))
    assert found["log"].level == OK and "will be made" in found["log"].text


def test_a_slow_latency_timer_is_a_note_for_a_show_and_a_hung_sound_system_cannot_hang_it(tmp_path):
    device = tmp_path / "ttyUSB7"
    device.write_text("")
    timer = tmp_path / "sys" / "bus" / "usb-serial" / "devices" / "ttyUSB7" / "latency_timer"
    timer.parent.mkdir(parents=True)
    timer.write_text("16\n")
    found = checks(tmp_path, request(tmp_path, show(tmp_path), port=str(device)), sysfs=tmp_path / "sys",
                   talk=False)
    latency = found["latency"]
    assert latency.level == NOTE and "16 ms" in latency.text and "asks the driver" in latency.text
    assert latency.fix and "latency_timer" in latency.fix and found["exit"] == 0
    song(tmp_path / "song.wav", 6.0)
    release = threading.Event()
    try:
        found = checks(tmp_path, request(tmp_path, show(tmp_path, music="song.wav"), audio_device="7"),
                       time_source=None, talk=False, audio=lambda asked: str(release.wait(60)), deadline_s=0.05)
    finally:
        release.set()
    assert found["audio"].level == PROBLEM and "no answer within 0.05 s" in found["audio"].text


def test_the_table_wraps_at_the_terminals_width_and_names_ports_as_given(tmp_path, capsys, monkeypatch):
    monkeypatch.chdir(tmp_path)
    monkeypatch.setenv("COLUMNS", "80")
    canon = str(REPO / "shows" / "canon.yaml")
    assert vmain(["doctor", canon, "--port", "lead=sim://?drop=1&junk=1", "--port", "follow=sim://"]) == 1
    lines = capsys.readouterr().out.splitlines()
    assert all(len(line) <= 80 for line in lines), lines
    indent = lines[0].index("detail")
    board = next(i for i, line in enumerate(lines) if line.startswith("board lead "))
    rest = []
    for line in lines[board + 1:]:
        if not line[:indent].isspace():
            break
        rest.append(line[indent:])
    text = " ".join([lines[board][indent:], *rest])
    assert "port sim://?drop=1&junk=1: no answer" in text and "durations" not in text  # as the user named it
    assert "fix: choreo probe --port 'sim://?drop=1&junk=1' says more" in text


@pytest.mark.parametrize("kind", ["flac", "mp3"])
def test_a_song_cut_short_is_decoded_not_taken_at_its_headers_word(tmp_path, kind):
    """A file cut short keeps the header of the whole (8 s here): the doctor decodes the song as
    far as the show needs it, and the cue at 3 s would play in silence."""
    whole = (REPO / "tests" / "data" / "songs" / f"drums.{kind}").read_bytes()
    (tmp_path / f"cut.{kind}").write_bytes(whole[:12000])
    found = checks(tmp_path, request(tmp_path, show(tmp_path, music=f"cut.{kind}")))
    music = found["music"]
    assert found["exit"] == 1 and music.level == PROBLEM, music
    assert "decodes only to" in music.text and "of its 8.000 s" in music.text and "cue 1 'late'" in music.text
    assert music.fix.startswith("the whole file again")
    (tmp_path / f"cut.{kind}").write_bytes(whole)  # the whole file: all clear
    assert checks(tmp_path, request(tmp_path, show(tmp_path, music=f"cut.{kind}")))["music"].level == OK


def test_json_keeps_its_keys_when_the_show_does_not_load(tmp_path, capsys, monkeypatch):
    monkeypatch.chdir(tmp_path)
    keys = {"ok", "exit", "show", "log_estimate_bytes", "log_room_bytes", "findings"}
    assert vmain(["doctor", show(tmp_path), "--port", "sim://", "--json"]) == 0
    loaded = json.loads(capsys.readouterr().out)
    assert set(loaded) == keys and loaded["log_room_bytes"] > loaded["log_estimate_bytes"] > 0
    assert vmain(["doctor", str(tmp_path / "gone.yaml"), "--json"]) == 1
    gone = json.loads(capsys.readouterr().out)
    assert set(gone) == keys and gone["log_estimate_bytes"] is None and gone["log_room_bytes"] is None
    first = gone["findings"][0]
    assert first["check"] == "show" and first["level"] == "problem"
    assert first["fix"] == "the path of the show's YAML file"
    assert [f["check"] for f in gone["findings"]] == ["show", "log", "log space"]  # the rest still checked


def test_a_line_that_loses_frames_is_a_problem_and_one_that_loses_a_few_a_note(tmp_path):
    """The probe's few questions may all be answered on a line that loses a frame in two: twenty
    ACK checks, none retried, tell (on the simulator's faults: the run on such a line stops)."""
    path = show(tmp_path)
    lossy = checks(tmp_path, request(tmp_path, path, port="sim://?drop=0.5&seed=0"))
    assert lossy["board"].level == OK and lossy["line"].level == PROBLEM and lossy["exit"] == 1
    assert "3 of " in lossy["line"].text and "then stops" in lossy["line"].text
    assert "choreo probe --port 'sim://?drop=0.5&seed=0'" in lossy["line"].fix
    once = checks(tmp_path, request(tmp_path, path, port="sim://?junk=20"))
    assert once["line"].level == NOTE and "1 of 20" in once["line"].text and once["exit"] == 0
