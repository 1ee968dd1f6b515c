"""The console as a stage manager found it (issue 24's review): one number a cue on the whole
screen (rows name a cue's step by its cue number), a skipped cue never shown as anyone's next
step (screen and `/choreo/status`), messages cut in their outside text and never in what they
tell the operator to do, no `-0.0`, keys that say and do the same in either case, and a
mistyped cue answered with the nearest one. No terminal: screens as values, drawn through rich."""

from __future__ import annotations

import io
import os
import time
from pathlib import Path

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from rich.console import Console as RichConsole

from choreo.cli import screen

from choreo.cli.console import Console
from choreo.cli.keys import PASTE_WAIT_S, KeyParser, KeyReader, unmarked_paste
from choreo.cli.screen import (
    LEGEND,
    PAUSED_LEGEND,
    SHORT_PAUSED_LEGEND,
    Note,
    Screen,
    fit_message,
    render,
    seconds,
)
from choreo.events import Answer, Command, CommandEvent, StepEvent, StopRequest
from choreo.live.controls import Live
from choreo.live.status import ShowStatus
from choreo.run.session import Session
from choreo.run.settings import RunRequest
from choreo.show.cues import cue_list
from choreo.textfit import display_width
from runlog import write_show
from test_console import Pane, commands_in, needs_tmux, pane  # noqa: F401 - pane: the fixture

EVENING = """\
version: 1
name: Evening
robots:
  left: {}
  right: {}
motions:
  home: {number: 0, duration: 1.5}
  bow:  {number: 1, duration: 2.0}
  wave: {number: 2, duration: 1.2}
  clap: {number: 3, duration: 0.6}
on_abort: home
steps:
  - {play: bow, at: go, label: applause}
  - wait: done
  - {play: wave, at: 4, label: hello world}
  - wait: done
  - {play: clap, at: go, cue: 12.5, label: act 2/intro}
  - wait: done
  - {play: bow, at: 10, label: finale}
  - wait: done
  - {play: home, at: go, label: curtain}
  - wait: done
"""


def evening(tmp_path: Path) -> tuple[Console, Session, Live, ShowStatus]:
    """The run's one status, given to the live controls and the console, as `choreo run` does."""
    session = Session.prepare(RunRequest(str(write_show(tmp_path, EVENING)), no_log=True))
    settings = session.settings
    status = ShowStatus(settings.plans, settings.sections.starts)
    live = Live(StopRequest(), cues=cue_list(settings.plans), status=status)
    console = Console(session, live, status=status, out=io.StringIO(), keys=io.StringIO())
    live.subscribe(console)
    return console, session, live, status


def step_event(session: Session, robot: str, index: int, kind: str = "start", at_s: float = 0.0) -> StepEvent:
    return StepEvent(session.settings.plans[robot].steps[index], kind, at_s, at_s, 0, robot=robot)


def lines_of(console: Console, width: int) -> list[str]:
    out = io.StringIO()
    RichConsole(file=out, width=width, height=24, color_system=None).print(console.renderable(width, 24))
    return out.getvalue().splitlines()


# -- 1. one number a cue -----------------------------------------------------------------------


def test_rows_name_a_cued_step_by_its_cue_number_as_the_cue_list_does(tmp_path):
    console, session, live, status = evening(tmp_path)
    (left, right) = console.screen().rows
    assert left.next == "GO cue 1 'applause': play 1 (bow)"  # not step 0
    for robot in ("left", "right"):
        status.on_step(step_event(session, robot, 3))  # the wait after cue 2
    (left, _) = console.screen().rows
    assert left.now.startswith("wait until motion 2 is done")
    assert left.next == "GO cue 12.5 'act 2/intro': play 3 (clap)"
    status.on_step(step_event(session, "left", 4))
    assert console.screen().rows[0].now == "GO cue 12.5 'act 2/intro': play 3 (clap)"
    status.on_step(step_event(session, "left", 5))
    assert console.screen().rows[0].next == "@10 s cue 13 'finale': play 1 (bow)"
    assert "cue 13" in " ".join(line for line in lines_of(console, 80) if line.startswith("left"))


# -- 2. a skipped cue is nobody's next step ----------------------------------------------------


def test_a_skipped_cue_is_not_shown_as_the_next_step_on_screen_or_in_status(tmp_path):
    console, session, live, status = evening(tmp_path)
    for robot in ("left", "right"):
        status.on_step(step_event(session, robot, 1))  # the wait after cue 1: cue 2 comes next
    assert console.screen().rows[0].next.startswith("@4 s cue 2 'hello world'")
    assert live.command(Command("skip", "key", "2")).ok
    rows = console.screen().rows
    assert all(row.next.startswith("wait until motion 2 is done") for row in rows), rows  # cue 2's play passed
    nexts = {name: robot["next"] for name, robot in live.status()["robots"].items()}
    assert all(n is not None and n["cue"] is None and n["step"] == 3 for n in nexts.values()), nexts
    assert all(4.0 not in row.due_s for row in status.robots(live.skipped))  # no quiet window kept for it
    assert 4.0 in status.robots()[0].due_s  # (without the skips, it would be)
    assert live.command(Command("skip", "key", "2")).message.startswith("skip undone")
    assert console.screen().rows[0].next.startswith("@4 s cue 2 'hello world'")


# -- 3. messages keep what they tell the operator to do ----------------------------------------

LONG = "the-longest-label-a-stage-manager-ever-typed-for-a-cue"
MESSAGES = [  # (message, who sent it, the tail that must stay whole)
    ("unknown command /choreo/go/: did you mean '/choreo/go'?", "osc udp 127.0.0.1:43023",
     "did you mean '/choreo/go'?"),
    (f"cue 2 '{LONG}' is a timed cue (at 4.000 s): nothing to GO; move the playhead", "osc udp 127.0.0.1:1",
     "nothing to GO; move the playhead"),
    ("nothing waits for GO now (the show waits for its start: /choreo/start)", "osc tcp 10.0.0.2:5000",
     "/choreo/start)"),
    (f"no cue '{LONG}x' in this show (cues: 1, 2, 12.5, 13, 14): did you mean cue 14 'curtain'?", "",
     "did you mean cue 14 'curtain'?"),
    (f"robot right: step 2 '{LONG}' skipped (cue 2): not run", "", "not run"),
    (f"GO refused: cue 3 '{LONG}' is not reached yet: press p to resume", "", "press p to resume"),
    (f"unknown command /choreo/cue/{LONG}/{LONG}/go: send a label's slash as %2F", "osc udp 127.0.0.1:9",
     "send a label's slash as %2F"),
    ("paused at 2.706 s: no new step starts (one under way finishes); resume: p or /choreo/resume", "",
     "p or /choreo/resume"),
]


@pytest.mark.parametrize("width", (60, 72, 80))
@pytest.mark.parametrize(("message", "aside", "tail"), MESSAGES)
def test_a_message_is_cut_in_its_outside_text_and_keeps_its_instruction(width, message, aside, tail):
    line = fit_message(f"{'1.0':>7} s  {message}", width, aside)
    assert display_width(line) <= width
    assert line.endswith(tail) or line.endswith(f"{tail} ({aside[:3]}") or aside and f"{tail} (" in line, line
    assert line.startswith("    1.0 s  ") and line.count("…") <= 3, line


def test_on_screen_the_sender_goes_first_then_the_address(tmp_path):
    console, session, live, status = evening(tmp_path)
    refused = Answer("error", "unknown command /choreo/go/: did you mean '/choreo/go'?")
    console.on_command(CommandEvent(Command("go/", "osc udp 127.0.0.1:43023"), refused, 0, 1.0))
    for width in (60, 72, 80):
        (line,) = [line for line in lines_of(console, width) if "unknown command" in line]
        assert "did you mean '/choreo/go'?" in line and display_width(line) <= width, line
        assert line.count("…") <= 1, line  # cut once, not twice


# -- 4. no -0.0 --------------------------------------------------------------------------------


def test_no_time_on_the_console_is_negative_zero(tmp_path):
    assert seconds(-0.04) == "0.0" and seconds(-0.0, None) == "0" and seconds(-0.06) == "-0.1"
    assert seconds(12.5, None) == "12.5" and seconds(3.14159, 3) == "3.142"
    screen = Screen("show", -0.0, "machine clock", "", "", False, (), (Note("robot left: skipped", "", -0.04),))
    out = io.StringIO()
    RichConsole(file=out, width=80, color_system=None).print(render(screen, 80, 24))
    assert "-0.0" not in out.getvalue() and "show 0.0 s" in out.getvalue() and "    0.0 s  robot left" in out.getvalue()


# -- 5. keys -----------------------------------------------------------------------------------


def test_paused_the_legend_says_p_resumes(tmp_path):
    console, session, live, status = evening(tmp_path)
    assert console.screen().legend == LEGEND
    live._paused = True  # what a pause leaves (no show clock to stop here)
    assert console.screen().legend == PAUSED_LEGEND
    assert lines_of(console, 80)[-1] == PAUSED_LEGEND and lines_of(console, 60)[-1] == SHORT_PAUSED_LEGEND


class Given:
    """The live controls, keeping the commands the keys give."""

    def __init__(self, live: Live) -> None:
        self.live = live
        self.given: list[tuple[str, str | None]] = []

    def __getattr__(self, name: str):  # type: ignore[no-untyped-def]
        return getattr(self.live, name)

    def command(self, command: Command):  # type: ignore[no-untyped-def]
        self.given.append((command.name, command.label))
        return self.live.command(command)


def test_every_letter_key_works_in_either_case_and_j_keeps_the_case_typed(tmp_path):
    console, session, live, status = evening(tmp_path)
    console.live = given = Given(live)  # type: ignore[assignment]
    for key in ("S", "P", "P", "J", "Q", "u", "i", "E", "T", "enter", "Q", "n", "Q", "Y"):
        console.on_key(key)
    assert given.given == [("skip", None), ("pause", None), ("resume", None), ("playhead", "QuiET"), ("stop", None)]


def test_a_mistyped_cue_is_answered_with_the_nearest(tmp_path):
    console, session, live, status = evening(tmp_path)
    for key in ("j", "c", "u", "r", "t", "enter"):
        console.on_key(key)
    note = console.screen().notes[-1]
    assert note.text.startswith("no cue 'curt' in this show") and note.text.endswith(": did you mean cue 14 'curtain'?")
    assert live.command(Command("playhead", "key", "finalle")).message.endswith("did you mean cue 13 'finale'?")
    assert "did you mean" not in live.command(Command("playhead", "key", "zzz")).message


# -- a long show: each redraw looks up, never walks ---------------------------------------------


class Counted:
    """The live controls, counting the cue states the console asks for."""

    def __init__(self, live: Live) -> None:
        self.live = live
        self.asked = 0

    def __getattr__(self, name: str):  # type: ignore[no-untyped-def]
        if name == "cue_states":
            raise AssertionError("every cue's state asked for")
        return getattr(self.live, name)

    def cue_state(self, cue):  # type: ignore[no-untyped-def]
        self.asked += 1
        return self.live.cue_state(cue)


def test_a_redraw_of_a_long_show_asks_a_window_of_cue_states_not_every_cue(tmp_path):
    n = 600
    body = "version: 1\nname: long\nrobots:\n  a: {}\n  b: {}\nsteps:\n"
    body += "".join(f"- {{play: 1, at: {'go' if i % 2 else i * 0.5}}}\n" for i in range(n))
    session = Session.prepare(RunRequest(str(write_show(tmp_path, body)), no_log=True))
    settings = session.settings
    status = ShowStatus(settings.plans, settings.sections.starts)
    live = Live(StopRequest(), cues=cue_list(settings.plans), status=status)
    console = Console(session, live, status=status, out=io.StringIO(), keys=io.StringIO())
    console.live = counted = Counted(live)  # type: ignore[assignment]
    for index in range(n - 6):
        for robot in ("a", "b"):
            for kind in ("start", "end"):
                event = step_event(session, robot, index, kind)
                status.on_step(event)
                live.on_step(event)
    screen = console.screen()
    assert counted.asked <= 2 * 9 + 1 + 64
    assert [line.number for line in screen.cues][:3] == [str(n - 8), str(n - 7), str(n - 6)]  # where the show is
    assert screen.cues[screen.playhead].number == str(n - 4)  # the next GO cue (cue n-4 is step n-5)
    assert screen.cue.startswith(f"next cue: cue {n - 5} at ")  # the next timed one


alphabet = st.sampled_from(list("ab '/:; ()…") + ["ロ", "\u0301", "\x1b", "\u202e", "é"])


@settings(max_examples=300, deadline=None)
@given(st.lists(alphabet, max_size=200).map("".join), st.integers(min_value=1, max_value=100),
       st.lists(alphabet, max_size=30).map("".join))
def test_any_message_fits_any_width_escaped(text: str, width: int, aside: str) -> None:
    line = fit_message(text, width, aside)
    assert display_width(line) <= width and "\x1b" not in line and "\u202e" not in line


@pytest.mark.parametrize("text", ["'abc' " * 20000, "/ab " * 30000, ": " * 50000, "ロ" * 50000 + ": do this",
                                  ("'" + "y" * 50 + "' ") * 2000 + ": do this"])
def test_a_hostile_message_of_any_length_costs_a_bounded_measure(monkeypatch, text):
    """Fitting measured the text again at each piece it cut (a message of 12,000 characters in
    quotes or slashes: seconds of a redraw); now a bounded number of passes over at most
    LONGEST_FITTED characters, whatever comes. Counted in characters measured, not timed."""
    measured = []

    def counted(part: str) -> int:
        measured.append(len(part))
        return display_width(part)

    monkeypatch.setattr(screen, "display_width", counted)
    for width in (20, 60, 80):
        line = fit_message(text, width, "osc udp 127.0.0.1:9")
        assert display_width(line) <= width
    assert sum(measured) <= 3 * 40 * screen.LONGEST_FITTED


def test_j_takes_a_label_typed_in_any_script(tmp_path):
    """Kondo robots' shows are often labelled in Japanese: `j` and the label typed jumps there
    (a character typed arrives as UTF-8 bytes, maybe split across reads)."""
    body = EVENING.replace("label: finale", "label: お辞儀")
    session = Session.prepare(RunRequest(str(write_show(tmp_path, body)), no_log=True))
    live = Live(StopRequest(), cues=cue_list(session.settings.plans))
    console = Console(session, live, out=io.StringIO(), keys=io.StringIO())
    live.subscribe(console)
    parser = KeyParser()
    for chunk in (b"j", "お辞".encode()[:4], "お辞".encode()[4:], "儀".encode(), b"\r"):
        for key in parser.feed(chunk):
            console.on_key(key)
    assert live.playhead is not None and live.playhead.number == "13"
    assert console.screen().notes[-1].text == "playhead: cue 13 'お辞儀'"


# -- on a terminal: 20 columns and 5 lines, then a hurried operator ----------------------------


@needs_tmux
def test_at_20x5_the_console_fits_and_keys_work_and_capital_q_stops(tmp_path, pane):  # noqa: F811 - the fixture
    run: Pane = pane(EVENING)
    run.wait_for("GO fires cue 1 'applause'")
    run._tmux("resize-window", "-t", "run", "-x", "20", "-y", "5")
    screen = run.wait_for("GO fires")  # the GO line stays in sight, near the top
    assert all(display_width(line.rstrip()) <= 20 for line in screen.splitlines()), screen
    run.keys("p", "Space")  # paused: GO is refused, and says how to go on
    run.keys("P", "S")  # resumed, then cue 1 (waiting) skipped
    run._tmux("resize-window", "-t", "run", "-x", "80", "-y", "24")
    run.wait_for("skipped: cue 1 'applause'")
    run.wait_for("robot left: step 0 'applause' skipped (cue 1): not run")
    run.keys("Q")
    run.wait_for("stop the show? y/n")
    run.keys("Y")
    assert run.exit_code() == 130
    assert [(name, ok) for name, _, ok in commands_in(tmp_path)] == [
        ("pause", "ok"), ("go", "error"), ("resume", "ok"), ("skip", "ok"), ("stop", "ok")]
    assert run.terminal_restored()


def test_an_unmarked_paste_is_no_key():
    assert unmarked_paste(["space", "s", "p", "up", "q", "y", "j", "down"]) == ["space", "s", "p", "up", "q", "y",
                                                                                "j", "down"]  # 6 typed: a hand
    pasted = KeyParser().feed(b"notes for the show: qy s p\r")
    assert unmarked_paste(pasted) == ["paste"]
    assert unmarked_paste(pasted + ["escape"]) == ["paste", "escape"]  # Esc still panics


@needs_tmux
def test_text_pasted_where_the_terminal_does_not_mark_it_gives_no_go_skip_or_stop(tmp_path, pane):  # noqa: F811
    run: Pane = pane(EVENING)
    run.wait_for("GO fires cue 1 'applause'")
    run.keys("-l", "a note pasted: qy p s and  spaces\r")  # one write, as a terminal sends a paste unmarked
    run.wait_for("a paste is no key")
    time.sleep(2 * PASTE_WAIT_S)  # keys before a pause would be the paste's rest
    run.keys("q", "y")
    assert run.exit_code() == 130
    assert commands_in(tmp_path) == [("stop", "key", "ok")]
    assert run.terminal_restored()


def test_with_the_playhead_moved_off_a_cue_that_waits_the_go_line_says_how_to_reach_it(tmp_path):
    console, session, live, status = evening(tmp_path)
    live.command(Command("start", "key"))
    for robot in ("left", "right"):
        live.await_go(session.settings.plans[robot].steps[0], robot, reached_s=0.0, should_stop=lambda: True)
    assert console.screen().go == "GO fires cue 1 'applause': press Space or Enter"
    assert live.command(Command("playhead_next", "key")).ok  # onto cue 2, timed
    screen = console.screen()
    # GO on a timed cue fires the earliest cue waiting (the Live's rule): the line says so
    assert screen.go == "GO fires cue 1 'applause' (the playhead's cue 2 'hello world' is timed): press Space or Enter"
    assert screen.go_waiting
    for width in (60, 72, 80):
        line = next(line for line in lines_of(console, width) if line.startswith("GO fires cue 1 "))
        assert line.endswith("press Space or Enter"), line


@pytest.mark.parametrize("width", (72, 80))
def test_an_unknown_address_stays_whole_in_its_message(width):
    """A message with nothing after a `: ` keeps more of its start; an address is cut last."""
    message = ("unknown command /choreo/skip/2 (choreo takes /choreo/ followed by go, panic, start, stop, pause, "
               "resume, skip, playhead/next|previous|CUE, cue/CUE/go, status, thump, updates)")
    line = fit_message(f"{'0.0':>7} s  {message}", width, "osc udp 127.0.0.1:54446")
    assert line.startswith("    0.0 s  unknown command /choreo/skip/2 (cho") and line.endswith("thump, updates)")


# -- pastes longer than a read, and an input method's word after j -----------------------------


def read_all(data: bytes, on_key, **kwargs) -> KeyReader:
    """`data` in one write, then the end of input: the reader reads it all, then stops."""
    read, write = os.pipe()
    reader = KeyReader(read, on_key, **kwargs)
    try:
        os.write(write, data)
    finally:
        os.close(write)
    reader.start()
    reader._thread.join(10.0)
    os.close(read)
    assert not reader._thread.is_alive()
    return reader


@pytest.mark.parametrize("length", (65, 68, 200, 5000, 60000))
def test_an_unmarked_paste_longer_than_a_read_is_one_paste_with_no_key_after(length):
    """The 64 bytes of the first read make it a paste; its tail (` s p`: GO, skip, GO, pause)
    came after as keys."""
    text = (b"Lorem ipsum dolor sit amet, consectetur adipiscing elit, sed do eiusmod " * 1000)[:length - 4] + b" s p"
    keys: list[str] = []
    read_all(text, keys.append)
    assert keys == ["paste"]


def wait_until(condition, timeout_s: float = 10.0) -> None:
    deadline = time.monotonic() + timeout_s
    while not condition():
        assert time.monotonic() < deadline, "timed out"
        time.sleep(0.005)


def test_after_a_pause_an_unmarked_paste_is_over_and_keys_are_keys():
    read, write = os.pipe()
    keys: list[str] = []
    reader = KeyReader(read, keys.append, paste_wait_s=0.05)
    reader.start()
    try:
        os.write(write, b"notes for the show: qy s p " * 10)
        wait_until(lambda: keys == ["paste"] and not reader._unmarked)
        os.write(write, b" ")
        wait_until(lambda: len(keys) > 1)
        assert keys == ["paste", "space"]
    finally:
        os.close(write)
        reader.close()
        os.close(read)


def ime_evening(tmp_path: Path, label: str) -> tuple[Console, Live]:
    body = EVENING.replace("label: finale", f"label: {label}")
    session = Session.prepare(RunRequest(str(write_show(tmp_path, body)), no_log=True))
    live = Live(StopRequest(), cues=cue_list(session.settings.plans))
    console = Console(session, live, out=io.StringIO(), keys=io.StringIO())
    live.subscribe(console)
    return console, live


@pytest.mark.parametrize("after", (b"", b" s p s p s p s p"))
def test_a_label_an_input_method_commits_in_one_write_after_j_is_typed_not_a_paste(tmp_path, after):
    """An input method sends `フィナーレのお辞儀` as one write: 9 characters, more than a hand
    types between two reads, yet typed. Once Enter ends the prompt, keys are commands again and
    the paste rule holds (a pasted tail gives no GO)."""
    console, live = ime_evening(tmp_path, "フィナーレのお辞儀")
    read, write = os.pipe()
    keys: list[str] = []
    reader = KeyReader(read, lambda key: (keys.append(key), console.on_key(key)), text_wanted=console.typing)
    reader.start()
    try:
        os.write(write, b"j")
        wait_until(console.typing)
        os.write(write, "フィナーレのお辞儀".encode() + b"\r" + after)
    finally:
        os.close(write)
        reader._thread.join(10.0)
        os.close(read)
    assert live.playhead is not None and live.playhead.number == "13"
    assert keys[-1] == ("paste" if after else "enter")
    jumped = "playhead: cue 13 'フィナーレのお辞儀'"
    assert console.screen().notes[-1].text == ("a paste is no key: ignored (type a cue's number after j)"
                                               if after else jumped)


# -- after a panic or a stop: no robot row says done or a step it will not finish --------------


@pytest.mark.parametrize("command", ("panic", "stop"))
def test_after_a_panic_or_stop_the_rows_say_aborted_or_stopped_not_done(tmp_path, command):
    """`left` was cut off on its last step (the runner ends it `aborted`): it said `done`;
    `right`, mid-show and cut off between steps, said its last step and what came next."""
    console, session, live, status = evening(tmp_path)
    live.command(Command("start", "key"))
    last = len(session.settings.plans["left"].steps) - 1
    for index in range(last):
        status.on_step(step_event(session, "left", index))
        status.on_step(step_event(session, "left", index, "end"))
    status.on_step(step_event(session, "left", last))
    status.on_step(step_event(session, "right", 2))
    status.on_step(step_event(session, "right", 2, "end"))
    assert live.command(Command(command, "key")).ok
    status.on_step(StepEvent(session.settings.plans["left"].steps[last], "end", 9.0, 9.0, 0, outcome="aborted",
                             robot="left"))
    console.close()
    screen = console.screen()
    rows = {row.robot: (row.now, row.next) for row in screen.rows}
    assert rows == {"left": ("aborted: wait until motion 0 is done (timeout 60 s)", "-"), "right": ("stopped", "-")}
    assert {row["robot"]: row["state"] for row in (r.to_json() for r in status.robots())} == {
        "left": "aborted", "right": "between"}
    assert screen.legend == ("the show was stopped by panic; keys off" if command == "panic"
                             else "the show was stopped; keys off")


def test_with_the_playhead_on_a_skipped_cue_while_one_waits_the_go_line_says_go_fires_the_waiting_one(tmp_path):
    console, session, live, status = evening(tmp_path)
    live.command(Command("start", "key"))
    for robot in ("left", "right"):
        live.await_go(session.settings.plans[robot].steps[0], robot, reached_s=0.0, should_stop=lambda: True)
    assert live.command(Command("skip", "key", label="2")).ok
    assert live.command(Command("playhead", "key", label="2")).ok  # back onto the skipped cue
    assert console.screen().go == ("GO fires cue 1 'applause' (the playhead's cue 2 'hello world' is skipped): "
                                   "press Space or Enter")
