"""An output that cannot be written (issue 11, item 3): one line and exit 2, never a traceback;
a reader that went away (a closed pipe) ends the command quietly. A file that cannot be read is
said to be unreadable, never "cannot write the output"; log folders hold things named `*.mcap`
that are not logs; `--json` fails as JSON (issue 21, item 6)."""

from __future__ import annotations

import contextlib
import errno
import io
import json
import os
import shutil
import subprocess
import sys
from pathlib import Path

import pytest

from choreo.cli import main
from runlog import choreo_here, vmain

ROOT = Path(__file__).resolve().parent.parent


@pytest.fixture(scope="module")
def run_log(tmp_path_factory) -> Path:
    path = tmp_path_factory.mktemp("output") / "run.mcap"
    assert vmain(["run", str(ROOT / "shows" / "minimal.yaml"), "--port", "sim://?motion_s=0.1",
                 "--log", str(path), "-q"]) == 0
    return path


COMMANDS = [
    ["plan", "shows/dance.yaml"],
    ["validate", "shows/dance.yaml"],
    ["frames", "play", "3"],
    ["ports"],
    ["schema"],
    ["log", "frames", "LOG"],
    ["log", "summary", "LOG"],
    ["log", "timeline", "LOG"],
    ["log", "export", "LOG", "--csv", "-"],
]


@pytest.mark.skipif(not os.path.exists("/dev/full"), reason="no /dev/full here")
@pytest.mark.parametrize("argv", COMMANDS, ids=lambda a: " ".join(a[:2]))
def test_a_full_output_is_one_line_and_exit_2(argv, run_log):
    argv = [str(run_log) if a == "LOG" else a for a in argv]
    with open("/dev/full", "w") as full:
        done = subprocess.run([sys.executable, "-m", "choreo", *argv], stdout=full, stderr=subprocess.PIPE,
                              text=True, cwd=ROOT, timeout=60)
    assert done.returncode == 2, done.stderr
    assert done.stderr == "choreo: cannot write the output: No space left on device\n"


def test_a_closed_pipe_ends_quietly(run_log):
    reader = subprocess.Popen([sys.executable, "-m", "choreo", "log", "frames", str(run_log)],
                              stdout=subprocess.PIPE, stderr=subprocess.PIPE, cwd=ROOT)
    reader.stdout.readline()
    reader.stdout.close()
    _, err = reader.communicate(timeout=60)
    assert reader.returncode == 0 and b"Traceback" not in err


# ------------------------------------------------------------------ issue 21, item 6


def choreo(*argv: str, stdout=subprocess.PIPE) -> subprocess.CompletedProcess:
    """choreo in a process of its own; env given, so that the COLUMNS readline exports behind
    os.environ's back does not cut the lines."""
    return subprocess.run([sys.executable, "-m", "choreo", *argv], stdout=stdout, stderr=subprocess.PIPE,
                          text=True, cwd=ROOT, timeout=60, env=dict(os.environ))


@pytest.mark.skipif(not os.path.exists("/dev/full"), reason="no /dev/full here")
@pytest.mark.parametrize("argv", [["--help"], ["--version"], ["log", "--help"], ["import", "--help"]])
def test_help_into_a_full_output_is_exit_2(argv):
    with open("/dev/full", "w") as full:
        done = choreo(*argv, stdout=full)
    assert (done.returncode, done.stderr) == (2, "choreo: cannot write the output: No space left on device\n")


@pytest.mark.skipif(not os.path.exists("/proc/self/mem"), reason="no /proc here")
@pytest.mark.parametrize("argv, says", [
    (["log", "summary", "/proc/self/mem"], "/proc/self/mem: cannot read the run log: Input/output error"),
    (["log", "frames", "/proc/self/mem"], "/proc/self/mem: cannot read the run log: Input/output error"),
    (["replay", "/proc/self/mem"], "/proc/self/mem: cannot read the run log: Input/output error"),
    (["beats", "/proc/self/mem"], "/proc/self/mem: cannot read the sound file: Input/output error"),
    (["validate", "/proc/self/mem"], "/proc/self/mem: cannot read the show file: Input/output error"),
])
def test_a_read_error_is_reported_as_a_read_error(argv, says):
    done = choreo(*argv)
    assert (done.returncode, done.stdout) == (2, "")
    assert says in done.stderr and "write" not in done.stderr and done.stderr.count("\n") == 1, done.stderr


class FullStream(io.StringIO):
    """stdout on a full disk: every write fails, as /dev/full's do."""

    def write(self, text: str) -> int:
        raise OSError(errno.ENOSPC, "No space left on device")


def test_a_write_failure_a_command_swallowed_is_still_reported(monkeypatch, capsys):
    import choreo.cli.schema

    def swallowing(args) -> int:
        with contextlib.suppress(Exception):  # what a careless command might do
            print("the schema")
        return 0

    monkeypatch.setattr(choreo.cli.schema, "run", swallowing, raising=False)
    parser_default = choreo.cli.schema.register

    def register(subparsers):
        parser_default(subparsers)
        subparsers.choices["schema"].set_defaults(handler=swallowing)

    monkeypatch.setattr(choreo.cli.schema, "register", register)
    monkeypatch.setattr(sys, "stdout", FullStream())
    assert main(["schema"]) == 2
    assert capsys.readouterr().err == "choreo: cannot write the output: No space left on device\n"


# ------------------------------------------------------------------ log folders


@pytest.fixture
def hostile_folder(tmp_path, run_log) -> tuple[Path, Path]:
    """A folder with one real log among things named *.mcap that are not logs, all newer."""
    folder = tmp_path / "runs"
    folder.mkdir()
    real = folder / "real.mcap"
    shutil.copyfile(run_log, real)
    os.utime(real, (1_000_000, 1_000_000))
    (folder / "dangling.mcap").symlink_to(folder / "gone.mcap")
    (folder / "loop-a.mcap").symlink_to(folder / "loop-b.mcap")
    (folder / "loop-b.mcap").symlink_to(folder / "loop-a.mcap")
    (folder / "x.mcap").mkdir()
    if hasattr(os, "mkfifo"):
        os.mkfifo(folder / "fifo.mcap")
    if os.path.exists("/dev/zero"):
        (folder / "zero.mcap").symlink_to("/dev/zero")
    return folder, real


def test_log_latest_is_the_newest_regular_log_whatever_else_is_named_mcap(hostile_folder):
    folder, real = hostile_folder
    done = choreo_here("log", "latest", str(folder))
    assert (done.returncode, done.stdout, done.stderr) == (0, f"{real}\n", "")


def test_log_summary_of_a_folder_reads_only_its_logs(hostile_folder):
    folder, real = hostile_folder
    done = choreo_here("log", "summary", str(folder))
    assert done.returncode == 0, done.stderr
    assert done.stderr == "" and str(real) in done.stdout and done.stdout.count("\nmessages ") == 1


@pytest.mark.parametrize("name, says", [
    ("gone.mcap", "cannot read the run log: it is a link to"),
    ("loop-a.mcap", "cannot read the run log: a loop of symbolic links"),
    ("x" * 300 + ".mcap", "cannot read the run log: the name is too long for this system"),
    ("fifo.mcap", "not a regular file (a named pipe): give a run log"),
    ("x.mcap", "not a regular file (a folder): give a run log"),
])
def test_a_log_that_is_not_a_file_is_one_line(tmp_path, name, says):
    (tmp_path / "gone.mcap").symlink_to(tmp_path / "nothing.mcap")
    (tmp_path / "loop-a.mcap").symlink_to(tmp_path / "loop-b.mcap")
    (tmp_path / "loop-b.mcap").symlink_to(tmp_path / "loop-a.mcap")
    (tmp_path / "x.mcap").mkdir()
    os.mkfifo(tmp_path / "fifo.mcap")
    for argv in (["log", "summary"], ["log", "frames"], ["log", "timeline"], ["replay"]):
        done = choreo_here(*argv, str(tmp_path / name))
        assert (done.returncode, done.stdout) == (2, ""), done.stderr
        expected = "no .mcap logs in this folder" if argv[-1] == "summary" and name == "x.mcap" else says
        assert expected in done.stderr and done.stderr.count("\n") == 1, done.stderr


@pytest.mark.parametrize("argv", [["log", "latest"], ["log", "summary"]])
def test_a_folder_that_cannot_be_listed_says_so(argv, tmp_path, monkeypatch, capsys):
    folder = tmp_path / "runs"
    folder.mkdir()
    real_scandir = os.scandir

    def refused(path):  # what a folder without read permission does (the tests may run as root)
        if os.fspath(path) == str(folder):
            raise PermissionError(errno.EACCES, "Permission denied", str(path))
        return real_scandir(path)

    monkeypatch.setattr(os, "scandir", refused)
    assert main([*argv, str(folder)]) == 2
    assert capsys.readouterr().err == f"{folder}: cannot read the log folder: Permission denied\n"


def test_log_latest_of_a_folder_that_is_not_there_or_not_a_folder(tmp_path, capsys):
    assert main(["log", "latest", str(tmp_path / "nowhere")]) == 2
    said = capsys.readouterr().err
    assert said == f"{tmp_path / 'nowhere'}: no such folder (`choreo run` writes its logs to runs/)\n"
    (tmp_path / "file").write_text("x")
    assert main(["log", "latest", str(tmp_path / "file")]) == 2
    assert capsys.readouterr().err == f"{tmp_path / 'file'}: not a folder (a file): give a log folder\n"
    long_name = tmp_path / ("d" * 300)  # was 'no such folder'
    assert main(["log", "latest", str(long_name)]) == 2
    assert capsys.readouterr().err.endswith(": cannot read the log folder: the name is too long for this system\n")


# ------------------------------------------------------------------ --json on failure


def test_log_summary_json_gives_every_log_a_line_the_bad_one_an_error_object(run_log, tmp_path, capsys):
    bad = tmp_path / "bad.mcap"
    bad.write_text("not a log")
    assert main(["log", "summary", str(run_log), str(bad), "--json"]) == 2
    out, err = capsys.readouterr()
    good, failed = (json.loads(line) for line in out.splitlines())
    assert good["log"] == str(run_log) and "steps" in good
    assert failed == {"ok": False, "exit": 2, "error": err.strip(), "log": str(bad)}


@pytest.mark.parametrize("argv", [["log", "summary", "NOPE", "--json"], ["log", "frames", "NOPE", "--json"],
                                  ["replay", "NOPE", "--json"]])
def test_json_failures_are_one_json_object(argv, tmp_path, capsys):
    argv = [str(tmp_path / "nope.mcap") if a == "NOPE" else a for a in argv]
    assert main(argv) == 2
    out, err = capsys.readouterr()
    record = json.loads(out)
    assert record["ok"] is False and record["exit"] == 2 and "nope.mcap" in record["error"]


def test_log_frames_json_is_one_object_with_the_export_fields(run_log, capsys):
    assert main(["log", "frames", str(run_log), "--json", "--kind", "play"]) == 0
    record = json.loads(capsys.readouterr().out)
    assert record["ok"] is True and record["log"] == str(run_log) and record["cut"] is None
    assert record["frames"] and {f["frame"] for f in record["frames"]} == {"play"}
    assert {"seq", "tx_hex", "frame_meaning", "reply", "layout"} <= set(record["frames"][0])


def test_replay_json_is_one_object_with_the_result(run_log, tmp_path, capsys):
    new_log = tmp_path / "again.mcap"
    assert vmain(["replay", str(run_log), "--json", "--log", str(new_log), "-q"]) == 0
    record = json.loads(capsys.readouterr().out)
    assert record["ok"] is True and record["exit"] == 0 and record["replay_log"] == str(new_log)
    assert record["frames"] > 0 and record["frames"] == record["same"] + record["different"]
    assert isinstance(record["differences"], list)


def test_a_folder_of_things_named_mcap_that_are_not_logs_says_so(hostile_folder, capsys):
    folder, real = hostile_folder
    real.unlink()
    others = len([p for p in folder.iterdir() if p.name.endswith(".mcap")])
    for argv in (["log", "latest"], ["log", "summary"]):
        assert main([*argv, str(folder)]) == 2
        said = capsys.readouterr().err
        assert said == f"{folder}: no .mcap logs in this folder ({others} named *.mcap are not regular files)\n"


@pytest.mark.skipif(not os.path.exists("/dev/full"), reason="no /dev/full here")
def test_a_json_failure_into_a_full_output_still_tells_the_failure():
    with open("/dev/full", "w") as full:
        done = choreo("log", "summary", "/nonexistent.mcap", "--json", stdout=full)
    assert done.returncode == 2
    assert done.stderr == ("log /nonexistent.mcap: cannot read the run log: No such file or directory\n"
                           "choreo: cannot write the output: No space left on device\n")


@pytest.mark.skipif(not hasattr(os, "mkfifo"), reason="no named pipes here")
def test_an_output_file_that_is_a_pipe_nobody_reads_is_one_line_not_a_hang(run_log, tmp_path):
    fifo = tmp_path / "out.csv"
    os.mkfifo(fifo)
    done = choreo("log", "export", str(run_log), "--csv", str(fifo))  # it blocked until the timeout
    assert (done.returncode, done.stderr) == (2, f"log export --csv {fifo}: cannot write: a named pipe nobody reads\n")


@pytest.mark.parametrize("argv", [
    ["log", "export", "LOG", "--csv", "OUT"], ["log", "export", "LOG", "--json", "OUT"],
    ["log", "export", "LOG", "--jsonl", "-", "--csv", "OUT"],
    ["log", "export", "LOG", "--format", "jsonl", "-o", "OUT"],
    ["log", "export", "LOG", "--cues", "--csv", "OUT"], ["log", "timeline", "LOG", "--png", "OUT"],
], ids=lambda argv: " ".join(argv[1:2] + argv[3:4]))
@pytest.mark.parametrize("named", ["itself", "dot", "link", "hard link"])
def test_an_output_that_is_the_log_read_is_refused_and_the_log_kept(run_log, tmp_path, capsys, argv, named):
    """Issue 21, item 6: `log export LOG --csv LOG` (or through a link) opened its output first,
    emptied the log, then read it: 'not an MCAP file', the run's log gone."""
    log = tmp_path / "run.mcap"
    log.write_bytes(run_log.read_bytes())
    out = {"itself": log, "dot": tmp_path / "." / "run.mcap", "link": tmp_path / "link.mcap",
           "hard link": tmp_path / "hard.mcap"}[named]
    if named == "link":
        out.symlink_to(log)
    if named == "hard link":
        os.link(log, out)
    assert main([str(log) if a == "LOG" else str(out) if a == "OUT" else a for a in argv]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "that is the log being read" in err, err
    assert log.read_bytes() == run_log.read_bytes()


@pytest.mark.skipif(not os.path.exists("/dev/full"), reason="no /dev/full here")
@pytest.mark.parametrize("argv, code", [(["plan", "NOPE.yaml"], 2), (["validate", "--json", "NOPE.yaml"], 2),
                                        (["frames", "play", "3", "--baud", "9"], 2)])
def test_an_error_into_a_full_stderr_keeps_its_exit_status(argv, code, tmp_path):
    """Issue 21, item 6: with stderr on a full disk the error line's failed write escaped as a
    traceback nobody could read, and the exit status became 1."""
    argv = [str(tmp_path / a) if a == "NOPE.yaml" else a for a in argv]
    with open("/dev/full", "w") as full:
        done = subprocess.run([sys.executable, "-m", "choreo", *argv], stdout=subprocess.DEVNULL, stderr=full,
                              cwd=ROOT, timeout=60)
    assert done.returncode == code
