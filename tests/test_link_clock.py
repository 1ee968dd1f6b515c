"""The Link clock for real (issue 25): choreo hosts and scripted peers (linkpeer.py) in one
Ableton Link session, each test in a loopback-only network namespace of its own (linkns.py), so
no test talks to the machine's network and the tests run in parallel. Where namespaces are
unavailable the tests fail saying so.

Every assertion reads the logs (the /choreo/clock samples carry the session: Link's time, the
show's beat, the session's beat, tempo, peers, and the event a sample marks) and the peers'
reports. Shows are short and fast (240 bpm: a bar a second). Each cue is checked where the
runner placed it (arithmetic on the session's timeline) and, unless the machine stalled that play
(see Play), where its motion started, within a tolerance a loaded two-core machine keeps
(TOLERANCE_S): a wrong tempo or a wrong bar line is off by hundreds of milliseconds; the real
skew between hosts is bench/link.py's to measure.
"""

from __future__ import annotations

import json
import os
import signal
import statistics
from dataclasses import dataclass
from pathlib import Path

import pytest

from choreo.log.merge import merge_logs
from linkns import Job, choreo_argv, ended, output_has, peer_argv, run_in_namespace
from runlog import RunLog, choreo, read_log, write_show

TOLERANCE_S = 0.015
STALL_S = 0.005  # a play late or off its lead by more than this was stalled by the machine (see Play)
MERGE_SPREAD_NS = 2_000_000  # the hosts' samples place one another this closely: arithmetic, not scheduling
BPM = 240.0
METER = 4
PHASE_BEATS = TOLERANCE_S * BPM / 60  # two views of the session's phase agree this closely

SHOW = """
version: 1
name: {name}
clock: link
tempo: {{bpm: 240, meter: 4}}
{hosts}robots:
{robots}
motions:
  home: {{number: 0, duration: 0.1}}
  wave: {{number: 4, duration: 0.15}}
on_abort: home
tracks:
{tracks}
"""


def _show(directory: Path, name: str, a: tuple[str, ...], b: tuple[str, ...] = (), hosts: str = "") -> Path:
    """A show at 240 bpm in 4 whose robot a (and b, if given cues) waves at each of the cues."""
    tracks = {robot: cues for robot, cues in (("a", a), ("b", b)) if cues}
    robots = "\n".join(f"  {robot}: {{layout: hth4-2.2}}" for robot in tracks)
    lines = "\n".join(f"  {robot}:\n" + "\n".join(f"    - play: wave\n      at: {at}" for at in cues)
                      for robot, cues in tracks.items())
    return write_show(directory, SHOW.format(name=name, hosts=hosts, robots=robots, tracks=lines))


def _run(show: Path, log: Path, *more: str, robots: str = "a") -> list[str]:
    ports = [arg for robot in robots for arg in ("--port", f"{robot}=sim://")]
    return choreo_argv("run", str(show), *ports, "--log", str(log), "--no-console", *more)


def _peer_lines(stdout: str) -> list[dict]:
    return [json.loads(line) for line in stdout.splitlines() if line.startswith("{")]


def _clock(log: RunLog) -> list[dict]:
    return log.topic("/choreo/clock")


def _start_sample(log: RunLog) -> dict:
    [start] = [sample for sample in _clock(log) if sample.get("event") == "start"]
    return start


@dataclass(frozen=True)
class Play:
    """A play as its robot's log tells it: where the runner placed its cue (show time, from
    the session's timeline as it stood), when its motion started, and whether the machine
    stalled it: the run woke late, or the frames' exchange took longer or shorter than the
    lead the runner sent them ahead by (a loaded machine's scheduler, or a lead learnt from
    an exchange it slowed; the log says both, and bench/ measures them)."""

    end: dict
    placed: float
    started: float
    stalled: bool


def _plays(log: RunLog, robot: str) -> list[Play]:
    steps = log.topic(f"/choreo/{robot}/step")
    began = {s["index"]: s for s in steps if s["event"] == "start"}
    plays = []
    for end in (s for s in steps if s["event"] == "end"):
        start = began[end["index"]]
        lead_s = end["lead_ms"] / 1e3
        exchange_s = end["start_s"] - start["actual_s"]  # from the first frame's going out to the motion
        stalled = start["late_ms"] / 1e3 > STALL_S or abs(exchange_s - lead_s) > STALL_S
        plays.append(Play(end, end["planned_s"] + lead_s, end["start_s"], stalled))
    return plays


def _lands(play: Play, due: float, context: object = None) -> bool:
    """The play's cue was placed at `due` (show time), and its motion started there unless the
    machine stalled the run on it; whether the motion was checked."""
    assert abs(play.placed - due) < TOLERANCE_S, (play, due, context)
    if not play.stalled:
        assert abs(play.started - due) < TOLERANCE_S, (play, due, context)
    return not play.stalled


def _phase_off(beat: float) -> float:
    """How far `beat` is from the nearest bar line, in beats."""
    phase = beat % METER
    return min(phase, METER - phase)


def _peer_beat(line: dict, link_us: float) -> float:
    """The peer's beat at Link time `link_us` on the timeline its report saw."""
    return line["beat"] + (link_us - line["link_us"]) * line["tempo"] / 60e6


def _ok(ended, what: str) -> None:
    assert ended.returncode == 0, f"{what} exited {ended.returncode}: {ended.stderr[-800:]}"


def _is_180(sample: dict) -> bool:
    return abs(sample.get("tempo", 0.0) - 180.0) < 0.01  # Link's tempo, a float that went through its wire


def test_two_hosts_play_in_unison_each_with_its_own_robots(tmp_path):
    """A show with hosts: run by two choreo processes (--host left, --host right), started by a
    peer's transport, through a tempo change: each log holds its host's robot only, the same
    cue's motion starts at the same instant on both, and the logs merge into one show."""
    hosts = "hosts:\n  left: [a]\n  right: [b]\n"
    cues = ("{bar: 1, beat: 2}", "{bar: 2, beat: 1}", "{bar: 3, beat: 1}", "2.75")
    show = _show(tmp_path, "duo", cues, cues, hosts)
    waiting = "waiting for the session to play"
    run = run_in_namespace(tmp_path, [
        Job("left", _run(show, tmp_path / "left.mcap", "--host", "left", robots="a")),
        Job("right", _run(show, tmp_path / "right.mcap", "--host", "right", robots="b")),
        # the peer starts the transport once both hosts wait for it and it knows them both (Link
        # tells a peer that joins later nothing of a transport already playing)
        # and 2 ms after its bar line, as an app's audio buffer may: the show is on that bar line
        Job("peer", peer_argv("--tempo", "240", "--tempo-to", "200", "--start-on-signal", "--start-with-peers", "2",
                              "--start-late-ms", "2"),
            signals=(("USR2", f"{output_has(tmp_path, 'left', waiting)} && {output_has(tmp_path, 'right', waiting)}"),
                     ("USR1", output_has(tmp_path, "left", "a: step 0 ")), ("TERM", ended(tmp_path, "left", "right")))),
    ])
    for host in ("left", "right"):
        _ok(run[host], host)
    left, right = read_log(tmp_path / "left.mcap"), read_log(tmp_path / "right.mcap")
    for log, mine, other in ((left, "a", "b"), (right, "b", "a")):
        assert log.metadata["choreo"]["robots"] == mine
        assert [t for t in log.messages if f"/{mine}/" in t] and not [t for t in log.messages if f"/{other}/" in t]
    assert abs(_start_sample(left)["link_us"] - _start_sample(right)["link_us"]) < TOLERANCE_S * 1e6
    [started] = [line for line in _peer_lines(run["peer"].stdout) if line["event"] == "started"]
    # the bar line the transport started (2 ms late) on, not the next one a bar later
    assert abs(_start_sample(left)["link_us"] + 2_000 - started["at_us"]) < TOLERANCE_S * 1e6, (started,)
    assert abs(_start_sample(left)["beat"]) < 1e-3 and abs(_start_sample(right)["beat"]) < 1e-3
    zero = {name: int(log.metadata["choreo.result"]["show_zero_monotonic_ns"]) / 1e9
            for name, log in (("left", left), ("right", right))}
    on_left, on_right = _plays(left, "a"), _plays(right, "b")
    assert len(on_left) == len(on_right) == len(cues)
    shift = zero["right"] - zero["left"]  # right's show time on left's (~0: one bar line is show time 0)
    together = 0
    for play_l, play_r in zip(on_left, on_right, strict=True):
        # one cue placed at one instant on both hosts, and its motions started together
        assert abs(play_l.placed - (play_r.placed + shift)) < TOLERANCE_S, (play_l, play_r)
        if not (play_l.stalled or play_r.stalled):
            together += 1
            assert abs(play_l.started - (play_r.started + shift)) < TOLERANCE_S, (play_l, play_r)
    # `together` may be 0 on a worker the machine stalled on every play: the placements above
    # are checked all the same (bench/link.py measures the motions' skew on a quiet machine)
    # the two hosts' logs merge into one show by their clock samples (show time lines them up),
    # and a review reads the merged log
    report = merge_logs([tmp_path / "left.mcap", tmp_path / "right.mcap"], tmp_path / "show.mcap")
    [axis, placed] = report.alignments
    # the first given is the axis: the two shows are as long (the longer would be, by more than 0.5 s)
    assert (axis.host, placed.host, placed.by) == ("left", "right", "clock"), report.alignments
    assert placed.samples >= 3 and placed.spread_ns < MERGE_SPREAD_NS, placed
    summary = choreo("log", "summary", str(tmp_path / "show.mcap"), timeout=30)
    assert summary.returncode == 0, summary.stderr


def test_choreo_starts_a_peers_transport_on_a_bar_line_of_the_session(tmp_path):
    """One host, no --wait-start, a peer there not playing: choreo starts the transport on a
    bar line; the show's beat 0 is the session's bar line, and the peer plays with it."""
    show = _show(tmp_path, "on a bar", ("{bar: 1, beat: 1}", "{bar: 2, beat: 1}"))
    run = run_in_namespace(tmp_path, [
        Job("peer", peer_argv("--tempo", "240"), signals=(("TERM", ended(tmp_path, "host")),)),
        Job("host", _run(show, tmp_path / "host.mcap"), after=output_has(tmp_path, "peer", "joined")),
    ])
    _ok(run["host"], "choreo")
    assert "starting the session's transport with 1 peer" in run["host"].stderr  # found before it started
    lines = _peer_lines(run["peer"].stdout)
    assert not [line for line in lines if line["event"] == "started"]
    # the peer follows start/stop: it saw the transport play (Link tells only the peers it knows)
    played = [line for line in lines if line["event"] == "playing"]
    assert len(played) == 1, (run["host"].stderr, run["peer"].stdout)
    playing = played[0]
    log = read_log(tmp_path / "host.mcap")
    start = _start_sample(log)
    assert start["show_s"] == 0.0 and start["beat"] == 0.0 and abs(start["tempo"] - BPM) < 0.01
    assert _phase_off(start["session_beat"]) < 1e-3, start
    # the peer's own count (a whole number of bars off choreo's) has a bar line there too
    assert _phase_off(_peer_beat(playing, start["link_us"])) < PHASE_BEATS, (playing, start)
    [first, _] = _plays(log, "a")
    _lands(first, 0.0)


def test_a_peers_tempo_change_moves_the_cues_in_bars_and_not_those_in_seconds(tmp_path):
    """A peer changes the tempo (240 -> 180 bpm) as the show's first cue plays: each cue in bars still
    to come starts where the session's new tempo puts its beat; a cue in seconds keeps its
    second; the change is a 'tempo' sample carrying the new tempo, and no jump of the beat."""
    bars = ("{bar: 1, beat: 1}", "{bar: 2, beat: 1}", "{bar: 2, beat: 3}", "{bar: 3, beat: 1}", "{bar: 3, beat: 3}")
    show = _show(tmp_path, "tempo change", bars, ("0.5", "2.25"))
    run = run_in_namespace(tmp_path, [
        Job("peer", peer_argv("--tempo", "240", "--tempo-to", "180"),
            signals=(("USR1", output_has(tmp_path, "host", "a: step 0 ")), ("TERM", ended(tmp_path, "host")))),
        Job("host", _run(show, tmp_path / "host.mcap", robots="ab"), after=output_has(tmp_path, "peer", "joined")),
    ])
    _ok(run["host"], "choreo")
    [tempo_set] = [line for line in _peer_lines(run["peer"].stdout) if line["event"] == "tempo_set"]
    log = read_log(tmp_path / "host.mcap")
    samples = _clock(log)
    assert [s for s in samples if s.get("event") == "tempo" and _is_180(s)], samples
    assert not [s for s in samples if s.get("event") == "jump"], samples  # a tempo change keeps the beat going
    # Link's beat after the change, as the host sampled it (periodic samples), and as the peer has it
    after = [s for s in samples if s.get("event") is None and _is_180(s)]
    assert after, samples
    for sample in after:
        assert _phase_off(_peer_beat(tempo_set, sample["link_us"]) - sample["session_beat"]) < PHASE_BEATS
    changed_s = min(s["show_s"] for s in samples if _is_180(s))
    checked = []
    motions = 0
    for play in _plays(log, "a")[1:]:
        beat = play.end["cue"] * BPM / 60.0  # the plan's cue is at its beat on the show's written tempo
        # where the session's timeline after the change puts that beat (each sample's say; their middle)
        due = statistics.median(s["show_s"] + (beat - s["beat"]) * 60.0 / s["tempo"] for s in after)
        if due > changed_s + 0.1:
            checked.append(due - play.end["cue"])
            motions += _lands(play, due, after)
    # `motions` may be 0 on a worker stalled on every play: the placements are checked all the same
    assert len(checked) >= 2 and max(checked) > 0.2, (changed_s, motions, log.topic("/choreo/a/step"))
    seconds = _plays(log, "b")
    assert len(seconds) == 2
    _lands(seconds[1], 2.25)


def test_a_peer_leaving_mid_show_is_a_peers_sample_and_the_show_goes_on(tmp_path):
    """The peer leaves as the show's second cue plays: a 'peers' sample says so (none left),
    and the show plays on to its end."""
    show = _show(tmp_path, "leaving", ("{bar: 1, beat: 1}", "{bar: 2, beat: 1}", "{bar: 3, beat: 1}"))
    run = run_in_namespace(tmp_path, [
        Job("peer", peer_argv("--tempo", "240"), signals=(("TERM", output_has(tmp_path, "host", "a: step 1 ")),)),
        Job("host", _run(show, tmp_path / "host.mcap"), after=output_has(tmp_path, "peer", "joined")),
    ])
    _ok(run["host"], "choreo")
    assert "Link peers: 1 -> 0" in run["host"].stderr
    log = read_log(tmp_path / "host.mcap")
    assert [s for s in _clock(log) if s.get("event") == "peers" and s["show_s"] > 0 and s["peers"] == 0], _clock(log)
    assert log.metadata["choreo.result"]["outcome"] == "done"
    plays = _plays(log, "a")
    assert len(plays) == 3
    _lands(plays[2], 2.0)  # bar 3 where the session has it


def test_alone_a_show_starts_as_the_sessions_first_peer_and_says_so(tmp_path):
    show = _show(tmp_path, "alone", ("{bar: 1, beat: 1}", "{bar: 1, beat: 3}"))
    run = run_in_namespace(tmp_path, [Job("host", _run(show, tmp_path / "host.mcap"))])
    _ok(run["host"], "choreo")
    said = [line for line in run["host"].stderr.splitlines() if "alone, as the session's first peer" in line]
    assert len(said) == 1, run["host"].stderr
    log = read_log(tmp_path / "host.mcap")
    assert _start_sample(log)["peers"] == 0 and log.metadata["choreo.result"]["outcome"] == "done"


def _waits_alone_then(tmp_path: Path, sig: signal.Signals) -> None:
    """A show for several hosts with no peer at all waits, says so once, and a signal stops it
    cleanly (exit 130, as for any interrupted run), never a hang."""
    show = _show(tmp_path, "waits", ("{bar: 1, beat: 1}",), ("{bar: 1, beat: 1}",),
                 "hosts:\n  left: [a]\n  right: [b]\n")
    waiting = "waiting for the session to play"
    run = run_in_namespace(tmp_path, [
        Job("host", _run(show, tmp_path / "host.mcap", "--host", "left"),
            signals=((sig.name[3:], output_has(tmp_path, "host", waiting)),)),
    ], timeout=20)
    ended = run["host"]
    assert ended.returncode == 130, ended.stderr
    assert len([line for line in ended.stderr.splitlines() if waiting in line]) == 1, ended.stderr
    assert "Traceback" not in ended.stderr
    assert read_log(tmp_path / "host.mcap").metadata["choreo.result"]["outcome"] == "aborted"


def test_a_show_for_hosts_alone_waits_and_sigterm_stops_it(tmp_path):
    _waits_alone_then(tmp_path, signal.SIGTERM)


def test_a_show_for_hosts_alone_waits_and_ctrl_c_stops_it(tmp_path):
    _waits_alone_then(tmp_path, signal.SIGINT)


# -- where namespaces are unavailable, the tests fail (never skip) ----------------------------

def test_without_namespaces_a_link_test_fails_saying_why(tmp_path, monkeypatch):
    """A machine where unshare is refused (user namespaces off, a container without the
    capability): the Link test fails with a line saying namespaces are needed."""
    bin_dir = tmp_path / "bin"
    bin_dir.mkdir()
    for tool, script in (("unshare", "echo 'unshare: unshare failed: Operation not permitted' >&2; exit 1"),
                         ("ip", "exit 0")):
        (bin_dir / tool).write_text(f"#!/bin/sh\n{script}\n")
        (bin_dir / tool).chmod(0o755)
    monkeypatch.setenv("PATH", f"{bin_dir}{os.pathsep}{os.environ['PATH']}")
    with pytest.raises(pytest.fail.Exception, match="need a network namespace .*Operation not permitted"):
        run_in_namespace(tmp_path, [Job("peer", peer_argv())], timeout=10)
    monkeypatch.setenv("PATH", str(tmp_path / "nowhere"))
    with pytest.raises(pytest.fail.Exception, match="need network namespaces: unshare is not installed"):
        run_in_namespace(tmp_path, [Job("peer", peer_argv())], timeout=10)
