"""Reviews of a show on an Ableton Link session (issue 25), from a log written without Link: the
records a `--host left` run of a two-host show writes, through choreo's Recorder, with a peer's
tempo change from 120 to 150 bpm at show time 1.47 s. Bar 2 (show beat 4) then falls at
1.894 s, bar 3 (beat 8) at 3.494 s, not at the 2.0 and 4.0 s the plan drew at 120 bpm: every
review plans them there, says the session's tempo, peers and transport, and reviews only the
robots this host drove."""

from __future__ import annotations

import json
from pathlib import Path
from typing import Any

import pytest

from choreo.cli import main
from choreo.events import RxEvent, Tag, TxEvent
from choreo.log.format import ClockRecord, StepRecord
from choreo.log.reader import LogReader
from choreo.log.recorder import Recorder, RobotInfo, RobotTap, RunInfo
from choreo.review.export import cue_rows
from choreo.review.showtime import LinkTimes
from choreo.review.summary import summarize, summary_record
from choreo.review.summarytext import render
from choreo.review.timeline import build, link_text, render_text
from choreo.wire import protocol

SHOW = b"""\
version: 1
name: Link duo
clock: link
tempo: {bpm: 120, meter: 4}
hosts:
  left: [a]
  right: [b]
robots:
  a: {}
  b: {}
motions:
  wave: {number: 4, duration: 0.8}
  clap: {number: 20, duration: 0.4}
tracks:
  a:
    - play: wave
      at: {bar: 1, beat: 2}
    - play: clap
      at: {bar: 2, beat: 1}
    - play: wave
      at: {bar: 3, beat: 1}
    - play: clap
      at: 5.5
  b:
    - play: wave
      at: {bar: 1, beat: 2}
    - play: clap
      at: {bar: 2, beat: 1}
    - play: wave
      at: {bar: 3, beat: 1}
    - play: clap
      at: 5.5
"""
ZERO = 1_790_000_000_000_000_000  # log time of show time 0
CHANGE_S = 1.47  # the peer's tempo change
LEAD_S = 0.005
# (step, motion, cue as the plan drew it at 120 bpm, where the session put it)
CUES = [(0, 4, 0.5, 0.5), (1, 20, 2.0, 1.894), (2, 4, 4.0, 3.494), (3, 20, 5.5, 5.5)]


def _beat(show_s: float) -> float:
    """The session's show beat: 120 bpm, then 150 from CHANGE_S."""
    return 2 * show_s if show_s < CHANGE_S else 2 * CHANGE_S + 2.5 * (show_s - CHANGE_S)


def _ns(show_s: float) -> int:
    return ZERO + round(show_s * 1e9)


def _sample(show_s: float, event: str | None = None, peers: int = 2, stale: bool = False) -> ClockRecord:
    """A Link sample; `stale`: the change's own sample, still the timeline before it (as logged)."""
    tempo = 120.0 if show_s < CHANGE_S or stale else 150.0
    beat = 2 * show_s if stale else _beat(show_s)
    return ClockRecord(round(show_s, 6), round(show_s * 1e9), "link", link_us=round(show_s * 1e6),
                       beat=round(beat, 6), session_beat=round(beat, 6), tempo=tempo, peers=peers, event=event)


def _samples(until: float) -> list[ClockRecord]:
    samples = [_sample(-2.5), _sample(0.0, "start")]
    samples += [_sample(n / 2) for n in range(1, 3)] + [_sample(1.48, "tempo", stale=True)]
    samples += [_sample(n / 2, peers=2 if n < 8 else 1) for n in range(3, 12)]
    samples.insert(-4, _sample(4.0, "peers", peers=1))
    return [s for s in samples if s.show_s <= until] + ([_sample(5.9, "stopped", peers=1)] if until > 5.9 else [])


def _play(tap: RobotTap, seq: int, step: int, motion: int, at: float) -> int:
    for frame in protocol.play_sequence(motion):
        t = _ns(at) + seq * 1_000_000
        tap.on_tx(TxEvent(seq, frame, 1, t, Tag(step, None)))
        tap.on_rx(RxEvent(seq, frame, protocol.Reply(protocol.ReplyKind.ACK, protocol.ack(frame.data[1])),
                          t + 500_000, 0.0005, Tag(step, None)))
        seq += 1
    return seq


def _write_log(path: Path, steps: int = 4, closed: bool = True, link: bool = True) -> Path:
    """Host left's log (robot a): `steps` of its cues run; the samples up to the last one's
    (`link` False: the machine's samples, with no session in them)."""
    info = RunInfo("duo.yaml", "Link duo", SHOW, "sim://", 115200, ZERO - 3 * 10**9,
                   robots=(RobotInfo("a", "sim://", 115200),), show_host="left")
    recorder = Recorder(path, info)
    tap = recorder.for_robot("a")
    until = CUES[steps - 1][3] + 0.6 if steps < len(CUES) else 6.0
    samples = _samples(until) if link else [ClockRecord(s.show_s, s.monotonic_ns) for s in _samples(until)]
    events: list[tuple[int, Any]] = [(_ns(s.show_s), s) for s in samples]
    seq = 1
    for index, motion, cue, placed in CUES[:steps]:
        due = placed - LEAD_S
        common: dict[str, Any] = dict(kind="play", planned_s=round(due, 6), estimated_s=cue, path=f"tracks.a[{index}]",
                      motion=motion, cue=cue, robot="a", cue_number=str(2 * index + 1))
        events.append((_ns(due), StepRecord(index, event="start", actual_s=round(due, 6), **common)))
        events.append((_ns(placed + 0.004), StepRecord(index, event="end", actual_s=round(placed + 0.004, 6),
                                                       outcome="ok", start_s=placed, lead_ms=LEAD_S * 1e3,
                                                       **common)))
    for log_time, record in sorted(events, key=lambda pair: pair[0]):
        if isinstance(record, ClockRecord):
            recorder.on_clock(record, log_time)
        else:
            recorder.on_step_record(record, log_time)
            if record.event == "start":
                seq = _play(tap, seq, record.index, record.motion or 0, record.actual_s)
    recorder.close({"outcome": "done", "show_s": f"{until:.6f}"} if closed else None)
    return path


@pytest.fixture(scope="module")
def link_log(tmp_path_factory: pytest.TempPathFactory) -> Path:
    return _write_log(tmp_path_factory.mktemp("link") / "left.mcap")


def test_a_beat_is_placed_on_the_session_timeline_across_a_tempo_change():
    times = LinkTimes()
    for sample in _samples(6.0):
        times.see(sample)
    assert times.show_of_beat(1) == pytest.approx(0.5, abs=1e-6)
    assert times.show_of_beat(4) == pytest.approx(1.894, abs=1e-6)  # after the change's stale sample
    assert times.show_of_beat(8) == pytest.approx(3.494, abs=1e-6)
    assert times.show_of_beat(2.9) == pytest.approx(1.45, abs=1e-6)  # before the change, at 120 bpm
    assert times.show_of_beat(40) == pytest.approx(CHANGE_S + (40 - 2 * CHANGE_S) / 2.5, abs=1e-6)  # past the end
    assert times.tempos == [(-2.5, 120.0), (1.48, 150.0)]  # heard at the change's sample
    assert (times.peers, times.joined, times.left) == ((1, 2), 0, 1)
    assert [c.kind for c in times.changes] == ["tempo", "peers", "stopped"]


def test_a_sample_with_no_tempo_a_link_could_have_places_nothing():
    times = LinkTimes()
    for n, tempo in enumerate((0.0, -120.0, 1e-300, 1e300)):
        times.see(ClockRecord(float(n), n, "link", beat=float(n), tempo=tempo, peers=-1))
    assert times.show_of_beat(4) is None and times.tempos == [] and times.peers is None
    assert link_text(times) == "the Link session's: no tempo sampled"


def test_many_tempo_changes_are_named_a_few_and_counted():
    times = LinkTimes()
    for n in range(11):
        times.see(ClockRecord(float(n), n, "link", beat=float(n), tempo=100.0 + n, peers=0))
    text = link_text(times)
    assert text.startswith("the Link session's: 100.00 bpm, 101.00 from 1.00 s, ")
    assert text.count(" from ") == 5 and text.endswith(", ... (5 more tempo changes); no other peer")


def test_a_long_show_at_one_tempo_keeps_few_samples():
    times = LinkTimes()
    for n in range(20_000):
        times.see(ClockRecord(n / 2, n * 500_000_000, "link", beat=float(n), tempo=120.0, peers=1))
    assert len(times._beats) <= 10_000 / 5 + 2  # one every 5 s of the 10_000 s, and the last
    assert times.show_of_beat(12_345.5) == pytest.approx(6_172.75)


def test_the_summary_says_the_session_and_measures_motion_starts_from_the_placed_cues(link_log):
    summary = summarize(link_log)
    text = "\n".join(render(summary))
    clock = next(line for line in text.splitlines() if line.startswith("clock"))
    assert clock.startswith("clock     the Link session's: 120.00 bpm, 150.00 from 1.48 s; 1..2 other peers "
                            "(1 left); transport stopped at 5.90 s; "), clock
    assert "the machine's" not in text
    assert "\nhost      left of the show's hosts: its robots only; " in text
    assert summary.motion_starts.max is not None and abs(summary.motion_starts.max) < 0.01  # not -106 ms
    record = summary_record(summary)["clock"]["link"]
    assert record["tempos"] == [{"show_s": -2.5, "bpm": 120.0}, {"show_s": 1.48, "bpm": 150.0}]
    assert record["peers"] == {"min": 1, "max": 2, "joined": 0, "left": 1}
    assert [c["kind"] for c in record["changes"]] == ["tempo", "peers", "stopped"]
    json.dumps(record)


def test_the_timeline_plans_bar_cues_where_the_session_put_them_and_only_this_hosts_robots(link_log):
    with LogReader(link_log) as reader:
        timeline = build(reader)
    planned = {run.step: run.planned_s for run in timeline.runs}
    assert planned == pytest.approx({0: 0.5, 1: 1.894, 2: 3.494, 3: 5.5}, abs=1e-6)
    assert [round(cue.show_s, 6) for cue in timeline.cues] == [0.5, 1.894, 3.494, 5.5]
    assert not timeline.unplayed and {run.robot for run in timeline.runs} == {"a"}
    assert timeline.elsewhere == ["b"] and timeline.host == "left"
    assert [m.text for m in timeline.session] == ["tempo 120.00 -> 150.00 bpm", "peers 2 -> 1", "transport stopped"]
    text = "\n".join(render_text(timeline, 120))
    assert "host left: the show's other robots (b) are other hosts'" in text
    assert "robot b" not in text and "not played" not in text.replace("':' not played", "")
    assert "    1 motion 20 clap   1.894-2.294" in text
    assert "cue 3 at 1.894 s, cue 5 at 3.494 s" in text
    link_row = next(line for line in text.splitlines() if line.lstrip().startswith("link"))
    assert link_row.count("t") == 1 and "p" in link_row and "|" in link_row.split("|", 1)[1]


def test_a_cut_run_plans_the_cues_it_never_reached_on_the_session_timeline(tmp_path):
    log = _write_log(tmp_path / "cut.mcap", steps=2, closed=False)
    with LogReader(log) as reader:
        timeline = build(reader)
        rows = cue_rows(reader)
    unplayed = {run.step: run.planned_s for run in timeline.unplayed}
    assert unplayed == pytest.approx({2: 3.494, 3: 5.5}, abs=1e-6)  # the session's tempo at the end: 150
    assert [(r["number"], r["robot"], r["planned_s"], r["released"]) for r in rows] == [
        ("1", "a", 0.5, "time"), ("3", "a", 1.894, "time"), ("5", "a", 3.494, "not reached"),
        ("7", "a", 5.5, "not reached")]


def test_the_cue_export_plans_bar_cues_on_the_session(link_log, capsys):
    assert main(["log", "export", "--cues", "--json", "-", str(link_log)]) == 0
    rows = json.loads(capsys.readouterr().out)
    assert [(r["number"], r["robot"], r["planned_s"], r["bar_beat"]) for r in rows] == [
        ("1", "a", 0.5, "1.2"), ("3", "a", 1.894, "2.1"), ("5", "a", 3.494, "3.1"),
        ("7", "a", 5.5, "4.2.015")]  # 5.5 s fell on beat 13.015 of the session (3.4 at 120 bpm)


def test_a_machine_clock_log_keeps_its_planned_times(tmp_path):
    """The same run on the machine's clock (`--clock machine` rehearses a Link show): the plan's times."""
    path = _write_log(tmp_path / "machine.mcap", link=False)
    with LogReader(path) as reader:
        timeline = build(reader)
    assert timeline.link is None
    assert {run.step: run.planned_s for run in timeline.runs} == {0: 0.5, 1: 2.0, 2: 4.0, 3: 5.5}


def test_the_png_draws_the_session_changes_on_a_row_of_their_own(link_log, tmp_path, monkeypatch):
    import matplotlib.pyplot as plt

    from choreo.review.timeline import render_png

    figures = []
    close = plt.close
    monkeypatch.setattr(plt, "close", lambda fig=None: (figures.append(fig), close(fig)))
    with LogReader(link_log) as reader:
        timeline = build(reader)
    with open(tmp_path / "t.png", "wb") as out:
        render_png(timeline, out)
    (ax,) = next(fig for fig in figures if not isinstance(fig, str) and fig is not None).axes
    labels = [label.get_text() for label in ax.get_yticklabels()]
    assert labels[:2] == ["a: motion 4 wave", "a: motion 20 clap"] and "Link session" in labels
    row = labels.index("Link session")
    marked = sorted(x for line in ax.lines for x, y in zip(line.get_xdata(), line.get_ydata(), strict=True) if y == row)
    assert marked == pytest.approx([1.48, 4.0, 5.9])
    assert {text.get_text() for text in ax.texts} >= {"tempo 120.00 -> 150.00 bpm", "peers 2 -> 1"}
