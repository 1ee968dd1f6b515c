"""What choreo writes on a terminal (issue 21, items 4 and 5): outside text never drives the
terminal (every command's output, the console, the progress lines), and the terminal never
drives the show (a terminal stopped with Ctrl-S or a pipe nobody reads holds up no robot;
every line drawn fits the terminal's width, after a resize too)."""

from __future__ import annotations

import fcntl
import io
import json
import os
import pty
import re
import select
import signal
import struct
import subprocess
import sys
import termios
import threading
import time
from pathlib import Path

import pytest
from mcap.reader import make_reader
from rich.console import Console as RichConsole

from choreo.cli.screen import Note, Row, Screen, render
from choreo.cli.progress import Progress
from choreo.cli.terminal import StatusWriter, VisibleStream, visible_output
from choreo.events import Answer, Command, CommandEvent, StepEvent
from choreo.run.settings import RunRequest
from choreo.textfit import display_width, is_hidden, visible
from runlog import REPO, off_cue_s, prepare, read_log, started_on_cue, vmain, wait_for, write_show

HOSTILE = "\x1b]0;pwned\x07\x1b[2J\u202eevil\u200b\x9b31m"


def assert_safe(text: str) -> None:
    """Nothing in `text` a terminal would obey or hide (newlines aside)."""
    assert not [c for c in text if c != "\n" and is_hidden(c)], repr(text)


# -- outside text: every output made visible ------------------------------------------------------


def test_an_error_naming_a_hostile_file_shows_its_escapes(capsys) -> None:
    assert vmain(["validate", f"/nonexistent/{HOSTILE}.yaml"]) == 2
    err = capsys.readouterr().err
    assert_safe(err)
    assert "\\x1b]0;pwned\\x07\\x1b[2J\\u202eevil\\u200b\\u009b31m" in err


def test_json_output_stays_json_and_keeps_the_text(capsys) -> None:
    path = f"/nonexistent/{HOSTILE}\udcff.yaml"  # an undecodable byte too (a surrogate)
    assert vmain(["run", "--json", path]) == 2
    out = capsys.readouterr().out
    assert_safe(out)
    assert json.loads(out)["show"] == path


def test_a_show_and_a_command_source_of_hostile_text_are_shown_escaped(tmp_path, capsys) -> None:
    """The run's lines (the show's name in a header, an OSC source in a command's line) and
    `log summary` of its log: every one made visible, whatever printed it."""
    show = write_show(tmp_path, "version: 1\nname: plain\nsteps:\n  - play: 1\n")
    session = prepare(RunRequest(str(show), log_path=str(tmp_path / "run.mcap")))
    out = io.StringIO()
    progress = Progress(session, out, live=False, quiet=False)
    command = Command("go", f"osc udp 10.0.0.9:9 {HOSTILE}")
    progress.on_command(CommandEvent(command, Answer("error", f"unknown address /choreo/{HOSTILE}"), 0, 1.0))
    progress.on_log(3, f"warning from {HOSTILE}")
    progress.finish()
    assert_safe(out.getvalue())
    assert out.getvalue().count("\\x1b]0;pwned") == 3
    with visible_output():
        print(f"show: {HOSTILE}", file=sys.stderr)
        sys.stdout.writelines([HOSTILE, "\n"])
    captured = capsys.readouterr()
    assert_safe(captured.err + captured.out)
    assert captured.err == "show: \\x1b]0;pwned\\x07\\x1b[2J\\u202eevil\\u200b\\u009b31m\n"


def test_log_summary_of_a_log_with_hostile_commands_shows_them_escaped(tmp_path, capsys) -> None:
    from choreo.live.controls import Live
    from choreo.events import StopRequest

    show = write_show(tmp_path, "version: 1\nname: plain\nsteps:\n  - play: 1\n  - wait: 0.5\n  - play: 2\n")
    log_path = tmp_path / "run.mcap"
    session = prepare(RunRequest(str(show), log_path=str(log_path)))
    stop = StopRequest()
    live = Live(stop)

    class Attacker:
        def on_log(self, *args: object) -> None:
            pass

        def on_step(self, event: StepEvent) -> None:
            if event.event == "start" and event.step.index == 1:
                live.command(Command("stop", f"osc udp 10.0.0.9:9 {HOSTILE}"))  # accepted: logged

    with session:
        session.run([Attacker()], stop, live)
    assert any(HOSTILE in m["source"] for m in read_log(log_path).topic("/choreo/command"))  # the log keeps it raw
    capsys.readouterr()
    vmain(["log", "summary", str(log_path)])
    out = capsys.readouterr().out
    assert_safe(out)
    assert "\\x1b]0;pwned" in out


def test_the_console_draws_outside_text_escaped() -> None:
    screen = Screen(HOSTILE, 1.0, "machine clock", f"next cue: {HOSTILE}", f"GO waits: '{HOSTILE}'", True,
                    (Row(HOSTILE, HOSTILE, HOSTILE, 1.0),), (Note(f"GO refused ({HOSTILE})", "", 1.0),))
    for width in (40, 80, 200):
        text = io.StringIO()
        RichConsole(file=text, width=width, color_system=None).print(render(screen, width))
        assert_safe(text.getvalue())
        assert "\\x1b]0;" in text.getvalue() or width < 80


def test_a_visible_stream_is_the_stream_for_everything_but_writing() -> None:
    raw = io.StringIO()
    stream = VisibleStream(raw)  # type: ignore[arg-type]
    assert stream.write("a\x1bb\n") == 4 and raw.getvalue() == "a\\x1bb\n"
    assert stream.getvalue() == raw.getvalue()  # the rest is the stream's own


def test_what_a_command_writes_as_bytes_is_shown_escaped_too(capsysbinary, monkeypatch) -> None:
    """`choreo import` writes its UTF-8 under the text stream (sys.stdout.buffer): whatever the
    show it writes holds, the terminal is shown it escaped, as every text output is."""
    import choreo.show.hth4
    import choreo.show.starter

    monkeypatch.setattr(choreo.show.hth4, "read_project", lambda path: None)
    monkeypatch.setattr(choreo.show.starter, "starter_show", lambda project, *rest: f"name: {HOSTILE}\xff\n")
    assert vmain(["import", "project.h4p"]) == 0
    out = capsysbinary.readouterr().out.decode("utf-8")
    assert_safe(out)
    assert out == "name: \\x1b]0;pwned\\x07\\x1b[2J\\u202eevil\\u200b\\u009b31m\u00ff\n"


# -- the terminal never holds the show ----------------------------------------------------------


def _full_pipe() -> tuple[int, int]:
    """A pipe whose buffer is full: the next write to it blocks."""
    read, write = os.pipe()
    os.set_blocking(write, False)
    try:
        while True:
            os.write(write, b"x" * 4096)
    except BlockingIOError:
        pass
    os.set_blocking(write, True)
    return read, write


def _drain(fd: int) -> bytes:
    got = b""
    while select.select([fd], [], [], 0.5)[0]:
        chunk = os.read(fd, 65536)
        if not chunk:
            break
        got += chunk
    return got


@pytest.mark.parametrize("live", [False, True])
def test_progress_never_waits_for_an_output_that_takes_nothing(tmp_path, live: bool) -> None:
    """A runner's step, a warning, a command's answer: noted at once however full the output
    is; what did not fit is counted and said once the output takes lines again."""
    session = prepare(RunRequest(str(write_show(tmp_path, "version: 1\nsteps:\n  - play: 1\n")), no_log=True))
    read, write = _full_pipe()
    with os.fdopen(write, "w", closefd=True) as out:
        progress = Progress(session, out, live=live, quiet=False)
        step = session.settings.plans["robot"].steps[0]
        count = StatusWriter.CAPACITY * 3

        def show_thread() -> None:
            for n in range(count):
                progress.on_step(StepEvent(step, "start", 0.0, n / 1000, 0))
                progress.on_log(3, f"warning {n}")

        thread = threading.Thread(target=show_thread, daemon=True)
        thread.start()
        thread.join(10)
        assert not thread.is_alive(), "a runner waited for the terminal"
        drained: list[bytes] = []
        reader = threading.Thread(target=lambda: drained.append(_drain(read)), daemon=True)
        reader.start()
        progress.finish()
        reader.join(10)
    os.close(read)
    text = drained[0].decode().lstrip("x")
    assert "warning 0\n" in text
    dropped = progress.writer.dropped_total  # type: ignore[union-attr]
    said = [int(n) for n in re.findall(r"\((\d+) progress lines? not shown: the output did not keep up\)\n", text)]
    assert dropped > 0 and said and sum(said) == dropped


def _pty(columns: int) -> tuple[int, int]:
    primary, secondary = pty.openpty()
    fcntl.ioctl(secondary, termios.TIOCSWINSZ, struct.pack("HHHH", 24, columns, 0, 0))
    return primary, secondary


TIMED_SHOW = """\
version: 1
name: a show whose plays are all cued, on the simulator's time
motions:
  short: {number: 2, duration: 0.05}
steps:
""" + "".join(f"  - play: short\n    at: {0.3 + 0.15 * n:.2f}\n" for n in range(12))


def _run_on_pty(tmp_path: Path, columns: int, port: str, hold: bool,
                resize_to: int | None = None) -> tuple[str, Path, int]:
    """`choreo run --no-console` on a pseudo-terminal `columns` wide; with `hold`, the terminal
    stopped (Ctrl-S) from the header's last line until the log is closed; with `resize_to`,
    made that wide once the header is out."""
    show = write_show(tmp_path, TIMED_SHOW)
    log = tmp_path / "run.mcap"
    primary, secondary = _pty(columns)
    env = {k: v for k, v in os.environ.items() if k not in ("COLUMNS", "LINES")}
    process = subprocess.Popen([str(REPO / ".venv" / "bin" / "choreo"), "run", str(show), "--no-console",
                                "--port", port, "--log", str(log)], stdin=secondary, stdout=secondary,
                               stderr=secondary, cwd=REPO, env=env, start_new_session=True)
    os.close(secondary)
    seen = b""
    try:
        deadline = time.monotonic() + 20
        while (hold or resize_to) and b"\n" not in seen.partition(b"log: ")[2] and time.monotonic() < deadline:
            if select.select([primary], [], [], 0.1)[0]:  # the header's last line, whole
                seen += os.read(primary, 65536)
        if resize_to:
            fcntl.ioctl(primary, termios.TIOCSWINSZ, struct.pack("HHHH", 24, resize_to, 0, 0))
        if hold:
            os.write(primary, b"\x13")  # Ctrl-S: the terminal takes no more output
            assert wait_for(lambda: _closed(log), timeout=30), "the show did not finish while the terminal was stopped"
            os.write(primary, b"\x11")  # Ctrl-Q
        while True:
            try:
                ready = select.select([primary], [], [], 0.2)[0]
                if ready:
                    seen += os.read(primary, 65536)
                elif process.poll() is not None:
                    break
            except OSError:
                break
        code = process.wait(20)
    finally:
        if process.poll() is None:
            os.killpg(process.pid, signal.SIGKILL)
        os.close(primary)
    return seen.decode("utf-8", "replace"), log, code


def _closed(log: Path) -> bool:
    try:
        read_log(log)
        return True
    except Exception:  # noqa: BLE001 - not written to its end yet
        return False


def _every_play_on_its_cue(log: Path, when: str) -> None:
    """TIMED_SHOW's twelve plays all ran, each motion on its cue (`started_on_cue`: past how late
    the run measured its own wake-up, which a loaded machine's scheduler delays: a wake-up 453 ms
    late failed a bound on the wake-ups beside CI). A runner that waited for the output at all
    would have waited until it took lines again: after the log was closed, which the tests wait
    for before they let the output go on."""
    steps = read_log(log).steps
    ends = [m for m in steps if m["event"] == "end"]
    assert [m["outcome"] for m in ends] == ["ok"] * 12
    late = [round(off_cue_s(steps, end) * 1e3) for end in ends if not started_on_cue(steps, end)]
    assert not late, f"motions {late} ms off their cues {when}"


def test_a_terminal_stopped_with_ctrl_s_holds_up_no_play(tmp_path) -> None:
    output, log, code = _run_on_pty(tmp_path, 300, "sim://", hold=True)
    assert code == 0, output
    _every_play_on_its_cue(log, "while the terminal was stopped")


@pytest.mark.parametrize("columns", [50, 33])
def test_every_line_of_a_run_fits_the_terminal(tmp_path, columns: int) -> None:
    durations = ",".join(f"{n}:{0.05 + n / 1000:g}" for n in range(40))
    output, log, code = _run_on_pty(tmp_path, columns, f"sim://?durations={durations}", hold=False)
    assert code == 0, output
    assert "port: sim://?durations=" in output and "…" in output
    for line in output.replace("\x1b[K", "").replace("\r\n", "\n").replace("\r", "\n").split("\n"):
        assert display_width(line) <= columns, (line, columns)


def test_what_reaches_stderr_under_the_console_is_shown_escaped(tmp_path, monkeypatch) -> None:
    """On a terminal the console has rich print stderr's lines above the screen (a library's
    warning): made visible on the way, and stderr is put back as it was after."""
    from choreo.cli.console import Console
    from choreo.live.controls import Live
    from choreo.events import StopRequest

    session = prepare(RunRequest(str(write_show(tmp_path, "version: 1\nsteps:\n  - play: 1\n")), no_log=True))
    primary, secondary = _pty(80)
    drained: list[bytes] = []
    with os.fdopen(secondary, "w", encoding="utf-8") as tty:
        monkeypatch.setattr(sys, "__stderr__", tty)  # the console on the process's own terminal
        before = sys.stderr
        console = Console(session, Live(StopRequest()), out=tty, keys=io.StringIO())
        console.start()
        try:
            assert sys.stderr is not before
            print(f"WARNING:root: {HOSTILE}", file=sys.stderr)
        finally:
            console.close()
        assert sys.stderr is before
        reader = threading.Thread(target=lambda: drained.append(_drain(primary)), daemon=True)
        reader.start()
        reader.join(10)
    os.close(primary)
    err = drained[0].decode("utf-8", "replace")
    assert "WARNING:root: \\x1b]0;pwned" in err
    assert "\x1b]0;pwned" not in err and "\u202e" not in err


def test_the_live_line_fits_the_terminal_after_a_resize(tmp_path) -> None:
    output, log, code = _run_on_pty(tmp_path, 120, "sim://", hold=False, resize_to=30)
    assert code == 0, output
    segments = [s for s in output.replace("\x1b[K", "").replace("\r\n", "\n").replace("\r", "\n").split("\n") if s]
    last = segments[-3:]  # the live line's last draw (at the show's end), then the outcome and the log
    assert last[0].startswith("step ") and "/1.9 s [" in last[0] and last[1].startswith("done: "), segments
    assert all(display_width(line) <= 30 for line in last), last
    assert any(display_width(line) > 30 for line in segments[:3])  # the header, drawn at 120


def test_a_pipe_nobody_reads_holds_up_no_play(tmp_path) -> None:
    """stderr a pipe that fills up once the header is out (a `choreo run ... 2>&1 | less`
    left unread): the plays keep their cues; the lines that did not fit are counted."""
    show = write_show(tmp_path, TIMED_SHOW)
    log = tmp_path / "run.mcap"
    read, write = os.pipe()
    process = subprocess.Popen([str(REPO / ".venv" / "bin" / "choreo"), "run", str(show), "--log", str(log)],
                               stdin=subprocess.DEVNULL, stdout=subprocess.DEVNULL, stderr=write, cwd=REPO)
    seen = b""
    try:
        deadline = time.monotonic() + 20
        while b"\n" not in seen.partition(b"log: ")[2] and time.monotonic() < deadline:
            if select.select([read], [], [], 0.1)[0]:
                seen += os.read(read, 65536)
        filler = os.open(f"/proc/self/fd/{write}", os.O_WRONLY | os.O_NONBLOCK)  # its own flags, not choreo's
        try:
            while True:
                os.write(filler, b"\n" * 4096)  # the pipe full: the next line waits for a reader
        except BlockingIOError:
            pass
        finally:
            os.close(filler)
        assert wait_for(lambda: _closed(log), timeout=30), "the show did not finish while the pipe was full"
        drained: list[bytes] = []
        reader = threading.Thread(target=lambda: drained.append(_drain(read)), daemon=True)
        reader.start()
        assert process.wait(20) == 0
        reader.join(10)
        drained.append(_drain(read))  # what came after a pause
    finally:
        if process.poll() is None:
            process.kill()
        os.close(write)
        os.close(read)
    _every_play_on_its_cue(log, "while the pipe was full")
    assert b"done: 12 steps" in b"".join(drained)


def test_a_non_blocking_output_is_waited_for_not_given_up(tmp_path) -> None:
    """A stderr another process made non-blocking (a full one answers EAGAIN): the writer's
    thread waits for room, and the lines arrive once someone reads."""
    read, write = _full_pipe()
    os.set_blocking(write, False)
    with os.fdopen(write, "w", closefd=True) as out:
        writer = StatusWriter(out, fit_lines=False)
        writer.line("after the wait")
        time.sleep(0.3)  # the writer meets the full pipe (EAGAIN) meanwhile
        drained: list[bytes] = []
        reader = threading.Thread(target=lambda: drained.append(_drain(read)), daemon=True)
        reader.start()
        writer.close(5)
        reader.join(10)
    os.close(read)
    assert drained[0].endswith(b"after the wait\n")


def test_a_stuck_output_is_waited_for_once_however_often_the_writer_is_closed() -> None:
    """`choreo run` closes its progress at the end and again in its `finally`: on a stuck
    output (Ctrl-S, a pipe nobody reads) each close waited its second, two in all."""
    class Stuck(io.StringIO):
        def write(self, text: str) -> int:
            threading.Event().wait(3)
            return len(text)

    writer = StatusWriter(Stuck(), fit_lines=False)
    writer.line("a line the output never takes")
    writer.close(0.05)
    joins = []
    writer._thread.join = lambda *args: joins.append(args)  # type: ignore[method-assign]
    writer.close(0.05)
    assert joins == []


def test_a_show_and_a_log_named_with_bytes_that_are_not_utf8_run_review_and_replay(tmp_path, capsys,
                                                                                     monkeypatch) -> None:
    """A file name is bytes: one that is not UTF-8 (`\\xff`, a lone surrogate to Python) was a
    traceback when the log's metadata and the show's attachment were written."""
    monkeypatch.chdir(tmp_path)  # replay writes its own log under ./runs
    folder = os.fsencode(tmp_path)
    show = folder + b"/show\x1b]0;t\x07\xff.yaml"
    Path(os.fsdecode(show)).write_text("version: 1\nsteps:\n  - play: 1\n  - wait: done\n")
    log = os.fsdecode(folder + b"/log\xfe\x1b[2J.mcap")
    assert vmain(["run", "--no-console", os.fsdecode(show), "--log", log]) == 0
    assert vmain(["log", "summary", log]) == 0
    assert vmain(["replay", log]) == 0
    assert vmain(["log", "summary", "--json", log]) == 0
    out, err = capsys.readouterr()
    assert_safe(out + err)
    assert "\\udcff" in out and "Traceback" not in err


def _signalled_run(tmp_path: Path, body: str, signum: int) -> tuple[int, bytes, Path]:
    """`choreo run --no-console` given `signum` once its show is under way: exit status, stderr, log."""
    show = write_show(tmp_path, body)
    log = tmp_path / "run.mcap"
    process = subprocess.Popen([sys.executable, "-m", "choreo", "run", str(show), "--no-console", "--log", str(log)],
                               stdin=subprocess.DEVNULL, stdout=subprocess.PIPE, stderr=subprocess.PIPE, cwd=REPO)
    try:
        assert wait_for(log.exists, timeout=20)  # the show's signal handlers are in place before it opens
        process.send_signal(signum)
        _, err = process.communicate(timeout=20)
    finally:
        if process.poll() is None:
            process.kill()
            process.wait()
    return process.returncode, err, log


@pytest.mark.parametrize("signum", [signal.SIGTSTP, signal.SIGTTOU])
def test_ctrl_z_does_not_suspend_a_show(tmp_path, signum) -> None:
    """Ctrl-Z (or a background run writing to a `stty tostop` terminal) stopped the process
    mid-show: no later cue played until someone typed `fg`."""
    code, err, log = _signalled_run(tmp_path, TIMED_SHOW, signum)
    assert code == 0, err
    assert len([m for m in read_log(log).topic("/choreo/step") if m.get("event") == "start"]) == 12


def test_ctrl_backslash_stops_a_show_as_ctrl_c_does(tmp_path) -> None:
    """SIGQUIT (Ctrl-\\ without the console) killed choreo: no abort motion, the log unfinished."""
    code, err, log = _signalled_run(tmp_path, "version: 1\nsteps:\n  - play: 1\n  - wait: 30\n", signal.SIGQUIT)
    assert code == 130, err
    assert b"show stopped (SIGQUIT)" in err and b"Traceback" not in err
    with log.open("rb") as stream:  # the log was closed (a killed run leaves no summary); the
        assert make_reader(stream).get_summary() is not None  # signal may come before the first step


def test_a_traceback_shows_outside_text_escaped_too() -> None:
    """A crash prints after the CLI's visible streams are gone: its message may hold a file name."""
    code = ("import threading, choreo.__main__ as entry\n"
            "entry.show_crashes_visibly()\n"
            "def crash():\n    raise OSError(f'cannot read {chr(27)}]0;pwned{chr(7)}{chr(0x202e)}')\n"
            "thread = threading.Thread(target=crash, name=f'thread{chr(27)}[2J')\n"
            "thread.start(); thread.join(); crash()\n")
    done = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, cwd=REPO, timeout=60)
    assert done.returncode == 1
    assert_safe(done.stderr)
    assert done.stderr.count("OSError: cannot read \\x1b]0;pwned\\x07\\u202e") == 2
    assert "Exception in thread thread\\x1b[2J" in done.stderr


@pytest.mark.parametrize("width", [2, 8, 20, 40, 43, 44, 60, 120])
def test_every_line_of_the_doctor_table_fits_the_terminal(width: int) -> None:
    """Beside a long check name (a robot's), the detail column had 24 columns at least and ran
    past the edge of a narrower terminal; there the detail goes below its check (issue 21, item 5)."""
    from choreo.board.doctor import Finding
    from choreo.cli.doctor import table

    findings = [Finding("problem", "port", f"sim://?durations=0:1.5,1:2,4:1.2,5:1.2,20:0.6,40:1 {HOSTILE} busy",
                        "close the other program", robot="a_robot_with_a_long_name"),
                Finding("ok", "log", "folder runs takes a new file"), Finding("note", "ロボット", "日本語の説明 " * 6)]
    lines = table(findings, width)
    assert all(display_width(line) <= width for line in lines), [line for line in lines if display_width(line) > width]
    assert_safe("\n".join(lines))
    joined = "".join(line.strip() for line in lines)
    assert "closetheotherprogram" in joined.replace(" ", "")  # the fix is wrapped, never cut


def test_validates_line_fits_the_terminal_and_stays_whole_in_a_pipe(tmp_path) -> None:
    """`choreo validate`'s ok line (every motion named) ran 168 columns on a terminal of 30
    (issue 21, item 5; `beats`' comments and `devices` alike, by the same print_fitted): cut
    there; whole to a pipe."""
    primary, secondary = _pty(30)
    env = {k: v for k, v in os.environ.items() if k not in ("COLUMNS", "LINES")}
    command = [str(REPO / ".venv" / "bin" / "choreo")]
    process = subprocess.Popen(command + ["validate", "shows/dance.yaml"], stdin=secondary, stdout=secondary,
                               stderr=secondary, cwd=REPO, env=env)
    os.close(secondary)
    seen = b""
    try:
        while select.select([primary], [], [], 20)[0]:
            try:
                data = os.read(primary, 65536)
            except OSError:
                break  # the command ended and closed the terminal
            if not data:
                break
            seen += data
    finally:
        assert process.wait(20) == 0
        os.close(primary)
    lines = seen.decode().splitlines()
    assert lines and all(display_width(line) <= 30 for line in lines), lines
    assert lines[0].startswith("shows/dance.yaml: ok") and lines[0].endswith("…")
    piped = subprocess.run(command + ["validate", "shows/dance.yaml"], capture_output=True, text=True, cwd=REPO,
                           env=env, check=True)
    assert piped.stdout.rstrip("\n").endswith("estimated 22.0 s")  # a pipe takes it whole


class _NarrowTerminal(io.StringIO):
    """A terminal whose width only COLUMNS tells (no descriptor to ask)."""

    def isatty(self) -> bool:
        return True


def test_report_lines_are_cut_to_a_terminal_and_whole_elsewhere(monkeypatch) -> None:
    """log merge, log export, replay, probe and ports say their lines through print_fitted, sim
    through a StatusWriter fitting them on a terminal (issue 21, item 5: log merge's ran 117
    columns on a terminal of 40)."""
    from choreo.cli.terminal import print_fitted

    monkeypatch.setenv("COLUMNS", "30")
    line = f"merged 2 logs, 83 messages, hosts stage-left (lead), stage-right (follow): /tmp/{HOSTILE}.mcap"
    terminal, pipe = _NarrowTerminal(), io.StringIO()
    print_fitted(line, terminal)
    print_fitted(line, pipe)
    assert display_width(terminal.getvalue().rstrip("\n")) == 30 and terminal.getvalue().endswith("…\n")
    assert pipe.getvalue() == visible(line) + "\n"
    assert_safe(terminal.getvalue() + pipe.getvalue())
    commands = ("log", "probe", "ports", "importer", "beats", "devices", "show")
    sources = {name: (REPO / "choreo" / "cli" / f"{name}.py").read_text() for name in commands}
    assert sources["log"].count("print_fitted(") >= 10 and all("print_fitted(" in text for text in sources.values())
    sim = (REPO / "choreo" / "cli" / "sim.py").read_text()
    assert "StatusWriter(sys.stderr, fit_lines=sys.stderr.isatty()" in sim and "print(" not in sim.replace(
        "print(server.path", "")  # the device paths alone go to stdout, whole


def test_choreo_sim_answers_while_its_journal_goes_to_a_pipe_nobody_reads() -> None:
    """`choreo sim -v` wrote each journal line from the board's thread: a pipe nobody read (or
    a terminal stopped with Ctrl-S) stopped its replies, and the show's link timed out (issue 21,
    item 5); its opening line, written before the boards served, held up their start. Its stderr
    has a thread of its own; the board answers. The pipe is full before the sim starts."""
    read, write = os.pipe()
    filler = os.open(f"/proc/self/fd/{write}", os.O_WRONLY | os.O_NONBLOCK)  # a description of its own:
    for size in (4096, 1):  # the sim's stays blocking; filled to the last byte
        with pytest.raises(BlockingIOError):
            while True:
                os.write(filler, b"x" * size)
    os.close(filler)
    sim = subprocess.Popen([sys.executable, "-m", "choreo", "sim", "-v"], stdout=subprocess.PIPE, stderr=write,
                           cwd=REPO, text=True, start_new_session=True)
    try:
        assert sim.stdout is not None
        device = sim.stdout.readline().strip()
        probe = subprocess.run([str(REPO / ".venv" / "bin" / "choreo"), "probe", "--port", device],
                               capture_output=True, text=True, cwd=REPO, timeout=60)
        assert probe.returncode == 0 and "answers on" in probe.stdout, probe.stdout + probe.stderr
    finally:
        os.killpg(sim.pid, signal.SIGKILL)
        sim.wait(10)
        os.close(read)
        os.close(write)


@pytest.mark.parametrize("width", [30, 80])
def test_every_commands_help_fits_the_terminal(monkeypatch, width: int) -> None:
    """argparse wraps help text, but not a usage line indented under a long command nor an
    option's choices, and `choreo sim --help`'s paragraphs were written out by hand (93 columns
    on a terminal of 80) (issue 21, item 5)."""
    import argparse

    from choreo.cli import build_parser

    monkeypatch.setenv("COLUMNS", str(width))

    def parsers(parser: argparse.ArgumentParser):  # type: ignore[no-untyped-def]
        yield parser
        for action in parser._actions:
            if isinstance(action, argparse._SubParsersAction):
                for sub in action.choices.values():
                    yield from parsers(sub)

    lines = [line for parser in parsers(build_parser()) for line in parser.format_help().splitlines()]
    assert len(lines) > 500 and [line for line in lines if display_width(line) > width] == []


@pytest.mark.parametrize("width", [4, 16, 40, 80])
def test_doctors_check_lines_wrap_within_the_terminal(width: int) -> None:
    """`choreo doctor` without a show: a check's line and its fix (150-257 columns) wrapped on
    a terminal, nothing of it cut (issue 21, item 5); to a pipe it stays one line."""
    from choreo.board.doctor import Finding
    from choreo.cli.doctor import _hanging

    line = Finding("problem", "board", f"no port to check: {HOSTILE} ロボット",
                   "choreo doctor --port /dev/ttyUSB0 (or sim:// to try the simulator)").line()
    lines = _hanging(line, width)
    assert all(display_width(shown) <= width for shown in lines), lines
    assert "".join(shown.strip() for shown in lines).replace(" ", "") == line.replace(" ", "")
    assert _hanging(line, None) == [line]
