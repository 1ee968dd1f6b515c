"""`choreo log ...` and `choreo replay` on real logs made by `choreo run`.

Four runs of short shows, started together once for the module: a complete one (with a cue the
show overruns, so one play starts late), one through a faulty simulated line (NAKs, dropped and
junk-prefixed replies, retried), one that fails (the port is lost mid-show: exit 3), and one
SIGKILLed mid-show (no footer; the file may end inside a chunk). Counts the review prints are
checked against the log as the mcap library reads it.
"""

from __future__ import annotations

import csv
import io
import json
import os
import signal
import subprocess
import sys
import time
from collections import Counter
from dataclasses import dataclass
from pathlib import Path

import pytest
from mcap.reader import NonSeekingReader

from runlog import vmain
from choreo.log.reader import LogReader

REPO = Path(__file__).resolve().parent.parent

SHOW = """\
version: 1
name: review
motions:
  wave: {number: 3, duration: 0.33}   # not a multiple of the 50 ms poll: no poll falls on an end
  bow: {number: 5, duration: 0.22}
steps:
  - play: wave
    label: start
  - wait: done
  - play: bow
    at: 0.2            # the wave is still running: this cue starts late
    label: late-bow
  - wait: done
  - play: wave
    at: 0.8
  - wait: done
"""

LONG_SHOW = """\
version: 1
name: long
motions:
  wave: {number: 3, duration: 0.2}
steps:
  - repeat: 200
    steps:
      - play: wave
      - wait: done
"""

FAULTS = "sim://?nak=7&drop=11&junk=16"


@dataclass
class Logs:
    complete: Path
    faulty: Path
    failed: Path
    killed: Path
    failed_exit: int
    directory: Path


def _choreo(*args: str) -> list[str]:
    return [sys.executable, "-m", "choreo", *args]


@pytest.fixture(scope="module")
def logs(tmp_path_factory) -> Logs:
    """The four runs the review commands read: three on virtual time in-process (the same log,
    frame for frame and to the nanosecond, on any machine), and one real run killed mid-show."""
    tmp = tmp_path_factory.mktemp("review")
    show = tmp / "review.yaml"
    show.write_text(SHOW)
    long_show = tmp / "long.yaml"
    long_show.write_text(LONG_SHOW)
    paths = {name: tmp / f"{name}.mcap" for name in ("complete", "faulty", "failed", "killed")}
    killed = subprocess.Popen(_choreo("run", str(long_show), "--log", str(paths["killed"]), "-q"),
                              cwd=tmp, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    try:
        codes = {
            "complete": vmain(["run", str(show), "--log", str(paths["complete"]), "-q"]),
            "faulty": vmain(["run", str(show), "--log", str(paths["faulty"]), "-q", "--port", FAULTS,
                             "--timeout", "0.05", "--retries", "4"]),
            "failed": vmain(["run", str(show), "--log", str(paths["failed"]), "-q", "--port", "sim://?lose=8"]),
        }
        _kill_when_logged(killed, paths["killed"])
    finally:
        killed.kill()
    codes["killed"] = killed.wait(timeout=30)
    assert codes["complete"] == 0 and codes["faulty"] == 0, codes
    assert codes["killed"] == -signal.SIGKILL
    return Logs(paths["complete"], paths["faulty"], paths["failed"], paths["killed"], codes["failed"], tmp)


def _kill_when_logged(proc: subprocess.Popen, path: Path, frames: int = 20) -> None:
    """SIGKILL the run once its log holds some frames (the recorder flushes every 0.5 s)."""
    deadline = time.monotonic() + 20
    while time.monotonic() < deadline:
        if path.exists() and path.stat().st_size > 2000:
            with LogReader(path) as reader:
                if sum(1 for t, _, _ in reader.messages() if t == "/rcb4/tx") >= frames:
                    break
        time.sleep(0.05)
    else:
        proc.kill()
        pytest.fail("the long run wrote no frames to its log in 20 s")
    os.kill(proc.pid, signal.SIGKILL)


def mcap_topics(path: Path) -> dict[str, list[dict]]:
    """The log's messages by topic, decoded, as the mcap library reads them (a cut log: until the cut)."""
    out: dict[str, list[dict]] = {}
    with open(path, "rb") as f:
        try:
            for _, channel, message in NonSeekingReader(f).iter_messages(log_time_order=False):
                out.setdefault(channel.topic, []).append(json.loads(message.data))
        except Exception:  # the mcap library stops with an error at the cut
            pass
    return out


def cli(capsys, *argv: str) -> tuple[int, str, str]:
    code = vmain(list(argv))
    captured = capsys.readouterr()
    return code, captured.out, captured.err


def field(out: str, name: str) -> str:
    return next(line for line in out.splitlines() if line.startswith(name))


# -- summary -----------------------------------------------------------------------------------


def test_summary_of_a_complete_run(logs, capsys):
    code, out, err = cli(capsys, "log", "summary", str(logs.complete))
    assert code == 0 and err == ""
    topics = mcap_topics(logs.complete)
    tx = Counter(m["kind"] for m in topics["/rcb4/tx"])
    assert "(complete)" in field(out, "log")
    assert "review" in field(out, "show") and "sha256" in field(out, "show")
    assert "sim://?durations=3:0.33,5:0.22 at 115200 baud" in field(out, "run")
    assert field(out, "outcome").startswith("outcome   done (exit 0)")
    # the overrun cue is late by construction; on a loaded machine another play may be too, so
    # the summary must agree with the run's own count rather than with a fixed 1
    with LogReader(logs.complete) as reader:
        list(reader.messages())
        run_late = int(reader.result["late_steps"])
    assert run_late >= 1 and f"6 run: 6 done, {run_late} late, 0 failed" in field(out, "steps")
    frames = f"{sum(tx.values())} sent (stop 3, play 3, restore 3, status {tx['status']}); 0 retries"
    assert frames in field(out, "frames")
    assert f"ACK 9, NAK 0, status {tx['status']}, timeout 0, invalid 0" in field(out, "replies")
    assert "median" in field(out, "latency") and f"({sum(tx.values())} replies)" in field(out, "latency")
    assert "(3 plays, 1 over 1 ms)" in field(out, "cues")
    plays = [line for line in out.splitlines() if " motion " in line and " step " in line]
    assert len(plays) == 3
    for line, expected in zip(plays, (0.33, 0.22, 0.33), strict=True):
        measured = float(line.rsplit(":", 1)[1].strip().split()[0])
        # To the status poll that saw it end: up to one 50 ms poll period, plus up to one 50 ms
        # status refresh of the board (the simulator's too), plus scheduling.
        assert expected - 0.01 <= measured <= expected + 0.17, line


def test_summary_of_a_run_with_faults(logs, capsys):
    code, out, _ = cli(capsys, "log", "summary", str(logs.faulty))
    assert code == 0
    topics = mcap_topics(logs.faulty)
    rx = Counter(m["kind"] for m in topics["/rcb4/rx"])
    retries = sum(1 for m in topics["/rcb4/tx"] if m["attempt"] > 1)
    assert rx["nak"] and rx["timeout"] and rx["invalid"] and retries
    replies = field(out, "replies")
    for kind in ("nak", "timeout", "invalid"):
        word = "NAK" if kind == "nak" else kind
        assert f"{word} {rx[kind]}" in replies
    assert f"; {retries} retries" in field(out, "frames")
    warnings = len([m for m in topics["/choreo/log"] if m["level"] == 3])
    assert f"{warnings} warnings" in field(out, "log lines")
    assert "(complete)" in field(out, "log")


def test_summary_of_a_failed_run(logs, capsys):
    assert logs.failed_exit == 3
    code, out, _ = cli(capsys, "log", "summary", str(logs.failed))
    assert code == 0
    assert "(complete)" in field(out, "log")
    assert field(out, "outcome").startswith("outcome   failed (exit 3)")
    assert "port sim://?lose=8" in out and "lost" in out
    assert "1 failed" in field(out, "steps")
    assert "error" in out


def test_summary_of_a_killed_run_says_where_it_stops(logs):
    done = subprocess.run(_choreo("log", "summary", str(logs.killed)), capture_output=True, text=True,
                          cwd=logs.directory)
    assert done.returncode == 0 and done.stderr == ""
    out = done.stdout
    assert "UNFINISHED" in field(out, "log") and "the run" in field(out, "log")
    assert "unknown (no result recorded)" in field(out, "outcome")
    topics = mcap_topics(logs.killed)
    frames = len(topics["/rcb4/tx"])
    assert frames >= 20
    sent = int(field(out, "frames").split()[1])
    assert sent >= frames  # the mcap library stops at the cut chunk; this reader keeps its whole messages


# -- frames ------------------------------------------------------------------------------------


def test_frames_one_line_each_in_words(logs, capsys):
    code, out, _ = cli(capsys, "log", "frames", str(logs.complete))
    assert code == 0
    topics = mcap_topics(logs.complete)
    lines = out.splitlines()[1:]
    tx = [line for line in lines if "  tx  " in line]
    rx = [line for line in lines if "  rx  " in line]
    assert len(tx) == len(topics["/rcb4/tx"]) and len(rx) == len(topics["/rcb4/rx"])
    assert any(line.endswith("CALL 0x0023b8: motion 3") and "07 0c b8 23 00 00 ee" in line for line in tx)
    assert any(line.endswith("status query") for line in tx)
    assert any(line.endswith("ACK") for line in rx)
    assert any(line.endswith("status 0x23: executing") for line in rx)
    assert any(line.endswith("status 0x21: not executing") for line in rx)
    times = [float(line.split()[0]) for line in lines]
    assert times == sorted(times) and 0 <= times[0] < 0.05


def test_frames_of_one_step_and_one_kind(logs, capsys):
    _, out, _ = cli(capsys, "log", "frames", str(logs.complete), "--step", "2")
    tx = [line for line in out.splitlines() if "  tx  " in line]
    assert [line.split()[5] for line in tx] == ["stop", "play", "restore"]
    assert all(" step 2 " in line for line in tx)
    _, out, _ = cli(capsys, "log", "frames", str(logs.faulty), "--kind", "nak")
    lines = out.splitlines()[1:]
    naks = len([m for m in mcap_topics(logs.faulty)["/rcb4/rx"] if m["kind"] == "nak"])
    assert len(lines) == 2 * naks and all(line.endswith("NAK") for line in lines[1::2])
    _, out, _ = cli(capsys, "log", "frames", str(logs.complete), "--kind", "timeout")
    assert out.splitlines()[-1] == "no frames with kind timeout in this log"


def test_frames_of_faults_and_of_a_killed_run(logs, capsys):
    _, out, _ = cli(capsys, "log", "frames", str(logs.faulty))
    assert "timeout: no complete reply" in out and "invalid: junk" in out and "(try 2)" in out
    code, out, _ = cli(capsys, "log", "frames", str(logs.killed))
    assert code == 0 and out.splitlines()[-1].startswith("log unfinished: the file ends")


# -- timeline ----------------------------------------------------------------------------------


def test_timeline_text_planned_against_actual(logs, capsys):
    code, out, _ = cli(capsys, "log", "timeline", str(logs.complete))
    assert code == 0
    rows = [line for line in out.splitlines() if "|" in line and line.split()[0] not in ("step", "cues")]
    assert [r.split()[0] for r in rows] == ["0", "2", "4"]
    assert "motion 3 wave" in rows[0] and "motion 5 bow" in rows[1]
    assert "0.000-0.330" in rows[0]  # planned from the attached show's durations
    assert "!" in rows[1] and ("#" in rows[1] or "=" in rows[1])  # the overrun cue, started late
    assert "cues: cue 1 'late-bow' at " in out
    late = out.split("late plays: ", 1)[1]
    assert int(late.split()[0]) >= 1 and "step 2 'late-bow' started" in late  # by construction
    assert "faults: none" in out


def test_timeline_marks_faults(logs, capsys):
    _, out, _ = cli(capsys, "log", "timeline", str(logs.faulty))
    rx = [m for m in mcap_topics(logs.faulty)["/rcb4/rx"] if m["kind"] not in ("ack", "status")]
    faults = out.split("faults: ", 1)[1].splitlines()
    assert int(faults[0]) == len(rx)
    assert any("NAK to" in line for line in faults) and any("TIMEOUT to" in line for line in faults)


def _picture(path: Path):
    from matplotlib import image

    pixels = image.imread(path)
    assert pixels.ndim == 3 and pixels.shape[0] > 100 and pixels.shape[1] > 300
    return pixels


@pytest.mark.parametrize("which", ["complete", "faulty", "killed"])
def test_timeline_png_is_a_picture_with_content(logs, capsys, tmp_path, which):
    pytest.importorskip("matplotlib")
    png = tmp_path / f"{which}.png"
    code, out, _ = cli(capsys, "log", "timeline", str(getattr(logs, which)), "--png", str(png))
    assert code == 0 and str(png) in out
    pixels = _picture(png)
    assert pixels.std() > 0.05
    colours = {tuple(p) for p in (pixels[:, :, :3] * 255).astype(int).reshape(-1, 3)[::7]}
    assert len(colours) > 20
    # the bars: a good share of the planned colour (#b8c4d6) and the actual colour (#2f6db5)
    rgb = (pixels[:, :, :3] * 255).round().astype(int)
    for colour in ((0xB8, 0xC4, 0xD6), (0x2F, 0x6D, 0xB5)):
        assert ((abs(rgb - colour).sum(axis=2)) < 6).sum() > 200, colour
    if which == "faulty":
        red = ((abs(rgb - (0xD6, 0x27, 0x28)).sum(axis=2)) < 30).sum()
        assert red > 50  # the fault marks


def test_timeline_png_without_matplotlib_says_how_to_get_it(logs, capsys, monkeypatch, tmp_path):
    monkeypatch.setitem(sys.modules, "matplotlib", None)
    code, out, err = cli(capsys, "log", "timeline", str(logs.complete), "--png", str(tmp_path / "x.png"))
    assert code == 2 and out == ""
    assert "pip install 'choreo[plot]'" in err and len(err.splitlines()) == 1
    assert not (tmp_path / "x.png").exists()


@pytest.mark.parametrize("command", ["timeline", "export"])
def test_an_output_that_cannot_be_written_is_one_line_exit_2(logs, capsys, tmp_path, command):
    """Same rule for --png and --csv/--json: a missing folder is refused, never created."""
    pytest.importorskip("matplotlib")
    option, flag = ("--png", "timeline --png") if command == "timeline" else ("--csv", "log export --csv")
    missing = tmp_path / "no" / "such" / "dir" / "out.x"
    for target, says in (
            (missing, f"cannot write: folder {missing.parent} does not exist (create it first)"),
            (Path("/proc/x.png"), "cannot write: No such file or directory"),
            (logs.complete / "x.png", f"cannot write: folder {logs.complete} is not a folder (a file)")):
        code, out, err = cli(capsys, "log", command, str(logs.complete), option, str(target))
        assert code == 2 and out == "", err
        assert err == f"{flag} {target}: {says}\n"
    assert not (tmp_path / "no").exists()


def test_an_output_that_fills_the_disk_is_one_line_and_leaves_the_device_alone(logs, capsys):
    if not Path("/dev/full").exists():
        pytest.skip("no /dev/full here")
    code, _, err = cli(capsys, "log", "export", str(logs.complete), "--csv", "/dev/full")
    assert code == 2 and err == "log export --csv /dev/full: cannot write: No space left on device\n"
    assert Path("/dev/full").exists()


def test_a_picture_not_finished_is_not_left_behind(tmp_path, capsys):
    """The log turns out not to be choreo's after the PNG was opened: no empty PNG remains."""
    pytest.importorskip("matplotlib")
    from mcap.writer import Writer

    path = tmp_path / "foreign.mcap"
    with open(path, "wb") as f:
        writer = Writer(f)
        writer.start()
        tx = writer.register_channel("/rcb4/tx", "json", writer.register_schema("choreo.Tx", "jsonschema", b"{}"))
        writer.add_message(tx, log_time=2, publish_time=2, data=b'{"kind": "play"}')
        writer.finish()
    code, _, err = cli(capsys, "log", "timeline", str(path), "--png", str(tmp_path / "t.png"))
    assert code == 2 and "is not a choreo /rcb4/tx message" in err
    assert not (tmp_path / "t.png").exists()


# -- export ------------------------------------------------------------------------------------


def test_export_csv_and_json_one_row_a_frame(logs, capsys, tmp_path):
    csv_path, json_path = tmp_path / "f.csv", tmp_path / "f.json"
    code, _, err = cli(capsys, "log", "export", str(logs.faulty), "--csv", str(csv_path), "--json", str(json_path))
    assert code == 0 and "exported" in err
    topics = mcap_topics(logs.faulty)
    rows = list(csv.DictReader(io.StringIO(csv_path.read_text())))
    records = json.loads(json_path.read_text())
    assert len(rows) == len(records) == len(topics["/rcb4/tx"])
    for row, record, tx, rx in zip(rows, records, topics["/rcb4/tx"], topics["/rcb4/rx"], strict=True):
        assert record["seq"] == tx["seq"] == rx["seq"] == int(row["seq"])
        assert (record["frame"], record["attempt"], record["tx_hex"], record["step"]) == (
            tx["kind"], tx["attempt"], tx["hex"], tx.get("step"))
        assert (record["reply"], record["rx_hex"], record["latency_ms"], record["executing"], record["error"],
                record["stale"]) == (rx["kind"], rx["hex"], rx["latency_ms"], rx.get("executing"), rx.get("error"),
                                     rx.get("stale"))
        assert row["reply"] == rx["kind"] and row["tx_hex"] == tx["hex"]
        assert record["rx_time_ns"] >= record["tx_time_ns"]
    assert {"NAK", "ACK"} <= {r["reply_meaning"] for r in records}


def test_export_of_a_killed_run_to_stdout(logs, capsys):
    code, out, _ = cli(capsys, "log", "export", str(logs.killed), "--json", "-")
    assert code == 0
    records = json.loads(out)
    assert len(records) >= 20 and records[0]["frame_meaning"].endswith("stop and save status")
    code, _, err = cli(capsys, "log", "export", str(logs.killed))
    assert code == 2 and "--csv, --json and/or --jsonl FILE" in err


# -- replay ------------------------------------------------------------------------------------


def test_replay_of_a_clean_run_matches(logs, capsys, tmp_path):
    new_log = tmp_path / "replay.mcap"
    code, out, err = cli(capsys, "replay", str(logs.complete), "--log", str(new_log), "--speed", "1")
    assert code == 0, err
    frames = len(mcap_topics(logs.complete)["/rcb4/tx"])
    assert f"replayed {frames} frames: " in out
    # every reply the same, but for a poll at a motion's end the board's status refresh tick
    # may fall on the other side of (its phase since the port opened is in no log)
    differs = [line for line in out.splitlines() if line.startswith("differs:")]
    assert len(differs) <= 1 and all("(timing: " in line for line in differs), out
    assert "sim://?durations=3:0.33,5:0.22" in err
    replayed = mcap_topics(new_log)
    recorded = mcap_topics(logs.complete)
    assert [m["hex"] for m in replayed["/rcb4/tx"]] == [m["hex"] for m in recorded["/rcb4/tx"]]
    assert len(replayed["/choreo/step"]) == len(recorded["/choreo/step"])
    code, out, _ = cli(capsys, "log", "summary", str(new_log))
    assert "(complete)" in out and "outcome   done" in out


def test_replay_of_a_faulty_run_reports_the_differences(logs, capsys, tmp_path):
    code, out, _ = cli(capsys, "replay", str(logs.faulty), "--log", str(tmp_path / "r1.mcap"), "--speed", "3")
    assert code == 0
    rx = mcap_topics(logs.faulty)["/rcb4/rx"]
    bad = [m for m in rx if m["kind"] not in ("ack", "status")]
    differs = [line for line in out.splitlines() if line.startswith("differs:")]
    assert len(differs) >= len(bad)
    assert any("recorded NAK (04" in line and "replay ACK" in line or "replay status" in line for line in differs)
    code, out, _ = cli(capsys, "replay", str(logs.faulty), "--log", str(tmp_path / "r2.mcap"), "--speed", "3",
                       "--strict", "-q")
    assert code == 1 and not [line for line in out.splitlines() if line.startswith("differs:")]


def test_replay_of_a_killed_run_goes_as_far_as_the_log(logs, capsys, tmp_path):
    code, out, _ = cli(capsys, "replay", str(logs.killed), "--log", str(tmp_path / "r.mcap"), "--speed", "4")
    assert code == 0
    assert "the recorded log is unfinished" in out
    sent = int(out.split("replayed ", 1)[1].split()[0])
    assert sent >= 20


def test_replay_refuses_a_bad_speed_and_a_bad_port(logs, capsys, tmp_path):
    code, _, err = cli(capsys, "replay", str(logs.complete), "--speed", "0", "--log", str(tmp_path / "a.mcap"))
    assert code == 2 and "--speed 0" in err
    code, _, err = cli(capsys, "replay", str(logs.complete), "--port", str(tmp_path / "no-such-tty"),
                       "--log", str(tmp_path / "b.mcap"))
    assert code == 3 and "cannot open" in err
    with LogReader(tmp_path / "b.mcap") as reader:  # the failed replay's own log is still closed properly
        list(reader.messages())
        assert reader.complete and reader.result["outcome"] == "failed"
        assert reader.result["exit_code"] == "3" and "cannot open" in reader.result["error"]
    # as a run's: what the replay was, then why the port did not open
    lines = [m["message"] for m in mcap_topics(tmp_path / "b.mcap")["/choreo/log"]]
    assert lines[0].startswith(f"replay of {logs.complete}") and "cannot open" in lines[-1]


def _live_sim() -> str:
    """A simulator whose status is live. Where one refreshes its status on ticks (as the RCB-4
    does, every 50 ms), their phase since the port opened is in no log, so which side of a tick
    a motion's end falls on is chance in any replay, whatever its speed: these runs pin it."""
    from choreo.sim.options import SETTINGS

    return "sim://?refresh_ms=0" if "refresh_ms" in SETTINGS else "sim://"


@pytest.fixture(scope="module")
def live_log(logs) -> Path:
    """A clean run of the review show on a live-status simulator."""
    path = logs.directory / "live.mcap"
    assert vmain(["run", str(logs.directory / "review.yaml"), "--log", str(path), "-q", "--port", _live_sim()]) == 0
    return path


@pytest.mark.parametrize("speed", ["1", "2", "10"])
def test_replay_of_a_clean_run_is_clean_at_any_speed(live_log, capsys, tmp_path, speed):
    """The simulator's motions run `speed` times faster too: every poll falls where it did."""
    code, out, err = cli(capsys, "replay", str(live_log), "--log", str(tmp_path / "r.mcap"),
                         "--speed", speed, "--strict", "--port", _live_sim())
    frames = len(mcap_topics(live_log)["/rcb4/tx"])
    assert code == 0, out
    assert f"replayed {frames} frames: " in out
    # none differs, but for a poll a busy machine held back past a motion's end (said, excused)
    differs = [line for line in out.splitlines() if line.startswith("differs:")]
    assert all("not the board's doing" in line for line in differs), out
    durations = {"1": "3:0.33,5:0.22", "2": "3:0.165,5:0.11", "10": "3:0.033,5:0.022"}[speed]
    assert f"durations={durations}" in err and "note:" not in err


def test_speed_scales_a_sim_board_and_nothing_else():
    from urllib.parse import parse_qsl

    from choreo.run.settings import at_speed
    from choreo.sim.options import parse_query

    def options(url: str) -> dict[str, str]:
        assert url.startswith("sim://?")
        query = url.split("?", 1)[1]
        parse_query(query)  # the simulator takes it
        return dict(parse_qsl(query))

    assert at_speed("sim://?durations=3:0.33,5:0.22", 1) == "sim://?durations=3:0.33,5:0.22"
    fast = options(at_speed("sim://?durations=3:0.33&drop=5", 2))
    assert (fast["durations"], fast["drop"], fast["motion_s"], fast["reply_ms"], fast["wire"]) == (
        "3:0.165", "5", "0.5", "0.1", "0")
    assert fast.get("refresh_ms", "25") == "25"  # a simulator with a 50 ms status refresh: 25 ms
    wired = options(at_speed("sim://?motion_s=2&wire=1", 4))
    assert (wired["motion_s"], wired["wire"], wired["reply_ms"]) == ("0.5", "1", "0.05")
    slow = options(at_speed("sim://", 0.5))
    assert (slow["motion_s"], slow["reply_ms"]) == ("2", "0.4") and "wire" not in slow
    assert at_speed("/dev/ttyUSB0", 2) == "/dev/ttyUSB0"
    assert at_speed("sim://?bogus=1", 2) == "sim://?bogus=1"  # the link says what is wrong with it


def test_replay_on_a_sim_at_another_baud_gives_the_board_that_baud(logs, capsys, tmp_path):
    code, out, err = cli(capsys, "replay", str(logs.complete), "--log", str(tmp_path / "r.mcap"),
                         "--baud", "625000", "-q")
    assert code == 0, err
    frames = len(mcap_topics(logs.complete)["/rcb4/tx"])
    assert f"{frames} same, 0 differ" in out
    with LogReader(tmp_path / "r.mcap") as reader:
        assert reader.run_info["baud"] == "625000" and "baud=625000" in reader.run_info["port"]


@pytest.mark.parametrize("option, value, says", [
    ("--baud", "9600", "--baud 9600: the RCB-4 runs at 115200, 625000, 1250000 baud"),
    ("--timeout", "0", "--timeout 0: give the seconds to wait for a reply"),
    ("--timeout", "nan", "--timeout nan: give the seconds"),
    ("--timeout", "inf", "--timeout inf: give the seconds"),
    ("--timeout", "11", "--timeout 11: give the seconds"),
    ("--speed", "nan", "--speed nan: give a speed from 0.01 to 1000"),
    ("--speed", "inf", "--speed inf: give a speed from 0.01 to 1000"),
    ("--speed", "-2", "--speed -2: give a speed from 0.01 to 1000"),
])
def test_replay_refuses_what_the_board_or_a_clock_cannot_do(logs, capsys, tmp_path, option, value, says):
    new_log = tmp_path / "r.mcap"
    code, out, err = cli(capsys, "replay", str(logs.complete), "--log", str(new_log), option, value)
    assert code == 2 and out == "" and err.startswith(says) and len(err.splitlines()) == 1
    assert not new_log.exists()  # refused before anything was opened


def test_not_a_log_is_exit_2_with_one_line(logs, capsys):
    show = logs.directory / "review.yaml"
    for argv in (["log", "summary", str(show)], ["log", "frames", str(show)], ["replay", str(show)]):
        code, out, err = cli(capsys, *argv)
        assert code == 2 and out == ""
        assert err == f"log {show}: not an MCAP file (it does not start with the MCAP magic bytes); " \
                      "choreo logs are the .mcap files `choreo run` writes\n"


def test_a_poll_the_replay_sent_late_is_not_held_against_the_board(live_log, capsys, tmp_path, monkeypatch):
    """A busy machine holds one poll back 30 ms (300 ms of the run at speed 10): it finds the motion
    over where the run found it executing. Reported, but not a difference --strict fails on."""
    from choreo.board.link import Link

    send = Link.send
    polls = {"n": 0}

    def busy_send(self, frame, *args, **kwargs):
        if frame.kind.value == "status":
            polls["n"] += 1
            if polls["n"] == 3:  # the wave's third poll: it was still executing in the run
                self.clock.sleep(0.03)
        return send(self, frame, *args, **kwargs)

    monkeypatch.setattr(Link, "send", busy_send)
    code, out, _ = cli(capsys, "replay", str(live_log), "--log", str(tmp_path / "r.mcap"), "--speed", "10",
                       "--strict", "--port", _live_sim())
    differs = [line for line in out.splitlines() if line.startswith("differs:")]
    assert code == 0, out
    assert differs and all("the replay sent this poll" in line and "not the board's doing" in line
                           for line in differs)  # that poll, and the ones kept as far behind it
    n = len(differs)
    assert f"{n} differ ({n} of them status polls at a motion's end, {n} sent late by the replay)" in out


def test_summary_counts_late_plays_as_the_run_did(logs, capsys):
    """A play its retries delayed is late (the runner's count in the log's result); one late at
    its cue is not counted again when it is retried too."""
    path = logs.directory / "retried.mcap"
    done = subprocess.run(_choreo("run", str(logs.directory / "review.yaml"), "--log", str(path), "-q",
                                  "--port", "sim://?nak=4", "--timeout", "0.05", "--retries", "4"),
                          cwd=logs.directory, capture_output=True, timeout=30)
    assert done.returncode == 0, done.stderr
    code, out, _ = cli(capsys, "log", "summary", str(path))
    assert code == 0
    with LogReader(path) as reader:
        list(reader.messages())
        run_late = int(reader.result["late_steps"])
    warnings = [m["message"] for m in mcap_topics(path)["/choreo/log"] if "tries)" in m["message"]]
    by_retries = f" ({len(warnings)} by retries)" if warnings else ""
    assert f", {run_late} late{by_retries}, " in field(out, "steps")
    for name in ("complete", "faulty"):
        _, out, _ = cli(capsys, "log", "summary", str(getattr(logs, name)))
        with LogReader(getattr(logs, name)) as reader:
            list(reader.messages())
            assert f" {reader.result['late_steps']} late" in field(out, "steps")


def test_frames_of_the_links_ack_checks(logs, capsys):
    """After a timeout the link sends the ACK check (tx kind sync): `--kind sync` lists them."""
    syncs = [m for m in mcap_topics(logs.faulty)["/rcb4/tx"] if m["kind"] == "sync"]
    code, out, _ = cli(capsys, "log", "frames", str(logs.faulty), "--kind", "sync")
    assert code == 0
    tx = [line for line in out.splitlines() if "  tx  " in line]
    assert len(tx) == len(syncs) and all(" sync " in line for line in tx)
