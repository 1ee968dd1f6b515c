"""Benchmark 11, GO over OSC: from an OSC GO sent on this machine to the first frame of the cue
it releases, on the wire.

A show of GO cues (`at: go`, a play each) runs against `choreo sim` on a pseudo-terminal with
the log on, as on stage, controlled as `choreo run --osc` controls it: a `Live` and choreo's
`OscServer`. Once the show waits at a cue, a python-osc client sends `/choreo/go` (built
beforehand); the figure is the moment the released play's first frame is handed to the port's
write call, minus the moment just before the client's send. It covers the datagram (or TCP
segment) through the kernel, the server's thread, the `Live`'s answer and its listeners (the
log among them), the runner's wake-up and the step's start. The time the reply takes back to
the client is reported beside it; it does not hold the show (the runner goes on meanwhile).

The first GO of a run is a warm-up (first-use code paths) and is not counted; the double-press
lockout is off (GOs come as fast as the show reaches its cues; the lockout only refuses).

Goal (issue 14): under 5 ms, median and p99.
"""

from __future__ import annotations

import sys
import threading
import time
from dataclasses import dataclass, field

from pythonosc.osc_message_builder import build_msg
from pythonosc.tcp_client import SimpleTCPClient
from pythonosc.udp_client import SimpleUDPClient

from common import Capture, median, percentile, pty_sim, row, run_session_into, temp_dir, write_show

from choreo.live.controls import Live
from choreo.live.limits import Limits, Rate
from choreo.live.osc import OscServer
from choreo.events import StopRequest
from choreo.run.session import Session
from choreo.run.settings import RunRequest

GOAL_MS = 5.0
FULL, QUICK = 30, 10  # GOs counted a transport
TIMEOUT_S = 10.0
# A GO each time the show reaches a cue is faster than any operator, and than the limits on one
# sender's commands and replies allow (they bound floods): lifted here, as they do not change how
# fast a GO that is taken goes.
NO_LIMITS = Limits(commands_per_sender=Rate(10_000, 10_000.0), commands_total=Rate(10_000, 10_000.0),
                   replies_per_sender=Rate(10_000, 10_000.0))
POLL_S = 0.0005  # how often the client looks (the figure comes from timestamps, not from this)


def go_show(cues: int) -> str:
    steps = "\n".join(f"  - play: {1 + i % 3}\n    at: go" for i in range(cues))
    return f"version: 1\nname: bench-go\nsteps:\n{steps}\n"


@dataclass
class Timings:
    """Per GO, ms after the send: the first frame written, the reply received."""

    frame_ms: list[float] = field(default_factory=list)
    reply_ms: list[float] = field(default_factory=list)


def _until(predicate, what: str) -> None:  # type: ignore[no-untyped-def]
    deadline = time.monotonic() + TIMEOUT_S
    while not predicate():
        if time.monotonic() > deadline:
            raise RuntimeError(f"timed out waiting for {what}")
        time.sleep(POLL_S)


def one_go(live: Live, client, capture: Capture, timings: Timings | None) -> None:  # type: ignore[no-untyped-def]
    """Wait for the show to reach its next cue, send GO, time the first frame and the reply."""
    _until(lambda: live.waiting, "the show to reach a GO cue")
    message = build_msg("/choreo/go", [])
    before = len(capture.writes)
    sent = time.monotonic_ns()
    client.send(message)
    reply = next(client.get_messages(TIMEOUT_S), None)
    replied = time.monotonic_ns()
    if reply is None or '"status": "ok"' not in reply.params[0]:
        raise RuntimeError(f"GO not taken: {reply.params if reply else 'no reply'}")
    _until(lambda: len(capture.writes) > before, "the cue's first frame")
    if timings is not None:
        timings.frame_ms.append((capture.writes[before] - sent) / 1e6)
        timings.reply_ms.append((replied - sent) / 1e6)


def measure(transport: str, gos: int) -> Timings:
    """One run of `gos` + 1 GO cues over `transport` (udp | tcp), the first a warm-up."""
    timings = Timings()
    with temp_dir() as tmp, pty_sim("--motion-s", "0.05") as device:
        show = write_show(tmp, go_show(gos + 1))
        session = Session.prepare(RunRequest(str(show), port=device, log_path=str(tmp / "go.mcap")))
        live = Live(StopRequest(), lockout_s=0.0)
        server = OscServer(live, 0, limits=NO_LIMITS)
        capture = Capture()
        with session:
            capture.watch_writes(session.stage.links["robot"].port)
            server.start()
            live.subscribe(server)
            errors: list[BaseException] = []
            runner = threading.Thread(target=run_session_into, args=(session, [server], live, errors), daemon=True)
            runner.start()
            try:
                with _client(transport, server.port) as client:
                    for i in range(gos + 1):
                        one_go(live, client, capture, timings if i else None)
            finally:
                live.stop.request("benchmark over")
                runner.join(TIMEOUT_S)
                server.close()
            if errors:
                raise errors[0]
    return timings



def _client(transport: str, port: int):  # type: ignore[no-untyped-def]
    return SimpleUDPClient("127.0.0.1", port) if transport == "udp" else SimpleTCPClient("127.0.0.1", port)


def run(quick: bool = False) -> list[dict]:
    gos = QUICK if quick else FULL
    rows = []
    for transport, name in (("udp", "UDP"), ("tcp", "TCP/SLIP")):
        timings = measure(transport, gos)
        p50, p99 = median(timings.frame_ms), percentile(timings.frame_ms, 99)
        rows.append(row(f"GO over OSC ({name}, localhost) -> the cue's first frame written: median / p99 "
                        f"({gos} GOs, log on, pty)", f"{p50:.3f} / {p99:.3f}", "ms", f"< {GOAL_MS:g}",
                        p50 < GOAL_MS and p99 < GOAL_MS))
        rows.append(row(f"GO over OSC ({name}) -> its reply received: median / p99",
                        f"{median(timings.reply_ms):.3f} / {percentile(timings.reply_ms, 99):.3f}", "ms", None, None))
    return rows


if __name__ == "__main__":
    from run import print_table

    sys.exit(print_table(run(quick="--quick" in sys.argv)))
