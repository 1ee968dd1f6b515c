"""Skipping cues in a run (issue 24): a skipped cue's step is not run (one `skip` event, no
frame), a GO cue waiting is released as skipped, a skip is undone by skipping again, and with
several robots (shared steps and tracks) every robot passes the cue and the gates still open.

On virtual time against the in-process simulator (`test_pause.VirtualRun`): commands before
the show or from the run's own steps, so that what is skipped, and when, is exact.
"""

from __future__ import annotations

import pytest

from runlog import wait_for
from test_pause import VirtualRun

SOLO = """\
version: 1
steps:
  - play: 1
    label: one
  - play: 2
    at: 0.5
    label: two
  - wait: done
  - play: 3
    at: 1.5
    label: three
"""

SHARED = """\
version: 1
robots: {a: {}, b: {}}
steps:
  - play: 1
    label: one
  - play: 2
    at: 0.5
    label: two
  - wait: done
  - play: 3
    at: 2
    label: three
"""

TRACKS = """\
version: 1
robots: {a: {}, b: {}}
tracks:
  a:
    - play: 1
      at: 0.2
      label: a-one
    - play: 2
      at: 1
      label: a-two
    - play: 3
      label: a-three
  b:
    - play: 4
      at: 0.5
      label: b-one
    - play: 5
      at: 1
      label: b-two
"""


def events(log, topic: str = "/choreo/step") -> list[tuple]:  # type: ignore[no-untyped-def]
    return [(m.get("label"), m["event"], m.get("outcome")) for m in log.topic(topic)]


def motions(log, topic: str = "/rcb4/tx") -> list[int]:  # type: ignore[no-untyped-def]
    return [m["motion"] for m in log.topic(topic) if m["kind"] == "play"]


def test_a_cue_skipped_ahead_is_passed_without_a_frame(tmp_path):
    run = VirtualRun(tmp_path, SOLO, before=["skip two"])
    log = run.finish()
    assert run.result.outcome == "done" and run.result.steps_run == 3
    assert ("two", "skip", "skipped") in events(log)
    assert [e for e in events(log) if e[0] == "two"] == [("two", "skip", "skipped")]  # no start, no end
    assert motions(log) == [1, 3]
    three = next(m for m in log.steps if m.get("label") == "three" and m["event"] == "end")
    assert three["start_s"] == pytest.approx(1.5, abs=1e-3)  # the cues after it keep their times
    skip = next(m for m in log.steps if m["event"] == "skip")
    assert skip["cue_number"] == "1" and skip["outcome"] == "skipped"
    assert run.live.cue_state(run.live.cues.find("two")) == "skipped"
    assert any("step 1 'two' skipped (cue 1): not run" in m["message"] for m in log.logs)


def test_a_skip_given_while_the_robot_sleeps_towards_the_cue(tmp_path):
    run = VirtualRun(tmp_path, SOLO, at={(0, "end"): ["skip two"]})  # asleep towards 0.5 s
    log = run.finish()
    assert run.hook.answers[0].message == "skipped: cue 1 'two' will not run"
    assert motions(log) == [1, 3]
    assert [(m["command"], m["label"], m["status"]) for m in log.topic("/choreo/command")] == [("skip", "two", "ok")]


def test_a_skip_undone_runs_the_cue(tmp_path):
    run = VirtualRun(tmp_path, SOLO, at={(0, "start"): ["skip two", "skip 1"]})
    log = run.finish()
    assert motions(log) == [1, 2, 3] and "skip" not in [e[1] for e in events(log)]
    messages = [m["message"] for m in log.topic("/choreo/command")]
    assert messages == ["skipped: cue 1 'two' will not run", "skip undone: cue 1 'two' will run"]


def test_skipping_a_waiting_go_cue_lets_the_robot_go_on_past_it(tmp_path):
    body = SOLO.replace("    at: 0.5\n", "    at: go\n")
    run = VirtualRun(tmp_path, body)
    assert wait_for(lambda: bool(run.live.waiting), 10, 0.001)
    answer = run.say("skip")
    assert answer.ok and answer.message == "skipped: cue 1 'two'"
    log = run.finish()
    assert motions(log) == [1, 3] and ("two", "skip", "skipped") in events(log)
    assert not run.live.waiting and run.live.cue_state(run.live.cues.find("1")) == "skipped"


def test_a_shared_cue_skipped_is_passed_by_every_robot(tmp_path):
    run = VirtualRun(tmp_path, SHARED, at={(0, "start"): ["skip two"]}, robot="a")
    log = run.finish()
    assert run.result.outcome == "done" and run.hook.answers[0].ok
    for robot in ("a", "b"):
        assert motions(log, f"/rcb4/{robot}/tx") == [1, 3], robot
        assert [e for e in events(log, f"/choreo/{robot}/step") if e[0] == "two"] == [("two", "skip", "skipped")]
        three = next(m for m in log.topic(f"/choreo/{robot}/step") if m.get("label") == "three" and m["event"] == "end")
        assert three["start_s"] == pytest.approx(2.0, abs=2e-3)  # the gates opened: the cue after, on time


def test_a_shared_go_cue_skipped_while_both_robots_wait(tmp_path):
    """A GO cue of shared steps, skipped before the robots reach it: both pass it and neither
    waits for GO."""
    body = SHARED.replace("    at: 0.5\n", "    at: go\n")
    run = VirtualRun(tmp_path, body, before=["skip two"])
    log = run.finish()
    assert run.result.outcome == "done" and not run.live.waiting
    assert motions(log, "/rcb4/a/tx") == [1, 3] and motions(log, "/rcb4/b/tx") == [1, 3]


def test_a_tracks_cue_skipped_leaves_the_other_robot_alone(tmp_path):
    run = VirtualRun(tmp_path, TRACKS, before=["skip a-two"])
    log = run.finish()
    assert motions(log, "/rcb4/a/tx") == [1, 3] and motions(log, "/rcb4/b/tx") == [4, 5]
    b_two = next(m for m in log.topic("/choreo/b/step") if m.get("label") == "b-two" and m["event"] == "end")
    assert b_two["start_s"] == pytest.approx(1.0, abs=2e-3)
    cues = {c.label: run.live.cue_state(c) for c in run.live.cues}
    assert cues == {"a-one": "done", "b-one": "done", "a-two": "skipped", "b-two": "done"}


def test_jump_then_skip_with_several_robots(tmp_path):
    """The playhead put on b's cue (a jump), then `s`: that cue is skipped, a's is not."""
    run = VirtualRun(tmp_path, TRACKS, at={(0, "start"): ["playhead b-two", "skip"]}, robot="a")
    log = run.finish()
    assert motions(log, "/rcb4/a/tx") == [1, 2, 3] and motions(log, "/rcb4/b/tx") == [4]
    assert [m["message"] for m in log.topic("/choreo/command")] == ["playhead: cue 4 'b-two'",
                                                                      "skipped: cue 4 'b-two' will not run"]


def test_a_shared_go_cue_skipped_while_a_robot_waits_there_is_passed_by_both(tmp_path):
    body = SHARED.replace("    at: 0.5\n", "    at: go\n")
    run = VirtualRun(tmp_path, body)
    assert wait_for(lambda: bool(run.live.waiting), 10, 0.001)
    assert run.say("skip").message == "skipped: cue 1 'two'"
    log = run.finish()
    assert run.result.outcome == "done" and not run.live.waiting
    for robot in ("a", "b"):
        assert motions(log, f"/rcb4/{robot}/tx") == [1, 3], robot
        assert [e for e in events(log, f"/choreo/{robot}/step") if e[0] == "two"] == [("two", "skip", "skipped")]


def test_a_go_cue_skipped_as_its_robot_reaches_it_does_not_hold_the_show(tmp_path):
    """The skip lands between the runner's look at the skips and its arrival at the GO cue
    (a race the runner cannot close alone): the cue is passed at once, not waited at (the
    show held for a GO the operator had skipped), and the clock does not hold for it."""
    import threading

    from choreo.events import Command, StopRequest, never
    from choreo.live.controls import HoldingShowClock, Live
    from choreo.show.cues import cue_list
    from choreo.show.load import load_show
    from choreo.show.plan import compile_plans
    from runlog import write_show

    body = "version: 1\nsteps:\n  - play: 1\n  - play: 2\n    at: go\n    label: bow\n"
    plans = compile_plans(load_show(write_show(tmp_path, body)))
    mono = [100.0]
    live = Live(StopRequest(), cues=cue_list(plans), now=lambda: mono[0])
    clock = HoldingShowClock(100.0, lambda: mono[0])
    live.use_clock(clock)
    assert live.command(Command("skip", "test", "bow")).ok  # the runner has just looked: not skipped then
    step = next(s for s in next(iter(plans.values())).steps if s.go)
    went: list = []
    runner = threading.Thread(target=lambda: went.append(live.await_go(step, "robot", 0.0, never)), daemon=True)
    runner.start()
    runner.join(5)
    assert went == [0.0] and not live.waiting and clock.state == "running"


def skip_times(log, robots=("",)) -> list[float]:  # type: ignore[no-untyped-def]
    topics = [f"/choreo/{robot}/step" if robot else "/choreo/step" for robot in robots]
    return [m["actual_s"] for topic in topics for m in log.topic(topic) if m["event"] == "skip"]


def test_a_skip_undone_as_the_robot_wakes_for_it_runs_the_cue_and_aborts_nothing(tmp_path, monkeypatch):
    """The sleep towards a cue ends when it is skipped; the skip undone before the runner looks
    again raised Interrupted with no stop requested: the abort motion played, the show ended.
    Only a stop interrupts: the runner sleeps on and the cue runs, as the undo promised."""
    from choreo.live import controls
    looks = []
    real = controls.Live.skipped

    def skipped(self, robot: str, index: int) -> bool:  # type: ignore[no-untyped-def]
        if index != 1:
            return real(self, robot, index)
        looks.append(index)
        return len(looks) == 2  # skipped when the sleep looks, undone before the runner looks again

    monkeypatch.setattr(controls.Live, "skipped", skipped)
    run = VirtualRun(tmp_path, "version: 1\non_abort: 9\n" + SOLO.removeprefix("version: 1\n"))
    log = run.finish()
    assert len(looks) > 2  # the look after the sleep's was taken
    assert run.result.outcome == "done" and not run.live.stop(), [m["message"] for m in log.logs]
    assert motions(log) == [1, 2, 3]  # no abort motion 9
    assert [e for e in events(log) if e[0] == "two"] == [("two", "start", None), ("two", "end", "ok")]


def test_a_skip_wakes_the_robot_asleep_towards_the_cue_and_passes_it_then(tmp_path):
    # robot a is asleep towards a-two (at 5 s) when b's first step starts (0.5 s): it passes the
    # cue then, and a-three follows at once, not 5 s later, nor counted late from a-one
    body = TRACKS.replace("      at: 1\n      label: a-two", "      at: 5\n      label: a-two")
    run = VirtualRun(tmp_path, body, at={(0, "start"): ["skip a-two"]}, robot="b")
    log = run.finish()
    assert run.result.late_steps == 0, [m["message"] for m in log.logs]
    assert skip_times(log, "a") == [pytest.approx(0.5, abs=0.01)]
    three = next(m for m in log.topic("/choreo/a/step") if m.get("label") == "a-three" and m["event"] == "start")
    assert three["actual_s"] == pytest.approx(0.5, abs=0.01) and three["late_ms"] < 10
    assert not any("late" in m["message"] for m in log.logs)


def test_a_go_cue_skipped_after_the_clock_went_on_times_the_next_step_from_the_skip(tmp_path):
    # b's GO lets the clock go on; a's GO cue, skipped 3 s later, passes then: a-three is not
    # 'late' by the time a waited at its GO cue
    body = """\
version: 1
robots: {a: {}, b: {}}
tracks:
  a:
    - play: 1
    - play: 2
      at: go
      label: a-go
    - play: 3
      label: a-three
  b:
    - play: 1
    - play: 4
      at: go
      label: b-go
"""
    run = VirtualRun(tmp_path, body)
    assert wait_for(lambda: len(run.live.waiting) == 2, 10, 0.001)
    assert run.say("cue_go", "b-go").ok
    assert wait_for(lambda: run.live.cue_state(run.live.cues.find("b-go")) != "waiting", 10, 0.001)
    run.source.advance(3.0)
    assert run.say("skip", "a-go").ok
    log = run.finish()
    assert run.result.late_steps == 0, [m["message"] for m in log.logs]
    assert not any("late" in m["message"] for m in log.logs)
