"""Benchmark 15, Link across hosts: two choreo hosts on one Ableton Link session, in unison.

One show with `clock: link` and `hosts:` (robot `a` on host `left`, `b` on host `right`, the
same track each: a play on beats 1 and 3 of every bar) runs as two `choreo run --host`
processes, each with its own simulated board (`sim://`), for 2 minutes (--quick: 30 s). A
scripted Link peer (this file run with `--peer`, an aalink peer as Live would be) starts the
session's transport once both hosts wait for it, changes the tempo from 120 to 140 bpm halfway
through (between two cues), and leaves when the hosts are done. Everything runs in a loopback-only
network namespace (`unshare -rn`, `lo` up, a multicast route on it): the benchmark never talks to
the machine's network; without namespaces it fails, saying so.

Measured from the two logs, on the machine's monotonic clock (common to both processes): a
motion starts when the frame that starts it was written (a play's end record, `start_s`, on the
show clock; show time 0 is `show_zero_monotonic_ns` of the log's `choreo.result`).

- skew: per cue, host `left`'s motion start minus host `right`'s. Goal (issue 25): p99 <= 2 ms.
- cue error against the host's Link timeline: each cue's motion start minus the instant its bar
  and beat fall on the session's beat timeline as the host's `/choreo/clock` samples carry it
  (monotonic_ns, beat, tempo: the last sample before the motion start, or the first after it
  if the tempo changed in between).
- cue error against the peer's Link timeline: the same, with the beat timeline the scripted
  peer read from its own aalink every 5 ms (Link's clock paired with the monotonic one by a read
  on each side): what a Live on this machine would call the beat, independent of choreo's own
  reading of the session.

The full run plays the show twice: as `choreo run` runs by default (time-shared with whatever
else the machine runs), and with the hosts at real-time priority (`chrt -f 20`, as audio software
runs; where this machine allows it). Beside the figures, what the error is made of: where each
host's samples put a cue's beat against where the peer's Link did (the hosts' reading of the
session), and for each cue skewed by more than 1 ms, for the host further from the beat: whether
its step woke late (the scheduler: a busy machine), or the play's frames before its start frame
took longer than the lead they were given (the exchange with the board, here the in-process
simulator, slowed down the same way), or shorter (the lead, a running estimate, still raised by
an earlier slow play: the start early).
"""

from __future__ import annotations

import asyncio
import json
import math
import os
import shutil
import subprocess
import sys
import time
from dataclasses import dataclass
from datetime import timedelta
from pathlib import Path

from common import ROOT, env, median, percentile, row, temp_dir, write_show

from choreo.log.format import Result
from choreo.log.reader import open_log

GOAL_P99_MS = 2.0
FULL_S, QUICK_S = 120.0, 30.0  # the show's length, about
BPM, NEW_BPM, METER = 120.0, 140.0, 4
MOTION_S = 0.3
HOSTS = {"left": "a", "right": "b"}
PEER_SAMPLE_S = 0.005
READY_TIMEOUT_S = 30.0  # both hosts wait for the session's start within this
REALTIME = ["chrt", "-f", "20"]  # SCHED_FIFO, as audio software runs: no time-shared process preempts the hosts
NAMESPACE = "ip link set lo up && ip route add 224.0.0.0/4 dev lo && exec \"$@\""


@dataclass(frozen=True)
class Plan:
    """The show's cues as show beats (0: bar 1 beat 1) and the beat the peer changes the tempo on."""

    beats: list[int]
    change_beat: int
    seconds: float


def plan(seconds: float) -> Plan:
    """Cues on beats 1 and 3 of every bar for `seconds`: half at BPM, half at NEW_BPM; the tempo
    change on an odd show beat, halfway between two cues."""
    half_beats = seconds / 2 * BPM / 60
    change = 2 * round(half_beats / 2) + 1
    total = half_beats + seconds / 2 * NEW_BPM / 60
    return Plan(list(range(0, math.ceil(total), 2)), change, seconds)


def show_yaml(beats: list[int]) -> str:
    track = "".join(f"    - play: m{1 + i % 3}\n      at: {{bar: {1 + b // METER}, beat: {1 + b % METER}}}\n"
                    for i, b in enumerate(beats))
    motions = "".join(f"  m{n}: {{number: {n}, duration: {MOTION_S}}}\n" for n in (1, 2, 3))
    hosts = "".join(f"  {host}: [{robot}]\n" for host, robot in HOSTS.items())
    robots = "".join(f"  {robot}: {{layout: hth4-2.2}}\n" for robot in HOSTS.values())
    tracks = "".join(f"  {robot}:\n{track}" for robot in HOSTS.values())
    return (f"version: 1\nname: bench-link\nclock: link\ntempo: {{bpm: {BPM:g}, meter: {METER}}}\n"
            f"hosts:\n{hosts}robots:\n{robots}motions:\n  home: {{number: 0, duration: {MOTION_S}}}\n{motions}"
            f"on_abort: home\ntracks:\n{tracks}")


# -- inside the namespace: the two hosts and the scripted peer ----------------------------------


def inside(directory: Path, seconds: float) -> int:
    """Run the hosts and the peer (this process is in the namespace); 0 when both hosts were done."""
    show = plan(seconds)
    hosts = {}
    for host, robot in HOSTS.items():
        out = (directory / f"{host}.out").open("w")
        hosts[host] = subprocess.Popen(
            [sys.executable, "-m", "choreo", "run", str(directory / "show.yaml"), "--host", host, "--port",
             f"{robot}=sim://", "--log", str(directory / f"{host}.mcap"), "--no-console"],
            stdout=out, stderr=subprocess.STDOUT, cwd=ROOT, env=env())
    try:
        _await_waiting(directory, hosts)
        samples, start_beat = asyncio.run(_peer(show, hosts))
        (directory / "peer.json").write_text(json.dumps({"start_beat": start_beat, "samples": samples}))
        codes = {host: proc.wait(timeout=30) for host, proc in hosts.items()}
    finally:
        for proc in hosts.values():
            if proc.poll() is None:
                proc.kill()
    return 0 if all(code == 0 for code in codes.values()) else 1


def _await_waiting(directory: Path, hosts: dict[str, subprocess.Popen]) -> None:
    deadline = time.monotonic() + READY_TIMEOUT_S
    while True:
        waiting = [h for h in hosts if "waiting for the session to play" in (directory / f"{h}.out").read_text()]
        if len(waiting) == len(hosts):
            return
        gone = [h for h, proc in hosts.items() if proc.poll() is not None]
        if gone or time.monotonic() > deadline:
            raise RuntimeError(f"host {(gone or ['?'])[0]} never waited for the session")
        time.sleep(0.05)


async def _peer(show: Plan, hosts: dict[str, subprocess.Popen]) -> tuple[list[list[float]], float]:
    """Start the transport two bars ahead once both hosts are peers, change the tempo on the
    show's change beat, sample the timeline until the hosts are done; the samples
    [monotonic_ns, link_us, beat, tempo] and the peer's beat that is show beat 0."""
    from aalink import Link

    link = Link(BPM)
    link.quantum = METER
    link.start_stop_sync_enabled = True
    link.enabled = True
    try:
        deadline = time.monotonic() + 10
        while link.num_peers < len(hosts):
            if time.monotonic() > deadline:
                raise RuntimeError(f"the peer sees {link.num_peers} Link peers, not {len(hosts)}")
            await asyncio.sleep(0.05)
        beat = link.beat
        start = (math.floor(beat / METER) + 2) * METER
        at = link.time + timedelta(seconds=(start - beat) * 60 / link.tempo)
        link.set_is_playing_and_request_beat_at_time(True, at, start)
        # With peers in the session, Link maps the requested beat to the next bar line strictly
        # after `at` (this peer's count moves a bar), while the transport starts at `at`: show
        # beat 0 is this peer's beat at `at` now, the bar line the transport started on.
        start = round((link.beat + (at - link.time) / timedelta(seconds=1) * link.tempo / 60) / METER) * METER
        samples: list[list[float]] = []
        changed = False
        ends = time.monotonic() + show.seconds * 1.5 + 30
        while any(proc.poll() is None for proc in hosts.values()) and time.monotonic() < ends:
            samples.append(_sample(link))
            if not changed and samples[-1][2] >= start + show.change_beat:
                link.tempo = NEW_BPM
                changed = True
            await asyncio.sleep(PEER_SAMPLE_S)
        return samples, float(start)
    finally:
        link.enabled = False


def _sample(link) -> list[float]:  # type: ignore[no-untyped-def]
    """Link's clock between two monotonic reads, and the beat then."""
    m1 = time.monotonic_ns()
    t1 = link.time / timedelta(microseconds=1)
    m2 = time.monotonic_ns()
    beat = link.beat
    t2 = link.time / timedelta(microseconds=1)
    mono = (m1 + m2) / 2 + (t2 - t1) * 500  # the beat was read between t1 and t2: their middle
    return [mono, (t1 + t2) / 2, beat, link.tempo]


# -- outside: start the namespace, read the logs ------------------------------------------------


def check_namespace() -> None:
    """Fail saying why when this machine cannot give a loopback-only network namespace."""
    if shutil.which("unshare") is None or shutil.which("ip") is None:
        raise RuntimeError("needs `unshare` and `ip` (util-linux, iproute2) for a loopback-only network namespace")
    probe = subprocess.run(["unshare", "-rn", "sh", "-c", NAMESPACE, "sh", "true"], capture_output=True, text=True)
    if probe.returncode != 0:
        raise RuntimeError(f"no loopback-only network namespace here (unshare -rn): {probe.stderr.strip()[:200]}")
    try:
        import aalink  # noqa: F401 - the hosts need it: fail here with the hint, not in each host
    except ImportError:
        raise RuntimeError("needs the aalink package: pip install 'choreo[link]'") from None


def realtime_refused() -> str | None:
    """Why the hosts cannot run at real-time priority here (None: they can)."""
    if shutil.which("chrt") is None:
        return "no chrt (util-linux)"
    probe = subprocess.run([*REALTIME, "true"], capture_output=True, text=True)
    return None if probe.returncode == 0 else "chrt -f needs CAP_SYS_NICE or an rtprio limit"


def play(directory: Path, seconds: float, realtime: bool = False) -> None:
    write_show(directory, show_yaml(plan(seconds).beats))
    command = [*(REALTIME if realtime else []), "unshare", "-rn", "sh", "-c", NAMESPACE, "sh", sys.executable,
               str(Path(__file__).resolve()), "--inside", str(directory), str(seconds)]
    done = subprocess.run(command, capture_output=True, text=True, timeout=seconds * 1.5 + 120)
    if done.returncode != 0:
        outs = " | ".join((directory / f"{h}.out").read_text().strip().splitlines()[-1:][0]
                          for h in HOSTS if (directory / f"{h}.out").exists()
                          and (directory / f"{h}.out").read_text().strip())
        raise RuntimeError(f"the hosts' run failed: {done.stderr.strip()[-300:]} {outs}")


@dataclass(frozen=True)
class HostLog:
    """One host's run, by the cue's place in the track: each motion start (monotonic ns), how
    late its step woke, how much longer than their lead the frames before the start frame took
    (ms); and the clock samples."""

    starts: dict[int, int]
    woke_late_ms: dict[int, float]
    exchange_over_ms: dict[int, float]
    samples: list[tuple[int, float, float]]  # monotonic_ns, show beat, tempo


def read_host(path: Path) -> HostLog:
    log = HostLog({}, {}, {}, [])
    with open_log(path) as reader:
        messages = reader.messages(["/choreo/step", "/choreo/clock"])
        records = [(topic, json.loads(bytes(data))) for topic, _, data in messages]
        result = reader.result
    if result is None:
        raise RuntimeError(f"{path.name}: the run did not close its log")
    zero = int(result[Result.SHOW_ZERO_MONOTONIC_NS])
    began: dict[int, float] = {}
    for topic, record in records:
        if topic == "/choreo/clock":
            if record.get("beat") is not None:
                log.samples.append((record["monotonic_ns"], record["beat"], record["tempo"]))
            continue
        cue = int(record["path"].rpartition("[")[2].rstrip("]"))
        if record["event"] == "start":
            began[cue] = record["actual_s"]
            log.woke_late_ms[cue] = record["late_ms"]
        elif record["event"] == "end" and record.get("start_s") is not None and cue in began:
            log.starts[cue] = zero + round(record["start_s"] * 1e9)
            log.exchange_over_ms[cue] = (record["start_s"] - began[cue]) * 1e3 - (record.get("lead_ms") or 0.0)
    return log


def mono_of_beat(samples: list[tuple[int, float, float]], beat: float, near_ns: int) -> float:
    """Monotonic ns at which `beat` falls on the timeline of the last sample before `near_ns`,
    or of the first after it if the tempo changed in between (the timeline then in force)."""
    before = [s for s in samples if s[0] <= near_ns]
    after = [s for s in samples if s[0] > near_ns]
    pick = before[-1] if before else after[0]
    if before and after and after[0][2] != pick[2]:
        pick = after[0]
    return pick[0] + (beat - pick[1]) * 60e9 / pick[2]


def measure(seconds: float, realtime: bool = False) -> dict[str, list[float]]:
    """Play the show once; skews, cue errors, and what made each skew over 1 ms, ms."""
    show = plan(seconds)
    with temp_dir() as tmp:
        play(tmp, seconds, realtime)
        logs = {host: read_host(tmp / f"{host}.mcap") for host in HOSTS}
        peer = json.loads((tmp / "peer.json").read_text())
    cues = sorted(set(logs["left"].starts) & set(logs["right"].starts))
    if len(cues) != len(show.beats):
        raise RuntimeError(f"{len(cues)} of {len(show.beats)} cues ran on both hosts")
    peer_samples = [(round(m), b - peer["start_beat"], t) for m, _, b, t in peer["samples"]]
    figures: dict[str, list[float]] = {"own": [], "peer": [], "views": [], "causes": [0, 0, 0]}
    errors: dict[str, dict[int, float]] = {}
    for host, log in logs.items():
        errors[host] = {}
        for cue in cues:
            start = log.starts[cue]
            own = start - mono_of_beat(log.samples, show.beats[cue], start)
            errors[host][cue] = (start - mono_of_beat(peer_samples, show.beats[cue], start)) / 1e6
            figures["own"].append(own / 1e6)
            figures["peer"].append(errors[host][cue])
            figures["views"].append(errors[host][cue] - own / 1e6)
    figures["skew"] = [(logs["left"].starts[cue] - logs["right"].starts[cue]) / 1e6 for cue in cues]
    for cue, skew in zip(cues, figures["skew"], strict=True):
        if abs(skew) > 1.0:
            off = max(HOSTS, key=lambda host: abs(errors[host][cue]))  # the host further from the beat
            woke, exchange = logs[off].woke_late_ms[cue], logs[off].exchange_over_ms[cue]
            figures["causes"][0 if woke >= abs(exchange) else 1 if exchange > 0 else 2] += 1
    return figures


def _spread(values: list[float]) -> str:
    sizes = [abs(v) for v in values]
    return f"{median(sizes):.3f} / {percentile(sizes, 99):.3f} / {max(sizes):.3f}"


def rows(figures: dict[str, list[float]], seconds: float, how: str) -> list[dict]:
    skews = [abs(v) for v in figures["skew"]]
    p99 = percentile(skews, 99)
    what = f"{len(skews)} cues, {seconds:g} s, {BPM:g} -> {NEW_BPM:g} bpm halfway, {how}"
    woke, slow, early = figures["causes"]
    return [
        row(f"Link, 2 hosts: motion-start skew between hosts, p50 / p99 / max of its size ({what})",
            _spread(figures["skew"]), "ms", f"p99 <= {GOAL_P99_MS:g}", p99 <= GOAL_P99_MS),
        row("  cues skewed over 1 ms: the host further from the beat woke late / its frames before the start "
            "frame ran over their lead / under it (early)", f"{woke} / {slow} / {early}", "cues", None, None),
        row("  cue error against the host's Link timeline (its /choreo/clock), p50 / p99 / max of its size",
            _spread(figures["own"]), "ms", None, None),
        row("  cue error against the scripted peer's Link timeline, p50 / p99 / max of its size; mean (late +)",
            f"{_spread(figures['peer'])}; {sum(figures['peer']) / len(figures['peer']):+.3f}", "ms", None, None),
        row("  where a host's samples put a cue's beat against where the peer's Link did, p50 / p99 / max",
            _spread(figures["views"]), "ms", None, None),
    ]


def run(quick: bool = False) -> list[dict]:
    check_namespace()
    seconds = QUICK_S if quick else FULL_S
    figures = measure(seconds)
    result = rows(figures, seconds, f"as run, load average {os.getloadavg()[0]:.1f} after")
    if quick:
        return result
    refused = realtime_refused()
    if refused is not None:
        return [*result, row(f"Link, 2 hosts at real-time priority: not measured ({refused})", None, "", None, None)]
    figures = measure(seconds, realtime=True)
    return [*result, *rows(figures, seconds, f"hosts at {' '.join(REALTIME)}, load average "
                                             f"{os.getloadavg()[0]:.1f} after")]


def main(argv: list[str]) -> int:
    if argv[:1] == ["--inside"]:
        return inside(Path(argv[1]), float(argv[2]))
    from run import print_table

    return print_table(run(quick="--quick" in argv))


if __name__ == "__main__":
    os.environ.setdefault("PYTHONUNBUFFERED", "1")
    sys.exit(main(sys.argv[1:]))
