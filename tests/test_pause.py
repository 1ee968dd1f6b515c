"""Pause and resume (issue 24): the show clock stands still, no step starts, a step under way
finishes (a play's frames all go out), panic and stop still work, and every step after the
resume is timed from it; the log marks the pause and the resume with clock samples that say
the clock's state.

The runs are on virtual time against the in-process simulator, so the show times in their
logs are exact: the operator's commands come from the run's own steps (a listener that pauses
when a step starts, as a key pressed at that instant would) and from the test's thread while
the runner is held, which also lets virtual time pass for the length of the pause.
"""

from __future__ import annotations

import threading
import time

import pytest

from choreo.clock import HELD, PAUSED, RUNNING, PausableShowClock, VirtualTime
from choreo.events import PANIC, Command, StepEvent, StopRequest
from choreo.live.controls import HoldingShowClock, Live
from choreo.run.session import Session
from choreo.run.settings import RunRequest
from choreo.show.cues import cue_list
from runlog import LiveRun, read_log, wait_for, write_show


class OnStep:
    """Gives `live` a command when a step event comes (from the runner's thread, at that
    instant): `(step index, event) -> command names`."""

    def __init__(self, live: Live, commands: dict[tuple[int, str], list[str]], robot: str | None = None) -> None:
        self.live = live
        self.commands = commands
        self.robot = robot
        self.answers: list = []
        self.seen: list[tuple[int, str]] = []  # (step index, event) heard, in order

    def on_step(self, event: StepEvent) -> None:
        if self.robot is not None and event.robot != self.robot:
            return
        self.seen.append((event.step.index, event.event))
        for name in self.commands.pop((event.step.index, event.event), []):
            label = None
            if " " in name:
                name, label = name.split(" ", 1)
            self.answers.append(self.live.command(Command(name, "test", label)))

    def on_log(self, level: int, message: str, time_ns: int) -> None:
        pass


class VirtualRun:
    """A show on virtual time in a thread, with a `Live` holding the show's cue list; `at`:
    commands given when steps start or end (`OnStep`)."""

    def __init__(self, tmp_path, body: str, at: dict | None = None, robot: str | None = None,  # type: ignore[no-untyped-def]
                 before=(), attach=lambda live: [], **request) -> None:  # type: ignore[no-untyped-def]
        self.source = VirtualTime()
        self.log_path = tmp_path / "run.mcap"
        self.session = Session.prepare(RunRequest(str(write_show(tmp_path, body)), log_path=str(self.log_path),
                                                  **request), self.source)
        clock = self.session.clock
        self.live = Live(StopRequest(), cues=cue_list(self.session.settings.plans), now=clock.mono,
                         wall_ns=clock.wall_ns, lockout_s=0.0)
        for name in before:  # commands before the show starts
            assert self.say(*name.split(" ", 1)).ok
        self.hook = OnStep(self.live, dict(at or {}), robot)
        self.others = attach(self.live)  # more listeners of the run, made with its Live
        self.result = None
        self.error: BaseException | None = None
        self.thread = threading.Thread(target=self._run, daemon=True)
        self.thread.start()

    def _run(self) -> None:
        try:
            with self.session:
                self.result = self.session.run([self.hook, *self.others], live=self.live)
        except BaseException as exc:  # noqa: BLE001 - the test asserts on it
            self.error = exc

    def say(self, name: str, label: str | None = None):  # type: ignore[no-untyped-def]
        return self.live.command(Command(name, "test", label))

    def held(self, robots: tuple[str, ...] = ("robot",)) -> None:
        """Until the pause holds `robots` back (their runners wait to start their next step)."""
        assert wait_for(lambda: self.live.paused_robots == robots, 10, 0.001), self.live.paused_robots

    def curtain(self) -> None:
        """The show's last cue waits for GO: its GO. On virtual time a resume lets the runner
        run the rest of the show at once, maybe before the resume's own record is written:
        a GO cue at the end keeps the log open for it."""
        assert wait_for(lambda: bool(self.live.waiting), 10, 0.001)
        assert self.say("go").ok

    def finish(self):  # type: ignore[no-untyped-def]
        self.thread.join(20)
        assert not self.thread.is_alive()
        assert self.error is None, self.error
        return read_log(self.log_path)


def starts(log, topic: str = "/choreo/step") -> dict:  # type: ignore[no-untyped-def]
    return {m.get("label") or m["index"]: m for m in log.topic(topic) if m["event"] == "start"}


def command_time(log, name: str) -> int:  # type: ignore[no-untyped-def]
    return next(m["_log_time"] for m in log.topic("/choreo/command") if m["command"] == name and m["status"] == "ok")


# -- the machine's clock ---------------------------------------------------------------------------


class Mono:
    def __init__(self) -> None:
        self.now = 100.0

    def __call__(self) -> float:
        return self.now


def test_the_machine_clock_pauses_and_goes_on_from_where_it_stood() -> None:
    mono = Mono()
    clock = HoldingShowClock(100.0, mono)
    assert isinstance(clock, PausableShowClock) and clock.state == RUNNING
    mono.now = 103.0
    assert clock.pause() == 3.0 and clock.state == PAUSED
    mono.now = 110.0
    assert clock.pause() == 3.0 and clock.show_at(mono.now) == 3.0 and clock.mono_at(3.5) == float("inf")
    clock.resume()
    assert clock.state == RUNNING and clock.show_at(110.0) == 3.0 and clock.mono_at(4.0) == 111.0
    clock.resume()  # not paused: nothing
    assert clock.show_at(111.0) == 4.0


def test_a_go_hold_and_a_pause_overlap_and_the_clock_stands_at_the_earlier() -> None:
    mono = Mono()
    clock = HoldingShowClock(100.0, mono)
    mono.now = 105.0
    clock.hold_at(5.0)  # a GO cue reached at 5 s
    assert clock.state == HELD and clock.held
    mono.now = 107.0
    assert clock.pause() == 5.0 and clock.state == PAUSED and clock.held
    mono.now = 108.0
    clock.release()  # the GO, while paused: still standing, at the pause
    assert clock.state == PAUSED and not clock.held and clock.show_at(109.0) == 5.0
    mono.now = 112.0
    clock.resume()
    assert clock.state == RUNNING and clock.show_at(112.0) == 5.0 and clock.show_at(113.0) == 6.0
    # a pause before the GO cue's time: the clock runs from the resume to the cue, and holds there
    mono.now = 114.0  # show 7
    clock.pause()
    clock.hold_at(8.0)
    mono.now = 120.0
    clock.resume()
    assert clock.show_at(120.5) == 7.5 and clock.show_at(125.0) == 8.0 and clock.state == HELD


def test_a_hold_never_sends_show_time_back() -> None:
    mono = Mono()
    clock = HoldingShowClock(100.0, mono)
    mono.now = 101.03  # the play before the GO cue took its frames' time
    clock.hold_at(1.0)
    assert clock.show_at(mono.now) == pytest.approx(1.03)


# -- a show paused ---------------------------------------------------------------------------------

WALK = """\
version: 1
on_abort: 9
motions:
  walk: {number: 2, duration: 1.0}
steps:
  - play: walk
    label: walk
  - wait: done
    label: done
  - play: 3
    at: 2
    label: later
  - wait: 0.5
    label: rest
  - play: 4
    label: last
  - play: 5
    at: go
    label: curtain
"""
PAUSE_S = 5.0  # how long the operator keeps the show paused (virtual time)


def test_pause_during_a_motion_finishes_the_play_and_times_the_rest_from_the_resume(tmp_path):
    run = VirtualRun(tmp_path, WALK, at={(0, "start"): ["pause"]})
    run.held()
    assert run.live.state == "paused" and run.live.show is not None
    stood = run.live.show.show_at(run.session.clock.mono())
    run.source.advance(PAUSE_S)  # the operator waits; the motion ends on the board meanwhile
    assert run.live.show.show_at(run.session.clock.mono()) == stood  # the show clock stood still
    resumed = run.session.clock.wall_ns()  # the runner waits: virtual time stands till the resume
    assert run.say("resume").ok
    run.curtain()
    log = run.finish()
    assert run.result.outcome == "done" and run.hook.answers[0].ok
    # (the resume's record may come after the runner's next steps: virtual time runs them at once)
    paused = command_time(log, "pause")
    assert command_time(log, "resume") >= resumed
    assert resumed - paused >= PAUSE_S * 1e9
    # the play under way finished: every frame of its sequence went out, and was answered, before the resume
    walk = [m for m in log.tx if m.get("step") == 0]
    assert [m["kind"] for m in walk] == ["stop", "play", "restore"]
    assert all(m["_log_time"] < resumed for m in walk + [m for m in log.rx if m.get("step") == 0])
    # no step started while paused: the next one started at the resume
    steps = starts(log)
    assert not [m for m in steps.values() if paused < m["_log_time"] < resumed]
    assert steps["done"]["_log_time"] >= resumed
    # everything after is timed from the resume: the cue at 2 s lands 2 s of show after the start,
    # (2 s - where the clock stood) of machine time after the resume, as if nothing had paused
    later = next(m for m in log.steps if m.get("label") == "later" and m["event"] == "end")
    assert later["start_s"] == pytest.approx(2.0, abs=1e-3)
    restore = next(m for m in log.tx if m.get("step") == 2 and m["kind"] == "restore")
    assert (restore["_log_time"] - resumed) / 1e9 == pytest.approx(2.0 - stood, abs=2e-3)
    assert steps["later"]["late_ms"] < 1.0 and steps["last"]["actual_s"] == pytest.approx(2.5, abs=0.01)
    # the log marks the pause and the resume: clock samples with the clock's state, at those instants
    samples = log.topic("/choreo/clock")
    assert {m.get("state") for m in samples} == {"running", "paused", "held"}  # held: at the curtain's GO cue
    pause_sample = next(m for m in samples if m.get("state") == "paused")
    assert pause_sample["show_s"] == pytest.approx(stood, abs=1e-6) and pause_sample["_log_time"] == paused
    assert [m for m in samples if m["_log_time"] >= resumed and m["state"] == "running"
            and m["show_s"] == pytest.approx(stood, abs=1e-6)]  # the resume's, wherever the runner's fell
    assert log.metadata["choreo.result"]["outcome"] == "done"


def test_a_wait_done_under_way_when_paused_polls_to_the_motions_end(tmp_path):
    run = VirtualRun(tmp_path, WALK, at={(1, "start"): ["pause"]})  # paused as `wait: done` starts
    assert wait_for(lambda: (1, "end") in run.hook.seen, 10, 0.001)  # it ended while paused
    assert run.live.paused and (2, "start") not in run.hook.seen
    # on virtual time the runner may run on before the resume's record is written: its instant
    # is read just before it (the runner dozes meanwhile, towards a cue the clock stands before)
    resumed = run.session.clock.wall_ns()
    assert run.say("resume").ok
    run.curtain()
    log = run.finish()
    assert command_time(log, "resume") >= resumed
    done = next(m for m in log.steps if m.get("label") == "done" and m["event"] == "end")
    assert done["outcome"] == "ok" and done["_log_time"] <= resumed
    polls = [m for m in log.tx if m["kind"] == "status" and m["_log_time"] <= resumed]
    assert len(polls) >= 2  # it went on polling while paused, until the board said the motion was over
    later = next(m for m in log.steps if m.get("label") == "later" and m["event"] == "end")
    assert later["start_s"] == pytest.approx(2.0, abs=1e-3) and later["_log_time"] > resumed


@pytest.mark.parametrize("command", ["panic", "stop"])
def test_panic_and_stop_work_while_paused(tmp_path, command):
    run = VirtualRun(tmp_path, WALK, at={(0, "start"): ["pause"]})
    run.held()
    assert run.say(command).ok
    log = run.finish()
    assert run.result.outcome == "aborted" and run.live.panicked == (command == "panic")
    assert [m.get("label") for m in starts(log).values()] == ["walk"]  # nothing after the pause started
    aborts = [(m["kind"], m.get("motion")) for m in log.tx if m.get("label") == "on_abort"]
    assert aborts[-3:] == [("stop", 9), ("play", 9), ("restore", 9)]  # the robot's abort motion
    assert log.metadata["choreo.result"]["stop_reason"] == (PANIC if command == "panic" else "stopped")


def test_a_go_cue_reached_while_paused_waits_for_the_resume_then_its_go(tmp_path):
    body = "version: 1\nsteps:\n  - play: 1\n  - play: 2\n    at: go\n    label: bow\n  - play: 3\n    at: 0.5\n"
    run = VirtualRun(tmp_path, body, at={(0, "start"): ["pause"]})
    assert wait_for(lambda: bool(run.live.waiting), 10, 0.001)
    assert run.live.state == "paused" and run.live.show is not None and run.live.show.state == PAUSED
    assert not run.say("go").ok
    run.source.advance(2.0)
    assert run.say("resume").ok and run.live.state == "held" and run.live.show.state == HELD
    run.source.advance(1.0)
    assert run.say("go").ok
    log = run.finish()
    assert starts(log)["bow"]["go"]
    third = next(m for m in log.steps if m["index"] == 2 and m["event"] == "end")
    assert third["start_s"] == pytest.approx(0.5, abs=1e-3)  # its cue, on the clock that paused and held
    assert [m.get("state") for m in log.topic("/choreo/clock")].count("held") >= 1


def test_pause_with_several_robots_holds_every_runner(tmp_path):
    """Real time: paused as robot a's first play starts, neither robot starts a step until the
    resume (the shared wait stands still with the clock); then both go on."""
    body = ("version: 1\nrobots: {a: {}, b: {}}\nsteps:\n  - play: 1\n    label: one\n  - wait: 0.2\n"
            "  - play: 2\n    label: two\n")
    run = LiveRun(tmp_path, body, cues=True, attach=lambda live: [OnStep(live, {(0, "start"): ["pause"]}, "a")])
    assert wait_for(lambda: run.live.paused, 10, 0.001)
    time.sleep(0.3)
    assert run.live.status()["state"] == "paused" and run.result is None
    assert run.go("resume").ok
    run.finish()
    assert run.error is None and run.result.outcome == "done"
    log = run.log()
    resumed = command_time(log, "resume")
    paused = command_time(log, "pause")
    for robot in ("a", "b"):
        robot_steps = [m for m in log.topic(f"/choreo/{robot}/step") if m["event"] == "start"]
        assert not [m for m in robot_steps if paused < m["_log_time"] < resumed]
        assert len(robot_steps) == 3


def test_pause_in_a_music_show_pauses_the_song_and_the_next_cue_keeps_its_place(tmp_path):
    """Real time, the null output: `pause` from the live controls stands the music's clock
    still (the song pauses), the log's clock samples say so, and the cue after the resume
    lands on its place in the music."""
    from runlog import started_on_cue
    from test_music import write_song

    write_song(tmp_path / "song.wav", 0.8)
    body = ("version: 1\nmusic: {file: song.wav}\nsteps:\n  - play: 1\n    at: 0.1\n    label: first\n"
            "  - play: 2\n    at: 0.5\n    label: after\n")
    run = LiveRun(tmp_path, body, cues=True, audio_device="null",
                  attach=lambda live: [OnStep(live, {(0, "start"): ["pause"]})])
    # the pause is said (live.paused) an instant before the music's clock stands: wait for both
    assert wait_for(lambda: run.live.paused and run.live.show is not None and run.live.show.state == PAUSED, 10, 0.001)
    assert run.live.state == "paused"
    stood = run.live.status()["show_s"]
    time.sleep(0.3)
    assert run.live.status()["show_s"] == stood  # the song's clock stands still
    assert run.go("resume").ok
    run.finish()
    assert run.error is None and run.result.outcome == "done"
    log = run.log()
    samples = log.topic("/choreo/clock")
    assert {m["source"] for m in samples} == {"music"} and "paused" in [m.get("state") for m in samples]
    steps = log.topic("/choreo/step")
    after = next(m for m in steps if m["event"] == "end" and m["label"] == "after")
    assert started_on_cue(steps, after), steps
    assert command_time(log, "resume") < after["_log_time"]


class PauseAtSecondStart:
    """Pauses `live` when the second robot starts step `index` (every robot is then past the
    pause's check, into its play sequence)."""

    def __init__(self, live: Live, index: int) -> None:
        self.live, self.index = live, index
        self.started: list[str] = []
        self.ended: list[str] = []

    def on_step(self, event: StepEvent) -> None:
        if event.step.index != self.index:
            return
        if event.event == "start":
            self.started.append(event.robot or "")
            if len(self.started) == 2:
                assert self.live.command(Command("pause", "test")).ok
        elif event.event == "end":
            self.ended.append(event.robot or "")

    def on_log(self, level: int, message: str, time_ns: int) -> None:
        pass


def test_a_unison_play_under_way_when_paused_starts_its_motions_and_a_stop_then_ends_the_run(tmp_path):
    """Two robots' unison play, paused once both have begun its sequence: the start frames the
    gate writes for both go out (a step under way finishes; it was waiting on the standing show
    clock for the resume, and a stop while paused hung the run for good)."""
    body = "version: 1\nrobots: {a: {}, b: {}}\nsteps:\n  - play: 1\n    label: one\n  - play: 2\n    at: 3\n"
    run = VirtualRun(tmp_path, body, attach=lambda live: [PauseAtSecondStart(live, 0)])
    hook = run.others[0]
    try:
        assert wait_for(lambda: sorted(hook.ended) == ["a", "b"], 10, 0.001), (hook.started, hook.ended)
        assert run.live.paused
        assert run.say("stop").ok
        log = run.finish()
    finally:
        if run.live.paused and run.thread.is_alive():
            run.say("resume")
    plays = [m for robot in ("a", "b") for m in log.topic(f"/choreo/{robot}/step")
             if m["event"] == "end" and m["index"] == 0]
    assert [m["outcome"] for m in plays] == ["ok", "ok"]
    assert run.result is None or run.result.outcome == "aborted"


def test_clock_samples_from_two_threads_reach_the_log_in_the_order_they_were_read():
    """A runner's periodic sample and the operator's forced one (a pause) at once: the log gets
    them in their own order (an older sample written last is passed over by the reviews, and
    if it was the pause's, the change is lost)."""
    from choreo.clock import RunClock
    from choreo.run.session import ClockSampler

    source = VirtualTime()
    first_in = threading.Event()
    second_done = threading.Event()
    written: list[int] = []

    class Recorder:
        def on_clock(self, record, time_ns):  # type: ignore[no-untyped-def]
            if not written and not first_in.is_set():
                first_in.set()
                second_done.wait(0.3)  # the runner's thread is put off here
            written.append(record.monotonic_ns)

    clock = RunClock(source)
    sampler = ClockSampler(Recorder(), clock, HoldingShowClock(clock.mono(), clock.mono), "machine")  # type: ignore[arg-type]
    runner = threading.Thread(target=sampler.sample, kwargs={"force": True})
    runner.start()
    assert first_in.wait(5)
    source.advance(0.001)

    def operator() -> None:
        sampler.sample(force=True)
        second_done.set()

    other = threading.Thread(target=operator)
    other.start()
    runner.join(5)
    other.join(5)
    assert len(written) == 2 and written == sorted(written)


@pytest.mark.parametrize("command", ["panic", "stop"])
def test_a_stop_while_paused_wakes_the_runners_dozing_on_any_clock(command):
    """On the music's clock too (paused: every later cue out of reach, the runners dozing in
    slices), a stop or panic ends their dozes at once through the run's time source, not a
    sleep slice (50 ms) later."""
    from choreo.music.player import MusicClock

    woken: list[int] = []
    live = Live(StopRequest())
    clock = MusicClock(48000, -0.25)
    clock.handed_over(100.0, 0)  # the device's first ask: the clock runs
    live.use_clock(clock, wake=lambda: woken.append(1))
    assert live.command(Command("pause", "test")).ok and clock.state == PAUSED and woken == []
    assert live.command(Command(command, "test")).ok and woken == [1]
