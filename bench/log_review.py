"""Benchmark: `choreo log summary` against bare iteration with the mcap library's reader.

PRODUCT.md asks that `choreo log summary` read a 1,000,000-message log at least as fast as
bare iteration with the mcap reader (`make_reader(f).iter_messages()`, which decodes nothing),
in bounded memory (under 200 MB). This script writes such a log with choreo's own Recorder (the
same writer settings as `choreo run`), from a realistic run: play sequences (stop, play, restore),
`wait: done` status polls every 50 ms, cue waits, the odd retry and warning. Then it times both
readers in the same process (best of a few runs each) and measures the summary's peak memory in
a fresh subprocess (its VmHWM), so the figure is the whole program's, not one allocation's.

`run(quick=False)` returns rows for bench/run.py; `python bench/log_review.py [--quick]` prints them.
"""

from __future__ import annotations

import argparse
import os
import subprocess
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
if str(ROOT) not in sys.path:
    sys.path.insert(0, str(ROOT))

FULL_MESSAGES = 1_000_000
QUICK_MESSAGES = 100_000
GOAL_RATIO = 1.0
GOAL_PEAK_MB = 200.0
SHOW = b"""version: 1
name: bench
motions:
  wave: {number: 3, duration: 1.0}
  bow: {number: 7, duration: 0.8}
steps:
  - repeat: 1000
    steps:
      - play: wave
      - wait: done
      - play: bow
      - wait: done
      - wait: 0.25
"""


def generate_log(path: Path, messages: int) -> int:
    """Write a realistic run log of at least `messages` messages with choreo's Recorder.

    Returns the number of messages written. Times advance as on a real run (frames a millisecond
    apart, polls 50 ms apart), so durations and latencies in the summary look like a show's.
    """
    from choreo.events import RunResult, RxEvent, StepEvent, Tag, TxEvent
    from choreo.log.format import WARNING, result_metadata
    from choreo.log.recorder import Recorder, RunInfo
    from choreo.wire import protocol
    from choreo.show.model import PlannedStep, StepKind

    start_ns = 1_790_000_000_000_000_000
    info = RunInfo("bench.yaml", "bench", SHOW, "sim://", 115200, start_ns)
    status = protocol.status_frame()
    executing = protocol.Reply(protocol.ReplyKind.STATUS, protocol.ram_reply(bytes((0x23, 0x87))),
                               executing=True, status=0x8723)
    idle = protocol.Reply(protocol.ReplyKind.STATUS, protocol.ram_reply(bytes((0x21, 0x87))),
                          executing=False, status=0x8721)
    ack_mov = protocol.Reply(protocol.ReplyKind.ACK, protocol.ack(protocol.CMD_MOV))
    ack_call = protocol.Reply(protocol.ReplyKind.ACK, protocol.ack(protocol.CMD_CALL))
    nak_mov = protocol.Reply(protocol.ReplyKind.NAK, protocol.nak(protocol.CMD_MOV),
                             error="the board refused the frame (NAK)")
    recorder = Recorder(path, info)
    t = [start_ns + 50_000_000]  # show clock zero 50 ms after the anchor
    seq = [0]
    zero = t[0]

    def frame(frame_: protocol.Frame, reply: protocol.Reply, tag: Tag, attempt: int = 1) -> None:
        seq[0] += 1
        recorder.on_tx(TxEvent(seq[0], frame_, attempt, t[0], tag))
        latency = 0.0009 + (seq[0] % 7) * 0.00003
        t[0] += int(latency * 1e9)
        recorder.on_rx(RxEvent(seq[0], frame_, reply, t[0], latency, tag))
        t[0] += 100_000

    def step(planned: PlannedStep, body) -> None:
        due = (t[0] - zero) / 1e9
        late = (seq[0] % 13) * 0.00004
        t[0] += int(late * 1e9)
        show_s = (t[0] - zero) / 1e9
        recorder.on_step(StepEvent(planned, "start", due, show_s, t[0], late * 1e3))
        body(Tag(planned.index, planned.label))
        recorder.on_step(StepEvent(planned, "end", due, (t[0] - zero) / 1e9, t[0], 0.0, "ok"))

    index = 0
    cycle = 0
    while recorder.messages < messages:
        for motion, polls in ((3, 20), (7, 16)):
            play = PlannedStep(index, f"steps[0]#{cycle}.steps[0]", StepKind.PLAY, motion=motion,
                               label="chorus" if index % 50 == 0 else None)
            index += 1

            def play_body(tag: Tag, motion: int = motion) -> None:
                stop, call, restore = protocol.play_sequence(motion)
                if seq[0] % 97 == 0:  # the odd NAK, retried from the stop frame
                    frame(stop, nak_mov, tag)
                    recorder.on_log(WARNING, f"{tag}: NAK to 'stop'", t[0])
                    attempt = 2
                else:
                    attempt = 1
                frame(stop, ack_mov, tag, attempt)
                frame(call, ack_call, tag, attempt)
                frame(restore, ack_mov, tag, attempt)

            step(play, play_body)
            done = PlannedStep(index, f"steps[0]#{cycle}.steps[1]", StepKind.WAIT_DONE, motion=motion,
                               seconds=60.0)
            index += 1

            def done_body(tag: Tag, polls: int = polls) -> None:
                for poll in range(polls):
                    t[0] += 48_000_000
                    frame(status, executing if poll < polls - 1 else idle, tag)

            step(done, done_body)
        wait = PlannedStep(index, f"steps[0]#{cycle}.steps[4]", StepKind.WAIT, seconds=0.25)
        index += 1
        step(wait, lambda tag: t.__setitem__(0, t[0] + 250_000_000))
        cycle += 1
    recorder.close(result_metadata(RunResult("done", index, 0, (t[0] - zero) / 1e9)))
    return recorder.messages


def time_mcap(path: Path) -> tuple[float, int]:
    """Seconds for bare iteration with the mcap library's default reader, and the count."""
    from mcap.reader import make_reader

    started = time.perf_counter()
    count = 0
    with open(path, "rb") as f:
        for _ in make_reader(f).iter_messages():
            count += 1
    return time.perf_counter() - started, count


def time_summary(path: Path) -> tuple[float, int]:
    """Seconds for `choreo log summary`'s library function (read and summarise, no printing)."""
    from choreo.review.summary import summarize

    started = time.perf_counter()
    summary = summarize(path)
    return time.perf_counter() - started, summary.messages


def peak_summary_mb(path: Path) -> float:
    """Peak resident memory (MB) of a fresh process that summarises the log."""
    # VmHWM, the peak of this process image: Linux carries ru_maxrss across exec, so a child
    # forked from a large benchmark process would report its parent's size.
    code = (
        "import sys\n"
        "from choreo.review.summary import summarize\n"
        "summarize(sys.argv[1])\n"
        "print(next(l.split()[1] for l in open('/proc/self/status') if l.startswith('VmHWM:')))\n"
    )
    done = subprocess.run([sys.executable, "-c", code, str(path)], capture_output=True, text=True,
                          cwd=ROOT, check=True, env={**os.environ, "PYTHONPATH": str(ROOT)})
    kib = int(done.stdout.split()[-1])  # kB
    return kib / 1024


def run(quick: bool = False) -> list[dict]:
    """Generate the log, time both readers (best of N), measure peak memory; rows for bench/run.py."""
    messages = QUICK_MESSAGES if quick else FULL_MESSAGES
    repeats = 2 if quick else 3
    with tempfile.TemporaryDirectory(prefix="choreo-bench-") as tmp:
        path = Path(tmp) / "bench.mcap"
        written = generate_log(path, messages)
        size_mb = path.stat().st_size / 1e6
        mcap_s = min(time_mcap(path)[0] for _ in range(repeats))
        ours = [time_summary(path) for _ in range(repeats)]
        ours_s = min(s for s, _ in ours)
        counted = ours[0][1]
        if counted != written:
            raise RuntimeError(f"summary counted {counted} messages, the log has {written}")
        peak = peak_summary_mb(path)
    ratio = mcap_s / ours_s
    label = f"{written:,} messages, {size_mb:.0f} MB"
    return [
        {"name": f"log summary: mcap make_reader iter_messages ({label})", "value": round(mcap_s, 3),
         "unit": "s", "goal": None, "ok": None},
        {"name": f"log summary: choreo summarize ({label})", "value": round(ours_s, 3),
         "unit": "s", "goal": None, "ok": None},
        {"name": "log summary: speed ratio (mcap time / choreo time)", "value": round(ratio, 2),
         "unit": "x", "goal": f">= {GOAL_RATIO}", "ok": ratio >= GOAL_RATIO},
        {"name": f"log summary: peak memory (whole process, {label})", "value": round(peak, 1),
         "unit": "MB", "goal": f"< {GOAL_PEAK_MB:g}", "ok": peak < GOAL_PEAK_MB},
    ]


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--quick", action="store_true", help=f"{QUICK_MESSAGES:,} messages instead of "
                        f"{FULL_MESSAGES:,}")
    args = parser.parse_args(argv)
    rows = run(quick=args.quick)
    for row in rows:
        goal = f"  (goal {row['goal']})" if row["goal"] else ""
        mark = "    " if row["ok"] is None else "ok  " if row["ok"] else "FAIL"
        print(f"{mark} {row['name']}: {row['value']} {row['unit']}{goal}")
    return 0 if all(row["ok"] is not False for row in rows) else 1


if __name__ == "__main__":
    sys.exit(main())
