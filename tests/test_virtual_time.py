"""The run's clock (issue 11, item 6): the runner, the link and the in-process simulator read
one time source, so a show can run on virtual time: exactly, and without waiting."""

from __future__ import annotations

import time

import pytest

from choreo.clock import RunClock, SystemTime, VirtualTime
from choreo.errors import LinkError
from choreo.board.link import Link
from choreo.run.settings import RunRequest
from runlog import prepare, read_log, write_show

SHOW = """
    version: 1
    name: timed
    motions:
      wave: {number: 3, duration: 0.4}
    steps:
      - play: wave
      - wait: done
      - play: 4
        at: 1.5
      - wait: 0.25
      - play: 5
"""


def run_virtual(tmp_path, name: str):
    log_path = tmp_path / f"{name}.mcap"
    session = prepare(RunRequest(str(write_show(tmp_path, SHOW, f"{name}.yaml")), log_path=str(log_path)))
    with session:
        result = session.run()
    return result, read_log(log_path)


def test_virtual_time_passes_only_when_slept_or_spun():
    clock = VirtualTime(start_s=5.0)
    assert clock.now() == clock.now() == 5.0
    clock.sleep(0.25)
    clock.spin()
    assert clock.now_ns() == 5_250_000_000 + VirtualTime.SPIN_NS
    clock.sleep(1e-12)  # less than a nanosecond still moves time: a wait always ends
    assert clock.now_ns() == 5_250_000_000 + VirtualTime.SPIN_NS + 1
    clock.sleep(-1)
    assert clock.now_ns() == 5_250_000_000 + VirtualTime.SPIN_NS + 1


def test_a_run_clock_on_virtual_time_sleeps_until_its_deadline_exactly():
    clock = RunClock(VirtualTime())
    deadline = clock.mono() + 2.0
    assert clock.sleep_until(deadline)
    assert 0 <= clock.mono() - deadline < 1e-5  # the last 2 ms spun, a microsecond a turn
    assert clock.wall_ns() - clock.wall_anchor_ns == clock.mono_ns() - clock.mono_anchor_ns


def test_a_show_on_virtual_time_takes_no_real_time_and_keeps_its_schedule(tmp_path):
    wall = time.monotonic()
    result, log = run_virtual(tmp_path, "one")
    assert time.monotonic() - wall < 10  # about 1.9 s of show; no sleep is real
    assert result.outcome == "done" and result.late_steps == 0
    starts = {m["index"]: m for m in log.steps if m["event"] == "start"}
    ends = {m["index"]: m for m in log.steps if m["event"] == "end"}
    # the play goes out early by its lead, so that the frame that starts the motion is on the cue
    assert starts[2]["actual_s"] == pytest.approx(1.5 - ends[2]["lead_ms"] / 1e3, abs=1e-4)
    assert ends[2]["start_s"] == pytest.approx(1.5, abs=1e-4)  # the motion starts on the cue
    assert starts[4]["actual_s"] == pytest.approx(1.75, abs=1e-4)  # absolute: the wait ends on time
    assert result.show_s > 1.75


def test_two_runs_on_virtual_time_are_the_same_to_the_nanosecond(tmp_path):
    _, first = run_virtual(tmp_path, "first")
    _, second = run_virtual(tmp_path, "second")

    def timing(log):
        zero = log.tx[0]["_log_time"]
        return [(m["seq"], m["kind"], m["_log_time"] - zero) for m in log.tx]

    assert timing(first) == timing(second)
    assert [m["latency_ms"] for m in first.rx] == [m["latency_ms"] for m in second.rx]


def test_only_the_in_process_simulator_runs_on_virtual_time(tmp_path):
    with pytest.raises(LinkError, match=r"only the in-process simulator \(sim://\) runs on virtual time"):
        Link.open("loop://", clock=RunClock(VirtualTime()))
    Link.open("loop://", clock=RunClock(SystemTime())).close()  # the machine's time: any port
