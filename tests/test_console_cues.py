"""The console's cue list, playhead and keys (issue 24) without a terminal: the screen as a value
and drawn through rich at 60, 72 and 80 columns with 8 robots (every line fits, the whole fits 24
lines, the instruction of a message survives a long label, outside text is escaped), the keys
turned into the live controls' commands (the `j` prompt above all), and the arrow keys parsed."""

from __future__ import annotations

import io
from pathlib import Path

import pytest
from rich.console import Console as RichConsole

from choreo.cli.console import MAX_TYPED, Console
from choreo.cli.keys import KeyParser
from choreo.cli.screen import LEGEND, SHORT_LEGEND, CueLine, Note, Row, Screen, fit_message, render
from choreo.events import Command, StepEvent, StopRequest
from choreo.live.controls import HoldingShowClock, Live
from choreo.log.format import WARNING
from choreo.run.session import Session
from choreo.run.settings import RunRequest
from choreo.show.cues import cue_list
from choreo.textfit import display_width
from runlog import write_show

ROBOTS = ["left", "right", "centre_stage_with_a_long_name", "d4", "e5", "f6", "g7", "h8"]
LONG_LABEL = "the-longest-label-a-stage-manager-ever-typed-for-a-cue-of-a-show-of-robots"  # 75: the most is 80
HOSTILE = "evil\x1b]0;pwned\x07\u202e"


def eight_robots(label: str = "bow") -> str:
    """Shared steps for 8 robots: a GO cue, timed cues, more GO cues."""
    body = "version: 1\nname: eight robots in a show with a name long enough to be cut\nrobots:\n"
    body += "".join(f"  {name}: {{}}\n" for name in ROBOTS) + "steps:\n"
    for i in range(12):
        at = "go" if i % 3 == 0 else str(i)
        body += f"  - play: 1\n    at: {at}\n    label: {label if i == 0 else f'cue-{i}'}\n"
    return body


def prepared(tmp_path: Path, body: str) -> tuple[Console, Session, Live]:
    session = Session.prepare(RunRequest(str(write_show(tmp_path, body)), no_log=True))
    live = Live(StopRequest(), cues=cue_list(session.settings.plans))
    return Console(session, live, out=io.StringIO(), keys=io.StringIO()), session, live


def drawn(console: Console, width: int, height: int | None = 24) -> list[str]:
    out = io.StringIO()
    RichConsole(file=out, width=width, height=height or 200, color_system=None).print(
        console.renderable(width, height))
    return out.getvalue().splitlines()


def everyone_waits(console: Console, session: Session, live: Live) -> None:
    """Every robot reaches the first GO cue (and waits there: nothing releases it)."""
    step = session.settings.plans["left"].steps[0]
    for name in ROBOTS:
        live.await_go(step, name, reached_s=0.0, should_stop=lambda: True)


# -- the screen --------------------------------------------------------------------------------


@pytest.mark.parametrize("width", (60, 72, 80))
def test_eight_robots_and_the_cue_list_fit_an_80x24_terminal_at_any_width(tmp_path, width):
    console, session, live = prepared(tmp_path, eight_robots())
    for n in range(8):
        console.on_log(WARNING, f"robot d4: step {n}: NAK to 'play 1', retried")
    lines = drawn(console, width)
    assert len(lines) <= 23, lines  # a line left for the cursor: nothing scrolls
    assert sum("NAK to 'play 1'" in line for line in lines) >= 1
    assert all(display_width(line) <= width for line in lines), lines
    assert lines[-1] == (LEGEND if width >= 80 else SHORT_LEGEND)
    playhead = [line for line in lines if line.startswith(">")]
    assert len(playhead) == 1 and playhead[0].split()[:3] == [">", "1", "bow"], lines
    assert "all" in playhead[0] and "GO ~0.0 s" in playhead[0] and "ahead" in playhead[0]
    assert sum(line.startswith(name[:10]) for line in lines for name in ROBOTS) == 8  # a row each
    assert any(line.split()[:2] == ["2", "cue-1"] and "@1 s" in line for line in lines)


@pytest.mark.parametrize("width", (60, 72, 80))
def test_robots_waiting_at_one_go_share_one_line(tmp_path, width):
    console, session, live = prepared(tmp_path, eight_robots())
    everyone_waits(console, session, live)
    screen = console.screen()
    assert screen.waits == ("left, right +6 wait for GO: cue 1 'bow'",)
    assert screen.rows == ()  # nobody left with a row of its own
    assert screen.go == "GO fires cue 1 'bow': press Space or Enter" and screen.go_waiting
    assert [c.state for c in screen.cues][:2] == ["waiting", "ahead"] and screen.playhead == 0
    lines = drawn(console, width)
    assert "left, right +6 wait for GO: cue 1 'bow'" in lines
    assert len(lines) <= 23 and all(display_width(line) <= width for line in lines)


@pytest.mark.parametrize("width", (60, 72, 80))
def test_a_long_label_is_cut_and_the_instruction_stays(tmp_path, width):
    console, session, live = prepared(tmp_path, eight_robots(LONG_LABEL))
    everyone_waits(console, session, live)
    lines = drawn(console, width)
    go = [line for line in lines if line.startswith("GO fires cue 1 '")]
    assert len(go) == 1 and go[0].endswith("': press Space or Enter") and "…" in go[0], lines
    wait = [line for line in lines if line.startswith("left, right +6 wait for GO: cue 1 '")]
    assert len(wait) == 1 and "…" in wait[0]
    assert all(display_width(line) <= width for line in lines)


def test_hostile_labels_and_names_are_drawn_escaped(tmp_path):
    """A show refuses control characters in its names; a screen escapes them all the same (an
    OSC sender's cue reference, a log line), and the typed prompt takes printable keys only."""
    screen = Screen(HOSTILE, 1.0, "machine clock", f"next cue: {HOSTILE}", f"GO fires cue 1 '{HOSTILE}'", True,
                    (Row(HOSTILE, HOSTILE, HOSTILE, 1.0),), (Note(f"refused ({HOSTILE})", "", 1.0),),
                    f"jump to cue: {HOSTILE}", cues=(CueLine("1", HOSTILE, HOSTILE, "GO ~0.0 s", "waiting"),),
                    playhead=0, waits=(f"{HOSTILE}, b wait for GO: cue 1 '{HOSTILE}'",))
    for width in (60, 72, 80):
        out = io.StringIO()
        RichConsole(file=out, width=width, color_system=None).print(render(screen, width, 24))
        text = out.getvalue()
        assert "\x1b" not in text and "\u202e" not in text and "\x07" not in text
        assert "\\x1b]0;" in text
    console, _, live = prepared(tmp_path, eight_robots())
    live.subscribe(console)
    live.command(Command("playhead", "osc udp 10.0.0.1:9", HOSTILE))
    text = "\n".join(drawn(console, 80))
    assert "\x1b" not in text and "no cue 'e" in text  # its outside text cut first, escaped


def test_a_message_is_cut_in_its_quoted_outside_text_first_then_in_its_middle():
    text = "GO refused: cue 3 '" + "very-long-label-" * 8 + "' is not reached yet: press p to resume"
    fitted = fit_message(text, 72)
    assert display_width(fitted) <= 72
    assert fitted.startswith("GO refused: cue 3 'very") and fitted.endswith("' is not reached yet: press p to resume")
    plain = "a message without a quoted name " * 4 + "and the part that says what to do"
    cut = fit_message(plain, 50)
    assert display_width(cut) <= 50 and cut.startswith("a message") and cut.endswith("what to do") and "…" in cut
    assert fit_message(HOSTILE, 80) == "evil\\x1b]0;pwned\\x07\\u202e"


def test_the_cue_list_follows_the_playhead_and_the_states(tmp_path):
    console, session, live = prepared(tmp_path, eight_robots())
    steps = session.settings.plans["left"].steps
    live.command(Command("playhead", "key", "10"))
    screen = console.screen()
    assert screen.playhead is not None and screen.cues[screen.playhead].number == "10"
    assert screen.go == "next GO: cue 10 'cue-9' (not reached yet)"
    lines = drawn(console, 80)
    assert any(line.startswith("> 10 ") for line in lines), lines
    for name in ROBOTS:  # cue 1 runs, then ends
        for kind in ("start", "end"):
            event = StepEvent(steps[0], kind, 0.0, 0.0, 0, robot=name)
            console.on_step(event)
            live.on_step(event)
    assert [c.number for c in console.screen().cues] == [str(n) for n in range(4, 13)]  # the playhead's end
    live.command(Command("skip", "key", "2"))
    live.command(Command("playhead", "key", "4"))
    states = {c.number: c.state for c in console.screen().cues}
    assert (states["2"], states["3"], states["4"]) == ("skipped", "ahead", "ahead")


def test_a_show_with_tempo_gives_each_cue_its_bar_and_beat(tmp_path):
    body = """\
version: 1
name: tempo
tempo: {bpm: 120}
steps:
  - play: 1
    at: go
  - play: 2
    at: {bar: 3, beat: 2}
"""
    console, _, _ = prepared(tmp_path, body)
    whens = [c.when for c in console.screen().cues]
    assert whens[0].startswith("GO ~0.0 s 1.1") and whens[1].endswith(" 3.2"), whens


def test_a_paused_show_says_how_to_go_on(tmp_path):
    console, _, live = prepared(tmp_path, eight_robots())
    assert live.command(Command("pause", "key")).ok
    screen = console.screen()
    assert screen.go == "PAUSED: press p to resume (Esc panics)" and screen.go_waiting
    assert screen.clock.endswith("PAUSED")


# -- keys --------------------------------------------------------------------------------------


class Commands:
    """A Live stand-in that keeps the commands it is given."""

    def __init__(self, live: Live) -> None:
        self.live = live
        self.given: list[tuple[str, str | None]] = []

    def __getattr__(self, name: str):  # type: ignore[no-untyped-def]
        return getattr(self.live, name)

    @property
    def paused(self) -> bool:
        return any(name == "pause" for name, _ in self.given[-1:])

    def command(self, command: Command):  # type: ignore[no-untyped-def]
        assert command.source == "key"
        self.given.append((command.name, command.label))


def keyed(tmp_path: Path) -> tuple[Console, Commands]:
    console, _, live = prepared(tmp_path, eight_robots())
    commands = Commands(live)
    console.live = commands  # type: ignore[assignment]  # the stand-in keeps what it is told
    return console, commands


def press(console: Console, *keys: str) -> None:
    for key in keys:
        console.on_key(key)


def test_each_key_is_a_command(tmp_path):
    console, commands = keyed(tmp_path)
    press(console, "space", "enter", "up", "down", "s", "S", "p", "p", "escape", "x", "?")
    assert commands.given == [("go", None), ("go", None), ("playhead_previous", None), ("playhead_next", None),
                              ("skip", None), ("skip", None), ("pause", None), ("resume", None), ("panic", None)]


def test_j_types_a_cue_and_enter_jumps_there(tmp_path):
    console, commands = keyed(tmp_path)
    press(console, "j", "1", "2", ".", "5")
    assert console.screen().prompt is not None and (console.screen().prompt or "").endswith(": 12.5_")
    assert commands.given == []  # nothing while typing
    press(console, *["9"] * 30)  # a long one: its end, being typed, is what stays at 60 columns
    assert drawn(console, 60)[-1].endswith("99999_") and drawn(console, 60)[-1].startswith("jump to cue")
    press(console, *["backspace"] * 30, "enter")
    assert commands.given == [("playhead", "12.5")] and console.screen().prompt is None
    press(console, "j", "b", "space", "o", "x", "backspace", "w", "enter")  # Space is typed, Backspace erases
    press(console, "j", "q", "s", "p", "up", "ctrl-u", "3", "enter")  # q, s, p are letters; Ctrl-U clears
    assert commands.given[1:] == [("playhead", "b ow"), ("playhead", "3")]


def test_an_empty_jump_cancels_and_esc_still_panics_while_typing(tmp_path):
    console, commands = keyed(tmp_path)
    press(console, "j", "space", "enter")
    assert commands.given == [] and console.screen().notes[-1].text == "jump cancelled"
    press(console, "j", "4", "escape")
    assert commands.given == [("panic", None)] and console.screen().prompt is None
    press(console, "4", "enter")  # the prompt is gone: Enter is GO again
    assert commands.given[-1] == ("go", None)


def test_what_is_typed_is_bounded(tmp_path):
    console, commands = keyed(tmp_path)
    press(console, "j", *["7"] * (MAX_TYPED * 3), "enter")
    assert commands.given == [("playhead", "7" * MAX_TYPED)]


def test_q_still_asks_and_a_prompt_answer_is_not_a_command(tmp_path):
    console, commands = keyed(tmp_path)
    press(console, "q", "j", "j", "3", "enter")  # q, then j answers no; then j types 3
    assert commands.given == [("playhead", "3")]


# -- arrow keys --------------------------------------------------------------------------------

ARROW_BYTES = [(b"\x1b[A", "up"), (b"\x1b[B", "down"), (b"\x1bOA", "up"), (b"\x1bOB", "down"),
               (b"\x9bA", "up"), (b"\x9bB", "down"), (b"\x8fA", "up"), (b"\x8fB", "down"),
               (b"\xc2\x9bA", "up"), (b"\xc2\x9bB", "down"), (b"\xc2\x8fA", "up"), (b"\xc2\x8fB", "down")]


@pytest.mark.parametrize(("sequence", "key"), ARROW_BYTES, ids=lambda v: v.hex(" ") if isinstance(v, bytes) else v)
def test_up_and_down_in_7_and_8_bit_forms_are_keys(sequence: bytes, key: str) -> None:
    assert KeyParser().feed(sequence) == [key]
    bytewise = KeyParser()
    assert [k for byte in sequence for k in bytewise.feed(bytes([byte]))] == [key]
    assert bytewise.feed(b" ") == ["space"]


@pytest.mark.parametrize("sequence", [b"\x1b[1;2A", b"\x1b[1;5B", b"\x1b\x1b[A", b"\x1b\x1bOB", b"\x1b[C",
                                      b"\x1bOD", b"\x9b1;3A", b"\x1b[2A", b"\x1b[200~\x1b[A\x1b[201~"])
def test_other_arrows_and_arrows_in_a_paste_are_no_key(sequence: bytes) -> None:
    parser = KeyParser()
    assert parser.feed(sequence) + parser.timeout() == []


def test_editing_keys() -> None:
    assert KeyParser().feed(b"\x7f\x08\x15j3\r") == ["backspace", "backspace", "ctrl-u", "j", "3", "enter"]


def test_a_paused_show_keeps_the_screen_still_and_clear_of_redraws(tmp_path, monkeypatch):
    """Paused, the show clock stands: what is drawn does not change however long the pause
    lasts (no redraw while nothing happens), and no due time calls for a quiet window."""
    console, session, live = prepared(tmp_path, eight_robots())
    now = [100.0]
    monkeypatch.setattr(session.clock, "mono", lambda: now[0])
    live.use_clock(HoldingShowClock(99.0, lambda: now[0]))  # 1 s into the show
    steps = session.settings.plans["left"].steps
    for name in ROBOTS:
        event = StepEvent(steps[1], "start", 1.0, 1.0, 0, robot=name)
        console.on_step(event)
        live.on_step(event)
    assert console.screen().cue == "next cue in 1.0 s: cue 3 'cue-2' at 2 s"
    assert live.command(Command("pause", "key")).ok
    paused = console.screen()
    now[0] += 30.0  # half a minute of pause
    assert console.screen() == paused and paused.show_s == 1.0
    assert console._quiet_left() == 0.0  # nothing falls due while paused: draw (nothing) at once
    updates = []
    monkeypatch.setattr(console._rich, "update", lambda renderable, refresh: updates.append(renderable))
    console._draw()
    now[0] += 5.0
    console._draw()
    assert len(updates) == 1
