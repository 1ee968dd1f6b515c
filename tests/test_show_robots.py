"""Shows for several robots: `robots:`, shared `steps:` (with per-step `robots:`) or `tracks:`;
located errors; one plan per robot on one show clock; `choreo plan` per robot."""

from __future__ import annotations

import json
from pathlib import Path
from textwrap import dedent

import pytest

from choreo.cli import main
from choreo.errors import ShowError
from choreo.show.load import load_show
from choreo.show.model import SOLO
from choreo.show.plan import compile_plan, compile_plans

UNISON = """
    version: 1
    robots:
      a: {}
      b: {layout: hth4-2.2, on_abort: 9}
      c: {on_fault: continue}
    on_abort: 0
    motions:
      bow: {number: 1, duration: 2}
    steps:
      - play: bow
      - wait: done
      - play: 2
        robots: [a]
      - wait: done
        robots: [a]
      - repeat: 2
        robots: [b, c]
        steps:
          - play: 3
          - wait: 0.5
      - play: 4
        at: 6
      - wait: done
"""

CANON = """
    version: 1
    robots:
      lead: {}
      follow: {}
    tracks:
      lead:
        - play: 1
          label: go
        - wait: done
        - play: 2
          at: 3
      follow:
        - play: 1
        - wait: 2
        - play: 2
          at: 5
          label: answer
"""


def write(tmp_path: Path, text: str) -> Path:
    path = tmp_path / "show.yaml"
    path.write_text(dedent(text).lstrip())
    return path


def problems(tmp_path: Path, text: str) -> list[tuple[int, int, str, str]]:
    with pytest.raises(ShowError) as info:
        load_show(write(tmp_path, text))
    return [(p.line, p.column, p.path, p.message) for p in info.value.problems]


def test_a_unison_show_loads_with_every_robot_and_its_settings(tmp_path):
    show = load_show(write(tmp_path, UNISON))
    assert show.ensemble and list(show.cast) == ["a", "b", "c"]
    assert show.cast["b"].layout == "hth4-2.2" and show.cast["c"].on_fault == "continue"
    assert show.abort_motion("a") == 0 and show.abort_motion("b") == 9
    assert show.steps[2].robots == ("a",) and show.steps[4].robots == ("b", "c")


def test_a_one_robot_show_is_the_robot_named_robot():
    show = load_show("shows/dance.yaml")
    assert not show.ensemble and list(show.cast) == [SOLO] and show.cast[SOLO] == show.robot


def test_unison_plans_share_indices_and_times_and_mark_who_does_what(tmp_path):
    show = load_show(write(tmp_path, UNISON))
    plans = compile_plans(show)
    assert list(plans) == ["a", "b", "c"] and all(plan.unison for plan in plans.values())
    starts = {name: [step.planned_s for step in plan.steps] for name, plan in plans.items()}
    assert starts["a"] == starts["b"] == starts["c"]
    a, b = plans["a"], plans["b"]
    assert [step.index for step in a.steps if step.is_for("a")] == [0, 1, 2, 3, 8, 9]
    assert [step.index for step in b.steps if step.is_for("b")] == [0, 1, 4, 5, 6, 7, 8, 9]
    # each robot's frames are its own layout's; steps for others send nothing
    assert a.steps[0].frames[0].data != b.steps[0].frames[0].data and b.layout == "hth4-2.2"
    assert b.steps[2].frames == () and a.steps[4].frames == ()
    # a `wait: done` for [a] waits for a's motion 2; the repeat for b and c starts after it
    assert a.steps[3].motion == 2 and a.steps[3].expected_s == pytest.approx(1.0)
    assert b.steps[4].planned_s == pytest.approx(3.0)
    assert a.steps[8].planned_s == 6.0 and a.estimated_s == pytest.approx(7.0)
    assert a.motions_used() == [1, 2, 4] and b.motions_used() == [1, 3, 4]


def test_a_wait_done_for_several_robots_lasts_until_the_latest_motion_ends(tmp_path):
    show = load_show(write(tmp_path, """
        version: 1
        robots: {a: {}, b: {}}
        motions: {short: {number: 1, duration: 1}, long: {number: 2, duration: 3}}
        steps:
          - play: short
            robots: [a]
          - play: long
            robots: [b]
          - wait: done
          - play: 5
    """))
    plans = compile_plans(show)
    assert plans["a"].steps[2].motion == 1 and plans["b"].steps[2].motion == 2
    assert plans["a"].steps[3].planned_s == pytest.approx(3.0)


def test_tracks_are_plans_of_their_own_on_one_clock(tmp_path):
    show = load_show(write(tmp_path, CANON))
    plans = compile_plans(show)
    assert not plans["lead"].unison and plans["lead"].robot == "lead"
    assert [s.planned_s for s in plans["lead"].steps] == [0.0, 0.0, 3.0]
    assert [s.planned_s for s in plans["follow"].steps] == [0.0, 0.0, 5.0]
    assert plans["follow"].steps[2].label == "answer" and plans["follow"].steps[0].path == "tracks.follow[0]"
    assert compile_plan(show).robot == "lead"  # the first robot's, for one-robot callers


@pytest.mark.parametrize("text, where, message", [
    ("version: 1\nrobots: {a: {}}\ntracks: {a: [{play: 1}], b: [{play: 1}]}\n",
     (3, 26, "tracks.b"), "a track for robot 'b', which `robots:` does not name"),
    ("version: 1\nrobots: {left: {}, right: {}}\ntracks: {left: [{play: 1}]}\n",
     (3, 1, "tracks"), "robot 'right' has no track"),
    ("version: 1\nrobots: {left: {}, right: {}}\nsteps:\n  - play: 1\n    robots: [lfet]\n",
     (5, 14, "steps[0].robots[0]"), "a step for robot 'lfet', which `robots:` does not name: did you mean 'left'?"),
    ("version: 1\nrobots: {a: {port: /dev/ttyUSB0}, b: {port: /dev/ttyUSB0}}\nsteps: [{play: 1}]\n",
     (2, 45, "robots.b.port"), "port /dev/ttyUSB0 is already robot a's: each robot needs its own port"),
    ("version: 1\nsteps:\n  - play: 1\n    robots: [a]\n", (4, 5, "steps[0].robots"),
     "this show has one robot (`robot:`)"),
    ("version: 1\nrobot: {}\nrobots: {a: {}}\nsteps: [{play: 1}]\n", (3, 1, "robots"),
     "a show has `robot:` (one robot) or `robots:` (several, by name), not both"),
    ("version: 1\nrobots: {a: {}}\nsteps: [{play: 1}]\ntracks: {a: [{play: 1}]}\n", (4, 1, "tracks"),
     "a show has `steps:` (every robot together) or `tracks:` (one list per robot), not both"),
    ("version: 1\ntracks: {a: [{play: 1}]}\n", (2, 1, "tracks"), "name the robots in `robots:` first"),
    ("version: 1\nrobots: {1a: {}}\nsteps: [{play: 1}]\n", (2, 10, 'robots["1a"]'),
     "robot name '1a' must start with a letter"),
    ("version: 1\nrobots: {a: {}, b: {}}\nsteps:\n  - play: 1\n    robots: [a]\n  - wait: done\n",
     (6, 11, "steps[1].wait"), "(robot 'b' has played nothing yet)"),
    ("version: 1\nrobots: {a: {}}\ntracks:\n  a:\n    - play: 1\n      robots: [a]\n", (6, 7, "tracks.a[0].robots"),
     "a step in a track is that robot's own"),
    ("version: 1\nrobot: {on_fault: continue}\nsteps: [{play: 1}]\n", (2, 9, "robot.on_fault"),
     "it is for a robot in `robots:`"),
    ("version: 1\nrobots: {a: {on_abort: homee}}\nmotions: {home: {number: 0}}\nsteps: [{play: 1}]\n",
     (2, 24, "robots.a.on_abort"), "unknown motion 'homee'"),
    ("version: 1\nrobots: {a: {}}\ntracks:\n  a:\n    - play: 1\n      at: 5\n    - play: 2\n      at: 3\n",
     (8, 11, "tracks.a[1].at"), "cues must not go back in time"),
])
def test_mistakes_with_robots_are_located_and_say_what_to_do(tmp_path, text, where, message):
    found = problems(tmp_path, text)
    assert any((line, column, path) == where and message in said for line, column, path, said in found), found


def test_labels_are_unique_across_tracks_and_cues_are_per_track(tmp_path):
    found = problems(tmp_path, """
        version: 1
        robots: {a: {}, b: {}}
        tracks:
          a: [{play: 1, at: 5, label: x}]
          b: [{play: 1, at: 2, label: x}]
    """)
    assert [(path, said.split(":")[0]) for _, _, path, said in found] == [
        ("tracks.b[0].label", "label 'x' is already used by tracks.a[0] (line 4)")]


def test_sim_ports_may_repeat_real_ones_may_not(tmp_path):
    show = load_show(write(tmp_path, "version: 1\nrobots: {a: {port: 'sim://'}, b: {port: 'sim://'}}\n"
                                     "steps: [{play: 1}]\n"))
    assert [s.port for s in show.cast.values()] == ["sim://", "sim://"]


def test_choreo_plan_prints_a_section_per_robot(tmp_path, capsys, monkeypatch):
    monkeypatch.setenv("COLUMNS", "200")
    assert main(["plan", str(write(tmp_path, UNISON))]) == 0
    out = capsys.readouterr().out
    assert "3 robots, shared steps, one show clock" in out
    sections = out.split("\nrobot ")[1:]
    assert [s.split(":")[0] for s in sections] == ["a", "b", "c"]
    assert "play 2 [a]" in sections[0] and "play 2" not in sections[1]
    assert "layout hth4-2.2" in sections[1] and "estimated total 7.0 s" in out
    assert main(["plan", "--json", str(write(tmp_path, CANON))]) == 0
    record = json.loads(capsys.readouterr().out)
    assert record["tracks"] is True and list(record["robots"]) == ["lead", "follow"]
    assert [step["start_s"] for step in record["robots"]["follow"]["plan"]] == [0.0, 0.0, 5.0]


def test_validate_counts_every_robots_steps(tmp_path, capsys):
    assert main(["validate", str(write(tmp_path, UNISON)), "shows/canon.yaml"]) == 0
    out = capsys.readouterr().out.splitlines()
    assert ": ok, 3 robots, 22 steps" in out[0] and "shows/canon.yaml: ok, 2 robots, 20 steps" in out[1]


def test_one_device_spelt_two_ways_is_still_one_port(tmp_path):
    found = problems(tmp_path, "version: 1\nrobots: {a: {port: /dev/ttyUSB0}, b: {port: /dev/../dev/ttyUSB0}}\n"
                               "steps: [{play: 1}]\n")
    assert [path for _, _, path, _ in found] == ["robots.b.port"]


@pytest.mark.parametrize("body, where, message", [
    ("robots: {a: {}}\nsteps:\n  - play: 1\n    robots: [1, a]\n", "steps[0].robots[0]",
     "expected text, not the number 1"),
    ("robots: {}\nsteps: [{play: 1}]\n", "robots", "`robots:` is empty: name at least one robot"),
    ("robots: {a: {}}\nsteps:\n  - play: 1\n    robots: [a, a]\n", "steps[0].robots", "names a robot twice"),
    ("robots: {a: {}}\nsteps:\n  - play: 1\n    robots: ['1']\n", "steps[0].robots[0]", "robot name '1' must start"),
    ("robots: {a: {}}\nsteps:\n  - play: 1\n    robots: []\n", "steps[0].robots", "a step's `robots:` is empty"),
    ("robots: {a: {}}\ntracks: {}\n", "tracks", "`tracks:` is empty"),
])
def test_robot_lists_of_the_wrong_shape_get_plain_words(tmp_path, body, where, message):
    found = problems(tmp_path, "version: 1\n" + body)
    assert any(path == where and message in said for _, _, path, said in found), found
    assert not any("Properties" in said or "uniqueItems" in said or "pattern" in said for _, _, _, said in found)
