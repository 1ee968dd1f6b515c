"""A picture of what `choreo beats` found (`--png OUT.png`), to check the beats by eye.

It draws what the tracker heard, the onset strength over time, under what it decided: a thin
line on each beat, a strong one on each downbeat with its bar number, and the tempo beat by beat
on a second axis, so a drift, a ritardando or a beat on the off-beat shows at a glance.

An hour of onset strength is 310,000 frames and 7,000 beats, more than a picture 1,400 pixels
wide can show and more than matplotlib draws quickly: the strength is cut into as many pieces as
the picture has room for and each drawn by its highest value (a peak stays a peak), beats are
left out once they would stand closer than a few pixels, bar lines and numbers drawn on every
first, second, fourth... bar, so that an hour draws about as fast as a song. matplotlib is
imported here, in the function: only `--png` needs it (the `plot` extra).
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any, BinaryIO

import numpy as np

if TYPE_CHECKING:
    from choreo.music.beats import BeatEstimate

WIDTH_IN, HEIGHT_IN, DPI = 14.0, 5.0, 100  # 1400 x 500 pixels
MAX_POINTS = 2800  # pieces the onset strength is cut into: 2 a pixel
MAX_TEMPO_POINTS = 700  # and the tempo curve: each a median of its beats, so one odd beat is no spike
MAX_BEAT_LINES = 400  # beats drawn at most (3.5 pixels apart); past it only bar lines are drawn
MAX_BAR_LINES = 200  # bar lines drawn at most (7 pixels apart); past it every 2nd, 4th... bar
MAX_BAR_LABELS = 32  # bar numbers written at most (44 pixels apart: room for "1793")
STRENGTH, BEAT, DOWNBEAT, TEMPO = "#8c8c8c", "#9ecae1", "#08519c", "#d62728"


@dataclass(frozen=True)
class Drawn:
    """What the picture shows, for its caller to say: beats and bars drawn, and bar labels."""

    beats: int
    bars: int
    labels: int


def render_png(strength: np.ndarray, fps: float, found: BeatEstimate, title: str, out: BinaryIO) -> Drawn:
    """Draw the onset strength (one value per frame, `fps` frames a second), the beats and
    downbeats of `found` and its tempo curve as a PNG into `out`, an open binary file."""
    from matplotlib.figure import Figure  # no pyplot: no global figure manager, no GUI backend

    fig = Figure(figsize=(WIDTH_IN, HEIGHT_IN), dpi=DPI)
    ax = fig.add_subplot()
    times, values = peaks(np.asarray(strength, dtype=np.float64), fps, MAX_POINTS)
    ax.fill_between(times, values, color=STRENGTH, linewidth=0.0, alpha=0.6, label="onset strength")
    drawn = _draw_beats(ax, found)
    if drawn.beats < len(found.beats) - len([b for b in found.beats if b.beat == 1]):
        title += f" (beat lines left out: {len(found.beats)} beats are too many for the width)"
    ax.set_xlim(0.0, max(found.duration_s, times[-1] if len(times) else 0.0, 1e-3))
    ax.set_ylim(bottom=0.0)
    ax.set_xlabel("song time (s)")
    ax.set_ylabel("onset strength")
    _draw_tempo(ax, found)
    ax.set_title(title, fontsize="medium", parse_math=False)  # a song named `$\x{$.wav` is a name, not TeX
    fig.tight_layout()
    fig.savefig(out, format="png")
    return drawn


def peaks(values: np.ndarray, fps: float, pieces: int) -> tuple[np.ndarray, np.ndarray]:
    """`values` (one a frame) cut into at most `pieces` runs of equal length, each given by its
    highest value at its middle's time: a short onset among long silences keeps its height."""
    if len(values) == 0:
        return np.zeros(0), np.zeros(0)
    run = max(1, math.ceil(len(values) / pieces))
    padded = np.pad(values, (0, -len(values) % run), constant_values=-np.inf)
    highest = padded.reshape(-1, run).max(axis=1)
    times = (np.arange(len(highest)) * run + (run - 1) / 2.0) / fps
    return times, highest


def _draw_beats(ax: Any, found: BeatEstimate) -> Drawn:  # ax: a matplotlib Axes, imported lazily
    """Beat lines only while they stand apart; bar lines and numbers thinned by powers of two, so
    that the bars left are still evenly spaced and their numbers easy to count on from."""
    beats = [b.time_s for b in found.beats if b.beat != 1]
    bars = [(b.time_s, b.bar) for b in found.beats if b.beat == 1]
    if len(found.beats) <= MAX_BEAT_LINES:
        ax.vlines(beats, 0.0, 1.0, transform=ax.get_xaxis_transform(), colors=BEAT, linewidth=0.6, label="beat")
    else:
        beats = []
    bar_every = _every(len(bars), MAX_BAR_LINES)
    shown = bars[::bar_every]
    ax.vlines([t for t, _ in shown], 0.0, 1.0, transform=ax.get_xaxis_transform(), colors=DOWNBEAT,
              linewidth=1.2, label="bar 1, 2, 3..." if bar_every == 1 else f"every {bar_every}th bar")
    label_every = bar_every * _every(len(shown), MAX_BAR_LABELS)
    labelled = [(t, bar) for t, bar in bars if (bar - 1) % label_every == 0]
    for time_s, bar in labelled:
        ax.annotate(str(bar), (time_s, 1.0), xycoords=("data", "axes fraction"), xytext=(2, -2),
                    textcoords="offset points", va="top", ha="left", fontsize="x-small", color=DOWNBEAT)
    return Drawn(len(beats), len(shown), len(labelled))


def _every(count: int, most: int) -> int:
    """1, 2, 4, 8...: the smallest power of two that leaves at most `most` of `count` things."""
    every = 1
    while count > most * every:
        every *= 2
    return every


def _draw_tempo(ax: Any, found: BeatEstimate) -> None:
    """The tempo beat by beat on a second axis, and the legend of both."""
    tempo = ax.twinx()
    curve = np.asarray(found.curve, dtype=np.float64).reshape(-1, 2)
    if len(curve):
        run = max(1, math.ceil(len(curve) / MAX_TEMPO_POINTS))
        whole = len(curve) // run * run or len(curve)
        middles = np.median(curve[:whole].reshape(-1, min(run, whole), 2), axis=1)
        tempo.plot(middles[:, 0], middles[:, 1], color=TEMPO, linewidth=1.0,
                   label="tempo (bpm)" if run == 1 else f"tempo (bpm, median of {run} beats)")
        low, high = float(middles[:, 1].min()), float(middles[:, 1].max())
        margin = max(0.05 * (high - low), 2.0)
        tempo.set_ylim(low - margin, high + margin)
    tempo.set_ylabel("tempo (bpm)", color=TEMPO)
    handles, labels = ax.get_legend_handles_labels()
    more_handles, more_labels = tempo.get_legend_handles_labels()
    ax.legend(handles + more_handles, labels + more_labels, loc="upper center", bbox_to_anchor=(0.5, -0.12),
              ncol=4, frameon=False, fontsize="small")
