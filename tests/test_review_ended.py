"""`log summary`'s line for a motion slot says what ended the plays no status query timed
(issue 21, hostile logs / item 2's follow-up): it said "no status query saw it end" of a play the
link's program state read found already over, of one the next play stopped, and of one still
running at the log's end alike."""

from __future__ import annotations

from pathlib import Path

from choreo.review.summary import MotionStats, Play, Summary, summarize, summary_record
from choreo.review.summarytext import ENDED_BY, render
from test_play_once import run_short


def _motion_line(summary: Summary, motion: int) -> str:
    return next(line for line in render(summary) if line.startswith(f"  motion {motion:3d}  x"))


def test_a_play_the_state_read_found_over_is_said_so_on_its_motions_line(tmp_path):
    run_short(tmp_path, "hth4-2.2", "lose_start=2")  # every second start reply lost, the motion over by the read
    summary = summarize(tmp_path / "run.mcap")
    lines = [_motion_line(summary, motion) for motion in sorted(summary.motions)]
    ended = [line for line in lines if ENDED_BY["state read"] in line]
    assert ended and not any("no status query saw it end" in line for line in lines), lines
    record = summary_record(summary)["motions"]
    assert sum(m["unmeasured"].get("state read", 0) for m in record) == 3


def test_each_way_a_play_ended_is_counted_beside_the_measured_ones():
    summary = Summary(Path("x.mcap"), {}, None, False, None)
    stats = summary.motions[7] = MotionStats(7)
    for duration, by in ((0.5, "status"), (None, "stop"), (None, "stop"), (None, "end of log"), (None, "state read")):
        stats.add(Play(7, 1, None, 0.0, duration, by))
    summary.plays_total = 5
    line = _motion_line(summary, 7)
    assert line.endswith(f"median 0.500 s (min 0.500, max 0.500); 4 not measured (2 {ENDED_BY['stop']}; "
                         f"1 {ENDED_BY['end of log']}; 1 {ENDED_BY['state read']})"), line


def test_the_timelines_legend_says_what_ended_the_plays_it_could_not_time(tmp_path, capsys):
    # Before: "'.' up to what stopped it (the next play, or the log's end)" of a play the state read ended.
    from runlog import vmain

    run_short(tmp_path, "hth4-2.2", "lose_start=2")
    capsys.readouterr()
    assert vmain(["log", "timeline", str(tmp_path / "run.mcap")]) == 0
    lines = capsys.readouterr().out.splitlines()
    legend = lines[next(n for n, line in enumerate(lines) if "up to what ended it" in line) + 1]
    assert "the state read after a lost start reply (over by then)" in legend and "the next play" in legend
