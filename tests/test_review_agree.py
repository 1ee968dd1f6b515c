"""Every review agrees to the millisecond (issue 24), on shows the first agreement test does not
play: two tracks with a GO cue in one, shared steps in unison skipped at a GO cue, --loop with a
hold in each pass, --from past a cue, a panic while paused, a log cut short, an older log without
clock states. On virtual time: the test moves the clock while the show waits.

The agreement: summary, timeline and replay give the same lengths; the timeline ends where the
summary does; every step record's own show time is where the reviews place its log time; the
frames (text and export) and the plays (summary and timeline) carry the same show times; the
cue rows carry the step records' times."""

from __future__ import annotations

import contextlib
import io
import json
import threading
from pathlib import Path

import pytest

from choreo.clock import VirtualTime
from choreo.events import Command, StopRequest
from choreo.live.controls import Live
from choreo.log.format import STEP_TOPIC, TX_TOPIC, parse
from choreo.log.reader import LogReader
from choreo.review.export import cue_rows
from choreo.review.frames import frame_lines
from choreo.review.showtime import ShowTimes
from choreo.review.summary import summarize
from choreo.review.timeline import build
from choreo.run.session import Session
from choreo.run.settings import RunRequest
from choreo.show.cues import cue_list
from runlog import vmain, wait_for, write_show

ONE = """\
version: 1
motions:
  wave: {number: 1, duration: 0.5}
  bow: {number: 2, duration: 0.3}
steps:
  - play: wave
    at: 0.2
    label: early
  - wait: done
  - play: bow
    at: go
    label: applause
  - wait: done
  - play: wave
    at: 2.0
    label: encore
  - wait: done
"""
TRACKS = """\
version: 1
robots: {a: {}, b: {}}
motions:
  wave: {number: 1, duration: 0.6}
  bow: {number: 2, duration: 0.4}
tracks:
  a:
    - play: wave
    - wait: done
    - play: bow
      at: go
      label: applause
    - wait: done
    - play: wave
      at: 3.0
      label: a-late
    - wait: done
  b:
    - play: bow
    - wait: done
    - play: wave
      at: 1.0
      label: b-one
    - wait: done
"""
SHARED = """\
version: 1
robots: {a: {}, b: {}}
motions:
  wave: {number: 1, duration: 0.6}
  bow: {number: 2, duration: 0.4}
steps:
  - play: wave
  - wait: done
  - play: bow
    at: go
    label: applause
  - wait: done
  - play: wave
    at: 2.0
    label: two
  - wait: done
  - play: bow
    at: go
    label: last
  - wait: done
"""


class Show:
    """A show on virtual time with the live controls, the test its operator."""

    def __init__(self, tmp: Path, body: str, **request) -> None:  # type: ignore[no-untyped-def]
        self.log = tmp / "run.mcap"
        self.source = VirtualTime()
        self.session = Session.prepare(RunRequest(str(write_show(tmp, body)), log_path=str(self.log), **request),
                                       self.source)
        self.live = Live(StopRequest(), cues=cue_list(self.session.settings.plans), now=self.source.now,
                         wall_ns=self.source.wall_ns)
        self.thread = threading.Thread(target=self._run, daemon=True)
        self.thread.start()

    def _run(self) -> None:
        with self.session:
            self.session.run([], live=self.live)

    def say(self, name: str, label: str | None = None) -> None:
        assert self.live.command(Command(name, "key", label)).ok, name

    def waits(self, robots: int = 1) -> None:
        assert wait_for(lambda: bool(self.live.waiting) and len(self.live.waiting[0].robots) >= robots, 20, 0.002)

    def after(self, condition) -> None:  # type: ignore[no-untyped-def]
        assert wait_for(condition, 20, 0.002)

    def done(self) -> Path:
        self.thread.join(20)
        assert not self.thread.is_alive()
        return self.log


def agreed(log: Path, tmp: Path, replayed: bool = True, within_s: float = 0.001) -> tuple[dict, list[dict]]:
    """Assert every review agrees (see the module's docstring); the lengths and the cue rows.
    `within_s`: how near a step's own show time is placed (a real-time music show's drift)."""
    summary = summarize(log)
    with LogReader(log) as reader:
        timeline = build(reader)
        rows = cue_rows(reader)
        times = ShowTimes.of(reader)
        steps = [(log_time, parse(topic, data)) for topic, log_time, data in reader.messages((STEP_TOPIC,))]
        frames = list(frame_lines(reader))
    lengths = summary.lengths
    assert lengths is not None and timeline.lengths == lengths
    assert round(timeline.end_s, 3) == round(lengths.show_s or 0.0, 3)
    assert lengths.wall_s == pytest.approx((lengths.ran_s or 0) + lengths.held_s + lengths.paused_s)
    rewinds = set(times._rewind_ns)  # a pass's last step and the next pass's start share a virtual instant
    for log_time, step in steps:
        if log_time not in rewinds:
            assert times.seconds(log_time) == pytest.approx(step.actual_s, abs=within_s), step
    runs = sorted(round(run.start_s, 3) for run in timeline.runs if run.start_s is not None)
    listed = summary.plays + [play for robot in summary.robots.values() for play in robot.plays]
    plays = sorted(round(play.start_s, 3) for play in listed)
    if len(runs) <= 30:
        assert runs == plays
    out = io.StringIO()
    with contextlib.redirect_stdout(out):
        assert vmain(["log", "export", "--json", "-", str(log)]) == 0
    exported = [round(r["tx_show_s"], 6) for r in json.loads(out.getvalue()) if r["tx_show_s"] is not None]
    listed = [float(line.split()[0]) for line in frames if " tx " in f" {line} "]
    assert listed == exported
    started = {(s.robot, round(s.actual_s, 3)) for _, s in steps if s.event == "start"}
    assert {(r["robot"], r["actual_s"]) for r in rows if r["actual_s"] is not None} <= started
    if replayed:
        out = io.StringIO()
        with contextlib.redirect_stdout(out):
            assert vmain(["replay", str(log), "--log", str(tmp / "replay.mcap"), "--json"]) in (0, 1)
        assert json.loads(out.getvalue())["recorded"] == lengths.to_json()
    return lengths.to_json(), rows


def _released(rows: list[dict]) -> list[tuple]:
    return [(r["number"], r["robot"], r["pass"], r["released"]) for r in rows]


def test_two_tracks_a_go_cue_in_one(tmp_path):
    show = Show(tmp_path, TRACKS)
    show.waits()
    show.source.advance(1.5)
    show.say("go")
    lengths, rows = agreed(show.done(), tmp_path)
    assert (lengths["holds"], lengths["held_s"], lengths["passes"]) == (1, 1.5, 1)
    assert _released(rows) == [("1", "a", 1, "go key"), ("2", "b", 1, "time"), ("3", "a", 1, "time")]


def test_shared_steps_in_unison_and_a_skip_at_a_go_cue(tmp_path):
    show = Show(tmp_path, SHARED)
    show.waits(robots=2)
    show.source.advance(0.7)
    show.say("go")
    show.after(lambda: bool(show.live.waiting) and show.live.waiting[0].name == "last")
    show.source.advance(0.4)
    show.say("skip")  # the cue the show holds at: both robots pass it
    lengths, rows = agreed(show.done(), tmp_path)
    assert lengths["holds"] == 2 and lengths["held_s"] == pytest.approx(1.1, abs=0.001)
    assert [r["released"] for r in rows] == ["go key"] * 2 + ["time"] * 2 + ["skipped"] * 2
    summary = summarize(tmp_path / "run.mcap")
    assert [(n.cue, n.by) for n in summary.stands] == [("cue 1 'applause'", "go from key"),
                                                       ("cue 3 'last'", "skip from key")]


def test_a_loop_with_a_hold_in_each_pass(tmp_path):
    show = Show(tmp_path, ONE, loop="applause..encore")
    for held in (0.5, 1.0, 1.5):
        show.waits()
        show.source.advance(held)
        show.say("go")
        show.after(lambda: not show.live.waiting)
    show.waits()
    show.say("stop")
    lengths, rows = agreed(show.done(), tmp_path)
    assert lengths["passes"] == 4 and lengths["holds"] == 4 and lengths["held_s"] == 3.0
    assert lengths["start_s"] == 0.7 and lengths["ran_s"] == pytest.approx(3 * 1.3, abs=0.02)
    assert summarize(tmp_path / "run.mcap").clock.drift_ms == pytest.approx(0.0, abs=0.01)  # a pass is no drift
    assert _released(rows) == [("1", None, 1, "not in this run")] + [
        (number, None, n, released) for n in (1, 2, 3) for number, released in (("2", "go key"), ("3", "time"))] + [
        ("2", None, 4, "waiting (stopped)"), ("3", None, 4, "not reached")]
    with LogReader(tmp_path / "run.mcap") as reader:
        timeline = build(reader)
    starts = [run.start_at for run in timeline.runs]
    assert starts == sorted(starts)  # the passes drawn one after the other, on an axis from --loop's start
    assert timeline.end_at - lengths["start_s"] == pytest.approx(lengths["wall_s"], abs=0.01)


def test_from_a_go_cue_past_a_timed_one(tmp_path):
    show = Show(tmp_path, ONE, from_step="applause")
    show.waits()
    show.source.advance(0.8)
    show.say("go")
    lengths, rows = agreed(show.done(), tmp_path)
    assert lengths["start_s"] == 0.7 and lengths["ran_s"] == pytest.approx(lengths["show_s"] - 0.7)
    assert lengths["wall_s"] == pytest.approx(lengths["show_s"] - 0.7 + 0.8)
    assert [r["released"] for r in rows] == ["not in this run", "go key", "time"]


def test_a_panic_while_paused(tmp_path):
    show = Show(tmp_path, SHARED)
    show.waits(robots=2)
    show.say("go")
    show.after(lambda: bool(show.live.paused_robots) or bool(show.live.waiting))
    show.say("pause")
    show.source.advance(0.9)
    show.say("panic")
    lengths, rows = agreed(show.done(), tmp_path)
    assert lengths["pauses"] == 1 and lengths["paused_s"] == pytest.approx(0.9, abs=0.01)
    summary = summarize(tmp_path / "run.mcap")
    assert summary.stands[-1].by == "panic from key" and summary.stands[-1].stand.end_ns is None


@pytest.fixture(scope="module")
def stopped(tmp_path_factory) -> Path:
    """ONE held at its GO cue, then stopped: the log the cut and older-log variants are made of."""
    tmp = tmp_path_factory.mktemp("stopped")
    show = Show(tmp, ONE)
    show.waits()
    show.source.advance(2.0)
    show.say("stop")
    return show.done()


def test_a_run_stopped_at_a_go_cue_left_it_waiting(stopped, tmp_path):
    lengths, rows = agreed(stopped, tmp_path)
    assert lengths["held_s"] == 2.0
    assert [r["released"] for r in rows] == ["time", "waiting (stopped)", "not reached"]


def test_a_log_cut_short_without_its_result_nor_its_last_sample(stopped, tmp_path):
    """The run killed during the hold: no result metadata, no sample after the hold began."""
    cut = tmp_path / "cut.mcap"
    held_at = next(m["_log_time"] for m in _messages(stopped) if m.get("state") == "held")
    _rewrite(stopped, cut, lambda topic, m: m if m["_log_time"] <= held_at else None, result=False)
    lengths, rows = agreed(cut, tmp_path, replayed=False)
    assert lengths["holds"] == 1 and lengths["held_s"] == 0.0  # the log ends as the hold began
    assert [r["released"] for r in rows] == ["time", "waiting (stopped)", "not reached"]


def test_an_older_log_without_clock_states_nor_cue_numbers(stopped, tmp_path):
    old = tmp_path / "old.mcap"
    dropped = ("state", "cue_number", "cue", "cue_label")

    def older(topic: str, message: dict) -> dict:
        return {k: v for k, v in message.items() if k not in dropped or topic == STEP_TOPIC and k == "cue"}

    _rewrite(stopped, old, older)
    lengths, rows = agreed(old, tmp_path)
    assert lengths["holds"] == 1 and lengths["held_s"] == pytest.approx(2.0, abs=0.001)
    assert [(r["number"], r["released"]) for r in rows] == [("1", "time"), ("2", "waiting (stopped)"),
                                                             ("3", "not reached")]


def _messages(path: Path) -> list[dict]:
    from runlog import read_log

    log = read_log(path)
    return sorted((m for ms in log.messages.values() for m in ms), key=lambda m: m["_log_time"])


def _rewrite(source: Path, target: Path, edit, result: bool = True) -> None:  # type: ignore[no-untyped-def]
    """The log again, each message through `edit(topic, message)` (None: left out)."""
    from mcap.reader import make_reader
    from mcap.writer import Writer

    with open(source, "rb") as stream:
        reader = make_reader(stream)
        messages = list(reader.iter_messages(log_time_order=False))
        metadata = [m for m in reader.iter_metadata() if result or m.name == "choreo"]
        attachments = list(reader.iter_attachments())
    with open(target, "wb") as stream:
        writer = Writer(stream)
        writer.start()
        channels: dict[int, int] = {}
        for schema, channel, message in messages:
            if channel.id not in channels:
                schema_id = writer.register_schema(schema.name, schema.encoding, schema.data)
                channels[channel.id] = writer.register_channel(channel.topic, channel.message_encoding, schema_id)
            edited = edit(channel.topic, {**json.loads(message.data), "_log_time": message.log_time})
            if edited is not None:
                edited.pop("_log_time", None)
                writer.add_message(channels[channel.id], message.log_time, json.dumps(edited).encode(),
                                   message.publish_time, message.sequence)
        for attachment in attachments:
            writer.add_attachment(attachment.create_time, attachment.log_time, attachment.name,
                                  attachment.media_type, attachment.data)
        for record in metadata:
            writer.add_metadata(record.name, dict(record.metadata))
        writer.finish()


MUSIC = """\
version: 1
music: {file: song.wav}
motions:
  bow: {number: 1, duration: 0.05}
steps:
  - play: bow
    at: 0.1
    label: first
  - play: bow
    at: 0.5
    label: after
"""


def test_a_music_show_paused_agrees_and_its_resume_gap_is_no_drift(tmp_path):
    """Real time, the null output: paused 0.2 s as the first step starts. The song is heard again
    a few buffers after the resume; the reviews count that as pause, so the steps after it are
    placed where they ran and the clock shows no drift (it was the gap, 10-35 ms, before)."""
    from test_music import write_song

    write_song(tmp_path / "song.wav", 0.8)
    session = Session.prepare(RunRequest(str(write_show(tmp_path, MUSIC)), log_path=str(tmp_path / "run.mcap"),
                                         audio_device="null"))
    live = Live(StopRequest(), cues=cue_list(session.settings.plans))

    class PauseAtFirst:
        def on_step(self, event) -> None:  # type: ignore[no-untyped-def]
            if event.event == "start" and event.step.label == "first":
                threading.Thread(target=self.pause).start()

        def pause(self) -> None:
            assert live.command(Command("pause", "key")).ok
            threading.Event().wait(0.2)
            assert live.command(Command("resume", "key")).ok

        def on_log(self, *args) -> None:  # type: ignore[no-untyped-def]
            pass

    with session:
        assert session.run([PauseAtFirst()], live=live).outcome == "done"
    lengths, rows = agreed(tmp_path / "run.mcap", tmp_path, replayed=False, within_s=0.008)
    assert lengths["pauses"] == 1 and lengths["paused_s"] >= 0.2
    clock = summarize(tmp_path / "run.mcap").clock
    assert clock is not None and clock.source == "music" and abs(clock.drift_ms) < 8.0
    assert [r["released"] for r in rows] == ["time", "time"]


def test_every_review_reads_a_step_and_frame_topic_as_the_recorder_writes_them():
    assert TX_TOPIC == "/rcb4/tx" and STEP_TOPIC == "/choreo/step"  # the rewrites above keep topics as they are
