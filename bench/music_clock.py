"""Benchmark 10, the music's clock: a show locked to a 5-minute song on miniaudio's null output.

The null output plays in real time on the machine's own clock, so here the music's clock and
the machine's should agree: what this measures is choreo's reading of the playback position
(the earliest of the device's requests over 2 s, less the buffer's latency), over a whole song.
The figures are the log's /choreo/clock samples (show time against the monotonic clock, every
half second): how far the music's clock ended from the machine's, and its largest deviation
from it along the way. On a real sound card the first figure is the card's drift, which is the
point of the music's clock; the second stays the estimate's own noise.

The same run plays a cued motion every 2 s against `choreo sim` on a pseudo-terminal: its start
frame against its cue, on the music's clock (goal as for benchmark 9: p99 within 1 ms).
"""

from __future__ import annotations

import array
import wave
from pathlib import Path

from common import median, percentile, pty_sim, row, temp_dir, write_show

from choreo.log.format import CLOCK_TOPIC, parse
from choreo.log.reader import LogReader
from choreo.events import StopRequest
from choreo.run.session import Session
from choreo.run.settings import RunRequest

FULL_S, QUICK_S = 300.0, 8.0  # the song's length
RATE = 22050
CUE_EVERY_S, QUICK_CUE_EVERY_S = 2.0, 0.5  # --quick: a shorter song, cued as often, so p99 still has ~20 plays
GOAL_MS = 1.0


def write_song(path: Path, seconds: float) -> Path:
    """A silent mono WAV (the null output plays silence as well as music)."""
    with wave.open(str(path), "wb") as out:
        out.setnchannels(1)
        out.setsampwidth(2)
        out.setframerate(RATE)
        out.writeframes(array.array("h", bytes(2 * int(seconds * RATE))).tobytes())
    return path


def music_show(seconds: float, every_s: float = CUE_EVERY_S) -> str:
    cues = [1.0 + i * every_s for i in range(int((seconds - 2.0) / every_s))]
    steps = "\n".join(f"  - play: {1 + i % 3}\n    at: {at:g}" for i, at in enumerate(cues))
    return f"version: 1\nname: bench-music\nmusic: {{file: song.wav}}\nsteps:\n{steps}\n"


class StartsVsCues:
    """Each cued play's start frame written minus its cue (ms)."""

    def __init__(self) -> None:
        self.errors: list[float] = []

    def on_step(self, event) -> None:  # type: ignore[no-untyped-def]
        if event.event == "end" and event.start_s is not None and event.step.at is not None:
            self.errors.append((event.start_s - event.step.at) * 1e3)

    def on_log(self, *args) -> None:  # type: ignore[no-untyped-def]
        pass


def clock_deviations(log: Path) -> list[float]:
    """Each /choreo/clock sample's show time minus the machine's elapsed time since the first
    sample (ms)."""
    with LogReader(log) as reader:
        samples = [parse(topic, data) for topic, _, data in reader.messages((CLOCK_TOPIC,))]
    first = samples[0]
    return [((s.show_s - first.show_s) - (s.monotonic_ns - first.monotonic_ns) / 1e9) * 1e3 for s in samples]


def run(quick: bool = False) -> list[dict]:
    seconds = QUICK_S if quick else FULL_S
    starts = StartsVsCues()
    with temp_dir() as tmp, pty_sim("--motion-s", "0.05") as device:
        write_song(tmp / "song.wav", seconds)
        show = write_show(tmp, music_show(seconds, QUICK_CUE_EVERY_S if quick else CUE_EVERY_S))
        log = tmp / "music.mcap"
        session = Session.prepare(RunRequest(str(show), port=device, log_path=str(log), audio_device="null"))
        with session:
            session.run([starts], StopRequest())
        deviations = clock_deviations(log)
    errors = starts.errors[1:]  # the first play teaches the lead
    sizes = [abs(e) for e in errors]
    song = f"{seconds / 60:g}-min song, null output"
    return [
        row(f"music clock - machine clock at the song's end ({song})", round(deviations[-1], 3), "ms",
            f"< {GOAL_MS:g}", abs(deviations[-1]) < GOAL_MS),
        row(f"music clock - machine clock, largest of {len(deviations)} samples", round(max(deviations, key=abs), 3),
            "ms", f"< {GOAL_MS:g}", max(map(abs, deviations)) < GOAL_MS),
        row(f"motion start vs cue on the music clock, median ({len(errors)} cued plays, pty)",
            round(median(errors), 3), "ms", None, None),
        row("motion start vs cue on the music clock, p99 of |error|", round(percentile(sizes, 99), 3), "ms",
            f"< {GOAL_MS:g}", percentile(sizes, 99) < GOAL_MS),
    ]


if __name__ == "__main__":
    import sys

    from run import print_table

    sys.exit(print_table(run(quick="--quick" in sys.argv)))
