"""`choreo log export --cues` (issue 24): a row a cue a robot, numbered as the show's cue list
numbers it; bar.beat in a show with a tempo; an older log's cues numbered from its attached show."""

from __future__ import annotations

import json

import pytest

from choreo.log.format import StepRecord
from choreo.log.reader import LogReader
from choreo.log.recorder import Recorder, RunInfo
from choreo.review.export import cue_rows
from runlog import vmain, write_show

TEMPO_SHOW = """\
version: 1
tempo: {bpm: 120}
motions:
  bow: {number: 2, duration: 0.2}
steps:
  - play: bow
    at: {bar: 2, beat: 1}
    label: down
  - play: bow
    at: 2.25
    label: off
    cue: 7.5
"""


def test_a_show_with_a_tempo_gives_each_cue_its_bar_and_beat(tmp_path, capsys):
    log = tmp_path / "run.mcap"
    assert vmain(["run", str(write_show(tmp_path, TEMPO_SHOW)), "--log", str(log), "-q"]) == 0
    assert vmain(["log", "export", "--cues", "--jsonl", "-", str(log)]) == 0
    rows = [json.loads(line) for line in capsys.readouterr().out.splitlines()]
    assert [(r["number"], r["label"], r["planned_s"], r["released"], r["bar_beat"]) for r in rows] == [
        ("1", "down", 2.0, "time", "2.1"), ("7.5", "off", 2.25, "time", "2.1.5")]
    assert all(r["late_ms"] is not None and r["actual_s"] is not None for r in rows)


def test_an_older_logs_cues_are_numbered_from_the_attached_show_or_left_blank(tmp_path):
    def logged(name: str, show: bytes) -> LogReader:
        path = tmp_path / name
        recorder = Recorder(path, RunInfo("show.yaml", "x", show, "sim://", 115200, 10**18, "hth4-2.2"))
        for index, at in ((0, 1.0), (1, 2.0)):  # written before step records carried cue numbers
            recorder.on_step_record(StepRecord(index, "play", "start", at, at, at, cue=at, motion=2), 10**18 + index)
        recorder.close({"outcome": "done"})
        return LogReader(path)

    show = (b"version: 1\nsteps:\n  - play: 2\n    at: 1.0\n  - play: 2\n    at: 2.0\n    cue: 4\n"
            b"  - play: 3\n    at: 3\n")
    with logged("old.mcap", show) as reader:
        rows = cue_rows(reader)
    assert [(r["number"], r["released"]) for r in rows] == [("1", "time"), ("4", "time"), ("5", "not reached")]
    with logged("bare.mcap", b"not: [a show") as reader:
        rows = cue_rows(reader)
    assert [(r["number"], r["released"], r["planned_s"]) for r in rows] == [(None, "time", 1.0), (None, "time", 2.0)]


def test_a_cue_export_to_a_file_says_how_many_rows(tmp_path, capsys):
    log = tmp_path / "run.mcap"
    assert vmain(["run", str(write_show(tmp_path, TEMPO_SHOW)), "--log", str(log), "-q"]) == 0
    out = tmp_path / "cues.csv"
    assert vmain(["log", "export", "--cues", "--csv", str(out), str(log)]) == 0
    assert "exported 2 cue rows to " in capsys.readouterr().err
    assert out.read_text().splitlines()[0] == "number,label,robot,pass,planned_s,actual_s,late_ms,released,bar_beat"


ENSEMBLE = """\
version: 1
robots:
  a: {}
  b: {}
motions:
  wave: {number: 1, duration: 1.0}
steps:
  - play: wave
  - play: 2
    at: go
    label: applause
  - wait: done
  - play: wave
    at: 2.0
    label: encore
  - wait: done
"""


def test_a_cue_of_two_robots_is_a_row_each_in_cue_order_released_by_the_one_go(tmp_path):
    import threading

    from choreo.clock import VirtualTime
    from choreo.events import Command, StopRequest
    from choreo.live.controls import Live
    from choreo.run.session import Session
    from choreo.run.settings import RunRequest
    from choreo.show.cues import cue_list
    from runlog import wait_for

    log = tmp_path / "run.mcap"
    source = VirtualTime()
    session = Session.prepare(RunRequest(str(write_show(tmp_path, ENSEMBLE)), log_path=str(log)), source)
    live = Live(StopRequest(), cues=cue_list(session.settings.plans), now=source.now, wall_ns=source.wall_ns)

    def run() -> None:
        with session:
            session.run([], live=live)

    thread = threading.Thread(target=run, daemon=True)
    thread.start()
    assert wait_for(lambda: bool(live.waiting) and len(live.waiting[0].robots) == 2, 20, 0.002)
    source.advance(1.5)
    assert live.command(Command("go", "osc udp 127.0.0.1:53001")).ok
    thread.join(20)
    with LogReader(log) as reader:
        rows = cue_rows(reader)
    assert [(r["number"], r["robot"], r["released"]) for r in rows] == [
        ("1", "a", "go osc udp 127.0.0.1:53001"), ("1", "b", "go osc udp 127.0.0.1:53001"),
        ("2", "a", "time"), ("2", "b", "time")]
    assert rows[2]["actual_s"] == rows[3]["actual_s"] == pytest.approx(1.994, abs=0.01)  # the hold is not in it


PANICKED = """\
version: 1
motions:
  spin: {number: 3, duration: 3.0}
steps:
  - {play: spin, at: go, cue: 30, label: spin}
  - wait: done
  - {play: 5, at: go, cue: 40, label: bow}
  - wait: done
"""


def test_a_cue_never_reached_is_not_reached_and_only_a_cue_waited_at_is_waiting(tmp_path):
    """GO on cue 30, then a panic as its motion runs: the `wait: done` ends aborted, and cue 40
    was never reached (no robot logged that it waits for GO there): `not reached`, not waiting.
    The panic comes from the runner's own thread as the wait begins: on virtual time a panic from
    the test's thread could come after the runner slept through the whole motion to cue 40."""
    from runlog import wait_for
    from test_pause import VirtualRun
    run = VirtualRun(tmp_path, PANICKED, at={(1, "start"): ["panic"]})
    assert wait_for(lambda: bool(run.live.waiting), 10, 0.001)
    assert run.say("cue_go", "30").ok
    run.finish()
    assert [answer.ok for answer in run.hook.answers] == [True]  # the panic, as the spin's wait began
    with LogReader(run.log_path) as reader:
        rows = cue_rows(reader)
    assert [(r["number"], r["released"]) for r in rows] == [("30", "go test"), ("40", "not reached")]


LATE = """\
version: 1
motions:
  spin: {number: 3, duration: 3.5}
steps:
  - play: spin
  - wait: done
  - {play: 5, at: 3, label: late}
  - {play: 6, at: go, label: curtain}
"""


def test_a_late_timed_cues_planned_time_is_its_cue_time_and_actual_less_planned_is_its_lateness(tmp_path):
    """Cue `at: 3` after a 3.5 s motion waited for: the plan starts its step at 3.5, but the cue
    is due at 3, and late from there: planned_s 3.0, actual_s - planned_s = late_ms (the plan's
    3.5 made it 500 ms less)."""
    from test_pause import VirtualRun
    run = VirtualRun(tmp_path, LATE)
    run.curtain()
    run.finish()
    with LogReader(run.log_path) as reader:
        rows = cue_rows(reader)
    late = next(r for r in rows if r["label"] == "late")
    assert late["released"] == "time" and late["planned_s"] == 3.0 and late["late_ms"] > 400
    # late from the cue less the play's lead (its first frames go out a few ms ahead of the cue)
    assert (late["actual_s"] - late["planned_s"]) * 1e3 == pytest.approx(late["late_ms"], abs=10.0), late
