"""GO cues (`at: go`) and the operator's commands: the show waits for GO (the machine's show clock
holding, the music playing on), panic, stop, start, a cue's GO; every command in the log.

Runs keep real time (a GO comes from another thread, as from the console or OSC) on the
in-process simulator; bounds are generous for a loaded machine.
"""

from __future__ import annotations

import json
import time
from itertools import pairwise

import pytest

from choreo.cli import main
from choreo.events import PANIC, CommandEvent, StepEvent, StopRequest
from choreo.live.controls import LOCKOUT_S, Live
from choreo.run.session import Session
from choreo.run.settings import RunRequest
from runlog import LiveRun as Running, prepare, read_log, started_on_cue, wait_for, write_show

GO_SHOW = """\
version: 1
motions:
  bow: {number: 2, duration: 0.1}
steps:
  - play: 1
  - play: bow
    at: go
    label: applause
  - wait: 0.2
  - play: 3
    at: 0.5
    label: after
"""


def starts(log, robot: str | None = None) -> dict:  # type: ignore[no-untyped-def]
    topic = f"/choreo/{robot}/step" if robot else "/choreo/step"
    return {m.get("label") or m["index"]: m for m in log.topic(topic) if m["event"] == "start"}


def test_the_plan_shows_where_the_show_waits_for_go(tmp_path, capsys):
    show = write_show(tmp_path, GO_SHOW + "  - repeat: 2\n    at: go\n    steps:\n      - play: 4\n      - play: 5\n"
                                "        at: go\n")
    assert main(["plan", str(show)]) == 0
    out = capsys.readouterr().out
    assert "0.000 s (waits for GO)  play 2 (bow)" in out
    assert main(["plan", str(show), "--json"]) == 0
    plan = json.loads(capsys.readouterr().out)["plan"]
    # the repeat's GO is its first pass's first step; a GO inside a repeat waits on every pass
    assert [s["index"] for s in plan if s.get("go")] == [1, 4, 5, 7]


# the show ends on a GO cue: on virtual time a GO lets the runner run the rest at once, maybe
# before the GO's own record is written; the last cue keeps the log open for it
HELD_SHOW = GO_SHOW + "  - play: 4\n    at: go\n    label: curtain\n"
HOLD_S = 0.4  # how long the operator takes to GO (virtual time)


def held_run(tmp_path):  # type: ignore[no-untyped-def]
    """HELD_SHOW on virtual time, its first GO given `HOLD_S` after the cue was reached (the
    show clock held meanwhile): the run, the GO's answer, the wall-clock instant of the GO, the log."""
    from test_pause import VirtualRun

    run = VirtualRun(tmp_path, HELD_SHOW)
    assert wait_for(lambda: bool(run.live.waiting), 10, 0.001)
    assert run.live.waiting[0].name == "applause"
    run.source.advance(HOLD_S)  # the runner waits for the GO: virtual time passes only here
    released = run.session.clock.wall_ns()
    answer = run.say("go")
    run.curtain()
    return run, answer, released, run.finish()


def test_the_machine_clock_holds_while_a_go_cue_waits(tmp_path):
    run, answer, released, log = held_run(tmp_path)
    assert answer.ok and answer.data == {"cue": "1", "label": "applause", "playhead": "3"}
    assert run.error is None and run.result.outcome == "done"
    steps = starts(log)
    # the show time the GO cue went on from is where the show reached it, not 0.4 s later
    assert steps["applause"]["go"] is True and steps["applause"]["actual_s"] < 0.1
    # the cue at 0.5 s counts on the held clock: on time, 0.5 s of show after the start, not late
    after = next(m for m in log.topic("/choreo/step") if m["event"] == "end" and m.get("label") == "after")
    assert after["start_s"] == pytest.approx(0.5, abs=1e-3)  # its motion, on its cue
    assert steps["after"]["actual_s"] == pytest.approx(0.5 - after["lead_ms"] / 1e3, abs=1e-3)
    assert steps["after"]["late_ms"] < 1
    go = [m for m in log.topic("/choreo/command") if m["command"] == "go"]
    assert [(m["source"], m["status"], m["message"]) for m in go] == [
        ("test", "ok", "GO: cue 1 'applause'"), ("test", "ok", "GO: cue 3 'curtain'")]
    assert go[0]["_log_time"] >= released
    # on the wall clock, the cue's step came (its planned start - where the GO cue was reached) after the GO
    waited = (steps["after"]["_log_time"] - released) / 1e9
    assert waited == pytest.approx(steps["after"]["actual_s"] - steps["applause"]["actual_s"], abs=1e-3)
    assert 0.35 < waited < 0.5


def test_go_refuses_a_double_press_and_a_go_with_nothing_waiting(tmp_path):
    # the double press comes after the bow has played: a lockout no loaded machine outlasts
    run = Running(tmp_path, "version: 1\nsteps:\n  - play: 1\n    at: go\n    label: bow\n"
                            "  - play: 4\n    at: go\n    label: encore\n", lockout_s=60.0)
    run.until_waiting()
    assert run.go().ok
    run.until_waiting("encore")  # right after the bow
    double = run.go()
    assert not double.ok and "a double press?" in double.message
    run.live.lockout_s = LOCKOUT_S  # the usual lockout, which the next GO comes after
    time.sleep(LOCKOUT_S)
    assert run.go().ok
    run.finish()
    time.sleep(0.5)
    late = run.go()
    assert not late.ok and late.message == "nothing waits for GO now"
    commands = [(m["command"], m["status"]) for m in run.log().topic("/choreo/command")]
    assert commands == [("go", "ok"), ("go", "error"), ("go", "ok")]  # the last came after the log closed


def test_a_cues_go_by_its_label(tmp_path):
    run = Running(tmp_path, GO_SHOW)
    run.until_waiting()
    wrong = run.go("cue_go", label="encore")
    assert not wrong.ok and wrong.message == "cue 'encore' is not waiting for GO (waiting: 'applause')"
    assert run.go("cue_go", label="applause").ok
    run.finish()
    assert [m["label"] for m in run.log().topic("/choreo/command")] == ["encore", "applause"]


def test_panic_halts_every_robot_and_plays_the_aborts(tmp_path):
    body = """\
        version: 1
        robots:
          a: {on_abort: 9}
          b: {}
        steps:
          - play: 1
          - play: 2
            at: go
        """
    run = Running(tmp_path, body)
    # both robots reach the shared GO cue (the second a moment after the first)
    assert wait_for(lambda: bool(run.live.waiting) and run.live.waiting[0].robots == {"a", "b"}, 10, 0.005)
    assert run.go("panic").ok
    run.finish()
    assert run.result.outcome == "aborted" and run.live.stop.reason == PANIC
    log = run.log()
    a = [(m["kind"], m.get("motion"), m.get("label")) for m in log.topic("/rcb4/a/tx")]
    b = [(m["kind"], m.get("motion"), m.get("label")) for m in log.topic("/rcb4/b/tx")]
    assert a[-3:] == [("stop", 9, "on_abort"), ("play", 9, "on_abort"), ("restore", 9, "on_abort")]
    assert b[-1] == ("stop", None, "on_abort")  # no abort motion: the stop frame halts what plays
    assert log.metadata["choreo.result"]["outcome"] == "aborted"


def test_one_go_releases_a_shared_step_for_every_robot(tmp_path):
    body = """\
        version: 1
        robots: {a: {}, b: {}}
        steps:
          - play: 1
          - play: 2
            at: go
            label: together
        """
    run = Running(tmp_path, body)
    assert wait_for(lambda: bool(run.live.waiting) and run.live.waiting[0].robots == {"a", "b"}, 10, 0.005)
    assert run.go().ok
    run.finish()
    log = run.log()
    assert starts(log, "a")["together"]["go"] and starts(log, "b")["together"]["go"]
    assert len([m for m in log.topic("/choreo/command")]) == 1


def test_wait_start_holds_the_show_until_start(tmp_path):
    run = Running(tmp_path, GO_SHOW.replace("    at: go\n", ""), wait_start=True)
    time.sleep(0.2)
    assert run.result is None and run.thread.is_alive()  # loaded, ports open, waiting for start
    go = run.go("go")  # GO is for GO cues: only start starts it (the console's GO key sends start)
    assert not go.ok and go.message == "nothing waits for GO now (the show waits for its start: /choreo/start)"
    assert run.go("start").ok and not run.go("start").ok
    run.finish()
    assert run.result.outcome == "done"


def test_a_go_cue_needs_a_console_or_osc(tmp_path, capsys):
    show = write_show(tmp_path, GO_SHOW)
    assert main(["run", str(show), "--no-log"]) == 2
    err = capsys.readouterr().err
    assert "step 1 'applause' waits for GO, but nothing can give it" in err


def test_in_a_music_show_a_go_cue_waits_while_the_music_plays_on(tmp_path):
    from test_music import write_song

    write_song(tmp_path / "song.wav", 2.0)
    body = ("version: 1\nmusic: {file: song.wav}\nsteps:\n  - play: 1\n  - play: 2\n    at: go\n    label: bow\n"
            "  - play: 3\n    at: 0.8\n    label: later\n")
    run = Running(tmp_path, body, audio_device="null")
    run.until_waiting()
    time.sleep(0.3)
    assert run.go().ok
    run.finish()
    assert run.error is None, run.error
    log = run.log()
    steps = starts(log)
    # the GO came 0.3 s or more into the music: the step went then, reported against the music,
    # at the music's time the GO itself was logged at (both read the music's clock as it went on,
    # on two threads: apart only by a scheduler's delay; a fixed upper bound counted the loaded
    # machine's delays in reaching the cue, in the sleep and in the GO too)
    go = next(m for m in log.topic("/choreo/command") if m["command"] == "go")
    assert steps["bow"]["actual_s"] > 0.25 and steps["bow"]["go"]
    assert abs(steps["bow"]["actual_s"] - go["show_s"]) < 0.2, (steps["bow"], go)
    # the cue after it stays where it is in the music (the clock did not hold)
    steps = log.topic("/choreo/step")
    end = next(m for m in steps if m["event"] == "end" and m.get("label") == "later")
    assert end["cue"] == 0.8 and started_on_cue(steps, end)


def test_a_go_cue_in_a_repeat_waits_on_every_pass(tmp_path):
    body = "version: 1\nsteps:\n  - repeat: 3\n    steps:\n      - play: 1\n        at: go\n        label: bow\n"
    run = Running(tmp_path, body)
    for name in ("bow", "bow#2", "bow#3"):
        run.until_waiting(name)
        time.sleep(0.5)  # past the lockout
        assert run.go().ok
    run.finish()
    assert [m["message"] for m in run.log().topic("/choreo/command")] == ["GO: cue 1 'bow'", "GO: cue 2 'bow#2'",
                                                                           "GO: cue 3 'bow#3'"]


class StopAfter:
    """Stops the run when the step labelled `label` has ended `times` times (a loop's passes
    counted, not timed: a timer's passes depend on how quickly the run got going)."""

    def __init__(self, stop: StopRequest, label: str, times: int) -> None:
        self.stop, self.label, self.left = stop, label, times

    def on_step(self, event: StepEvent) -> None:
        if event.event == "end" and event.step.label == self.label:
            self.left -= 1
            if self.left == 0:
                self.stop.request()

    def on_log(self, level: int, message: str, time_ns: int) -> None:
        pass


def test_loop_repeats_a_section_until_stopped(tmp_path):
    body = ("version: 1\nsteps:\n  - play: 1\n    label: intro\n  - play: 2\n    label: verse\n  - wait: 0.1\n"
            "  - play: 3\n    label: chorus\n  - play: 4\n    label: outro\n")
    show = write_show(tmp_path, body)
    log_path = tmp_path / "run.mcap"
    session = prepare(RunRequest(str(show), log_path=str(log_path), loop="verse..chorus"))
    stop = StopRequest()
    with session:
        result = session.run([StopAfter(stop, "chorus", 3)], stop)
    played = [m.get("motion") for m in read_log(log_path).topic("/rcb4/tx") if m["kind"] == "play"]
    assert played == [2, 3, 2, 3, 2, 3]
    assert result.outcome == "aborted" and result.steps_run == 9  # three steps a pass


def test_loop_and_rehearse_options_are_checked(tmp_path, capsys):
    show = write_show(tmp_path, GO_SHOW.replace("    at: go\n", ""))
    for args, message in ((["--loop", "after"], "--loop after: give FROM..TO"),
                          (["--loop", "after..applause"], "--loop ..applause: it comes before the loop's first step"),
                          (["--loop", "applause..nope"], "--loop ..nope: no step with that index"),
                          (["--loop", "applause..after", "--from", "after"], "leave out --from"),
                          (["--rehearse", "--port", "/dev/ttyUSB0"], "--rehearse runs every robot on the simulator")):
        assert main(["run", str(show), "--no-log", *args]) == 2, args
        assert message in capsys.readouterr().err, args


def test_rehearse_runs_on_the_simulator_whatever_the_show_says(tmp_path, capsys):
    show = write_show(tmp_path, "version: 1\nrobot: {port: /dev/ttyUSB9}\nsteps:\n  - play: 1\n")
    assert main(["run", str(show), "--rehearse", "--no-log"]) == 0
    assert "port: sim://" in capsys.readouterr().err


def test_the_summary_lists_who_pressed_what_and_when(tmp_path, capsys):
    run = Running(tmp_path, GO_SHOW)
    run.until_waiting()
    run.go("cue_go", label="nope")
    run.go()
    run.finish()
    assert main(["log", "summary", str(run.log_path)]) == 0
    out = capsys.readouterr().out
    assert "commands  2 received (1 refused)" in out
    # a command names the cue it acted on as the cue list does, or what was typed (quoted)
    assert "cue_go 'nope' test ERROR: cue 'nope' is not waiting for GO (waiting: 'applause')" in out
    assert "go cue 1 'applause' test: GO: cue 1 'applause'" in out
    assert main(["log", "summary", str(run.log_path), "--json"]) == 0
    record = json.loads(capsys.readouterr().out)
    assert [c["command"] for c in record["commands"]] == ["cue_go", "go"] and record["commands_total"] == 2


def test_loop_in_a_music_show_restarts_the_music_with_each_pass(tmp_path):
    from test_music import write_song

    write_song(tmp_path / "song.wav", 3.0)
    body = ("version: 1\nmusic: {file: song.wav}\nsteps:\n  - play: 1\n    at: 0.5\n    label: a\n"
            "  - play: 2\n    at: 0.7\n    label: b\n  - play: 3\n    at: 1.0\n")
    show = write_show(tmp_path, body)
    log_path = tmp_path / "run.mcap"
    session = Session.prepare(RunRequest(str(show), log_path=str(log_path), loop="a..b", audio_device="null"))
    stop = StopRequest()
    with session:
        session.run([StopAfter(stop, "b", 2)], stop)
    log = read_log(log_path)
    ends = [m for m in log.topic("/choreo/step") if m["event"] == "end"]
    assert [m["label"] for m in ends][:4] == ["a", "b", "a", "b"] and 3 not in [m.get("motion") for m in ends]
    # each pass starts the music again from a's moment: the motions start on its cues every time
    steps = log.topic("/choreo/step")
    assert all(started_on_cue(steps, m) for m in ends if m["outcome"] == "ok")
    shows = [m["show_s"] for m in log.topic("/choreo/clock")]
    assert any(later < earlier for earlier, later in pairwise(shows))  # the clock went back to a


def test_a_loops_go_cue_waits_on_every_pass(tmp_path):
    body = "version: 1\nsteps:\n  - play: 1\n    label: a\n  - play: 2\n    at: go\n    label: b\n  - play: 3\n"
    run = Running(tmp_path, body, loop="a..b", lockout_s=0.0)
    for _ in range(3):
        run.until_waiting("b")
        assert run.go().ok
    run.until_waiting("b")
    run.go("stop")
    run.finish()
    assert run.result.outcome == "aborted"
    assert [m["status"] for m in run.log().topic("/choreo/command")] == ["ok"] * 4


def test_a_play_after_a_play_is_not_late_by_its_exchanges(tmp_path):
    from runlog import vmain

    show = write_show(tmp_path, "version: 1\nsteps:\n  - play: 1\n  - play: 2\n  - play: 3\n    at: 1\n  - play: 4\n")
    assert vmain(["run", str(show), "--port", "sim://?reply_ms=2", "--log", str(tmp_path / "r.mcap"), "-q"]) == 0
    starts = [m for m in read_log(tmp_path / "r.mcap").steps if m["event"] == "start"]
    assert all(m["late_ms"] < 1.0 for m in starts), starts
    assert starts[1]["actual_s"] > 0.005  # it did wait for the play before to be answered


def test_osc_options_need_osc(tmp_path, capsys):
    show = write_show(tmp_path, "version: 1\nsteps:\n  - play: 1\n")
    assert main(["run", str(show), "--no-log", "--osc-allow", "10.0.0.2"]) == 2
    assert "--osc-allow: it is for OSC: give --osc PORT too" in capsys.readouterr().err


def test_a_music_shows_log_reviews_with_its_planned_lengths(tmp_path, capsys):
    from runlog import vmain
    from test_music import TEMPO_SHOW, write_song

    write_song(tmp_path / "song.wav", 1.6)
    show = write_show(tmp_path, TEMPO_SHOW)
    assert vmain(["run", str(show), "--no-music", "--log", str(tmp_path / "r.mcap"), "-q"]) == 0
    assert main(["log", "timeline", str(tmp_path / "r.mcap")]) == 0
    assert "does not load" not in capsys.readouterr().out


def test_the_reviews_place_frames_on_the_held_clock(tmp_path, capsys):
    """After a GO cue held the clock 0.4 s, `log frames`, `log summary` and `log timeline` put
    the later frames at their show times, not 0.4 s later (virtual time: to the millisecond)."""
    run, _answer, _released, log = held_run(tmp_path)
    path = run.log_path
    # the third play, cued at 0.5: what the reviews must show (0.9 would mean the hold counted)
    steps = log.topic("/choreo/step")
    third = [m for m in steps if m["event"] == "end" and m["kind"] == "play"][2]
    assert third["cue"] == 0.5 and third["start_s"] == pytest.approx(0.5, abs=1e-3)
    assert main(["log", "frames", str(path), "--kind", "play"]) == 0
    plays = [line for line in capsys.readouterr().out.splitlines() if "CALL" in line]
    assert len(plays) == 4 and float(plays[2].split()[0]) == pytest.approx(0.5, abs=2e-3), plays
    assert main(["log", "summary", str(path), "--json"]) == 0
    summary = json.loads(capsys.readouterr().out)
    assert summary["clock"]["samples"] >= 3
    from choreo.review.summary import summarize

    starts = [play.start_s for play in summarize(path).plays]
    assert starts[2] == pytest.approx(third["start_s"], abs=1e-3), starts  # the log's, on the show clock
    from choreo.log.reader import LogReader
    from choreo.review.timeline import build

    with LogReader(path) as reader:
        runs = [r for r in build(reader).runs if r.motion == 3]
    assert len(runs) == 1 and runs[0].start_s == pytest.approx(third["start_s"], abs=1e-3)


def test_while_the_show_opens_only_panic_and_stop_are_taken_and_the_log_hears_them_once_it_records():
    """`choreo run` serves OSC while the ports and the log open: a command carried out then
    would be missing from the log. Until the log records (`recording`), anything but a panic or
    a stop is refused, and those are told to the log when it begins."""
    from choreo.events import Command, StopRequest
    from choreo.live.controls import OPENING, Live

    live = Live(StopRequest(), wait_start=True, opening=True)
    assert live.state == "opening" and live.status()["state"] == "opening"
    for name in ("start", "go", "skip", "pause", "playhead_next"):
        answer = live.command(Command(name, "osc 127.0.0.1"))
        assert not answer.ok and answer.message == OPENING, name
    assert not live.started
    heard: list = []

    class Log:
        def on_command(self, event) -> None:  # type: ignore[no-untyped-def]
            heard.append((event.command.name, event.answer.status))

    assert live.command(Command("stop", "osc 127.0.0.1")).ok and live.stop()
    live.recording(Log())
    assert heard == [("stop", "ok")] and live.state == "stopping"
    live = Live(StopRequest(), wait_start=True, opening=True)
    live.recording(None)
    assert live.state == "waiting_start" and live.command(Command("start", "key")).ok


def test_a_panic_as_the_show_opens_is_logged_once_at_its_own_time_by_the_log_recording_subscribes():
    """The session subscribed its log, then called `recording`: a panic between the two was
    told the log live, then again as one held (and that one stamped with the time of
    `recording`). `recording` subscribes the log itself, under the lock such a command takes."""
    from choreo.events import Command, StopRequest
    from choreo.live.controls import Live

    ticks = iter(range(100, 10**6, 100))
    live = Live(StopRequest(), opening=True, wall_ns=lambda: next(ticks))
    heard: list = []

    class Log:
        def on_command(self, event) -> None:  # type: ignore[no-untyped-def]
            heard.append((event.command.name, event.answer.status, event.time_ns))

    assert live.command(Command("panic", "osc 10.0.0.5")).ok
    with live.recording(Log()):
        assert heard == [("panic", "ok", 100)]  # once, at the time it was carried out
        assert not live.command(Command("go", "key")).ok  # heard: the log is subscribed
        assert [name for name, _status, _ns in heard] == ["panic", "go"]
    live.command(Command("go", "key"))  # the subscription closed: the log hears no more
    assert len(heard) == 2


class SlowToHear:
    """Hears the commands before the log does, and is slow to hear a GO: as a console busy
    drawing, or an operator's thread the machine put off between carrying a GO out and telling
    the log of it."""

    def on_command(self, event: CommandEvent) -> None:
        if event.command.name == "go":
            time.sleep(0.3)


def test_a_go_that_ends_the_show_is_logged_however_late_it_is_told(tmp_path):
    """The show ends a few milliseconds after its last GO cue's GO: the run's end waits for the
    GO's telling, so the log has it (it closed under it, and lost it, when the GO's thread was
    put off that long)."""

    def slow_first(live: Live) -> list:
        live.subscribe(SlowToHear())  # before the run's log subscribes: told first
        return []

    run = Running(tmp_path, "version: 1\nsteps:\n  - play: 1\n    at: go\n    label: bow\n", attach=slow_first)
    run.until_waiting()
    assert run.go().ok
    run.finish()
    assert [(m["command"], m["status"]) for m in run.log().topic("/choreo/command")] == [("go", "ok")]
