"""Test helpers for `choreo log merge`: the logs of a show's two hosts, made on virtual time.

One show with `hosts:` run twice with `--host`, each run driving one robot on `sim://`, as two
choreo processes would on the night. Each run has its own VirtualTime started at another wall
time (37.25 s and the real time between the runs apart), so the merge has a shift to find; on
`--clock machine` (virtual time cannot keep Link's) show time 0 stands for the same instant on
both, as the Link clock's shared bar line makes it.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

from runlog import write_show

DUO = """
    version: 1
    name: duo
    clock: link
    tempo: {bpm: 120, meter: 4}
    hosts:
      stageleft: [lead]
      stageright: [follow]
    robots:
      lead: {layout: hth4-2.2}
      follow: {layout: hth4-2.2}
    motions:
      bow: {number: 1, duration: 1.0}
      wave: {number: 4, duration: 0.5}
    on_abort: bow
    steps:
      - play: bow
        label: bow
      - wait: done
      - play: wave
        at: 2
        label: wave
      - wait: done
      - play: bow
        at: 3.5
        label: again
      - wait: done
"""
HOSTS = (("stageleft", 1000.0), ("stageright", 1037.25))  # host, its virtual monotonic start (s)


@dataclass(frozen=True)
class HostLogs:
    show: Path
    logs: dict[str, Path]  # host -> its log, in HOSTS' order
    merged: Path
    report: object  # choreo.log.merge.MergeReport


def run_hosts(directory: Path, body: str = DUO, hosts: tuple[tuple[str, float], ...] = HOSTS) -> dict[str, Path]:
    """Each host's run of the show on its own virtual time; host -> log."""
    from choreo.cli import main
    from choreo.clock import VirtualTime

    show = write_show(directory, body, "duo.yaml")
    logs = {}
    for host, start_s in hosts:
        log = directory / f"{host}.mcap"
        argv = ["run", str(show), "--host", host, "--clock", "machine", "--log", str(log), "-q"]
        assert main(argv, time_source=VirtualTime(start_s)) == 0
        logs[host] = log
    return logs


def merged_hosts(directory: Path) -> HostLogs:
    """Both hosts' logs and their merge."""
    from choreo.log.merge import merge_logs

    logs = run_hosts(directory)
    merged = directory / "show.mcap"
    report = merge_logs(list(logs.values()), merged)
    return HostLogs(directory / "duo.yaml", logs, merged, report)
