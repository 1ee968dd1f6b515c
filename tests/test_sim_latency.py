"""The simulator's FTDI latency timer (`sim://?latency_ms=16`, `choreo sim --latency-ms 16`):
reply bytes reach the client at the timer's next tick, or at once when 62 are waiting."""

from __future__ import annotations

import pytest

from choreo.sim.options import parse_query
from choreo.sim.line import FTDI_PACKET, LatencyTimer
from runlog import read_log, vmain


def test_bytes_wait_for_the_next_tick_of_a_free_running_timer():
    timer = LatencyTimer(0.016, origin=0.0)
    out = timer.release([(0.0101, 5), (0.0102, 6), (0.0103, 7)])
    assert out == [(0.016, 5), (0.016, 6), (0.016, 7)]
    assert timer.release([(0.032, 1)]) == [(0.032, 1)]  # on a tick: out at once
    # a reply straddling a tick: what arrived before it goes then, the rest at the next one
    assert timer.release([(0.047, 1), (0.049, 2)]) == [(0.048, 1), (0.064, 2)]


def test_sixty_two_waiting_bytes_go_without_waiting_for_the_timer():
    timer = LatencyTimer(0.016, origin=0.0)
    burst = [(0.001 + i * 1e-5, i % 256) for i in range(FTDI_PACKET + 3)]
    out = timer.release(burst)
    assert [at for at, _ in out[:FTDI_PACKET]] == [burst[FTDI_PACKET - 1][0]] * FTDI_PACKET
    assert [at for at, _ in out[FTDI_PACKET:]] == [0.016] * 3
    assert [byte for _, byte in out] == [byte for _, byte in burst]


@pytest.mark.parametrize("text, ok", [("0", True), ("1", True), ("16", True), ("255", True),
                                      ("0.5", False), ("256", False), ("-1", False)])
def test_the_timer_takes_what_an_ftdi_chip_takes(text, ok):
    if ok:
        assert parse_query(f"latency_ms={text}").latency_s == float(text) / 1000
    else:
        with pytest.raises(ValueError, match="1..255 ms"):
            parse_query(f"latency_ms={text}")
    assert "USB latency timer 16 ms" in parse_query("latency_ms=16").describe()


@pytest.mark.parametrize("latency_ms", [1, 16])
def test_replies_through_the_timer_arrive_on_its_ticks(tmp_path, latency_ms):
    log = tmp_path / "run.mcap"
    show = tmp_path / "show.yaml"
    show.write_text("version: 1\nsteps:\n  - play: 1\n  - wait: done\n")
    assert vmain(["run", str(show), "--port", f"sim://?latency_ms={latency_ms}", "--log", str(log), "-q"]) == 0
    latencies = [m["latency_ms"] for m in read_log(log).rx]
    assert max(latencies) <= latency_ms + 2.5 and max(latencies) > 1.0  # the wire, then up to a tick
    if latency_ms == 16:
        assert sum(lat > 5 for lat in latencies) > len(latencies) / 2  # most replies wait for the timer
