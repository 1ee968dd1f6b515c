"""The cue list's playhead and the live controls' answers about cues (issue 24): where a GO
goes, moving the playhead, a cue's GO by number or label, skips and their undo, the states of
cues, and `Live.status()` in each state of a show.

Most of it is the `Live` alone, told the steps a run would tell it (`on_step`) and the GO cues
its runners reach (`await_go` from a thread): no port, no clock to wait on. The runs at the end
go through the session: a GO under a moved playhead with two robots waiting at once, and the
status of a real run in each of its states.
"""

from __future__ import annotations

import json
import threading
import time

import pytest

from choreo.events import Command, StepEvent, StopRequest
from choreo.live.controls import HoldingShowClock, Live
from choreo.run.settings import RunRequest, RunSettings
from choreo.show.cues import CueList, cue_list
from runlog import LiveRun, wait_for, write_show

# cue 1 GO 'bow', cue 2 at 1 s, cue 3 GO 'encore', cue 4 GO 'finale' (a label with a slash)
SHOW = """\
version: 1
steps:
  - play: 1
  - play: 2
    at: go
    label: bow
  - play: 3
    at: 1
  - play: 4
    at: go
    label: encore
  - play: 5
    at: go
    label: a/b finale
"""

TRACKS = """\
version: 1
robots: {a: {}, b: {}}
tracks:
  a:
    - play: 1
    - play: 2
      at: go
      label: a-go
    - play: 3
  b:
    - play: 1
    - play: 4
      at: go
      label: b-go
    - play: 5
"""


def settle(tmp_path, body: str) -> RunSettings:  # type: ignore[no-untyped-def]
    return RunSettings.settle(RunRequest(str(write_show(tmp_path, body)), no_log=True))


def live_of(tmp_path, body: str = SHOW, **options) -> tuple[Live, CueList, RunSettings]:  # type: ignore[no-untyped-def]
    settings = settle(tmp_path, body)
    cues = cue_list(settings.plans)
    return Live(StopRequest(), cues=cues, lockout_s=0.0, **options), cues, settings


def say(live: Live, name: str, ref: str | None = None):  # type: ignore[no-untyped-def]
    return live.command(Command(name, "test", ref))


def ran(live: Live, settings: RunSettings, index: int, *events: str, robot: str = "robot") -> None:
    """Tell `live` what a runner would of `robot`'s step `index`."""
    step = settings.plans[robot].steps[index]
    for event in events:
        live.on_step(StepEvent(step, event, 0.0, 0.0, 0, robot=None if robot == "robot" else robot))


class Waiter:
    """A runner's thread waiting at a GO cue (as `Runner._await_go` waits)."""

    def __init__(self, live: Live, settings: RunSettings, index: int, robot: str = "robot",
                 shared: bool = True) -> None:
        self.went: list[float | None] = []
        step = settings.plans[robot].steps[index]
        self.thread = threading.Thread(target=lambda: self.went.append(
            live.await_go(step, robot, step.planned_s, live.stop, shared)), daemon=True)
        self.thread.start()
        assert wait_for(lambda: any(step.index == w.step.index and robot in w.robots for w in live.waiting), 5, 0.001)

    def gone(self) -> bool:
        self.thread.join(5)
        return not self.thread.is_alive()


# -- the playhead --------------------------------------------------------------------------------


def test_the_playhead_is_auto_then_moves_among_the_cues_not_yet_run(tmp_path):
    live, cues, settings = live_of(tmp_path)
    assert [c.number for c in cues] == ["1", "2", "3", "4"]
    assert live.playhead == cues.cues[0]  # auto: the next GO cue ahead
    assert say(live, "playhead_previous").message == "the playhead is on the first cue not yet run (cue 1 'bow')"
    answer = say(live, "playhead_next")
    assert answer.ok and answer.data == {"cue": "2", "label": None, "playhead": "2"} and live.playhead == cues.cues[1]
    assert say(live, "playhead_next").ok and say(live, "playhead_next").ok and live.playhead == cues.cues[3]
    end = say(live, "playhead_next")
    assert not end.ok and end.message == "the playhead is on the last cue not yet run (cue 4 'a/b finale')"
    assert say(live, "playhead", "encore").data == {"cue": "3", "label": "encore", "playhead": "3"}
    assert say(live, "playhead", "a/b finale").ok and live.playhead == cues.cues[3]
    assert say(live, "playhead", "3.0").ok and live.playhead == cues.cues[2]  # a number of the same value
    missing = say(live, "playhead", "nope")
    assert not missing.ok and missing.message == "no cue 'nope' in this show (cues: 1, 2, 3, 4)"
    # a cue that ran is left behind: the playhead goes back to auto once its own cue runs
    ran(live, settings, 1, "start", "end")
    assert live.cue_state(cues.cues[0]) == "done" and live.playhead == cues.cues[2]
    assert list(live.cue_states().values()) == ["done", "ahead", "ahead", "ahead"]
    refused = say(live, "playhead", "1")
    assert not refused.ok and refused.message.startswith("cue 1 'bow' has run already: the playhead goes on")
    ran(live, settings, 3, "start")
    assert live.cue_state(cues.cues[2]) == "running" and live.playhead == cues.cues[3]  # auto again
    assert say(live, "playhead_previous").data["playhead"] == "2"  # a timed cue ahead: the playhead may stand on it


def test_go_fires_the_playheads_cue_or_says_why_not(tmp_path):
    live, cues, settings = live_of(tmp_path)
    ahead = say(live, "go")
    assert not ahead.ok and ahead.message == "nothing waits for GO now: cue 1 'bow' is not reached yet (planned at " \
                                             "0.000 s)"
    bow = Waiter(live, settings, 1)
    assert live.cue_state(cues.cues[0]) == "waiting" and live.state == "held"
    say(live, "playhead", "encore")
    early = say(live, "go")
    assert not early.ok and early.message.endswith("waiting: cue 1 'bow' (move the playhead to it)")
    assert bow.went == []  # nothing fired
    say(live, "playhead", "bow")
    answer = say(live, "go")
    assert answer.ok and answer.message == "GO: cue 1 'bow'" and bow.gone()
    assert answer.data == {"cue": "1", "label": "bow", "playhead": "3"}  # auto again: the next GO cue ahead


def test_a_go_with_the_playhead_on_a_timed_cue_fires_the_earliest_cue_waiting(tmp_path):
    """Up/Down may stand the playhead on a timed cue; GO is never dead while a cue waits."""
    live, cues, settings = live_of(tmp_path)
    ran(live, settings, 0, "start", "end")
    bow = Waiter(live, settings, 1)
    moved = say(live, "playhead_next")
    assert moved.message == "playhead: cue 2" and live.playhead == cues.cues[1]  # a timed cue
    answer = say(live, "go")
    assert answer.ok and bow.gone()
    assert answer.message == ("GO: cue 1 'bow' (the playhead is on cue 2, a timed cue: GO fired the earliest "
                              "cue waiting)")
    assert answer.data == {"cue": "1", "label": "bow", "playhead": "2"}
    nothing = say(live, "go")  # nothing waits: why, as before
    assert not nothing.ok and nothing.message.startswith("cue 2 is a timed cue (at 1.000 s): nothing to GO")


def test_a_cues_go_by_number_or_label(tmp_path):
    live, cues, settings = live_of(tmp_path)
    encore = Waiter(live, settings, 3)
    wrong = say(live, "cue_go", "1")
    assert not wrong.ok
    assert wrong.message == ("nothing waits for GO now: cue 1 'bow' is not reached yet (planned at 0.000 s); "
                             "waiting: cue 3 'encore'")  # a cue's own GO: no word of the playhead
    assert say(live, "cue_go", "3").ok and encore.gone()  # by number
    finale = Waiter(live, settings, 4)
    assert say(live, "cue_go", "a/b finale").ok and finale.gone()  # by label, a slash in it
    hostile = say(live, "cue_go", "\x1b[2J" + "x" * 5000)
    assert not hostile.ok and "\x1b" not in hostile.message and len(hostile.message) < 200
    assert not say(live, "cue_go", "").ok


def test_a_go_under_a_moved_playhead_fires_that_robots_cue_first(tmp_path):
    live, cues, settings = live_of(tmp_path, TRACKS)
    a = Waiter(live, settings, 1, "a", shared=False)
    b = Waiter(live, settings, 1, "b", shared=False)
    first, second = live.playhead, next(c for c in cues if c.go and c != live.playhead)
    assert say(live, "playhead", second.number).ok
    assert say(live, "go").message == f"GO: {second.name}"
    fired, still = (a, b) if second.label == "a-go" else (b, a)
    assert fired.gone() and still.went == [] and live.cue_state(first) == "waiting"
    assert live.playhead == first  # auto again: the cue still waiting
    assert say(live, "go").ok and still.gone()


def test_a_go_lets_the_machine_clock_go_on_while_another_tracks_cue_still_waits(tmp_path):
    """The robot given its GO goes on at once on a running clock; the other waits without
    holding the show (its steps are timed from its own GO when it comes)."""
    live, cues, settings = live_of(tmp_path, TRACKS)
    now = [100.0]
    clock = HoldingShowClock(100.0, lambda: now[0])
    live.use_clock(clock)
    now[0] = 100.5
    a = Waiter(live, settings, 1, "a", shared=False)
    b = Waiter(live, settings, 1, "b", shared=False)
    assert clock.state == "held" and clock.show_at(101.0) == 0.5  # reached at 0.5 s: it stands there
    now[0] = 102.0
    assert say(live, "cue_go", "b-go").ok and b.gone() and a.went == []
    assert clock.state == "running" and clock.show_at(102.25) == 0.75  # from where it stood, at once


# -- skips ----------------------------------------------------------------------------------------


def test_skip_ahead_undo_and_a_cue_already_run(tmp_path):
    live, cues, settings = live_of(tmp_path)
    answer = say(live, "skip")  # the playhead's: cue 1
    assert answer.ok and answer.message == "skipped: cue 1 'bow' will not run"
    assert live.skipped("robot", 1) and live.cue_state(cues.cues[0]) == "skipped"
    assert answer.data["playhead"] == "3" and live.playhead == cues.cues[2]  # auto: past the skipped cue
    again = say(live, "skip", "1")
    assert again.ok and again.message == "skip undone: cue 1 'bow' will run" and not live.skipped("robot", 1)
    say(live, "skip", "bow")
    ran(live, settings, 1, "skip")  # the runner passed it
    refused = say(live, "skip", "1")
    assert not refused.ok and refused.message == "cue 1 'bow' has been passed already: nothing to skip"
    ran(live, settings, 2, "start")
    assert say(live, "skip", "2").message == "cue 2 is running: nothing to skip"
    ran(live, settings, 2, "end")
    assert say(live, "skip", "2").message == "cue 2 has run already: nothing to skip"


def test_skipping_a_waiting_go_cue_releases_it_as_skipped(tmp_path):
    live, cues, settings = live_of(tmp_path)
    bow = Waiter(live, settings, 1)
    answer = say(live, "skip")
    assert answer.ok and answer.message == "skipped: cue 1 'bow'" and bow.gone()
    assert live.skipped("robot", 1) and not live.waiting and live.state == "running"


def test_skipping_the_moved_playheads_cue_lets_it_follow_the_show_again(tmp_path):
    """A stage manager moved the playhead down to skip a cue: after the skip it goes back to
    the show (the next GO cue, or one waiting), never stays parked on a cue not reached while
    another waits (GO would be dead)."""
    live, cues, settings = live_of(tmp_path)
    say(live, "playhead", "2")
    assert say(live, "skip").data == {"cue": "2", "label": None, "playhead": "1"}
    assert live.playhead == cues.cues[0]
    bow = Waiter(live, settings, 1)
    assert say(live, "go").ok and bow.gone()


# -- pause, and the state ------------------------------------------------------------------------


def test_pause_resume_and_what_they_refuse(tmp_path):
    live, cues, settings = live_of(tmp_path, wait_start=True)
    assert not say(live, "pause").ok  # not started: nothing to pause
    say(live, "start")
    clock = HoldingShowClock(time.monotonic(), time.monotonic)
    live.use_clock(clock)
    assert not say(live, "resume").ok
    paused = say(live, "pause")
    assert paused.ok and paused.message.startswith("paused at ") and live.paused and clock.state == "paused"
    assert say(live, "pause").message == "paused already"
    bow = Waiter(live, settings, 1)
    assert say(live, "go").message == "paused: resume first (p or /choreo/resume)"
    assert say(live, "cue_go", "bow").message == "paused: resume first (p or /choreo/resume)"
    assert live.state == "paused" and clock.state == "paused" and bow.went == []
    assert say(live, "resume").ok and not live.paused and clock.state == "held"  # the GO cue still holds it
    assert say(live, "go").ok and bow.gone() and clock.state == "running"


def test_a_runner_waits_while_paused_and_sees_a_stop(tmp_path):
    live, _, _ = live_of(tmp_path)
    assert live.await_running(live.stop)  # not paused: at once
    say(live, "pause")
    results: list[bool] = []
    thread = threading.Thread(target=lambda: results.append(live.await_running(live.stop, "a")))
    thread.start()
    assert wait_for(lambda: live.paused_robots == ("a",), 5, 0.001)
    assert say(live, "panic").ok  # panic works while paused
    thread.join(5)
    assert results == [False] and live.state == "stopping"
    assert say(live, "resume").message.startswith("refused: the show is stopping")


STATUS_KEYS = {"state", "show_s", "clock", "playhead", "waiting", "paused", "robots"}


def test_status_in_each_state_of_a_run(tmp_path):
    run = LiveRun(tmp_path, "version: 1\nsteps:\n  - play: 1\n  - play: 2\n    at: go\n    label: bow\n"
                            "  - wait: 30\n  - play: 3\n", wait_start=True, cues=True, lockout_s=0.0)
    seen = {}

    def status() -> dict:
        got = run.live.status()
        assert set(got) == STATUS_KEYS and json.loads(json.dumps(got)) == got
        seen[got["state"]] = got
        return got

    assert wait_for(lambda: status()["state"] == "waiting_start", 5, 0.005)
    assert seen["waiting_start"]["playhead"]["number"] == "1" and seen["waiting_start"]["show_s"] is None
    run.go("start")
    run.until_waiting()
    assert status()["state"] == "held"
    waiting = seen["held"]["waiting"]
    assert [(w["number"], w["label"], w["robots"]) for w in waiting] == [("1", "bow", ["robot"])]
    assert seen["held"]["clock"] == "machine" and seen["held"]["playhead"]["label"] == "bow"
    assert run.go().ok
    assert wait_for(lambda: status()["state"] == "running", 5, 0.005)
    assert run.go("pause").ok and status()["state"] == "paused" and seen["paused"]["paused"] is True
    stood = seen["paused"]["show_s"]
    time.sleep(0.05)
    assert status()["show_s"] == stood  # the clock stands still
    assert run.go("stop").ok and status()["state"] == "stopping"
    run.finish()
    run.live.close()
    assert status()["state"] == "over"
    assert set(seen) == {"waiting_start", "held", "running", "paused", "stopping", "over"}


def test_two_robots_waiting_at_different_go_cues_the_moved_playhead_fires_first(tmp_path):
    """A run of two tracks, each robot at its own GO cue: the operator moves the playhead to
    the cue that is not the earliest and GOes: that robot's step runs while the other waits."""
    run = LiveRun(tmp_path, TRACKS, cues=True, lockout_s=0.0)
    assert wait_for(lambda: len(run.live.waiting) == 2, 10, 0.005)
    other = next(c for c in run.live.cues if c.go and c != run.live.playhead)
    assert run.go("playhead", label=other.label).ok
    assert run.go().message == f"GO: {other.name}"
    fired = other.robots[0]
    assert wait_for(lambda: any(c.go and run.live.cue_state(c) == "done" for c in run.live.cues), 10, 0.005)
    assert len(run.live.waiting) == 1 and fired not in run.live.waiting[0].robots
    assert run.go().ok
    run.finish()
    assert run.error is None and run.result.outcome == "done"
    log = run.log()
    starts = {robot: next(m["_log_time"] for m in log.topic(f"/choreo/{robot}/step")
                          if m["event"] == "start" and m.get("go")) for robot in ("a", "b")}
    later = "b" if fired == "a" else "a"
    assert starts[fired] < starts[later]
    # the typed reference, and the cue the GO fired (by number: the record's cue, or its label in older logs)
    commands = [(m["command"], m.get("label"), m.get("cue", m.get("label"))) for m in log.topic("/choreo/command")]
    assert commands[0][:2] == ("playhead", other.label) and commands[1][::2] == ("go", other.number)


@pytest.mark.parametrize("ref", ["2", "bow"])
def test_cue_go_in_a_run_by_number_and_label(tmp_path, ref):
    run = LiveRun(tmp_path, "version: 1\nsteps:\n  - play: 1\n    at: 0.1\n  - play: 2\n    at: go\n"
                            "    label: bow\n", cues=True)
    run.until_waiting()
    assert run.go("cue_go", label=ref).message == "GO: cue 2 'bow'"
    run.finish()
    assert run.result.outcome == "done"


def test_run_gives_the_live_the_cue_list_and_one_status_that_hears_every_link_for_the_run(tmp_path):
    """`choreo run`'s wiring: one ShowStatus, a listener of the run and of each link from the
    session's opening to the run's end, read by `Live.status()`."""
    from argparse import Namespace

    from choreo.cli.run import _live, _watching
    from runlog import prepare

    body = "version: 1\nrobots: {a: {}, b: {}}\nsteps:\n  - play: 1\n  - play: 2\n    at: 0.3\n"
    session = prepare(RunRequest(str(write_show(tmp_path, body)), no_log=True))
    live, status = _live(Namespace(osc="0", wait_start=False), StopRequest(), False, session)
    assert live is not None and status is not None and live.status_of_robots is status
    assert [c.number for c in live.cues] == ["1"] and live.status()["clock"] == "machine"
    with session:
        assert session.stage is not None
        links = session.stage.links
        before = {name: list(link.listeners) for name, link in links.items()}
        with _watching(session, status) as watchers:
            assert watchers == [status]
            assert all(len(list(link.listeners)) == len(before[name]) + 1 for name, link in links.items())
            assert session.run(watchers, live=live).outcome == "done"
        assert {name: list(link.listeners) for name, link in links.items()} == before
    robots = live.status()["robots"]
    assert set(robots) == {"a", "b"} and all(r["state"] == "done" and r["latency_ms"] is not None
                                             for r in robots.values())
    assert live.cue_state(live.cues.cues[0]) == "done" and live.playhead is None


def test_with_only_timed_cues_ahead_the_playhead_moves_onto_the_first_and_a_section_bounds_it(tmp_path):
    live, cues, settings = live_of(tmp_path, "version: 1\nsteps:\n  - play: 1\n    at: 1\n  - play: 2\n    at: 2\n"
                                             "  - play: 3\n    at: go\n")
    live.use_section({"robot": 1}, {"robot": 2})  # --loop 1..1: cues 1 and 3 are not in this run
    assert [live.cue_state(c) for c in cues] == ["done", "ahead", "done"] and live.playhead is None
    assert say(live, "playhead_next").data == {"cue": "2", "label": None, "playhead": "2"}
    assert say(live, "playhead", "3").message.startswith("cue 3 is not in this run (--from, --loop)")
    assert say(live, "go").message == "cue 2 is a timed cue (at 2.000 s): nothing to GO; move the playhead"


def test_a_go_with_the_playhead_on_a_skipped_cue_fires_the_earliest_cue_waiting(tmp_path):
    """A skipped cue takes no GO, as a timed one: the playhead stood on it never leaves GO dead
    while a cue waits (it answered 'cue 3 is skipped' and cue 1 kept waiting)."""
    live, cues, settings = live_of(tmp_path)
    bow = Waiter(live, settings, 1)
    assert say(live, "skip", "encore").message == "skipped: cue 3 'encore' will not run"
    assert say(live, "playhead", "encore").ok and live.playhead == cues.cues[2]
    answer = say(live, "go")
    assert answer.ok and bow.gone() and bow.went != [None]
    assert answer.message == ("GO: cue 1 'bow' (the playhead is on cue 3 'encore', a skipped cue: GO fired the "
                              "earliest cue waiting)")
    nothing = say(live, "go")  # nothing waits: why, as before
    assert not nothing.ok and nothing.message == "cue 3 'encore' is skipped (skip it again to undo)"


def test_a_skip_refused_at_the_end_of_a_long_show_looks_at_a_few_cues(monkeypatch):
    """`nothing to skip` asks whether a timed cue is ahead: it walked all 10,000 cues under the
    lock the runners need, on every refused skip. It looks from where it last found one, and
    a new pass finds the earlier ones again."""
    from choreo.show.cues import Cue
    from choreo.show.model import PlannedStep, StepKind
    n = 10_000
    cues = CueList(tuple(Cue(str(i + 1), f"c{i}", ("robot",), float(i), i % 2 == 0, steps=(("robot", i),))
                         for i in range(n)))
    live = Live(StopRequest(), cues=cues, lockout_s=0.0)
    steps = [PlannedStep(index=i, path="", kind=StepKind.PLAY, line=1, go=i % 2 == 0, cue=str(i + 1))
             for i in range(n)]
    for step in steps[:n - 1]:
        live.on_step(StepEvent(step, "end", 0.0, 0.0, 0))
    timed = say(live, "skip")  # the last cue, timed, is ahead: the first look walks the list once
    assert not timed.ok and timed.message.startswith("nothing to skip under the playhead (no GO cue ahead)")
    looked = []
    state_of = live._state_of
    monkeypatch.setattr(live, "_state_of", lambda cue: looked.append(cue) or state_of(cue))
    for _ in range(3):
        assert say(live, "skip").message.startswith("nothing to skip under the playhead")
    live.on_step(StepEvent(steps[n - 1], "end", 0.0, 0.0, 0))
    for _ in range(3):
        assert say(live, "skip").message == "nothing to skip: no cue ahead"
    assert len(looked) < 20, len(looked)
    monkeypatch.undo()
    live.new_pass()
    assert say(live, "playhead", "2").ok and say(live, "skip").message == "skipped: cue 2 'c1' will not run"


def test_the_auto_playhead_looks_from_where_it_last_found_a_cue_not_from_cue_1(monkeypatch):
    """A 10,000-cue show near its end: the playhead (read by the console's redraw, status and a
    GO's answer, under the lock a released runner needs) looks at a few cues, not every cue
    before it; a skip undone and a new pass find earlier cues again."""
    from choreo.show.cues import Cue
    from choreo.show.model import PlannedStep, StepKind
    n = 10_000
    cues = CueList(tuple(Cue(str(i + 1), f"c{i}", ("robot",), float(i), True, steps=(("robot", i),))
                         for i in range(n)))
    live = Live(StopRequest(), cues=cues, lockout_s=0.0)
    steps = [PlannedStep(index=i, path="", kind=StepKind.PLAY, line=1, go=True, cue=str(i + 1)) for i in range(n)]
    for step in steps[:n - 5]:
        live.on_step(StepEvent(step, "end", 0.0, 0.0, 0))
    assert live.playhead is cues.cues[n - 5]  # the first look walks the list once
    looked = []
    state_of = live._state_of
    monkeypatch.setattr(live, "_state_of", lambda cue: looked.append(cue) or state_of(cue))
    for _ in range(3):
        assert live.playhead is cues.cues[n - 5] and live.status()["playhead"]["number"] == str(n - 4)
    live.on_step(StepEvent(steps[n - 5], "end", 0.0, 0.0, 0))
    assert live.playhead is cues.cues[n - 4]
    assert len(looked) < 20, len(looked)
    monkeypatch.undo()
    assert say(live, "skip").ok and live.playhead is cues.cues[n - 3]
    assert say(live, "skip", str(n - 3)).message.startswith("skip undone") and live.playhead is cues.cues[n - 4]
    live.new_pass()
    assert live.playhead is cues.cues[0]


def test_the_answers_say_how_to_skip_a_timed_cue_and_a_cues_go_names_no_playhead(tmp_path):
    body = "version: 1\nsteps:\n  - play: 1\n  - play: 2\n    at: 5\n    label: timed\n  - play: 3\n    at: 8\n"
    live, cues, settings = live_of(tmp_path, body)
    skip = say(live, "skip")
    assert not skip.ok and skip.message == ("nothing to skip under the playhead (no GO cue ahead): to skip a "
                                            "timed cue, move the playhead onto it (Up/Down, j, /choreo/playhead/CUE), "
                                            "then skip")
    named = say(live, "cue_go", "timed")
    assert not named.ok and named.message == "cue 1 'timed' is a timed cue (at 5.000 s): nothing to GO"
    assert say(live, "playhead", "timed").ok and say(live, "skip").message == "skipped: cue 1 'timed' will not run"


def test_a_go_right_after_the_start_is_a_double_press():
    """The console's GO key starts a --wait-start show: a nervous double tap must not also fire
    the first cue (the start counts as a GO for the double-press guard)."""
    now = [100.0]
    live = Live(StopRequest(), wait_start=True, lockout_s=0.5, now=lambda: now[0])
    assert live.command(Command("start", "key")).ok
    now[0] += 0.2
    answer = live.command(Command("go", "key"))
    assert not answer.ok and answer.message.startswith("GO ignored: 0.20 s after the last one (a double press?")
