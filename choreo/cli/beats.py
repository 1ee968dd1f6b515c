"""`choreo beats SONG`: the tempo and first downbeat of a song, as a `tempo:` block for a show.

numpy and miniaudio are imported in the handler: `choreo --help` must not pay for them, and
without the `music` extra only this command fails, with the line that installs it.
"""

from __future__ import annotations

import argparse
import json
import math
from typing import TYPE_CHECKING

from choreo.errors import UsageError, one_line

if TYPE_CHECKING:  # numpy and miniaudio load only when a song is read
    from choreo.music.beats import Beat, BeatEstimate

MUSIC_EXTRA = "choreo beats needs the music extra: pip install 'choreo[music]'"


def register(subparsers: argparse._SubParsersAction) -> None:
    parser = subparsers.add_parser(
        "beats",
        help="estimate a song's tempo and first downbeat, as a `tempo:` block for a show",
        description="Estimate a song's tempo (bpm) and its first downbeat (bar 1 beat 1, seconds "
        "from the start), and print them as a `tempo:` block to paste into a show file, after a "
        "comment that says how many beats an onset confirmed. An estimate: check it by ear "
        "(`--beats` lists every beat to check against). Reads wav, mp3, flac and ogg.",
    )
    parser.add_argument("song", metavar="SONG", help="the song: a wav, mp3, flac or ogg file")
    parser.add_argument("--meter", type=int, default=4, metavar="N",
                        help="beats a bar, 1..16 (default 4): the downbeat is sought among N places")
    parser.add_argument("--bpm-range", metavar="LO..HI", default=None,
                        help="the tempi to consider (default 40..240); narrow it when the estimate "
                        "is half or double the song's tempo, e.g. 100..180")
    parser.add_argument("--beats", action="store_true",
                        help="also print every beat from bar 1 on: its time, bar and beat, and how "
                        "far the onset heard there lies from it")
    parser.add_argument("--json", action="store_true",
                        help="one JSON object on stdout: the tempo, the figures behind it and every beat")
    parser.set_defaults(handler=run)


def run(args: argparse.Namespace) -> int:
    try:
        from choreo.music import beats
    except ModuleNotFoundError as exc:
        if exc.name not in ("numpy", "miniaudio"):
            raise
        raise UsageError(MUSIC_EXTRA) from None
    bpm_range = parse_bpm_range(args.bpm_range, beats.BPM_LIMITS) if args.bpm_range else beats.BPM_RANGE
    lo, hi = beats.METER_LIMITS
    if not lo <= args.meter <= hi:
        raise UsageError(f"choreo beats: --meter {args.meter}: give {lo}..{hi} beats a bar")
    song = beats.read_song(args.song)
    found = beats.estimate(song, meter=args.meter, bpm_range=bpm_range)
    if args.json:
        print(json.dumps(json_record(song.path, found), ensure_ascii=False))
        return 0
    for line in text_lines(song.path, found, with_beats=args.beats):
        print(one_line(line))  # a song named with a line break must not add a line to the YAML
    return 0


def parse_bpm_range(text: str, limits: tuple[float, float]) -> tuple[float, float]:
    """`100..180` as (100.0, 180.0); anything else is a usage error that shows the form."""
    lo, sep, hi = text.partition("..")
    try:
        bounds = (float(lo), float(hi)) if sep else None
    except ValueError:
        bounds = None
    if bounds is None or not limits[0] <= bounds[0] < bounds[1] <= limits[1]:  # NaN fails too
        raise UsageError(f"choreo beats: --bpm-range {text}: give LO..HI in bpm, "
                         f"{limits[0]:g} <= LO < HI <= {limits[1]:g} (e.g. 100..180)")
    return bounds


def tempo_line(found: BeatEstimate) -> str:
    """The block as YAML, figures in full (`:g` would cut an offset past 1000 s to 0.01 s)."""
    return f"tempo: {{bpm: {found.bpm!r}, offset: {found.offset!r}, meter: {found.meter}}}"


def summary_lines(path: str, found: BeatEstimate) -> list[str]:
    """What the block rests on, as YAML comments, so that they may be pasted along with it."""
    from choreo.music.beats import ON_BEAT_S

    lines = [f"# {path} ({found.duration_s:.1f} s): {found.bpm:g} bpm; {found.confirmed} of {len(found.beats)} "
             f"beats from bar 1 on have an onset within {1000 * ON_BEAT_S:.0f} ms of the grid "
             f"(rms {found.timing_rms_ms:.1f} ms)"]
    if found.downbeat_contrast is not None:
        by = "bass onsets" if found.downbeat_by == "bass" else "onsets"
        if math.isfinite(found.downbeat_contrast):
            stands = f"{found.downbeat_contrast:.2f}x as strong as beat {found.other_beat}'s"
        else:
            stands = f"the only ones heard, beat {found.other_beat} next"
        lines.append(f"# bar 1 beat 1 at {found.offset:.3f} s: its {by} {stands}, the next likeliest "
                     f"downbeat (that would be offset: {found.other_offset!r})")
    lines.append("# an estimate: check it by ear (`--beats` lists every beat)")
    return lines


def beat_line(beat: Beat) -> str:
    """`  12.480 s  bar 7 beat 1  onset +0.4 ms` (or `no onset`)."""
    if beat.onset_s is None:
        return f"{beat.time_s:9.3f} s  bar {beat.bar} beat {beat.beat}  no onset"
    early_or_late = round(1000.0 * (beat.onset_s - beat.time_s), 1) + 0.0  # never -0.0
    return f"{beat.time_s:9.3f} s  bar {beat.bar} beat {beat.beat}  onset {early_or_late:+.1f} ms"


def text_lines(path: str, found: BeatEstimate, *, with_beats: bool) -> list[str]:
    lines = [*summary_lines(path, found), tempo_line(found)]
    if with_beats:
        lines.extend(beat_line(beat) for beat in found.beats)
    return lines


def json_record(path: str, found: BeatEstimate) -> dict:
    downbeat = None
    if found.downbeat_contrast is not None:
        contrast = found.downbeat_contrast
        downbeat = {"by": found.downbeat_by, "contrast": contrast if math.isfinite(contrast) else None,
                    "next_beat": found.other_beat, "next_offset": found.other_offset}
    return {
        "song": path,
        "duration_s": found.duration_s,
        "tempo": {"bpm": found.bpm, "offset": found.offset, "meter": found.meter},
        "beats_on_onset": found.confirmed,
        "timing_rms_ms": found.timing_rms_ms,
        "downbeat": downbeat,
        "beats": [{"time_s": b.time_s, "bar": b.bar, "beat": b.beat, "onset_s": b.onset_s} for b in found.beats],
    }
