"""`compile_plan`: repeats expanded with traceable paths, the timing rule, the frames each step sends."""

from __future__ import annotations

from pathlib import Path
from textwrap import dedent

import pytest

from choreo.wire import protocol
from choreo.show.load import load_show
from choreo.show.model import DEFAULT_DONE_TIMEOUT_S, DEFAULT_MOTION_S, Repeat, Show, Step, StepKind
from choreo.show.plan import compile_plan, late_cues, load_plan

ROOT = Path(__file__).resolve().parent.parent


def plan_of(tmp_path: Path, text: str):
    path = tmp_path / "show.yaml"
    path.write_text(dedent(text).lstrip("\n"))
    return compile_plan(load_show(path))


def starts(plan) -> list[float]:
    return [step.planned_s for step in plan.steps]


def test_a_play_takes_no_time_and_a_wait_its_seconds(tmp_path):
    plan = plan_of(tmp_path, """
        version: 1
        steps:
          - play: 1
          - wait: 0.5
          - play: 2
          - wait: 0.25
    """)
    assert starts(plan) == [0.0, 0.0, 0.5, 0.5]
    assert [s.expected_s for s in plan.steps] == [0.0, 0.5, 0.0, 0.25]
    assert plan.estimated_s == 0.75


def test_wait_done_takes_the_rest_of_the_motion_from_its_start(tmp_path):
    plan = plan_of(tmp_path, """
        version: 1
        motions:
          wave: {number: 4, duration: 2.5}
        steps:
          - play: wave
          - wait: 0.5
          - wait: done
          - play: 7
          - wait: done
    """)
    assert starts(plan) == [0.0, 0.0, 0.5, 2.5, 2.5]
    assert plan.steps[2].expected_s == 2.0  # 2.5 s motion, 0.5 s of it already waited
    assert plan.steps[4].expected_s == DEFAULT_MOTION_S  # no duration given
    assert plan.estimated_s == 2.5 + DEFAULT_MOTION_S


def test_wait_done_after_the_motion_ended_takes_nothing(tmp_path):
    plan = plan_of(tmp_path, """
        version: 1
        motions: {bow: {number: 1, duration: 1}}
        steps: [{play: bow}, {wait: 3}, {wait: done}]
    """)
    assert plan.steps[2].planned_s == 3.0 and plan.steps[2].expected_s == 0.0


def test_a_second_wait_done_without_a_play_takes_nothing(tmp_path):
    plan = plan_of(tmp_path, """
        version: 1
        motions: {bow: {number: 1, duration: 2}}
        steps: [{play: bow}, {wait: done}, {wait: done}, {wait: 1}]
    """)
    assert [s.expected_s for s in plan.steps] == [0.0, 2.0, 0.0, 1.0]
    assert plan.estimated_s == 3.0


def test_a_cue_delays_a_step_and_a_missed_cue_does_not(tmp_path):
    plan = plan_of(tmp_path, """
        version: 1
        steps:
          - play: 1
            at: 2
          - wait: 1
          - play: 2
            at: 2.5
          - wait: 1
          - play: 3
            label: on-beat
            at: 10
    """)
    assert starts(plan) == [2.0, 2.0, 3.0, 3.0, 10.0]
    assert [s.at for s in plan.steps] == [2.0, None, 2.5, None, 10.0]
    assert late_cues(plan) == [plan.steps[2]]  # due at 2.5, the wait before it ends at 3
    assert plan.estimated_s == 10.0


def test_times_are_exact_to_the_microsecond(tmp_path):
    plan = plan_of(tmp_path, "version: 1\nsteps: [{wait: 0.1}, {wait: 0.2}, {play: 1}]\n")
    assert plan.steps[2].planned_s == 0.3


def test_frames_of_each_kind(tmp_path):
    plan = plan_of(tmp_path, "version: 1\nsteps: [{play: 119}, {wait: 1}, {wait: done, timeout: 5}]\n")
    play, wait, done = plan.steps
    assert play.frames == protocol.play_sequence(119)
    assert [f.hex for f in play.frames] == [
        "13 00 02 00 00 00 21 87 fd 03 00 00 00 00 00 00 00 00 bd",
        "07 0c b8 c3 03 00 91",
        "09 00 02 00 00 00 23 87 b5",
    ]
    assert wait.frames == ()
    assert done.frames == (protocol.status_frame(),)
    assert (done.kind, done.motion, done.seconds) == (StepKind.WAIT_DONE, 119, 5.0)


def test_wait_done_names_the_motion_it_waits_for(tmp_path):
    plan = plan_of(tmp_path, """
        version: 1
        motions: {wave: {number: 4}}
        steps: [{play: wave}, {wait: done}]
    """)
    assert (plan.steps[1].motion, plan.steps[1].motion_name) == (4, "wave")
    assert plan.steps[1].seconds == DEFAULT_DONE_TIMEOUT_S
    assert plan.steps[1].describe() == "wait until motion 4 is done (timeout 60 s)"
    assert plan.steps[0].describe() == "play 4 (wave)"


def test_repeats_expand_with_iteration_paths(tmp_path):
    plan = plan_of(tmp_path, """
        version: 1
        steps:
          - play: 1
          - repeat: 2
            steps:
              - play: 2
              - repeat: 2
                steps:
                  - wait: 0.5
          - play: 3
    """)
    assert [s.path for s in plan.steps] == [
        "steps[0]",
        "steps[1]#1.steps[0]",
        "steps[1]#1.steps[1]#1.steps[0]",
        "steps[1]#1.steps[1]#2.steps[0]",
        "steps[1]#2.steps[0]",
        "steps[1]#2.steps[1]#1.steps[0]",
        "steps[1]#2.steps[1]#2.steps[0]",
        "steps[2]",
    ]
    assert [s.index for s in plan.steps] == list(range(8))
    assert starts(plan) == [0.0, 0.0, 0.0, 0.5, 1.0, 1.0, 1.5, 2.0]
    assert [s.line for s in plan.steps] == [3, 6, 9, 9, 6, 9, 9, 10]


def test_labels_inside_repeats_are_marked_after_the_first_pass(tmp_path):
    plan = plan_of(tmp_path, """
        version: 1
        steps:
          - repeat: 3
            label: chorus
            at: 4
            steps:
              - play: 1
              - wait: 1
                label: hold
    """)
    assert [s.label for s in plan.steps] == ["chorus", "hold", None, "hold#2", None, "hold#3"]
    assert plan.steps[0].at == 4.0 and all(s.at is None for s in plan.steps[1:])
    assert starts(plan)[:3] == [4.0, 4.0, 5.0]
    assert plan.find("chorus") == 0 and plan.find("hold#3") == 5 and plan.find("2") == 2
    with pytest.raises(KeyError):
        plan.find("verse")


def test_motions_used_and_estimated_total_of_the_dance():
    show, plan = load_plan(ROOT / "shows" / "dance.yaml")
    assert plan.motions_used() == [0, 1, 4, 5, 10, 11, 20, 30, 40]
    assert plan.estimated_s == 22.0
    assert plan.estimated_s < 30  # the issue: it runs in under 30 s on the simulator
    assert late_cues(plan) == []
    spin = plan.steps[plan.find("spin")]
    assert (spin.planned_s, spin.at, spin.motion_name) == (14.0, 14.0, "spin")
    assert plan.find("groove") == 8 and plan.steps[8].path == "steps[8]#1.steps[0]"


@pytest.mark.parametrize("name", ["dance.yaml", "minimal.yaml", "music.yaml"])
def test_every_example_compiles_with_sane_steps(name):
    _, plan = load_plan(ROOT / "shows" / name)
    assert plan.steps and plan.steps[0].planned_s == 0.0
    assert starts(plan) == sorted(starts(plan))
    for step in plan.steps:
        if step.kind is StepKind.PLAY:
            assert step.frames == protocol.play_sequence(step.motion)


def test_music_stays_on_the_beat():
    _, plan = load_plan(ROOT / "shows" / "music.yaml")
    sways = [s.planned_s for s in plan.steps if s.motion_name == "sway"]
    assert sways == [6.0, 8.0, 10.0, 12.0]


def test_a_show_built_without_yaml_compiles():
    """The planner needs only the records: the runner's tests can build shows in code."""
    show = Show(
        path="<test>",
        name="t",
        source=b"",
        steps=(
            Step("steps[0]", StepKind.PLAY, motion=5),
            Repeat("steps[1]", 2, (Step("steps[1].steps[0]", StepKind.WAIT, seconds=0.5),)),
            Step("steps[2]", StepKind.WAIT_DONE, seconds=3.0),
        ),
    )
    plan = compile_plan(show)
    assert [s.path for s in plan.steps] == ["steps[0]", "steps[1]#1.steps[0]", "steps[1]#2.steps[0]", "steps[2]"]
    assert starts(plan) == [0.0, 0.0, 0.5, 1.0]
    assert plan.steps[3].expected_s == 0.0 and plan.estimated_s == 1.0  # 1 s default motion, 1 s waited
