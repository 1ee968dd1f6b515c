"""`choreo log merge` (issue 25): the logs of one show's hosts as one log every review reads.

Two hosts' logs of one show, made on virtual time with `--host` (tests/hostlogs.py), started
at different wall times: the merge must find the shift, and every review of the merged log must
say of each robot what the review of its host's own log says."""

from __future__ import annotations

import os
from pathlib import Path

import pytest
from mcap.writer import Writer

from choreo.cli import main
from choreo.log.format import CLOCK_TOPIC, METADATA_NAME, RESULT_METADATA_NAME, Info, Result, host_key
from choreo.log.merge import MAX_INPUTS, Alignment, HostLog, align, merge_logs, offsets_to
from choreo.log.reader import LogReader
from choreo.review.export import cue_rows, rows
from choreo.review.summary import summarize, summary_record
from choreo.review.timeline import build
from hostlogs import merged_hosts, run_hosts
from runlog import read_log, vmain, write_show

LEFT, RIGHT = "stageleft", "stageright"
WHOSE = {"lead": LEFT, "follow": RIGHT}


@pytest.fixture(scope="module")
def duo(tmp_path_factory):
    return merged_hosts(tmp_path_factory.mktemp("merge"))


def _zero(path: Path) -> int:
    with LogReader(path) as reader:
        list(reader.messages(()))
        return int(reader.result[Result.SHOW_ZERO_WALL_NS])


def test_the_shift_between_the_hosts_is_found_on_their_clock_samples(duo):
    axis, other = duo.report.alignments
    assert (axis.by, axis.shift_ns) == ("axis", 0)
    assert other.by == "clock" and other.samples >= 5
    expected = _zero(duo.logs[LEFT]) - _zero(duo.logs[RIGHT])  # the runs' show starts, 37.25 s and more apart
    assert expected < -37.2e9
    assert abs(other.shift_ns - expected) < 10_000  # to 10 us: virtual time keeps both clocks exact
    assert other.spread_ns < 10_000
    with LogReader(duo.merged) as reader:
        assert reader.info.hosts == [LEFT, RIGHT]
        assert reader.run_info[host_key(RIGHT, Info.SHIFT_NS)] == str(other.shift_ns)


def test_the_summary_gives_every_robot_of_every_host_as_its_host_log_does(duo):
    merged = summary_record(summarize(duo.merged))
    assert list(merged["robots"]) == ["lead", "follow"]
    for robot, host in WHOSE.items():
        alone = summary_record(summarize(duo.logs[host]))
        assert merged["robots"][robot] == alone["robots"][robot]
    lines = "\n".join(_cli(["log", "summary", str(duo.merged)]))
    assert f"hosts     2 merged: {LEFT} (the time axis" in lines and f"{RIGHT} shifted -3" in lines


def test_the_show_is_timed_by_the_first_hosts_clock_alone(duo):
    merged, left = summarize(duo.merged), summarize(duo.logs[LEFT])
    assert merged.clock is not None and left.clock is not None
    assert merged.clock.samples == left.clock.samples  # the other host's samples are not counted again
    assert merged.duration_s == left.duration_s
    topics = set(read_log(duo.merged).messages)
    assert {f"/choreo/{LEFT}/clock", f"/choreo/{RIGHT}/clock"} <= topics and CLOCK_TOPIC not in topics
    assert len(merged.skew) == 3  # a unison show: its plays' starts compare host to host


def _by_robot(items, robot: str, drop=()) -> list:
    return [{k: v for k, v in item.items() if k not in drop} for item in items if item["robot"] == robot]


def test_frames_and_export_agree_with_each_hosts_log(duo):
    with LogReader(duo.merged) as reader:
        merged = list(rows(reader))
    for robot, host in WHOSE.items():
        with LogReader(duo.logs[host]) as reader:
            alone = list(rows(reader))
        times = ("tx_time_ns", "rx_time_ns", "tx_show_s", "rx_show_s")
        assert _by_robot(merged, robot, times) == _by_robot(alone, robot, times)
        for ours, theirs in zip(_by_robot(merged, robot), _by_robot(alone, robot), strict=True):
            assert ours["tx_show_s"] == pytest.approx(theirs["tx_show_s"], abs=1e-5)
    frames = _cli(["log", "frames", str(duo.merged), "--robot", "follow"])
    assert len(frames) > 10 and all("lead" not in line for line in frames)


def test_export_cues_agrees_with_each_hosts_log(duo):
    with LogReader(duo.merged) as reader:
        merged = cue_rows(reader)
    assert {row["robot"] for row in merged} == {"lead", "follow"}
    for robot, host in WHOSE.items():
        with LogReader(duo.logs[host]) as reader:
            alone = cue_rows(reader)
        assert _by_robot(merged, robot, ("actual_s",)) == _by_robot(alone, robot, ("actual_s",))
        assert [r["actual_s"] for r in _by_robot(merged, robot)] == pytest.approx(
            [r["actual_s"] for r in _by_robot(alone, robot)], abs=1e-5)


def test_the_timeline_draws_each_robot_where_its_host_log_does(duo):
    with LogReader(duo.merged) as reader:
        merged = build(reader)
    assert not merged.unplayed
    for robot, host in WHOSE.items():
        with LogReader(duo.logs[host]) as reader:
            alone = build(reader)
        ours = [(r.step, r.start_s, r.end_s) for r in merged.runs if r.robot == robot]
        theirs = [(r.step, r.start_s, r.end_s) for r in alone.runs if r.robot == robot]
        assert len(ours) == len(theirs) == 3
        for (step, start, end), (step_, start_, end_) in zip(ours, theirs, strict=True):
            assert step == step_ and start == pytest.approx(start_, abs=1e-5) and end == pytest.approx(end_, abs=1e-5)


def test_the_merged_metadata_keeps_each_host_and_the_show_once(duo):
    log = read_log(duo.merged)
    info = log.metadata[METADATA_NAME]
    assert info[Info.ROBOTS] == "lead,follow" and info[Info.HOSTS] == f"{LEFT},{RIGHT}"
    assert info["robot.follow.layout"] == "hth4-2.2" and Info.SHOW_HOST not in info
    assert log.metadata[f"choreo.host.{RIGHT}"][Info.SHOW_HOST] == RIGHT
    assert f"choreo.host.{RIGHT}.result" in log.metadata
    assert log.metadata[RESULT_METADATA_NAME][Result.STEPS_RUN] == "12"  # six a host
    assert len(log.attachments) == 1 and log.attachments[0].data == duo.show.read_bytes()


def test_a_replay_of_the_merged_log_replays_every_robot(duo, tmp_path):
    assert vmain(["replay", str(duo.merged), "--log", str(tmp_path / "again.mcap"), "--strict", "-q"]) == 0
    assert list(summarize(tmp_path / "again.mcap").robots) == ["lead", "follow"]


def _cli(argv: list[str]) -> list[str]:
    """`choreo ARGV` in-process; its stdout's lines."""
    import contextlib
    import io

    out = io.StringIO()
    with contextlib.redirect_stdout(out):
        assert main(argv) == 0
    return out.getvalue().splitlines()


def test_the_command_reports_the_shift_and_spread(duo, tmp_path, capsys):
    target = tmp_path / "again.mcap"
    assert main(["log", "merge", *map(str, duo.logs.values()), "-o", str(target)]) == 0
    out, err = capsys.readouterr()
    assert out.splitlines()[0] == f"host {LEFT}: the time axis"
    assert out.splitlines()[1].startswith(f"host {RIGHT}: shifted -3") and "spread 0.0" in out
    assert "not both on the Link clock (machine)" in err  # --clock machine: said, not hidden
    assert target.read_bytes() == duo.merged.read_bytes()  # the same inputs, the same log


# -- one-robot logs, and the alignment's arithmetic -----------------------------------------------


SOLO = """
    version: 1
    name: solo
    motions:
      wave: {number: 4, duration: 0.3}
    steps:
      - play: wave
        at: 0.5
        label: wave
      - wait: done
"""


def test_one_robot_logs_become_their_hosts_robots(tmp_path):
    from choreo.clock import VirtualTime

    show = write_show(tmp_path, SOLO)
    for name, start in (("north", 1000.0), ("south", 1003.0)):
        argv = ["run", str(show), "--log", str(tmp_path / f"{name}.mcap"), "-q"]
        assert main(argv, time_source=VirtualTime(start)) == 0
    report = merge_logs([tmp_path / "north.mcap", tmp_path / "south.mcap"], tmp_path / "m.mcap")
    assert report.robots == ["north", "south"]
    log = read_log(tmp_path / "m.mcap")
    assert {"/rcb4/north/tx", "/rcb4/south/rx", "/choreo/south/step", "/choreo/north/clock"} <= set(log.messages)
    assert {m["robot"] for m in log.topic("/rcb4/south/tx")} == {"south"}
    summary = summarize(tmp_path / "m.mcap")
    assert list(summary.robots) == ["north", "south"] and summary.robots["south"].steps_run == 2


def _host(host: str, samples: list[tuple[float, int]], zero: int | None = None) -> HostLog:
    result = {RESULT_METADATA_NAME: {Result.SHOW_ZERO_WALL_NS: str(zero)}} if zero is not None else {}
    return HostLog(Path(f"{host}.mcap"), host, (host,), True, result, samples, {"link"}, None, None)


def test_the_shift_is_the_median_over_the_samples_and_its_spread_their_range():
    axis = [(s * 0.5, 1_000_000_000 + s * 500_000_000) for s in range(20)]  # show 0..9.5 s
    jitter = [0, 200_000, -100_000, 5_000_000, 0, 100_000]  # one sample 5 ms off: the median keeps it out
    other = [(s * 0.5 + 0.25, 7_000_000_000 + s * 500_000_000 + 250_000_000 - jitter[s % 6]) for s in range(12)]
    alignment = align([_host("a", axis), _host("b", other)])[1]
    assert alignment.by == "clock" and alignment.samples == 12
    assert alignment.shift_ns == -6_000_000_000 + 50_000
    assert alignment.spread_ns == 5_100_000
    assert list(offsets_to(axis, [(10.0, 0), (-1.0, 0)])) == []  # outside the axis's show times


def test_with_no_samples_in_common_the_recorded_show_starts_line_the_logs_up():
    axis = [(0.0, 1_000), (1.0, 1_000_001_000)]
    alignments = align([_host("a", axis, zero=5_000), _host("b", [(7.0, 9_000)], zero=2_000)])
    assert alignments[1] == Alignment("b", 3_000, 0, 0, "show start")


def test_a_looped_log_is_lined_up_by_its_first_pass_on_both_sides():
    """With --loop, show time starts over each pass: each log's samples are taken while their
    show time goes on (R2: pairing the second log's later passes with the first's first pass
    shifted it by -10 s with a spread of 20 s)."""
    def passes(offset_ns: int) -> list[tuple[float, int]]:
        return [(s * 0.5, offset_ns + (p * 10 + s * 0.5) * 1e9) for p in range(3) for s in range(20)]
    axis, other = passes(1_000_000_000), passes(1_007_000_000)
    alignment = align([_host("a", [(k, round(t)) for k, t in axis]), _host("b", [(k, round(t)) for k, t in other])])[1]
    assert alignment.shift_ns == -7_000_000 and alignment.spread_ns == 0


def test_on_link_the_hosts_line_up_by_the_shows_beat_and_their_clocks_drift_is_fitted():
    """Two machines' crystals drift apart (20 ppm: 72 ms an hour): equal show seconds are not one
    instant after an hour, equal beats of the session are. The shift follows the drift."""
    start_a, start_b, rate = 1_000_000_000, 5_000_000_000, 20e-6  # b's clock runs 20 ppm fast
    a = _host("a", [(k * 2.0, start_a + round(k * 2e9)) for k in range(1800)])  # an hour, a sample each 2 s
    a.beats = [(k * 4.0, start_a + round(k * 2e9), 120.0) for k in range(1800)]
    b = _host("b", [(k * 2.0 * (1 + rate), start_b + round(k * 2e9 * (1 + rate))) for k in range(1800)])
    b.beats = [(k * 4.0, start_b + round(k * 2e9 * (1 + rate)), 120.0) for k in range(1800)]
    alignment = align([a, b])[1]
    assert alignment.rate == pytest.approx(1 / (1 + rate) - 1, rel=1e-3)
    for k in (0, 900, 1799):  # the same beat lands on the same instant, all the way through
        log_time = start_b + round(k * 2e9 * (1 + rate))
        assert abs(log_time + alignment.shift_at(log_time) - (start_a + round(k * 2e9))) < 1_000
    assert alignment.spread_ns < 1_000 and "ppm" in alignment.describe()


def test_by_the_beat_only_within_one_tempo():
    """Across a tempo change the beat is no straight line in time, and two hosts sample it a few
    ms apart around the change: the pairs spanning it are left out (CI saw a 6.8 ms spread)."""
    a = _host("a", [])
    a.beats = [(0.0, 0, 120.0), (1.0, 500_000_000, 120.0), (1.5, 750_000_000, 120.0), (2.0, 1_000_000_000, 120.0),
               (3.0, 1_375_000_000, 160.0), (4.0, 1_750_000_000, 160.0)]  # 120, then 160 bpm from beat 2
    b = _host("b", [])
    b.beats = [(0.5, 250_000_000 + 7_000, 120.0), (2.5, 1_190_000_000, 160.0), (3.5, 1_562_500_000 + 7_000, 160.0),
               (3.8, 1_675_000_000 + 7_000, 160.0)]
    alignment = align([a, b])[1]
    assert alignment.samples == 2 and alignment.shift_ns == -7_000 and alignment.spread_ns == 0  # b.5: its last 120
    # the last sample before a change of tempo is left out on either side (it may read the old tempo)
    b.beats.insert(1, (1.9, 950_000_000 + 9_000_000, 120.0))  # heard late: the old tempo, 9 ms off
    assert align([a, b])[1].spread_ns == 0


# -- hostile inputs: one line, exit 2, nothing half written -------------------------------------


@pytest.fixture(scope="module")
def hosts(tmp_path_factory):
    directory = tmp_path_factory.mktemp("hostile")
    return run_hosts(directory)


def _refused(capsys, argv: list[str]) -> str:
    assert main(["log", "merge", *argv]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1, err
    return err


def test_the_same_host_twice_or_one_robot_on_two_hosts_is_refused(hosts, tmp_path, capsys):
    left = str(hosts[LEFT])
    assert "are both host stageleft" in _refused(capsys, [left, left, "-o", str(tmp_path / "m.mcap")])
    copy = tmp_path / "other.mcap"
    copy.write_bytes(hosts[LEFT].read_bytes())  # another file, the same host
    assert "both host stageleft" in _refused(capsys, [left, str(copy), "-o", str(tmp_path / "m.mcap")])
    assert os.listdir(tmp_path) == ["other.mcap"]


def test_the_logs_of_two_shows_are_refused(hosts, tmp_path, capsys):
    """Issue 21, item 6: a host's log of another show (here a one-robot show) merged without a
    word, its steps labelled by the first's show."""
    from choreo.clock import VirtualTime

    other = tmp_path / "solo.mcap"
    argv = ["run", str(write_show(tmp_path, SOLO)), "--log", str(other), "-q"]
    assert main(argv, time_source=VirtualTime(1000.0)) == 0
    err = _refused(capsys, [str(hosts[LEFT]), str(other), "-o", str(tmp_path / "m.mcap")])
    assert "of show 'duo'" in err and "of show 'solo'" in err and "merge the logs of one show" in err
    assert not (tmp_path / "m.mcap").exists()


def test_the_output_may_be_no_input_nor_in_a_missing_folder(hosts, tmp_path, capsys):
    logs = [str(path) for path in hosts.values()]
    before = hosts[RIGHT].read_bytes()
    assert "is one of the logs merged" in _refused(capsys, [*logs, "-o", logs[1]])
    assert hosts[RIGHT].read_bytes() == before
    assert "does not exist" in _refused(capsys, [*logs, "-o", str(tmp_path / "nowhere" / "m.mcap")])
    assert "not a regular file" in _refused(capsys, [*logs, "-o", str(tmp_path)])
    assert "-o '': give the path" in _refused(capsys, [*logs, "-o", ""])  # issue 21, item 6: said "-o ."
    assert "at least two" in _refused(capsys, [logs[0], "-o", str(tmp_path / "m.mcap")])
    many = [logs[0]] * (MAX_INPUTS + 1)
    assert f"at most {MAX_INPUTS}" in _refused(capsys, [*many, "-o", str(tmp_path / "m.mcap")])
    assert os.listdir(tmp_path) == []


def test_a_damaged_foreign_or_merged_log_is_refused_and_nothing_is_left(hosts, tmp_path, capsys):
    damaged = tmp_path / "damaged.mcap"
    data = bytearray(hosts[RIGHT].read_bytes())
    data[len(data) // 2] ^= 0xFF  # inside a chunk: its CRC no longer matches
    damaged.write_bytes(bytes(data))
    output = tmp_path / "m.mcap"
    assert "damaged" in _refused(capsys, [str(hosts[LEFT]), str(damaged), "-o", str(output)])
    foreign = tmp_path / "foreign.mcap"
    with open(foreign, "wb") as f:
        writer = Writer(f)
        writer.start()
        schema = writer.register_schema("x", "jsonschema", b"{}")
        writer.add_message(writer.register_channel("/camera", "json", schema), 1, b"{}", 1)
        writer.finish()
    assert "not a choreo log" in _refused(capsys, [str(hosts[LEFT]), str(foreign), "-o", str(output)])
    merge_logs(list(hosts.values()), tmp_path / "merged.mcap")
    assert "a merged log already" in _refused(capsys, [str(tmp_path / "merged.mcap"), str(foreign), "-o", str(output)])
    assert sorted(os.listdir(tmp_path)) == ["damaged.mcap", "foreign.mcap", "merged.mcap"]


def test_a_message_that_is_no_choreo_message_fails_the_merge_and_leaves_nothing(hosts, tmp_path, capsys):
    """Found on the second pass, once writing began: the half-written log is removed."""
    bad = tmp_path / "bad.mcap"
    with open(bad, "wb") as f:
        writer = Writer(f)
        writer.start(library="choreo 0.1.0")
        writer.add_metadata(METADATA_NAME, {Info.SHOW: "duo"})  # a host of the show whose message is no choreo message
        schema = writer.register_schema("choreo.Tx", "jsonschema", b"{}")
        writer.add_message(writer.register_channel("/rcb4/tx", "json", schema), 5, b'{"seq": "one"}', 5)
        writer.add_metadata(RESULT_METADATA_NAME, {Result.SHOW_ZERO_WALL_NS: str(_zero(hosts[LEFT]))})
        writer.finish()
    err = _refused(capsys, [str(hosts[LEFT]), str(bad), "-o", str(tmp_path / "m.mcap")])
    assert "is not a choreo /rcb4/tx message" in err
    assert os.listdir(tmp_path) == ["bad.mcap"]


def test_a_log_cut_short_is_merged_as_far_as_it_goes_with_a_warning(hosts, tmp_path):
    cut = tmp_path / "cut.mcap"
    data = hosts[RIGHT].read_bytes()
    cut.write_bytes(data[:len(data) // 2])  # a killed run: no footer, a chunk cut in half
    report = merge_logs([hosts[LEFT], cut], tmp_path / "m.mcap")
    assert any("its log is unfinished" in warning for warning in report.warnings)
    assert report.alignments[1].by == "clock"
    summary = summarize(tmp_path / "m.mcap")
    assert list(summary.robots) == ["lead", "follow"] and summary.complete  # the merge itself is whole
    assert 0 < summary.robots["follow"].frames_sent < summarize(hosts[RIGHT]).frames_sent


def test_the_merged_result_is_the_first_hosts_with_the_worst_outcome_and_the_steps_summed():
    from choreo.log.merge import merged_result

    first, second = _host("a", []), _host("b", [])
    first.metadata[RESULT_METADATA_NAME] = {Result.OUTCOME: "done", Result.STEPS_RUN: "4", Result.SHOW_S: "9.5"}
    second.metadata[RESULT_METADATA_NAME] = {Result.OUTCOME: "failed", Result.STEPS_RUN: "3",
                                             Result.ERROR: "port: no reply"}
    assert merged_result([first, second]) == {Result.OUTCOME: "failed", Result.STEPS_RUN: "7", Result.SHOW_S: "9.5",
                                              Result.ERROR: "host b: port: no reply"}
    del second.metadata[RESULT_METADATA_NAME]
    assert merged_result([first, second])[Result.OUTCOME] == "interrupted"
    assert merged_result([second, first]) is None  # the first host's run recorded no result


def test_a_missing_or_unreadable_input_is_one_line(hosts, tmp_path, capsys):
    output = str(tmp_path / "m.mcap")
    assert "nothing.mcap" in _refused(capsys, [str(hosts[LEFT]), str(tmp_path / "nothing.mcap"), "-o", output])
    assert "a folder" in _refused(capsys, [str(hosts[LEFT]), str(tmp_path), "-o", output])
    named = tmp_path / "two words.mcap"  # no show_host: the file's name names the host, and a topic
    with open(named, "wb") as f:
        writer = Writer(f)
        writer.start(library="choreo 0.1.0")
        writer.add_metadata(METADATA_NAME, {Info.SHOW: "x"})
        writer.finish()
    assert "cannot name a topic" in _refused(capsys, [str(hosts[LEFT]), str(named), "-o", output])
    assert os.listdir(tmp_path) == ["two words.mcap"]


def test_only_hosts_not_both_on_the_link_clock_are_warned_of():
    from choreo.log.merge import _warnings

    axis = [(0.0, 0), (1.0, 1_000_000_000)]
    logs = [_host("a", axis), _host("b", axis)]
    assert _warnings(logs, align(logs)) == []  # both on Link: show time 0 is one bar line
    logs[1].sources = {"machine"}
    assert _warnings(logs, align(logs)) == ["host b: not both on the Link clock (link/machine): show time 0 "
                                            "taken as the same instant"]


def test_a_shifted_hosts_log_lines_keep_their_own_time_with_their_log_time():
    """Foxglove's log panel shows a line's `timestamp`: it moves with the line's log time."""
    import json

    from choreo.log.format import LOG_TOPIC, LogRecord
    from choreo.log.merge import _place

    line = json.dumps(LogRecord.at(3, "late", 5_000_000_000 + 7).to_json()).encode()
    topic, data = _place(LOG_TOPIC, line, _host("b", []), -6_000_000_000)
    assert topic == "/choreo/b/log"
    assert data == line  # moved before 1970: no time, left as written
    topic, data = _place(LOG_TOPIC, line, _host("b", []), -2_000_000_000)
    assert json.loads(data)["timestamp"] == {"sec": 3, "nsec": 7}
    assert _place(LOG_TOPIC, line, _host("b", []), 0)[1] == line  # the axis's own lines: as written


def test_hosts_that_did_not_play_in_step_are_said_to_have_not():
    """R1: two hosts that started a bar apart through a tempo change merged without a word (a
    spread of 145 ms). Past 20 ms of spread, the merge says the hosts were not in step."""
    from choreo.log.merge import _warnings

    a = _host("a", [(k * 0.5, k * 500_000_000) for k in range(40)])
    b = _host("b", [(k * 0.5, k * 500_000_000 + (0 if k < 20 else 145_000_000)) for k in range(40)])
    alignments = align([a, b])
    said = _warnings([a, b], alignments)
    assert alignments[1].spread_ns == 145_000_000 and any("did not play in step" in line for line in said), said
    steady = align([a, _host("b", [(k * 0.5, k * 500_000_000 + 7_000) for k in range(40)])])
    assert not any("in step" in line for line in _warnings([a, _host("b", [])], steady))


def test_the_merged_show_lasts_as_long_as_its_longest_host_in_either_order(duo, tmp_path):
    """The docs trial: one show read 4.4 s or 9.5 s by the order the logs were given. The host
    whose show ran longest times the merged show (its clock, its time the axis) either way."""
    lengths = {}
    for host, path in duo.logs.items():
        with LogReader(path) as reader:
            list(reader.messages(()))
            lengths[host] = float(reader.result[Result.SHOW_S])
    for order in (list(duo.logs.values()), list(duo.logs.values())[::-1]):
        report = merge_logs(order, tmp_path / "m.mcap")
        first = report.hosts[0].host
        assert lengths[first] >= max(lengths.values()) - 0.5  # the longest (of as long, the first given)
        with LogReader(tmp_path / "m.mcap") as reader:
            list(reader.messages(()))
            assert float(reader.result[Result.SHOW_S]) == lengths[first] and reader.info.hosts[0] == first
    from choreo.log.merge import _longest_first

    short, long = _host("short", []), _host("long", [])
    short.metadata = {RESULT_METADATA_NAME: {Result.SHOW_S: "4.392"}}
    long.metadata = {RESULT_METADATA_NAME: {Result.SHOW_S: "9.502"}}
    assert [log.host for log in _longest_first([short, long])] == ["long", "short"]
    assert [log.host for log in _longest_first([long, short])] == ["long", "short"]
