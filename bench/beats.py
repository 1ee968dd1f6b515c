"""Benchmark 13, beat finding (issue 23): `choreo beats`' analysis on a generated set of songs with
known beats, scored by choreo/music/scoring.py against the issue's goals.

The songs are bench/songs.py's (every case twice; `--quick`: every case once), made from a seed
(`--seed N`, default 0: another seed is another set). Each is analysed in memory as `choreo beats
SONG --meter M` analyses a file: `features_of` on the samples at 22050 Hz, then
`choreo.music.beats.estimate` with the song's meter (a user gives `--meter`; 6/8 counts 2 dotted
quarters a bar). The table gives, per song, the true and the found tempo, the level found, bar 1,
the beat F-measure (+-70 ms), the downbeat F-measure and the seconds the analysis took; then the
totals against the goals: the right tempo level and bar 1 for >= 97.5 % of songs, F median >= 0.99
and mean >= 0.97, and <= 1 s a minute of audio (the median song's). Peak memory is traced
(tracemalloc) over one more analysis of the longest song, apart from the timed runs, which it
would slow. The full run (not `--quick`) also writes an hour of audio (the set's songs end to end,
16-bit WAV) to a temporary folder and analyses that file as `choreo beats` does, streamed from
disk: `read_features` then `estimate`, timed, then again under tracemalloc: <= 30 s and <= 400 MB.

    python bench/beats.py [--quick] [--seed N]    # the per-song table, then the totals
"""

from __future__ import annotations

import contextlib
import statistics
from collections import Counter
from collections.abc import Callable
import sys
import tempfile
import time
import tracemalloc
import wave
from dataclasses import dataclass
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parent.parent
for path in (ROOT, ROOT / "bench"):
    if str(path) not in sys.path:
        sys.path.insert(0, str(path))

from common import row  # noqa: E402
from songs import CASES, SET_SIZE, Song, generate_set  # noqa: E402

from choreo.errors import UsageError  # noqa: E402
from choreo.music import beats  # noqa: E402
from choreo.music.features import features_of, read_features  # noqa: E402
from choreo.music.scoring import (  # noqa: E402
    GOAL_BAR_ONE_SHARE,
    GOAL_F_MEAN,
    GOAL_F_MEDIAN,
    GOAL_LEVEL_SHARE,
    GOAL_S_PER_MINUTE,
    SetScore,
    SongScore,
    score_set,
    score_song,
)

QUICK_SIZE = len(CASES)  # every case once
HOUR_S = 3600  # the full run also analyses an hour of audio, against the goals for an hour:
GOAL_HOUR_S = 30.0
GOAL_MEMORY_MB = 400.0


@dataclass(frozen=True)
class Result:
    song: Song
    score: SongScore
    found_bpm: float | None
    seconds: float
    error: str | None = None  # what `choreo beats` said when it found no beat


def analyse(song: Song) -> tuple[beats.BeatEstimate | None, str | None]:
    """The estimate `choreo beats --meter M` would print for the song, or its one-line refusal."""
    try:
        return beats.estimate(features_of([song.samples], song.sample_rate, song.name), meter=song.meter), None
    except UsageError as exc:
        return None, str(exc)


def score(song: Song, find: Callable[[Song], tuple[beats.BeatEstimate | None, str | None]] = analyse) -> Result:
    """The song's figures against its truth, found by `find` (in memory by default; the held-out
    set reads a file)."""
    began = time.perf_counter()
    found, error = find(song)
    seconds = time.perf_counter() - began
    times = [b.time_s for b in found.beats] if found else []
    downbeats = [b.time_s for b in found.beats if b.beat == 1] if found else []
    scored = score_song(song.beats, song.downbeats, song.median_bpm, times, downbeats, found.bpm if found else None)
    return Result(song, scored, found.bpm if found else None, seconds, error)


def peak_memory_mb(analysis: Callable[[], object]) -> float:
    """An analysis's peak of traced allocations (numpy's arrays included), in MB."""
    tracemalloc.start()
    try:
        analysis()
        return tracemalloc.get_traced_memory()[1] / 1e6
    finally:
        tracemalloc.stop()


def table(results: list[Result]) -> list[str]:
    lines = [f"{'song':24} {'true bpm':>8} {'found':>7} {'level':>6} {'bar 1':>5} {'F':>5} {'beat F':>6} "
             f"{'seconds':>7}"]
    for r in results:
        found = "-" if r.found_bpm is None else f"{r.found_bpm:.2f}"
        lines.append(f"{r.song.name:24} {r.song.median_bpm:8.2f} {found:>7} {r.score.tempo.level:>6} "
                     f"{'right' if r.score.bar_one_right else 'WRONG':>5} {r.score.beats.f:5.3f} "
                     f"{r.score.downbeats.f:6.3f} {r.seconds:7.3f}" + (f"  ({r.error})" if r.error else ""))
    levels = Counter(r.score.tempo.level for r in results)
    lines.append("levels found: " + ", ".join(f"{level} {n}" for level, n in levels.most_common()))
    return lines


def rows(results: list[Result], totals: SetScore, memory_mb: float) -> list[dict]:
    n = totals.songs
    per_minute = statistics.median(r.seconds / (r.song.duration_s / 60) for r in results)
    goals = totals.meets_goals()
    audio_min = sum(r.song.duration_s for r in results) / 60
    return [
        row(f"beats: right tempo level ({n} songs)", round(100 * totals.level_share, 1), "%",
            f">= {100 * GOAL_LEVEL_SHARE:g}", goals["tempo level"]),
        row("beats: bar 1 within 70 ms", round(100 * totals.bar_one_share, 1), "%",
            f">= {100 * GOAL_BAR_ONE_SHARE:g}", goals["bar 1"]),
        row("beats: F-measure (+-70 ms), median", round(totals.f_median, 3), "", f">= {GOAL_F_MEDIAN:g}",
            goals["F median"]),
        row("beats: F-measure (+-70 ms), mean", round(totals.f_mean, 3), "", f">= {GOAL_F_MEAN:g}", goals["F mean"]),
        row("beats: downbeat F-measure, mean", round(totals.downbeat_f_mean, 3), "", None, None),
        row(f"beats: analysis time a minute of audio, median song ({audio_min:.1f} min in all)",
            round(per_minute, 3), "s", f"<= {GOAL_S_PER_MINUTE:g}", per_minute <= GOAL_S_PER_MINUTE),
        row(f"beats: peak traced memory, longest song ({max(r.song.duration_s for r in results):.0f} s)",
            round(memory_mb, 1), "MB", None, None),
    ]


def hour_rows(songs: list[Song]) -> list[dict]:
    """An hour of audio (the set's songs end to end, over and over) written to a 16-bit WAV file,
    then read and analysed as `choreo beats` does: decoding, features and estimate, timed, then
    again under tracemalloc for the peak memory of the whole."""
    rate = songs[0].sample_rate
    with tempfile.TemporaryDirectory() as folder:
        path = Path(folder) / "hour.wav"
        _write_hour(path, songs, rate)
        began = time.perf_counter()
        analyse_file(path)
        seconds = time.perf_counter() - began
        memory_mb = peak_memory_mb(lambda: analyse_file(path))
    return [
        row("beats: an hour of audio from a WAV file, analysis time", round(seconds, 1), "s",
            f"<= {GOAL_HOUR_S:g}", seconds <= GOAL_HOUR_S),
        row("beats: an hour of audio from a WAV file, peak traced memory", round(memory_mb), "MB",
            f"<= {GOAL_MEMORY_MB:g}", memory_mb <= GOAL_MEMORY_MB),
    ]


def _write_hour(path: Path, songs: list[Song], rate: int) -> None:
    """HOUR_S seconds of the songs, one after another and again, as 16-bit mono PCM."""
    with wave.open(str(path), "wb") as out:
        out.setnchannels(1)
        out.setsampwidth(2)
        out.setframerate(rate)
        written = 0
        while written < HOUR_S * rate:
            for song in songs:
                part = song.samples[: HOUR_S * rate - written]
                out.writeframes((np.clip(part, -1.0, 1.0) * 32767).astype("<i2").tobytes())
                written += len(part)


def analyse_file(path: Path) -> None:
    with contextlib.suppress(UsageError):  # the time and memory count, not the beat
        beats.estimate(read_features(path))


def measure(quick: bool = False, seed: int = 0) -> tuple[list[Result], list[dict]]:
    """The per-song results and the table's rows (the full run adds an hour of audio)."""
    songs = generate_set(seed, QUICK_SIZE if quick else SET_SIZE)
    beats.estimate(features_of([songs[0].samples[: 10 * songs[0].sample_rate]]))  # first-call costs
    results = [score(song) for song in songs]
    longest = max(songs, key=lambda s: s.duration_s)
    memory_mb = peak_memory_mb(lambda: analyse(longest))
    table_rows = rows(results, score_set([r.score for r in results]), memory_mb)
    return results, table_rows if quick else table_rows + hour_rows(songs)


def run(quick: bool = False) -> list[dict]:
    return measure(quick)[1]


if __name__ == "__main__":
    from run import print_table

    seed = int(sys.argv[sys.argv.index("--seed") + 1]) if "--seed" in sys.argv else 0
    results, summary = measure(quick="--quick" in sys.argv, seed=seed)
    print("\n".join(table(results)))
    print()
    sys.exit(print_table(summary))
