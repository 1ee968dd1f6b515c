"""The console's cue keys on a real terminal (issue 24): `choreo run` on a sim:// show inside tmux,
keys in with send-keys, the screen out with capture-pane, and the log read after: Up/Down then GO
fires the moved cue, `s` skips (a cue waiting and one ahead), `j` and a cue jumps the playhead,
`p` pauses and resumes, Esc panics while paused. Each waits for screen text with a generous
deadline (Pane.wait_for) and asserts what happened, never how long it took."""

from __future__ import annotations

import time
from pathlib import Path

import pytest

from runlog import read_log
from test_console import SCREEN_S, Pane, commands_in, needs_tmux, pane  # noqa: F401 - pane: the fixture

TWO_TRACKS = """\
version: 1
name: two tracks
robots:
  left: {}
  right: {}
tracks:
  left:
    - play: 1
      at: go
      label: left-go
    - play: 3
  right:
    - play: 2
      at: go
      label: right-go
    - wait: 0.6
    - play: 4
      label: right-after
"""

THREE_GOS = """\
version: 1
name: three GO cues
steps:
  - play: 1
    at: go
    label: one
  - play: 2
    at: go
    label: two
  - play: 3
    at: go
    label: three
"""

LONG_WAIT = """\
version: 1
name: a long wait
steps:
  - play: 1
    label: first
  - wait: 60
    label: the-long-wait
  - play: 2
"""


def played(tmp_path: Path, robot: str | None = None) -> list[int]:
    """The motions a robot was told to play, in order (the log's tx records)."""
    topic = f"/rcb4/{robot}/tx" if robot else "/rcb4/tx"
    return [m["motion"] for m in read_log(tmp_path / "run.mcap").topic(topic) if m["kind"] == "play"]


def starts_s(tmp_path: Path) -> dict[str, float]:
    """Each robot's first step's start on the show clock."""
    log = read_log(tmp_path / "run.mcap")
    return {robot: next(m["actual_s"] for m in log.topic(f"/choreo/{robot}/step") if m["event"] == "start")
            for robot in ("left", "right")}


@needs_tmux
def test_down_then_go_fires_the_moved_cue_not_the_earliest_waiting(tmp_path, pane):  # noqa: F811 - the fixture
    run: Pane = pane(TWO_TRACKS)
    run.wait_for("waits for GO: cue 2 ")
    run.wait_for("waits for GO: cue 1 ")  # both wait (which the playhead takes first: who came first)
    run.keys("j", "1", "Enter")
    run.wait_for("GO fires cue 1 'left-go'")
    run.keys("Down")
    run.wait_for("GO fires cue 2 'right-go'")
    run.keys("Up")
    run.wait_for("GO fires cue 1 'left-go'")
    run.keys("Down")
    run.wait_for("GO fires cue 2 'right-go'")
    run.keys("Space")
    run.wait_for("right done")  # right went on (0.6 s of show after its GO: past the lockout)
    screen = run.wait_for("GO fires cue 1 'left-go'")  # the playhead back on the one still waiting
    assert "waits for GO: cue 1 " in screen
    run.keys("Enter")
    assert run.exit_code() == 0
    assert commands_in(tmp_path) == [("playhead", "key", "ok"), ("playhead_next", "key", "ok"),
                                     ("playhead_previous", "key", "ok"), ("playhead_next", "key", "ok"),
                                     ("go", "key", "ok"), ("go", "key", "ok")]
    starts = starts_s(tmp_path)
    assert starts["right"] < starts["left"]  # cue 2 ran first, cue 1 at the second GO
    assert run.terminal_restored()


@needs_tmux
def test_s_skips_the_cue_waiting_and_one_ahead(tmp_path, pane):  # noqa: F811 - the fixture
    run: Pane = pane(THREE_GOS)
    run.wait_for("GO fires cue 1 'one'")
    run.keys("s")  # the cue waiting: released as skipped, the robot goes on to the next
    run.wait_for("GO fires cue 2 'two'")
    run.keys("Down")
    run.wait_for("playhead on cue 3 'three', not reached yet; cue 2 'two' waits: Up/Down to it")
    run.keys("s")  # the cue ahead: the robot will pass it
    run.wait_for("skipped: cue 3 'three'")
    run.wait_for("GO fires cue 2 'two'")  # the playhead goes on past it: the cue waiting
    run.keys("Space")
    assert run.exit_code() == 0
    assert commands_in(tmp_path) == [("skip", "key", "ok"), ("playhead_next", "key", "ok"), ("skip", "key", "ok"),
                                     ("go", "key", "ok")]
    assert played(tmp_path) == [2]  # one and three never ran
    events = [(m["index"], m["event"]) for m in read_log(tmp_path / "run.mcap").steps]
    assert (0, "skip") in events and (2, "skip") in events and (0, "start") not in events
    assert run.terminal_restored()


@needs_tmux
def test_j_and_a_number_or_a_label_then_enter_jumps_the_playhead(tmp_path, pane):  # noqa: F811 - the fixture
    run: Pane = pane(THREE_GOS)
    run.wait_for("GO fires cue 1 'one'")
    run.keys("j", "3")
    run.wait_for("cancels): 3_")
    run.keys("Enter")
    screen = run.wait_for("playhead on cue 3 'three', not reached yet; cue 1 'one' waits: Up/Down to it")
    assert any(line.startswith("> 3 ") for line in screen.splitlines()), screen
    run.keys("j", "x", "BSpace", "o", "n", "e", "Enter")  # Backspace erases; a label is a cue too
    run.wait_for("playhead: cue 1 'one'")
    run.wait_for("GO fires cue 1 'one'")
    run.keys("j", "Enter")  # an empty Enter cancels: no command
    run.wait_for("jump cancelled")
    run.keys("Escape")
    assert run.exit_code() == 130
    assert commands_in(tmp_path) == [("playhead", "key", "ok"), ("playhead", "key", "ok"), ("panic", "key", "ok")]
    assert played(tmp_path)[:1] != [1]  # the GO was never given: motion 1 never started
    assert run.terminal_restored()


@needs_tmux
def test_p_pauses_p_resumes_and_esc_panics_while_paused(tmp_path, pane):  # noqa: F811 - the fixture
    run: Pane = pane(LONG_WAIT)
    run.wait_for("'the-long-wait': wait 60")
    run.keys("p")
    screen = run.wait_for("PAUSED: press p to resume")
    assert "machine clock, PAUSED" in screen
    run.keys("p")
    run.wait_for("resumed")
    run.keys("p")
    run.wait_for("PAUSED: press p to resume")
    run.keys("Escape")
    assert run.exit_code() == 130
    assert "the show was stopped by panic" in run.screen()
    assert commands_in(tmp_path) == [("pause", "key", "ok"), ("resume", "key", "ok"), ("pause", "key", "ok"),
                                     ("panic", "key", "ok")]
    assert played(tmp_path)[:1] == [1] and 2 not in played(tmp_path)  # the step after the wait never started
    assert run.terminal_restored()


EIGHT = ["left", "right", "centre", "d4", "e5", "f6", "g7", "h8"]
EIGHT_ROBOTS = ("version: 1\nname: eight robots\nrobots:\n" + "".join(f"  {name}: {{}}\n" for name in EIGHT)
                + "steps:\n" + "".join(f"  - play: 1\n    at: {'go' if i % 3 == 0 else i}\n"
                                       f"    label: cue-{i}-of-the-show\n" for i in range(12)))


def fits(screen: str, width: int) -> list[str]:
    """The console's lines, checked whole on the terminal: its top line still there (nothing
    scrolled off), the legend at the bottom, the playhead's line between, every line in width."""
    lines = [line.rstrip() for line in screen.splitlines()]
    title = [at for at, line in enumerate(lines) if line.startswith("eight robots ")]
    assert len(title) == 1, screen
    legend = [at for at, line in enumerate(lines) if line.startswith(("Space/Enter GO", "Spc GO"))]
    assert len(legend) == 1 and legend[0] > title[0], screen
    assert any(line.startswith("> ") for line in lines[title[0]:]), screen
    assert all(len(line) <= width for line in lines)
    return lines[title[0]:legend[0] + 1]


def settled(run: Pane, text: str, width: int, timeout: float = SCREEN_S) -> str:
    """The first screen showing `text` that is drawn whole (tmux may capture a redraw half
    done: its top lines new, its lower ones the screen before), and the same on a second look."""
    deadline = time.monotonic() + timeout
    while True:
        screen = run.wait_for(text, max(0.1, deadline - time.monotonic()))
        try:
            fits(screen, width)
            if run.screen() == screen:
                return screen
        except AssertionError:
            if time.monotonic() > deadline:
                raise
        time.sleep(0.05)


@needs_tmux
@pytest.mark.parametrize("width", (60, 80))
def test_eight_robots_and_the_cue_list_fit_a_24_line_terminal(tmp_path, pane, width):  # noqa: F811 - the fixture
    run: Pane = pane(EIGHT_ROBOTS, width)
    fits(settled(run, "left, right +6 wait for GO: cue 1 'cue-0-of-the-show'", width), width)
    run.keys("Space")
    console = fits(settled(run, "next GO: cue 4 ", width), width)  # every robot on a row of its own now
    assert [line.split()[0] for line in console if line.split()[0] in EIGHT] == EIGHT
    assert any("GO: cue 1 'cue-0-of-the-show'" in line for line in console)  # and a message still fits
    run.keys("Escape")
    assert run.exit_code() == 130


DUET = """\
version: 1
name: duet
robots:
  left: {}
  right: {}
steps:
  - play: 1
    at: go
    label: start
  - wait: 0.6
  - play: 2
    at: go
    label: middle
  - play: 3
    at: go
    label: never
  - play: 4
"""


@needs_tmux
def test_skip_and_jump_with_two_robots_on_shared_cues(tmp_path, pane):  # noqa: F811 - the fixture
    run: Pane = pane(DUET)
    run.wait_for("left, right wait for GO: cue 1 'start'")  # one line for both
    run.keys("j", "n", "e", "v", "e", "r", "Enter")
    run.wait_for("playhead on cue 3 'never', not reached yet")
    run.keys("s")  # both robots will pass it
    run.wait_for("skipped: cue 3 'never' will not run")
    run.wait_for("GO fires cue 1 'start'")  # the playhead is back on the cue waiting
    run.keys("Space")
    run.wait_for("left, right wait for GO: cue 2 'middle'")  # 0.6 s of show later: past the GO lockout
    run.keys("Enter")
    assert run.exit_code() == 0
    assert commands_in(tmp_path) == [("playhead", "key", "ok"), ("skip", "key", "ok"), ("go", "key", "ok"),
                                     ("go", "key", "ok")]
    for robot in ("left", "right"):
        assert played(tmp_path, robot) == [1, 2, 4]  # cue 3's motion never played
        events = [(m["index"], m["event"]) for m in read_log(tmp_path / "run.mcap").topic(f"/choreo/{robot}/step")]
        assert (3, "skip") in events and (3, "start") not in events
