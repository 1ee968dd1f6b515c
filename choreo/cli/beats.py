"""`choreo beats SONG`: the tempo and first downbeat of a song, as a `tempo:` block for a show;
with `--click` the song with a click on every beat, with `--png` a picture of what was found.

numpy and miniaudio are imported in the handler (matplotlib only for `--png`): `choreo --help`
must not pay for them, and without the `music` extra only this command fails, with the line that
installs it.

Output files are checked before the song is read (a path that cannot be written is one line at
once, not after a long decode), written to a temporary file beside them and renamed into place
only when whole: a full disk, a damaged song or Ctrl-C leaves what was there before, never a
half-written file that looks whole. The song itself is never an output: writing it would
destroy it.
"""

from __future__ import annotations

import argparse
import json
import math
import os
import stat
import sys
from collections.abc import Iterator
from contextlib import ExitStack, closing, contextmanager
from pathlib import Path
from typing import TYPE_CHECKING, BinaryIO

from choreo.cli.terminal import print_fitted
from choreo.errors import UsageError, one_line
from choreo.textfit import visible
from choreo.userfile import same_file, write_why, written_whole

if TYPE_CHECKING:  # numpy and miniaudio load only when a song is read
    from choreo.music.beats import Beat, BeatEstimate
    from choreo.music.features import Features

MUSIC_EXTRA = "choreo beats needs the music extra: pip install 'choreo[music]'"
CLICK_FORMAT = "16-bit PCM WAV, 44100 Hz stereo"  # choreo.music.click.CLICK_RATE, CLICK_CHANNELS
MAP_WIDTH = 100  # columns a tempo map's lines are wrapped at


def register(subparsers: argparse._SubParsersAction) -> None:
    parser = subparsers.add_parser(
        "beats",
        help="estimate a song's tempo and first downbeat, as a `tempo:` block for a show",
        description="Estimate a song's tempo (bpm) and its first downbeat (bar 1 beat 1, seconds "
        "from the start), and print them as a `tempo:` block to paste into a show file, after a "
        "comment that says how many beats an onset confirmed. When one tempo does not fit the song "
        "(a live recording that drifts, a ritardando, a tempo change), the block is a tempo map: "
        "the time of every bar's beat 1. An estimate: check it by ear (`--click`) and by eye "
        "(`--png`). Reads wav, mp3, flac and ogg.",
    )
    parser.add_argument("song", metavar="SONG", help="the song: a wav, mp3, flac or ogg file")
    parser.add_argument("--meter", type=int, default=4, metavar="N",
                        help="beats a bar, 1..16 (default 4): the downbeat is sought among N places")
    parser.add_argument("--bpm-range", metavar="LO..HI", default=None,
                        help="the tempi to consider (default 40..240); narrow it when the estimate "
                        "is half or double the song's tempo, e.g. 100..180")
    parser.add_argument("--beats", action="store_true",
                        help="also print every beat from bar 1 on: its time (on the tempo map, if "
                        "there is one), bar and beat, and how far the onset heard there lies from it")
    parser.add_argument("--json", action="store_true",
                        help="one JSON object on stdout: the tempo, the figures behind it, every beat "
                        "and the tempo beat by beat")
    parser.add_argument("--click", metavar="OUT.wav", default=None,
                        help=f"also write the song with a click on every beat from bar 1, higher and "
                        f"louder on each bar's beat 1, to OUT.wav ({CLICK_FORMAT}, whatever the song's "
                        "format); an existing file is replaced only once the new one is whole")
    parser.add_argument("--png", metavar="OUT.png", default=None,
                        help="also draw the onset strength with the beats, the downbeats (with bar "
                        "numbers) and the tempo curve to OUT.png (needs matplotlib: "
                        "pip install 'choreo[plot]')")
    parser.set_defaults(handler=run)


def run(args: argparse.Namespace) -> int:
    try:
        from choreo.music import beats
        from choreo.music.features import read_features
    except ModuleNotFoundError as exc:
        if exc.name not in ("numpy", "miniaudio"):
            raise
        raise UsageError(MUSIC_EXTRA) from None
    bpm_range = parse_bpm_range(args.bpm_range, beats.BPM_LIMITS) if args.bpm_range else beats.BPM_RANGE
    lo, hi = beats.METER_LIMITS
    if not lo <= args.meter <= hi:
        raise UsageError(f"choreo beats: --meter {args.meter}: give {lo}..{hi} beats a bar")
    with ExitStack() as files:
        outputs = _open_outputs(args, files)
        features = read_features(args.song)
        found = beats.estimate(features, meter=args.meter, bpm_range=bpm_range)
        notes = _write_outputs(args, features, found, outputs)
    if args.json:
        print(json.dumps(json_record(features.path, found), ensure_ascii=False))
    else:
        for line in text_lines(features.path, found, with_beats=args.beats):
            line = one_line(line)  # a song named with a line break must not add a line to the YAML
            if line.startswith("#"):
                print_fitted(line)  # a comment cut to the terminal is still a comment
            else:
                print(line)
    for note in notes:
        print_fitted(one_line(note), sys.stderr)
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


# -- the text -----------------------------------------------------------------------------------


def tempo_line(found: BeatEstimate) -> str:
    """The block as YAML, figures in full (`:g` would cut an offset past 1000 s to 0.01 s)."""
    return f"tempo: {{bpm: {found.bpm!r}, offset: {found.offset!r}, meter: {found.meter}}}"


def tempo_lines(found: BeatEstimate, width: int = MAP_WIDTH) -> list[str]:
    """The `tempo:` block: one line for a steady song; for a tempo map a YAML flow mapping whose
    list of bar times (3 decimals: a millisecond) is wrapped at `width` columns."""
    if not found.bars:
        return [tempo_line(found)]
    words = [f"{bar:.3f}," for bar in found.bars]
    words[-1] = words[-1][:-1] + "]}"
    lines = [f"tempo: {{meter: {found.meter}, bars: [{words[0]}"]
    for word in words[1:]:
        if len(lines[-1]) + 1 + len(word) > width:
            lines.append("  " + word)
        else:
            lines[-1] += " " + word
    return lines


def summary_lines(path: str, found: BeatEstimate) -> list[str]:
    """What the block rests on, as YAML comments, so that they may be pasted along with it."""
    from choreo.music.beats import ON_BEAT_S

    median = " (the median of the map)" if found.bars else ""
    lines = [f"# {path} ({found.duration_s:.1f} s): {found.bpm:g} bpm{median}; {found.confirmed} of "
             f"{len(found.beats)} beats from bar 1 on have an onset within {1000 * ON_BEAT_S:.0f} ms of "
             f"{'the map' if found.bars else 'the grid'} (rms {found.timing_rms_ms:.1f} ms)"]
    if found.downbeat_contrast is not None:
        by = f"by {found.downbeat_by}" if found.downbeat_by else "by no cue in particular"
        if math.isfinite(found.downbeat_contrast):
            stands = f"a log-likelihood {found.downbeat_contrast:.0f} ahead of beat {found.other_beat}"
        else:
            stands = f"the only beat heard as one, beat {found.other_beat} next"
        lines.append(f"# bar 1 beat 1 at {found.offset:.3f} s, found {by}: {stands}, the next likeliest "
                     f"downbeat (that would be offset: {found.other_offset!r})")
    lines.extend(map_lines(found))
    lines.append("# an estimate: check it by ear (`--click OUT.wav`, `--beats` lists every beat)")
    return lines


def map_lines(found: BeatEstimate) -> list[str]:
    """Why the block is a tempo map, when it is one: how far one tempo would miss, and how far
    the tempo moves."""
    if not found.bars:
        return []
    from choreo.music.beats import one_tempo_miss

    miss_s, at_s = one_tempo_miss(found)
    bar_bpm = found.tempo().bar_bpm  # as a show reads the map
    return [f"# one tempo does not fit: the straight line nearest the beats puts the beat at {at_s:.2f} s "
            f"{1000 * miss_s:.0f} ms off;",
            f"# so this is a tempo map, each bar's beat 1 ({len(bar_bpm)} bars and where the next would begin), "
            f"from {min(bar_bpm):.1f} to {max(bar_bpm):.1f} bpm"]


def beat_line(beat: Beat) -> str:
    """`  12.480 s  bar 7 beat 1  onset +0.4 ms` (or `no onset`)."""
    if beat.onset_s is None:
        return f"{beat.time_s:9.3f} s  bar {beat.bar} beat {beat.beat}  no onset"
    early_or_late = round(1000.0 * (beat.onset_s - beat.time_s), 1) + 0.0  # never -0.0
    return f"{beat.time_s:9.3f} s  bar {beat.bar} beat {beat.beat}  onset {early_or_late:+.1f} ms"


def text_lines(path: str, found: BeatEstimate, *, with_beats: bool) -> list[str]:
    lines = [*summary_lines(path, found), *tempo_lines(found)]
    if with_beats:
        lines.extend(beat_line(beat) for beat in found.beats)
    return lines


def json_record(path: str, found: BeatEstimate) -> dict:
    """`tempo` keyed as plan's and validate's --json (bars only for a map), so one reader takes
    either; an infinite contrast (one phase alone heard) is null: JSON has no infinity."""
    downbeat = None
    if found.downbeat_contrast is not None:
        contrast = found.downbeat_contrast
        downbeat = {"by": found.downbeat_by, "contrast": contrast if math.isfinite(contrast) else None,
                    "next_beat": found.other_beat, "next_offset": found.other_offset}
    tempo: dict = {"bpm": found.bpm, "offset": found.offset, "meter": found.meter}
    if found.bars:
        tempo["bars"] = list(found.bars)
    return {
        "song": path,
        "duration_s": found.duration_s,
        "tempo": tempo,
        "beats_on_onset": found.confirmed,
        "timing_rms_ms": found.timing_rms_ms,
        "downbeat": downbeat,
        "beats": [{"time_s": b.time_s, "bar": b.bar, "beat": b.beat, "onset_s": b.onset_s} for b in found.beats],
        "curve": [[round(t, 3), round(bpm, 3)] for t, bpm in found.curve],
    }


# -- the files ----------------------------------------------------------------------------------


def _open_outputs(args: argparse.Namespace, files: ExitStack) -> dict[str, BinaryIO]:
    """`--click` and `--png` open (as temporary files beside them) before the song is read."""
    wanted = {option: path for option, path in (("--click", args.click), ("--png", args.png)) if path}
    for option, path in wanted.items():
        if path == "-":  # stdout carries the tempo block, and a WAV's header is written last
            raise UsageError(f"{option} -: give a file name (./- for a file named -); stdout is for the "
                             "tempo block")
    if len(wanted) == 2 and same_file(args.click, args.png):
        raise UsageError(f"--png {visible(args.png)}: the same file as --click: give each its own")
    opened = {option: files.enter_context(replacing(path, option, args.song)) for option, path in wanted.items()}
    if "--png" in wanted:  # after the paths: a wrong one is said without the second it takes to import matplotlib
        from choreo.review.timeline import require_matplotlib

        require_matplotlib("beats --png", "the rest of choreo beats works without it")
    return opened


def _write_outputs(args: argparse.Namespace, features: Features, found: BeatEstimate,
                   outputs: dict[str, BinaryIO]) -> list[str]:
    """Write what was asked for; the lines that say what was written."""
    notes = []
    if "--click" in outputs:
        from choreo.music.click import CLICK_CHANNELS, CLICK_RATE, write_click_track
        from choreo.music.features import song_blocks

        clicks = [(beat.time_s, beat.beat == 1) for beat in found.beats]
        with closing(song_blocks(args.song, CLICK_RATE, CLICK_CHANNELS)) as blocks:  # a failed write closes the song
            count = write_click_track(blocks, clicks, outputs["--click"])
        notes.append(f"click: {args.click}: {count.frames / CLICK_RATE:.1f} s with {count.clicks} clicks "
                     f"({CLICK_FORMAT})")
    if "--png" in outputs:
        from choreo.music.beats import onset_strength
        from choreo.music.picture import render_png

        title = f"{visible(features.path)}: {found.bpm:g} bpm{' (a tempo map)' if found.bars else ''}, " \
                f"{found.meter} beats a bar"
        drawn = render_png(onset_strength(features), features.fps, found, title, outputs["--png"])
        left_out = " (too many for the width)" if drawn.beats == 0 and found.meter > 1 else ""
        notes.append(f"png: {args.png}: {drawn.bars} bar lines, {drawn.beats} other beat lines{left_out}, "
                     f"{drawn.labels} bar numbers")
    return notes


@contextmanager
def replacing(path: str, option: str, song: str) -> Iterator[BinaryIO]:
    """A new file for `path`, written beside it and renamed over it when the block ends without
    an error; every failure one line (exit 2) and the temporary file removed."""
    from choreo.run.settings import check_output_folder

    if path.endswith(tuple(filter(None, (os.sep, os.altsep)))):  # Path() drops the slash: `new/` wrote a file `new`
        raise UsageError(f"{option} {visible(path)}: cannot write: that names a folder (it ends with a slash): "
                         "give a file name")
    check_output_folder(Path(path), option)
    target = Path(os.path.realpath(path))  # a link is followed: the file it names is replaced
    _check_target(target, path, option, song)
    with written_whole(target, f"{option} {visible(path)}") as file:
        yield file


def _check_target(target: Path, path: str, option: str, song: str) -> None:
    """An existing output must be a regular file, and not the song (nor a link to it)."""
    try:
        mode = os.stat(target).st_mode
    except FileNotFoundError:
        return
    except (OSError, ValueError) as exc:
        raise UsageError(f"{option} {visible(path)}: cannot write: {write_why(exc)}") from None
    if not stat.S_ISREG(mode):
        from choreo.userfile import kind_of

        raise UsageError(f"{option} {visible(path)}: cannot write: it is {kind_of(mode)}, not a file: "
                         "give a file name")
    if same_file(target, song):
        raise UsageError(f"{option} {visible(path)}: that is the song itself: writing it would destroy the "
                         "song; give another file name")
    if not os.access(target, os.W_OK):  # a rename would replace it all the same: its owner said no
        raise UsageError(f"{option} {visible(path)}: cannot write: the file is read-only")
