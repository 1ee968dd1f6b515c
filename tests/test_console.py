"""The live console of `choreo run` on a terminal: what it draws at 60, 80 and 120 columns, the
keys (GO, the double-press lockout, panic, q then y or n), and the terminal put back after.

Unit tests draw the console of a prepared session (nothing opened) through rich into a string;
the rest run `choreo run` inside tmux (a private server a test, killed after), press keys with
send-keys and read the screen with capture-pane, polling with a deadline, never a fixed sleep.
"""

from __future__ import annotations

import io
import os
import pty
import re
import shlex
import shutil
import subprocess
import sys
import termios
import threading
import time
import uuid
from pathlib import Path

import pytest
from rich.console import Console as RichConsole

from choreo.clock import MachineShowClock
from hypothesis import given, settings
from hypothesis import strategies as st

from choreo.cli.console import Console
from choreo.cli.screen import LEGEND, SHORT_LEGEND, Note, Row, Screen, render
from choreo.cli.keys import ARROWS, KEYS, KeyParser, KeyReader, TerminalMode
from choreo.events import Answer, Command, CommandEvent, RxEvent, StepEvent, StopRequest, TxEvent
from choreo.live.controls import Live
from choreo.show.cues import CueList, cue_list
from choreo.log.format import WARNING
from choreo.wire.protocol import Reply, ReplyKind
from choreo.run.session import Session
from choreo.run.settings import RunRequest
from runlog import REPO, read_log, write_show

GO_SHOW = """\
version: 1
name: console test
motions:
  bow: {number: 2, duration: 0.1}
steps:
  - play: 1
  - play: bow
    at: go
    label: applause
  - wait: 0.2
  - play: 3
    at: 0.5
    label: after
  - play: 4
    at: go
    label: encore
"""

# GO_SHOW for keys on a terminal: its encore comes 0.5 s after the first GO (a wait, measured from
# it), past the GO lockout however late a loaded machine brought the show to its first cue. With
# the cue 'after' at 0.5 s of show between, the encore came 0.5 s less that lateness after the GO:
# a first cue reached at 0.4 s had the encore's GO refused as a double press, 0.44 s after the first.
KEYS_SHOW = GO_SHOW.replace("  - wait: 0.2\n  - play: 3\n    at: 0.5\n    label: after\n",
                            "  - wait: 0.5\n  - play: 3\n")

TWO_ROBOTS = """\
version: 1
name: a show for two robots with a name long enough to be cut at sixty columns
robots:
  alpha: {on_abort: 9}
  beta_with_a_long_name: {}
steps:
  - play: 1
  - play: 2
    at: go
    label: the-first-of-the-go-cues-with-a-long-label
"""

WIDTHS = (60, 80, 120)


def drawn(console: Console, width: int) -> list[str]:
    out = io.StringIO()
    RichConsole(file=out, width=width, color_system=None).print(console.renderable(width))
    return out.getvalue().splitlines()


def prepared(tmp_path: Path, body: str) -> tuple[Console, Session, Live]:
    session = Session.prepare(RunRequest(str(write_show(tmp_path, body)), no_log=True))
    live = Live(StopRequest(), cues=cue_list(session.settings.plans))
    return Console(session, live, out=io.StringIO(), keys=io.StringIO()), session, live


def tell(console: Console, live: Live, event: StepEvent) -> None:
    """A step event as a run tells it: to the console (its own status) and the live controls."""
    console.on_step(event)
    live.on_step(event)


def started(step, robot=None, at_s: float = 0.0) -> StepEvent:  # type: ignore[no-untyped-def]
    return StepEvent(step, "start", at_s, at_s, 0, robot=robot)


# -- what it draws -----------------------------------------------------------------------------


@pytest.mark.parametrize("width", WIDTHS)
def test_every_line_fits_the_width_and_the_key_parts_stay(tmp_path, width):
    console, session, live = prepared(tmp_path, TWO_ROBOTS)
    steps = session.settings.plans["alpha"].steps
    tell(console, live, started(steps[0], "alpha"))
    tell(console, live, started(steps[0], "beta_with_a_long_name"))
    console.on_log(WARNING, "robot alpha: step 0: NAK (04 0c 15 25) to 'play 1' (play frame, seq 3), " * 3)
    lines = drawn(console, width)
    assert all(len(line) <= width for line in lines), lines
    text = "\n".join(lines)
    assert lines[0].startswith("a show for two robots") and "show not started · machine clock" in lines[0]
    assert "next GO: cue 1 'the-first-of" in text and "(not reached yet)" in text
    assert any(line.startswith("alpha ") and "play 1" in line for line in lines)
    assert any(line.startswith("beta_with_a") for line in lines)
    assert lines[-1] == (LEGEND if width >= 80 else SHORT_LEGEND)
    assert any("…" in line for line in lines)  # cut, not wrapped


def test_the_screen_says_where_each_robot_is_and_what_comes(tmp_path):
    console, session, live = prepared(tmp_path, GO_SHOW)
    steps = session.settings.plans["robot"].steps
    tell(console, live, started(steps[0]))
    screen = console.screen()
    (row,) = screen.rows
    assert (row.robot, row.now, row.next) == ("robot", "play 1", "GO cue 1 'applause': play 2 (bow)")
    assert screen.go == "next GO: cue 1 'applause' (not reached yet)" and not screen.go_waiting
    assert screen.cue == "next cue: cue 2 'after' at 0.5 s"  # the clock has not started
    assert screen.show_s is None and screen.clock == "machine clock"
    tell(console, live, started(steps[2], at_s=0.1))
    assert console.screen().rows[0].next == "@0.5 s cue 2 'after': play 3"  # by its number in the cue list
    for step in (steps[1], steps[3]):
        tell(console, live, StepEvent(step, "start", 0.6, 0.6, 0))
        tell(console, live, StepEvent(step, "end", 0.6, 0.6, 0, outcome="ok"))
    tell(console, live, StepEvent(steps[4], "start", 0.6, 0.6, 0))
    tell(console, live, StepEvent(steps[4], "end", 0.6, 0.6, 0, outcome="ok"))
    screen = console.screen()
    assert screen.rows[0].now == "done" and screen.rows[0].next == "-"
    assert screen.cue == "next cue: none ahead" and screen.go == "next GO: none ahead"
    assert [(c.number, c.state) for c in screen.cues] == [("1", "done"), ("2", "done"), ("3", "done")]


def test_the_countdown_runs_on_the_show_clock(tmp_path):
    console, session, live = prepared(tmp_path, GO_SHOW)
    tell(console, live, started(session.settings.plans["robot"].steps[2], at_s=0.1))
    live.use_clock(MachineShowClock(session.clock.mono() - 0.2))  # 0.2 s into the show
    screen = console.screen()
    assert screen.cue == "next cue in 0.3 s: cue 2 'after' at 0.5 s" and screen.show_s == 0.2
    live.use_clock(MachineShowClock(session.clock.mono() - 0.7))  # the cue overrun
    assert console.screen().cue == "next cue due now: cue 2 'after' at 0.5 s"


def test_redraws_keep_clear_of_a_cue_and_of_a_go_and_draw_only_changes(tmp_path, monkeypatch):
    console, session, live = prepared(tmp_path, GO_SHOW)
    tell(console, live, started(session.settings.plans["robot"].steps[2], at_s=0.1))  # the wait before the cue at 0.5 s
    live.use_clock(MachineShowClock(session.clock.mono() - 10.0))  # both long past: nothing in the way
    assert console._quiet_left() == 0.0
    live.use_clock(MachineShowClock(session.clock.mono() - 0.48))  # the cue 20 ms from now
    assert 0.04 < console._quiet_left() <= 0.05 + 1e-3
    live.use_clock(MachineShowClock(session.clock.mono() - 10.0))
    console.on_command(CommandEvent(Command("go", "key"), Answer("ok", "GO: applause"), 0, 10.0))
    assert 0.02 < console._quiet_left() <= 0.03  # the GO's frames go out now

    updates = []
    monkeypatch.setattr(console._rich, "update", lambda renderable, refresh: updates.append(renderable))
    live.use_clock(HeldAt(10.0))
    console._draw()
    console._draw()  # nothing changed: not drawn again
    console.on_log(WARNING, "something")
    console._draw()
    assert len(updates) == 2


class HeldAt:
    """A show clock standing still."""

    def __init__(self, show_s: float) -> None:
        self.show_s = show_s

    def show_at(self, mono: float) -> float:
        return self.show_s

    def mono_at(self, show_s: float) -> float:
        return float("inf")


def test_the_link_column_is_the_median_latency_and_the_retries(tmp_path):
    console, session, live = prepared(tmp_path, GO_SHOW)
    watch = console.status.link_listener("robot")
    frame = session.settings.plans["robot"].steps[0].frames[0]
    for ms in (1.0, 2.0, 9.0):
        watch.on_rx(RxEvent(1, frame, Reply(ReplyKind.ACK), 0, ms / 1e3, None))
    watch.on_tx(TxEvent(2, frame, 2, 0, None))
    watch.on_rx(RxEvent(2, frame, Reply(ReplyKind.TIMEOUT), 0, 0.2, None))
    row = console.screen().rows[0]
    assert (row.latency_ms, row.retries, row.trouble) == (2.0, 1, True)
    assert "2.0 ms, 1 retry" in "\n".join(drawn(console, 80))
    assert "2.0ms r1" in "\n".join(drawn(console, 60))


def test_a_waiting_go_cue_is_highlighted_and_commands_are_answered_on_screen(tmp_path):
    console, session, live = prepared(tmp_path, GO_SHOW)
    live.subscribe(console)
    # reached, then gave up
    live.await_go(session.settings.plans["robot"].steps[1], "robot", reached_s=0.0, should_stop=lambda: True)
    screen = console.screen()
    assert screen.go_waiting and screen.go == "GO fires cue 1 'applause': press Space or Enter"
    assert screen.rows[0].now == "waits for GO: cue 1 'applause'"
    live.command(Command("go", "osc udp 127.0.0.1:53001"))
    live.command(Command("go", "key"))
    notes = [(note.text, note.aside) for note in console.screen().notes]
    assert notes[0] == ("GO: cue 1 'applause'", "osc udp 127.0.0.1:53001")  # who sent it: said after, cut first
    notes = [note.text for note in console.screen().notes]
    assert notes[1].startswith("GO ignored: 0.") and "a double press?" in notes[1]


def test_a_screen_renders_whole_at_120_columns():
    screen = Screen("show", 12.34, "music clock", "next cue in 1.0 s: step 3 at 13 s", "next GO: none ahead", False,
                    (Row("robot", "2: play 1", "-", 1.25, 0),), (Note("hello", "", 1.0),))
    lines = [line.rstrip() for line in _render_text(screen, 120)]
    assert lines[0].endswith("show 12.3 s · music clock") and len(lines[0]) == 120
    assert lines[3].split() == ["robot", "now", "next", "link", "(median,", "retries)"]
    assert lines[4].split() == ["robot", "2:", "play", "1", "-", "1.2", "ms,", "0", "retries"]
    assert lines[6] == "    1.0 s  hello" and lines[7] == LEGEND


def _render_text(screen: Screen, width: int) -> list[str]:
    out = io.StringIO()
    RichConsole(file=out, width=width, color_system=None).print(render(screen, width))
    return out.getvalue().splitlines()


# -- keys --------------------------------------------------------------------------------------


class Commands:
    """A Live stand-in that keeps the commands it is given."""

    def __init__(self) -> None:
        self.given: list[str] = []
        self.show = MachineShowClock(time.monotonic())
        self.stop = StopRequest()
        self.panicked = False
        self.started = True
        self.waiting: list = []
        self.cues = CueList()
        self.playhead = None
        self.paused = False
        self.labels: list[str | None] = []

    def cue_state(self, cue) -> str:  # type: ignore[no-untyped-def]
        return "ahead"

    def skipped(self, robot: str, index: int) -> bool:
        return False

    def command(self, command: Command):  # type: ignore[no-untyped-def]
        assert command.source == "key"
        self.given.append(command.name)
        self.labels.append(command.label)
        if command.name in ("pause", "resume"):
            self.paused = command.name == "pause"


def test_keys_become_commands_and_q_asks_first(tmp_path):
    console, session, _ = prepared(tmp_path, GO_SHOW)
    console.live = commands = Commands()  # type: ignore[assignment]
    for key in ("space", "q", "n", "enter", "q", "escape", "q", "y", "x"):
        console.on_key(key)
    # q then n: nothing; q then Esc: panic all the same; q then y: stop; a stray key: nothing
    assert commands.given == ["go", "go", "panic", "stop"]
    assert [n.text for n in console.screen().notes] == ["stop cancelled: the show goes on"]


def test_the_key_reader_tells_esc_from_an_arrow_key():
    read, write = os.pipe()
    keys: list[str] = []
    got = threading.Event()
    reader = KeyReader(read, lambda key: (keys.append(key), got.set()))
    reader.start()
    try:
        for sent, expected in ((b"\x1b[A", "up"), (b"\x1bOB", "down"), (b"\x1b[1;5C", None), (b"\x1b\x1b[D", None),
                               (b"\x1b\x1bOP", None), (b"\x1b[1;3D", None), (b"\x1bq", None), (b" ", "space"),
                               (b"\r", "enter"), (b"\x1b", "escape"), (b"\x1b\x1b", "escape"), (b"q", "q"),
                               (b"y", "y")):
            got.clear()
            os.write(write, sent)
            if expected is None:
                assert not got.wait(0.1), keys
            else:
                assert got.wait(2) and keys.pop() == expected
        assert keys == []
    finally:
        reader.close()
        os.close(write)
        os.close(read)


# What terminals send for keys that are not Esc (xterm, VTE, Terminal.app, iTerm2, rxvt, tmux,
# screen, the Linux console, PuTTY): arrows, function keys, Alt with each, replies, mouse, paste.
NOT_ESC = [
    b"\x1b[C", b"\x1b[D", b"\x1bOC", b"\x1bOD", b"\x1b[H", b"\x1b[F", b"\x1b[1~",
    b"\x1b[4~", b"\x1b[5~", b"\x1b[6~", b"\x1b[2~", b"\x1b[3~", b"\x1b[Z",  # arrows, Home/End, PgUp, Ins, Del, S-Tab
    b"\x1bOP", b"\x1bOQ", b"\x1bOR", b"\x1bOS", b"\x1b[15~", b"\x1b[17~", b"\x1b[24~", b"\x1b[11~",  # F-keys
    b"\x1b[[A", b"\x1b[[E", b"\x1bO2P", b"\x1b[1;2P", b"\x1b[15;5~",  # Linux console F1/F5; modified F-keys
    b"\x1b[1;3D", b"\x1b[1;3C", b"\x1b[1;9A", b"\x1b[1;5D", b"\x1b[1;6B",  # Alt/Ctrl/Shift+arrow (xterm)
    b"\x1b\x1b[D", b"\x1b\x1b[A", b"\x1b\x1bOD", b"\x1b\x1b[1;5C",  # Alt+arrow (Terminal.app, rxvt, PuTTY)
    b"\x1b\x1bOP", b"\x1b\x1b[15~", b"\x1b\x1b[24~", b"\x1b\x1b[[A", b"\x1b[1;3P", b"\x1b[15;3~",  # Alt+F-keys
    b"\x1bq", b"\x1b ", b"\x1b\r", b"\x1bQ", b"\x1b\x7f", b"\x1by", b"\x1b\x1bq",  # Alt+key
    b"\x1b]11;rgb:0000/0000/0000\x07", b"\x1b]10;rgb:ffff/ffff/ffff\x1b\\", b"\x1bP1$r0m\x1b\\",  # replies
    b"\x1b[?1;2c", b"\x1b[24;80R", b"\x1b[I", b"\x1b[O",  # device attributes, cursor report, focus
    b"\x1b[M !!", b"\x1b[M#q ", b"\x1b[<0;12;5M", b"\x1b[<0;12;5m",  # mouse: X10 (a space in it), SGR
    b"\x1b[200~go q y \r\n\x1b[201~",  # a bracketed paste with spaces and q in it
    b"\x1b#8", b"\x1b(B", b"\x1b%G", b"\x1b\x1b(0", b"\x1bNa",  # intermediates and a final; SS2 (issue 21, item 5)
]


@pytest.mark.parametrize("sequence", NOT_ESC, ids=lambda b: b.hex(" "))
def test_only_a_bare_esc_panics_every_other_sequence_is_read_whole_and_ignored(sequence: bytes) -> None:
    parser = KeyParser()
    assert parser.feed(sequence) + parser.timeout() == []
    bytewise = KeyParser()  # the same, a byte a read
    assert [k for byte in sequence for k in bytewise.feed(bytes([byte]))] == []
    assert bytewise.feed(b" ") == ["space"]  # and the next key is a key
    assert parser.feed(b"\x1b") == [] and parser.timeout() == ["escape"]


def test_keys_and_bare_escs() -> None:
    parser = KeyParser()
    assert parser.feed(b" \r\nqQyx") == ["space", "enter", "enter", "q", "Q", "y", "x"]  # as typed
    assert parser.feed(b"\x03\x00\xe3\x83\xad\t") == ["ロ"]  # control bytes are no keys; UTF-8, its character
    assert parser.feed(b"\x1b") == [] and parser.pending and parser.timeout() == ["escape"]
    assert parser.feed(b"\x1b\x1b") == [] and parser.timeout() == ["escape"]  # Esc twice in a hurry
    assert parser.feed(b"\x1b\x1b\x1b") == ["escape"] and parser.timeout() == ["escape"]
    assert parser.feed(b"\x1b[1\x1b") == [] and parser.timeout() == ["escape"]  # broken off by an Esc
    assert not parser.pending and parser.timeout() == []


def test_a_sequence_cut_short_ends_at_the_pause() -> None:
    parser = KeyParser()
    for cut in (b"\x1b[1;3", b"\x1b]0;title", b"\x1b[200~abc", b"\x1b[M", b"\x1bO", b"\x1b\x1b["):
        assert parser.feed(cut) == [] and parser.pending
        assert parser.timeout() == [] and not parser.pending
        assert parser.feed(b" ") == ["space"]


_final = st.integers(0x40, 0x7E).map(lambda b: bytes([b]))
_params = st.binary(max_size=12).map(lambda raw: bytes(0x30 + b % 16 for b in raw))
_csi = st.builds(lambda p, f: b"\x1b[" + p + f, _params, _final.filter(lambda f: f not in (b"M", b"["))).filter(
    lambda s: s[1:] not in ARROWS)  # Up and Down are keys
_ss3 = st.builds(lambda p, f: b"\x1bO" + p + f, _params, _final).filter(lambda s: s[1:] not in ARROWS)
_alt = st.integers(0x20, 0x7E).map(lambda b: b"\x1b" + bytes([b])).filter(
    lambda s: s[1:] not in (b"[", b"O", b"]", b"P", b"X", b"^", b"_"))
_osc = st.builds(lambda text, end: b"\x1b]" + text + end, st.binary(max_size=20).map(
    lambda raw: bytes(0x20 + b % 0x5F for b in raw)), st.sampled_from([b"\x07", b"\x1b\\"]))
_sequence = st.one_of(_csi, _ss3, _alt, _osc, st.sampled_from(NOT_ESC))
_alt_sequence = st.one_of(_csi, _ss3).map(lambda s: b"\x1b" + s)  # ESC ESC [ ...: Alt with a key's sequence


@given(st.lists(st.one_of(_sequence, _alt_sequence), max_size=12), st.lists(st.integers(1, 8), min_size=1))
@settings(max_examples=400, deadline=None)
def test_any_run_of_key_sequences_in_any_chunks_gives_no_key(sequences: list[bytes], cuts: list[int]) -> None:
    data = b"".join(sequences)
    parser = KeyParser()
    keys: list[str] = []
    at = 0
    for cut in cuts * (len(data) + 1):
        if at >= len(data):
            break
        keys += parser.feed(data[at:at + cut])
        at += cut
    assert keys + parser.timeout() == []
    assert parser.feed(b"\x1b") == [] and parser.timeout() == ["escape"]


@given(st.binary(max_size=300))
@settings(max_examples=400, deadline=None)
def test_after_any_bytes_and_a_pause_esc_and_go_work(noise: bytes) -> None:
    parser = KeyParser()
    keys = parser.feed(noise) + parser.timeout()
    named = set(KEYS.values()) | {"escape", "up", "down"}
    assert all(key in named or len(key) == 1 and key.isprintable() and key != " " for key in keys)  # typed ones
    assert parser.feed(b"\x1b") == [] and parser.timeout() == ["escape"]
    assert parser.feed(b" ") == ["space"]


class BrokenTerminal(io.StringIO):
    """A terminal that has gone away."""

    def isatty(self) -> bool:
        return True

    def write(self, text: str) -> int:
        raise OSError(5, "Input/output error")


def test_the_terminal_is_put_back_exactly_even_when_the_screen_fails(tmp_path):
    primary, secondary = pty.openpty()
    with os.fdopen(secondary, "r") as tty:
        before = termios.tcgetattr(secondary)
        mode = TerminalMode(secondary)
        mode.enter()
        lflag = termios.tcgetattr(secondary)[3]
        assert not lflag & termios.ICANON and not lflag & termios.ECHO and lflag & termios.ISIG
        mode.restore()
        assert termios.tcgetattr(secondary) == before

        session = Session.prepare(RunRequest(str(write_show(tmp_path, GO_SHOW)), no_log=True))
        console = Console(session, Live(StopRequest()), out=io.StringIO(), keys=tty)
        console.start()
        assert not termios.tcgetattr(secondary)[3] & termios.ICANON
        console.close()
        assert termios.tcgetattr(secondary) == before

        console = Console(session, Live(StopRequest()), out=BrokenTerminal(), keys=tty)
        with pytest.raises(OSError):  # the screen cannot be drawn: start fails, the terminal is restored
            console.start()
        assert termios.tcgetattr(secondary) == before
    os.close(primary)


# -- the console in a terminal (tmux) ----------------------------------------------------------

needs_tmux = pytest.mark.skipif(shutil.which("tmux") is None, reason="tmux is not installed")
# how long a pane's screen or exit is polled for: the first includes choreo's start (a Python, its
# imports, the show's preparation), seconds on a loaded machine; a poll ends as soon as it is there
SCREEN_S = 30.0


class Pane:
    """`choreo run ...` in a tmux pane of its own server; after it exits, its exit status and
    `stty -a` go to files (the terminal as choreo left it)."""

    def __init__(self, tmp_path: Path, args: list[str], width: int = 80, height: int = 24,
                 env: dict[str, str] | None = None) -> None:
        # the pane's environment is the server's, which is this one: an explicit copy, since
        # readline (which pytest loads) exports COLUMNS and LINES behind os.environ's back
        self.env = {k: v for k, v in os.environ.items() if k not in ("COLUMNS", "LINES", "TMUX")}
        self.env.update(env or {})
        self.socket = f"choreo-console-{uuid.uuid4().hex[:12]}"
        self.exit_file = tmp_path / "exit"
        self.stty_file = tmp_path / "stty"
        # this interpreter's choreo: CI's pass on the lowest dependency versions runs in a venv of its own
        choreo = shlex.join([sys.executable, "-m", "choreo", "run", *args])
        script = (f"cd {shlex.quote(str(REPO))} && {choreo}; echo $? > {self.exit_file}.tmp; "
                  f"stty -a > {self.stty_file}; mv {self.exit_file}.tmp {self.exit_file}; sleep 60")
        self._tmux("new-session", "-d", "-x", str(width), "-y", str(height), "-s", "run",
                   f"sh -c {shlex.quote(script)}")

    def _tmux(self, *args: str) -> str:
        return subprocess.run(["tmux", "-L", self.socket, "-f", "/dev/null", *args], check=True,
                              capture_output=True, text=True, timeout=10, env=self.env).stdout

    def keys(self, *keys: str) -> None:
        self._tmux("send-keys", "-t", "run", *keys)

    def screen(self) -> str:
        return self._tmux("capture-pane", "-p", "-t", "run")

    def wait_for(self, text: str, timeout: float = SCREEN_S) -> str:
        """The first screen showing `text` that is drawn whole: the same on a second look a
        moment later (tmux may capture a redraw half done: its top lines new, the ones below
        still the screen before, which a test reading those lines would take for the console's)."""
        deadline = time.monotonic() + timeout
        while True:
            screen = self.screen()
            if text in screen:
                time.sleep(0.03)
                if self.screen() == screen:
                    return screen
            assert time.monotonic() < deadline, f"{text!r} never appeared (drawn whole); the screen:\n{screen}"
            time.sleep(0.02)

    def exit_code(self, timeout: float = SCREEN_S) -> int:
        deadline = time.monotonic() + timeout
        while not self.exit_file.exists():
            assert time.monotonic() < deadline, f"choreo run did not exit; the screen:\n{self.screen()}"
            time.sleep(0.02)
        return int(self.exit_file.read_text())

    def terminal_restored(self) -> bool:
        flags = self.stty_file.read_text().split()
        return "icanon" in flags and "echo" in flags and "-icanon" not in flags and "-echo" not in flags

    def close(self) -> None:
        subprocess.run(["tmux", "-L", self.socket, "kill-server"], capture_output=True, timeout=10)


@pytest.fixture
def pane(tmp_path):
    panes: list[Pane] = []

    def open_pane(body: str, width: int = 80, env: dict[str, str] | None = None) -> Pane:
        show = write_show(tmp_path, body)
        panes.append(Pane(tmp_path, [str(show), "--log", str(tmp_path / "run.mcap")], width, env=env))
        return panes[-1]

    yield open_pane
    for opened in panes:
        opened.close()


def commands_in(tmp_path: Path) -> list[tuple[str, str, str]]:
    return [(m["command"], m["source"], m["status"]) for m in read_log(tmp_path / "run.mcap").topic("/choreo/command")]


@needs_tmux
def test_go_releases_the_waiting_cue_and_a_double_press_is_refused(tmp_path, pane):
    run = pane(KEYS_SHOW)
    run.wait_for("GO fires cue 1 'applause'")
    run.keys("Space", "Space")  # one press too many, well within the lockout
    screen = run.wait_for("GO fires cue 2 'encore'")
    assert "GO: cue 1" in screen and "double press?" in screen
    run.keys("Enter")  # the encore waits 0.5 s after the GO: past the lockout
    assert run.exit_code() == 0
    assert "encore" in run.screen() and "the run is over; keys off" in run.screen()
    assert commands_in(tmp_path) == [("go", "key", "ok"), ("go", "key", "error"), ("go", "key", "ok")]
    assert run.terminal_restored()


@needs_tmux
def test_esc_panics_every_robot_and_exits_130(tmp_path, pane):
    run = pane(TWO_ROBOTS)
    run.wait_for("GO fires")
    run.keys("Escape")
    assert run.exit_code() == 130
    assert "the show was stopped by panic" in run.screen()
    assert commands_in(tmp_path) == [("panic", "key", "ok")]
    log = read_log(tmp_path / "run.mcap")
    a = [(m["kind"], m.get("motion"), m.get("label")) for m in log.topic("/rcb4/alpha/tx")]
    b = [(m["kind"], m.get("motion"), m.get("label")) for m in log.topic("/rcb4/beta_with_a_long_name/tx")]
    assert a[-3:] == [("stop", 9, "on_abort"), ("play", 9, "on_abort"), ("restore", 9, "on_abort")]
    assert (b[-1][0], b[-1][2]) == ("stop", "on_abort")  # no abort motion: the stop frame
    assert run.terminal_restored()


@needs_tmux
def test_q_asks_n_goes_on_y_stops(tmp_path, pane):
    run = pane(KEYS_SHOW)
    run.wait_for("GO fires cue 1 'applause'")
    run.keys("Left")  # an arrow key's escape sequence is not Esc
    run.keys("q")
    run.wait_for("stop the show? y/n")
    run.keys("n")
    run.wait_for("stop cancelled")
    run.keys("Space")
    run.wait_for("GO fires cue 2 'encore'")
    run.keys("q")
    run.wait_for("stop the show? y/n")
    run.keys("y")
    assert run.exit_code() == 130
    assert "the show was stopped; keys off" in run.screen()
    assert commands_in(tmp_path) == [("go", "key", "ok"), ("stop", "key", "ok")]
    assert run.terminal_restored()


@needs_tmux
def test_sixty_columns_draw_without_wrapping(tmp_path, pane):
    run = pane(TWO_ROBOTS, 60, {"COLUMNS": "132", "LINES": "50"})  # the terminal's own size wins
    screen = run.wait_for("GO fires")
    lines = screen.splitlines()
    assert all(len(line) <= 60 for line in lines)
    # the show time the clock was held at: 0.0 s, or later when a loaded machine reached the GO late
    title = [line for line in lines if re.search(r"show \d+\.\d s · machine clock, held for GO", line)]
    assert len(title) == 1 and title[0].startswith("a show for two"), screen  # one line, drawn once
    assert any(line.startswith("alpha, beta_with_a… wait for GO: cue 1 'the-first") for line in lines), screen
    assert SHORT_LEGEND in lines
    run.keys("Escape")
    assert run.exit_code() == 130
    assert run.terminal_restored()


def _two_gos_and_nothing_else(run, tmp_path: Path) -> None:  # type: ignore[no-untyped-def]
    """After keys that must do nothing: Space and Enter GO the two cues, and only they were commands."""
    run.keys("Space")
    run.wait_for("GO fires cue 2 'encore'")
    run.keys("Enter")
    assert run.exit_code() == 0
    assert commands_in(tmp_path) == [("go", "key", "ok"), ("go", "key", "ok")]
    assert run.terminal_restored()


@needs_tmux
def test_alt_arrows_and_alt_f_keys_do_not_panic(tmp_path, pane):
    run = pane(KEYS_SHOW)
    run.wait_for("GO fires cue 1 'applause'")
    run.keys("M-Left", "M-F1", "M-Up", "Left")  # tmux's own (xterm) sequences
    for raw in ("1b 1b 5b 44", "1b 1b 4f 50", "1b 1b 5b 31 35 7e", "1b 1b 5b 43"):  # ESC ESC [ D ...
        run._tmux("send-keys", "-t", "run", "-H", *raw.split())
    _two_gos_and_nothing_else(run, tmp_path)


@needs_tmux
def test_ctrl_keys_the_terminal_would_act_on_reach_the_console_and_do_nothing(tmp_path, pane):
    """Ctrl-Z would suspend the show mid-motion, Ctrl-\\ kill it (no abort motion, no closed log),
    Ctrl-S freeze the screen: in the console each is a byte it ignores."""
    run = pane(KEYS_SHOW)
    run.wait_for("GO fires cue 1 'applause'")
    for key in ("C-z", "C-\\", "C-s", "C-y", "C-v", "C-o", "C-q", "C-d", "C-w", "C-u", "C-r", "C-t"):
        run.keys(key)
    _two_gos_and_nothing_else(run, tmp_path)


def test_the_key_mode_takes_suspend_quit_and_flow_control_from_the_terminal():
    primary, secondary = pty.openpty()
    try:
        before = termios.tcgetattr(secondary)
        mode = TerminalMode(secondary)
        mode.enter()
        iflag, lflag, chars = (termios.tcgetattr(secondary)[i] for i in (0, 3, 6))
        assert not iflag & termios.IXON and not lflag & termios.IEXTEN and lflag & termios.ISIG
        off = bytes([os.fpathconf(secondary, "PC_VDISABLE") % 256])
        assert chars[termios.VSUSP] == off and chars[termios.VQUIT] == off
        assert chars[termios.VINTR] == before[6][termios.VINTR]  # Ctrl-C still stops the show
        mode.restore()
        assert termios.tcgetattr(secondary) == before
    finally:
        os.close(primary)
        os.close(secondary)


# Pastes: whatever text is between the terminal's paste marks, none of it is a key.
PASTES = [b"Iraqy see you ", b"a\x1b", b"\x1b\x1b", b"\x1b[1", b"\x1b]0;title", b"\x1bP", b"\x1b[200~q y",
          b"\x1b[201", b"\x1b[20", b"\x1b[M", b" \r\n\t\x03\x1a" * 3, b"\xe3\x83\xad \xff\x9b q", b"\x1b" * 7]


@pytest.mark.parametrize("text", PASTES, ids=lambda b: b.hex(" "))
def test_a_paste_is_skipped_whatever_it_holds_in_any_chunks(text: bytes) -> None:
    data = b"\x1b[200~" + text + b"\x1b[201~"
    for cut in range(1, len(data) + 1):  # the paste's end split across reads at every byte
        parser = KeyParser()
        assert parser.feed(data[:cut]) + parser.feed(data[cut:]) == [], cut
        assert not parser.pending and parser.feed(b"q ") == ["q", "space"]
    bytewise = KeyParser()
    assert [k for byte in data for k in bytewise.feed(bytes([byte]))] == [] and not bytewise.pending


def test_a_megabyte_paste_gives_no_key() -> None:
    text = b"x q y \x1b \x1b[201 \x1b]0;t\x07 " * 40_000
    parser = KeyParser()
    data = b"\x1b[200~" + text + b"\x1b[201~ "
    keys = [k for at in range(0, len(data), 4096) for k in parser.feed(data[at:at + 4096])]
    assert keys == ["space"]  # only the space after the paste


def test_a_pause_in_a_paste_is_not_its_end():
    """A big paste over a slow link comes in pieces: the escape wait ends no paste."""
    read, write = os.pipe()
    keys: list[str] = []
    reader = KeyReader(read, keys.append, escape_wait_s=0.01, paste_wait_s=30.0)
    reader.start()
    try:
        os.write(write, b"\x1b[200~first part ")
        time.sleep(0.1)  # ten escape waits
        os.write(write, b"q y \x1b[201~")
        got = threading.Event()
        reader.on_key = lambda key: (keys.append(key), got.set())
        os.write(write, b" ")
        assert got.wait(5) and keys == ["space"]
    finally:
        reader.close()
        os.close(write)
        os.close(read)


def test_the_console_asks_the_terminal_to_mark_pastes_and_stops_asking_after(tmp_path):
    primary, secondary = pty.openpty()
    with os.fdopen(secondary, "r") as tty:
        session = Session.prepare(RunRequest(str(write_show(tmp_path, GO_SHOW)), no_log=True))
        out = io.StringIO()
        console = Console(session, Live(StopRequest()), out=out, keys=tty, width=80)
        console.start()
        assert "\x1b[?2004h" in out.getvalue() and "\x1b[?2004l" not in out.getvalue()
        console.close()
        assert out.getvalue().rfind("\x1b[?2004l") > out.getvalue().rfind("\x1b[?2004h")
    os.close(primary)


@needs_tmux
def test_a_paste_is_no_key_in_a_run(tmp_path, pane):
    run = pane(KEYS_SHOW)
    run.wait_for("GO fires cue 1 'applause'")
    run._tmux("set-buffer", "-b", "text", "Iraqy: see you at the party, q y\n")
    run._tmux("paste-buffer", "-p", "-b", "text", "-t", "run")
    run.keys("Space")
    run.wait_for("GO fires cue 2 'encore'")
    run.keys("Enter")
    assert run.exit_code() == 0
    assert commands_in(tmp_path) == [("go", "key", "ok"), ("go", "key", "ok")]


WIDE_NAMES = """\
version: 1
name: ロボットのショー with a name long enough to be cut e\u0301\u0301 終わり
robots:
  alpha: {}
  bravo: {}
motions:
  歩く: {number: 2, duration: 0.1}
tracks:
  alpha:
    - play: 歩く
      label: ラベルの長い名前です
    - play: 1
      at: go
      label: 日本語のキュー
  bravo:
    - play: 3
      at: 30
"""


@needs_tmux
def test_after_each_resize_every_line_on_the_terminal_fits_it(tmp_path, pane):
    """tmux re-wraps the screen when its width changes, as VTE and iTerm2 do: a redraw that moved
    up over the old lines left pieces of them above the console, wider than the terminal."""
    from choreo.textfit import display_width

    run = pane(WIDE_NAMES, 80)
    run.wait_for("GO fires")
    for width in (25, 60, 20, 33, 100, 40):
        run._tmux("resize-window", "-t", "run", "-x", str(width))
        deadline = time.monotonic() + SCREEN_S
        while True:
            joined = run._tmux("capture-pane", "-p", "-J", "-t", "run").splitlines()  # wrapped rows joined
            wide = [line for line in joined if display_width(line.rstrip()) > width]
            if not wide and any("show " in line and " s · " in line for line in joined):
                break
            assert time.monotonic() < deadline, (width, wide)
            time.sleep(0.05)
    run.keys("Escape")
    assert run.exit_code() == 130
    assert run.terminal_restored()


def test_keys_typed_before_the_console_takes_the_terminal_are_dropped():
    """A Space typed while choreo loaded started a show run with --wait-start as soon as the
    console read keys."""
    primary, secondary = pty.openpty()
    keys: list[str] = []
    got = threading.Event()
    reader = KeyReader(secondary, lambda key: (keys.append(key), got.set()))
    try:
        os.write(primary, b" \r")  # typed before: the terminal holds it, unread
        mode = TerminalMode(secondary)
        mode.enter()
        reader.start()
        os.write(primary, b"q")
        assert got.wait(5) and keys == ["q"]
        mode.restore()
    finally:
        reader.close()
        os.close(primary)
        os.close(secondary)


@needs_tmux
def test_a_space_typed_while_choreo_loads_does_not_start_a_wait_start_show(tmp_path):
    show = write_show(tmp_path, GO_SHOW)
    run = Pane(tmp_path, [str(show), "--wait-start", "--log", str(tmp_path / "run.mcap")])
    try:
        run.keys("Space")  # choreo is still loading
        run.wait_for("the show waits for its start")
        time.sleep(0.3)  # had it read the Space, the show would be under way by now
        assert "the show waits for its start" in run.screen()
        run.keys("Escape")
        assert run.exit_code() == 130
        assert commands_in(tmp_path) == [("panic", "key", "ok")]
    finally:
        run.close()


# Replies and sequences longer than the parser keeps: a clipboard's (OSC 52), a capability list
# (DCS), a CSI with many parameters, Alt with one; each with keys in it, none of them keys.
LONG = [b"\x1b]52;c;" + b"QUJD q y " * 200 + b"\x07", b"\x1bP1+r" + b"q y " * 300 + b"\x1b\\",
        b"\x1b[" + b"1;" * 500 + b"m", b"\x1b\x1b]" + b"q y " * 300 + b"\x1b\\", b"\x1bO" + b"2;" * 300 + b"P",
        b"\x1b_" + b"\x1b[201~ q " * 100 + b"\x1b\\"]


@pytest.mark.parametrize("sequence", LONG, ids=lambda b: f"{b[:3].hex(' ')}x{len(b)}")
def test_a_sequence_of_any_length_is_read_to_its_end(sequence: bytes) -> None:
    parser = KeyParser()
    assert parser.feed(sequence) == [] and not parser.pending
    assert parser.feed(b" q") == ["space", "q"]
    bytewise = KeyParser()
    assert [k for byte in sequence + b" " for k in bytewise.feed(bytes([byte]))] == ["space"]


# A terminal sending 8-bit controls (VT220 and up, xterm after S8C1T): raw, or as UTF-8 (C2 9B).
EIGHT_BIT = [b"\x9bC", b"\x9b1;5C", b"\x8fP", b"\x9b200~go q y \r\x9b201~", b"\x9bM !!", b"\x9bM  q",
             b"\x9d11;rgb:0000/0000/0000 q y\x9c", b"\x90q y $r0m\x9c", b"\x9f q y \x07",
             b"\xc2\x9bD", b"\xc2\x9b200~ q y \xc2\x9b201~", b"\xc2\x9d0;\xe3\x80\x9c q y\xc2\x9c", b"\xc2\x9bM q "]


@pytest.mark.parametrize("sequence", EIGHT_BIT, ids=lambda b: b.hex(" "))
def test_a_sequence_begun_by_an_8_bit_control_is_no_key(sequence: bytes) -> None:
    parser = KeyParser()
    assert parser.feed(sequence) + parser.timeout() == []
    bytewise = KeyParser()
    assert [k for byte in sequence for k in bytewise.feed(bytes([byte]))] + bytewise.timeout() == []
    assert parser.feed(b" q") == ["space", "q"]


def test_utf8_text_typed_is_its_characters_and_no_sequence() -> None:
    parser = KeyParser()  # 〛 and 〜 end in 9B and 9C: continuation bytes, not 8-bit controls
    assert parser.feed("〛 q 〜 ロボ\u009c ".encode()) == ["〛", "space", "q", "space", "〜", "space", "ロ", "ボ",
                                                           "space"]  # (a C1 control is no key)
    assert parser.feed("\x1b〛 q".encode()) == ["space", "q"]  # Alt+〛 (no key), then keys
    assert parser.feed("お".encode()[:2]) == [] and parser.feed("お".encode()[2:]) == ["お"]  # across reads
    assert parser.feed("\u200b\u202e".encode()) == []  # invisible and bidi characters are no key
    assert not parser.pending
