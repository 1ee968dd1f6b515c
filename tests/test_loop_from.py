"""`--loop` over (nearly) no show time and `--from` past the music's end are refused with one
line and exit 2 before anything opens (no port, no log): a loop over no time restarted its motion
1,899 times in 2.3 s, and a start past the song's end ran the show in silence."""

from __future__ import annotations

from pathlib import Path

import pytest

from choreo.cli import main
from choreo.errors import UsageError
from choreo.run.sections import MIN_LOOP_S
from choreo.run.session import Session
from choreo.run.settings import RunRequest
from runlog import write_show
from test_music import write_song

TINY_WAITS = """\
version: 1
steps:
  - play: 1
    label: a
  - wait: 0.01
  - wait: 0.01
  - play: 2
    label: b
  - wait: 0.01
  - play: 3
"""

SHORT_MOTIONS = """\
version: 1
motions:
  blink: {number: 5, duration: 0.02}
steps:
  - play: blink
    label: a
  - wait: done
  - play: blink
  - wait: done
    label: b
  - play: 1
"""

TWO_ROBOTS = """\
version: 1
robots:
  left: {}
  right: {}
steps:
  - play: 1
    label: a
  - play: 2
    robots: [right]
    label: b
  - wait: 3
"""


def _refused_loop(tmp_path: Path, capsys: pytest.CaptureFixture[str], show: str, loop: str) -> str:
    """`choreo run SHOW --loop LOOP`'s one line, checked to be exit 2 with no port tried (3) and no log."""
    path = show if show.endswith(".yaml") else str(write_show(tmp_path, show))
    log = tmp_path / "run.mcap"
    ports = [f"{name}={tmp_path}/no-such-tty-{name}" for name in ("left", "right")] if "robots:" in show else \
        [str(tmp_path / "no-such-tty")]
    code = main(["run", path, "--loop", loop, *(a for p in ports for a in ("--port", p)), "--log", str(log), "-q"])
    err = capsys.readouterr().err.strip().splitlines()
    assert code == 2 and len(err) == 1, err  # 3 would mean the port was tried
    assert not log.exists()
    return err[0]


@pytest.mark.parametrize("show, loop", [
    ("shows/dance.yaml", "spin..spin"),
    ("shows/dance.yaml", "0..0"),
    ("shows/dance.yaml", "start..0"),
    ("shows/dance.yaml", "20..20"),
    (TINY_WAITS, "a..b"),
    (TINY_WAITS, "1..4"),
    (SHORT_MOTIONS, "a..b"),
    (TWO_ROBOTS, "a..b"),
])
def test_a_loop_over_no_time_is_refused_before_anything_opens(tmp_path, capsys, show, loop):
    said = _refused_loop(tmp_path, capsys, show, loop)
    assert said.startswith(f"--loop {loop}: one pass lasts") and f"needs {MIN_LOOP_S:g} s at least" in said


@pytest.mark.parametrize("show, loop", [
    ("shows/dance.yaml", "1..1"),  # the `wait: done` after `start`'s play, alone
    ("version: 1\nsteps:\n  - play: 1\n  - wait: 2\n    label: rest\n  - wait: 1\n  - play: 2\n", "rest..2"),
    (TWO_ROBOTS.replace("  - wait: 3\n", "  - wait: 3\n    label: c\n  - wait: 1\n"), "c..3"),
])
def test_a_loop_of_waits_alone_is_refused_before_anything_opens(tmp_path, capsys, show, loop):
    """`--loop 1..1` on dance.yaml polled a motion it never played, every 0.6 s, under a header
    that promised a 22 s show."""
    assert _refused_loop(tmp_path, capsys, show, loop).startswith(f"--loop {loop}: the section plays no motion")


def test_a_short_loop_is_refused_as_the_library_is_called_too(tmp_path):
    with pytest.raises(UsageError, match="one pass lasts 0.040 s"):
        Session.prepare(RunRequest(str(write_show(tmp_path, SHORT_MOTIONS)), loop="a..b", no_log=True))


@pytest.mark.parametrize("body, loop", [
    ("version: 1\nsteps:\n  - play: 1\n    label: a\n  - wait: 0.1\n  - play: 2\n", "a..1"),
    ("version: 1\nsteps:\n  - play: 1\n    label: a\n  - play: 2\n    at: go\n    label: b\n  - play: 3\n", "a..b"),
    ("version: 1\nsteps:\n  - play: 1\n    label: a\n  - wait: done\n  - play: 2\n", "a..1"),
])
def test_a_loop_that_takes_time_or_waits_for_go_is_taken(tmp_path, body, loop):
    """0.1 s of show time is enough; a GO cue paces a pass by hand, however short its plan."""
    session = Session.prepare(RunRequest(str(write_show(tmp_path, body)), loop=loop, no_log=True))
    assert session.settings.sections.loop is not None


MUSIC_SHOW = """\
version: 1
music: {file: song.wav, start: START}
steps:
  - play: 1
    at: 0.2
    label: early
  - play: 2
    at: 0.9
    label: edge
  - play: 3
    at: 2.0
    label: late
  - wait: 0.5
    label: after
"""


@pytest.mark.parametrize("start, options, at", [
    (0, ["--from", "late"], "2.000"),
    (0, ["--from", "after"], "2.000"),
    (0, ["--from", "3"], "2.000"),
    (0.5, ["--from", "edge"], "0.900"),
    (0, ["--loop", "late..after"], "2.000"),
])
def test_from_past_the_end_of_the_music_is_refused(tmp_path, capsys, start, options, at):
    write_song(tmp_path / "song.wav", 1.4)
    show = write_show(tmp_path, MUSIC_SHOW.replace("START", str(start)))
    log = tmp_path / "run.mcap"
    code = main(["run", str(show), *options, "--audio-device", "null", "--log", str(log), "-q",
                 "--port", str(tmp_path / "no-such-tty")])  # 3 would mean the port was tried
    err = capsys.readouterr().err.strip().splitlines()
    assert code == 2 and len(err) == 1, err
    assert f"it starts at {at} s of show time, past the end of the music" in err[0]
    assert err[0].startswith(" ".join(options)) and "--no-music" in err[0]
    assert not log.exists()


def test_from_inside_the_music_or_without_it_is_taken(tmp_path):
    write_song(tmp_path / "song.wav", 1.4)
    show = str(write_show(tmp_path, MUSIC_SHOW.replace("START", "0")))
    edge = Session.prepare(RunRequest(show, from_step="edge", no_log=True, audio_device="null"))
    assert edge.settings.sections.origin == 0.9
    late = Session.prepare(RunRequest(show, from_step="late", no_log=True, no_music=True))
    assert late.settings.sections.origin == 2.0


@pytest.mark.parametrize("ref", ["9" * 5000, "9" * 20, "1" + "0" * 4400])
@pytest.mark.parametrize("option", ["--from", "--loop"])
def test_a_step_number_too_long_for_any_show_is_one_line(tmp_path, capsys, ref, option):
    """int() refuses a number past 4,300 digits: `--from 999…` was a ValueError traceback."""
    show = write_show(tmp_path, "version: 1\nsteps:\n  - play: 1\n  - play: 2\n")
    value = ref if option == "--from" else f"0..{ref}"
    assert main(["run", str(show), "--no-log", option, value]) == 2
    err = capsys.readouterr().err
    assert len(err.splitlines()) == 1 and "Traceback" not in err, err[-500:]
