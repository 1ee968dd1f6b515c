"""The show format on the Ableton Link clock (issue 25): `clock: link`, `tempo: {bpm: link}`,
`hosts:`. What a Link show may not hold (a GO cue, music, a tempo map, an offset to bar 1) is
refused where it is written, in one line that says why and what to do; `--clock` moves a show
onto or off the Link clock when the show allows it. Nothing here opens a Link session."""

from __future__ import annotations

from pathlib import Path

import pytest

from choreo.errors import ShowError, UsageError
from choreo.run.settings import RunRequest, RunSettings
from choreo.show.load import load_show, load_show_bytes
from choreo.show.model import NOMINAL_BPM, LinkClock
from choreo.show.plan import compile_plans
from runlog import vmain, write_show



HOSTS_BASE = "version: 1\nclock: link\nrobots:\n  a: {}\n  b: {}\n  c: {}\n"


def problems(text: str) -> list[str]:
    """Every problem of a show, one line each."""
    with pytest.raises(ShowError) as caught:
        load_show_bytes(text.encode(), "show.yaml")
    lines = str(caught.value).splitlines()
    assert all(line.startswith("show.yaml:") for line in lines), lines
    return lines


def test_a_link_show_loads_with_its_tempo_meter_and_hosts():
    show = load_show_bytes(b"version: 1\nclock: link\ntempo: {bpm: 128, meter: 3}\nsteps:\n  - play: 1\n"
                           b"    at: {bar: 2}\n")
    assert show.clock == "link" and show.link == LinkClock(128.0, 3)
    assert show.steps[0].at == pytest.approx(3 * 60 / 128)  # bar 2 of 3/4 at 128 bpm: planned at the proposal


def test_bpm_link_takes_the_sessions_tempo_and_plans_at_a_nominal_one():
    show = load_show_bytes(b"version: 1\nclock: link\ntempo: {bpm: link, meter: 3}\nsteps:\n  - play: 1\n"
                           b"    at: {bar: 3, beat: 2}\n")
    assert show.link == LinkClock(None, 3)
    assert show.tempo is not None and show.tempo.bpm == NOMINAL_BPM == 120.0
    plan = compile_plans(show)["robot"]
    assert plan.steps[0].at == pytest.approx((2 * 3 + 1) * 0.5) and plan.steps[0].at_beat == (3, 2.0)


def test_clock_link_without_tempo_is_the_sessions_tempo_in_four_and_a_machine_show_has_no_link():
    show = load_show_bytes(b"version: 1\nclock: link\nsteps:\n  - play: 1\n    at: 2\n")
    assert show.link == LinkClock(None, 4) and show.tempo is None and show.hosts == {}
    machine = load_show_bytes(b"version: 1\ntempo: {bpm: 90}\nsteps:\n  - play: 1\n")
    assert machine.clock == "machine" and machine.link is None
    [bar] = problems("version: 1\nclock: link\nsteps:\n  - play: 1\n    at: {bar: 2}\n")
    assert bar.startswith("show.yaml:5:9: steps[0].at: a cue in bars and beats needs the music's `tempo:`")


@pytest.mark.parametrize(("body", "where", "says"), [
    ("tempo: {bpm: 120, offset: 0.5}\nsteps:\n  - play: 1\n", "3:27: tempo.offset",
     "on the Link clock bar 1 starts at show time 0, on a bar line of the session: leave out `offset:`"),
    ("tempo: {bars: [0, 2, 4]}\nsteps:\n  - play: 1\n", "3:9: tempo.bars",
     "a tempo map follows a recording's drift, and on the Link clock the session sets the tempo: give one tempo"),
    ("music: {file: song.wav}\nsteps:\n  - play: 1\n", "3:1: music",
     "music is not stretched to a tempo another peer sets: leave out `music:`"),
    ("steps:\n  - play: 1\n  - play: 2\n    at: go\n", "6:9: steps[1].at",
     "the Link session's beat never stops: a GO cue cannot hold it: cue the step in bars and beats or in seconds"),
    ("steps:\n  - repeat: 2\n    at: go\n    steps: [{play: 1}]\n", "5:9: steps[0].at",
     "a GO cue cannot hold it"),
    ("tempo: {bpm: 5}\nsteps:\n  - play: 1\n", "3:14: tempo.bpm",  # R1: Link took 20 bpm without a word
     "5 bpm: an Ableton Link session's tempo is 20 bpm at the least"),
])
def test_what_the_link_clock_cannot_keep_is_refused_where_it_is_written(body, where, says):
    [found] = problems("version: 1\nclock: link\n" + body)
    assert found.startswith(f"show.yaml:{where}: ") and says in found
    assert found.endswith("or use `clock: machine`")


def test_a_zero_offset_is_no_offset_and_bpm_link_needs_the_link_clock():
    assert load_show_bytes(b"version: 1\nclock: link\ntempo: {bpm: 100, offset: 0}\nsteps: [{play: 1}]\n").link \
        == LinkClock(100.0, 4)
    assert problems("version: 1\ntempo: {bpm: link}\nsteps: [{play: 1}]\n") == [
        "show.yaml:2:14: tempo.bpm: `bpm: link` takes the Ableton Link session's tempo: add `clock: link`, or "
        "give the beats a minute"]
    assert problems("version: 1\nclock: link\ntempo: {bpm: fast}\nsteps: [{play: 1}]\n") == [
        "show.yaml:3:14: tempo.bpm: the tempo is beats a minute (more than 0, at most 400) or `link` (with "
        "`clock: link`: the session's), not 'fast'"]
    assert problems("version: 1\nclock: midi\nsteps: [{play: 1}]\n") == [
        "show.yaml:2:8: clock: must be one of 'machine', 'link', not 'midi'"]


def test_a_link_show_with_a_missing_music_file_says_only_that_music_is_refused(tmp_path):
    path = write_show(tmp_path, "version: 1\nclock: link\nmusic: {file: gone.wav}\nsteps: [{play: 1}]\n")
    with pytest.raises(ShowError) as caught:
        load_show(path)
    assert len(str(caught.value).splitlines()) == 1 and "music is not stretched" in str(caught.value)


def test_hosts_share_the_robots_each_on_exactly_one():
    show = load_show_bytes((HOSTS_BASE + "hosts:\n  left: [a, b]\n  right-2: [c]\nsteps: [{play: 1}]\n").encode())
    assert show.hosts == {"left": ("a", "b"), "right-2": ("c",)}
    assert show.host_of("c") == "right-2" and show.host_of("a") == "left"


@pytest.mark.parametrize(("hosts", "found"), [
    ("  left: [a, b]\n  right: [b, c]\n",
     "show.yaml:9:11: hosts.right[0]: robot 'b' is already on host 'left' (line 8): one host drives each robot"),
    ("  left: [a]\n  right: [b]\n",
     "show.yaml:7:1: hosts: robot 'c' is on no host: add it to the list of the host that drives it"),
    ("  left: [a, bb]\n  right: [b, c]\n",
     "show.yaml:8:13: hosts.left[1]: host 'left' drives robot 'bb', which `robots:` does not name: "
     "did you mean 'b'? the robots are a, b, c"),
    ("  'left side': [a, b, c]\n",
     "show.yaml:8:3: hosts[\"left side\"]: host name 'left side' must hold only letters, digits, `_` and `-`"),
    ("  left: [a, a, b, c]\n", "show.yaml:8:9: hosts.left: host 'left' names a robot twice: list each once"),
    ("  left: []\n  right: [a, b, c]\n", "show.yaml:8:9: hosts.left: host 'left' drives no robot"),
    ("  {}\n", "show.yaml:8:3: hosts: `hosts:` is empty"),
])
def test_each_host_mistake_is_said_where_it_is(hosts, found):
    [said] = problems(HOSTS_BASE + "hosts:\n" + hosts + "steps: [{play: 1}]\n")
    assert said.startswith(found)


def test_hosts_need_the_link_clock_and_a_show_for_several_robots():
    [said] = problems(HOSTS_BASE.replace("clock: link\n", "") + "hosts:\n  h: [a, b, c]\nsteps: [{play: 1}]\n")
    assert said.startswith("show.yaml:6:1: hosts: hosts play in unison on the Ableton Link session's beat: "
                           "add `clock: link`")
    [said] = problems("version: 1\nclock: link\nrobot: {}\nhosts:\n  h: [robot]\nsteps: [{play: 1}]\n")
    assert said.startswith("show.yaml:4:1: hosts: `hosts:` shares a show's `robots:` among computers, and this "
                           "show has one robot (`robot:`): leave out `hosts:`")


def test_robots_on_different_hosts_may_name_the_same_device_but_not_on_one_host():
    text = ("version: 1\nclock: link\nrobots:\n  a: {port: /dev/ttyUSB0}\n  b: {port: /dev/ttyUSB0}\n"
            "hosts:\n  left: [a]\n  right: [b]\nsteps: [{play: 1}]\n")
    assert load_show_bytes(text.encode()).hosts == {"left": ("a",), "right": ("b",)}
    [said] = problems(text.replace("  left: [a]\n  right: [b]\n", "  left: [a, b]\n"))
    assert "port /dev/ttyUSB0 is already robot a's" in said


def test_validate_exits_2_on_a_link_refusal(tmp_path, capsys):
    path = write_show(tmp_path, "version: 1\nclock: link\nsteps:\n  - play: 1\n    at: go\n")
    assert vmain(["validate", str(path)]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "a GO cue cannot hold it" in err[0]


# --------------------------------------------------------------------------- --clock


def settle(tmp_path: Path, body: str, **request) -> RunSettings:
    return RunSettings.settle(RunRequest(str(write_show(tmp_path, body)), no_log=True, **request))


def test_the_run_is_on_the_link_clock_as_the_show_says_unless_clock_machine(tmp_path):
    body = "version: 1\nclock: link\ntempo: {bpm: link, meter: 3}\nsteps: [{play: 1}]\n"
    assert settle(tmp_path, body).link == LinkClock(None, 3)
    assert settle(tmp_path, body, clock="link").link == LinkClock(None, 3)
    rehearsal = settle(tmp_path, body, clock="machine")
    assert rehearsal.link is None and rehearsal.host is None


def test_clock_link_takes_a_machine_show_onto_the_session_with_its_tempo(tmp_path):
    assert settle(tmp_path, "version: 1\ntempo: {bpm: 96, meter: 6}\nsteps: [{play: 1}]\n",
                  clock="link").link == LinkClock(96.0, 6)
    assert settle(tmp_path, "version: 1\nsteps: [{play: 1}]\n", clock="link").link == LinkClock(None, 4)
    assert settle(tmp_path, "version: 1\nsteps: [{play: 1}]\n").link is None


@pytest.mark.parametrize(("body", "says"), [
    ("tempo: {bpm: 120, offset: 0.25}\nsteps: [{play: 1}]\n",
     "--clock link: the show's bar 1 is at 0.25 s; on the Link clock bar 1 starts at show time 0"),
    ("tempo: {bars: [0, 2, 4]}\nsteps: [{play: 1}]\n", "--clock link: the show has a tempo map;"),
    ("steps:\n  - play: 1\n  - play: 2\n    at: go\n    label: drop\n",
     "--clock link: step drop (line 4) waits for GO; the Link session's beat never stops"),
])
def test_clock_link_refuses_a_show_that_needs_a_clock_of_its_own(tmp_path, body, says):
    with pytest.raises(UsageError) as caught:
        settle(tmp_path, "version: 1\n" + body, clock="link")
    assert str(caught.value).startswith(says) and str(caught.value).endswith("(or leave out --clock link)")
    assert "\n" not in str(caught.value)


def test_clock_link_on_a_music_show_needs_no_music(tmp_path):
    (tmp_path / "song.wav").write_bytes(b"")
    body = "version: 1\nmusic: {file: song.wav}\nsteps: [{play: 1}]\n"
    with pytest.raises(UsageError, match=r"^--clock link: the show has `music:`; .*: add --no-music"):
        settle(tmp_path, body, clock="link")
    silent = settle(tmp_path, body, clock="link", no_music=True)
    assert silent.link == LinkClock(None, 4) and silent.song is None


def test_choreo_run_clock_link_refusal_exits_2(tmp_path, capsys):
    path = write_show(tmp_path, "version: 1\ntempo: {bars: [0, 2, 4]}\nsteps: [{play: 1}]\n")
    assert vmain(["run", str(path), "--clock", "link", "--no-log"]) == 2
    assert "--clock link: the show has a tempo map" in capsys.readouterr().err
    with pytest.raises(SystemExit) as caught:  # argparse's own refusal
        vmain(["run", str(path), "--clock", "midi", "--no-log"])
    assert caught.value.code == 2


def test_choreo_plan_says_the_plan_is_drawn_at_a_nominal_tempo(tmp_path, capsys):
    path = write_show(tmp_path, "version: 1\nclock: link\ntempo: {bpm: link, meter: 3}\nsteps:\n  - play: 1\n"
                                "    at: {bar: 2}\n")
    assert vmain(["plan", str(path)]) == 0
    out = capsys.readouterr().out
    assert "clock: Ableton Link, 3 beats a bar; tempo: the session's (planned here at 120 bpm)" in out
    assert "1.500 s (at 1.5 = bar 2 beat 1)" in out
    path.write_text("version: 1\nclock: link\ntempo: {bpm: 96}\nsteps: [{play: 1}]\n")
    assert vmain(["plan", str(path)]) == 0
    assert "clock: Ableton Link, 4 beats a bar; tempo: 96 bpm proposed to the session" in capsys.readouterr().out
