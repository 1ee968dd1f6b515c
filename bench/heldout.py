"""A held-out set of songs for beat finding (issue 23): made by other means than bench/songs.py,
never tuned on, to tell how far the tracker's figures carry to songs it has not seen.

bench/songs.py's set is what the tracker was tuned against; a tracker can learn a set's sounds.
This one shares nothing with it but the conventions of the truth (the beat is the quarter note in
simple meters and the dotted quarter in compound ones; bar 1 is the first downbeat of the music):
other instruments (a pitch-swept 808 kick, claps, metallic hats and ride from inharmonic square
waves, plucked saw bass, detuned saw chords, arpeggios, piano, strummed and skanked guitar), other
styles (disco, rock on the ride, metal's double kick, ska's off-beat chops, a reggae one-drop, an
arpeggiated EDM track, jazz swing with walking bass, an oom-pah-pah waltz with no drums, a 6/8
arpeggio ballad, 5/4, a strummed folk song, an ambient kick-and-pads track, boom bap played
loosely, an accelerando, a wide live drift), each mixed at random levels, softly clipped, over a
noise floor, some in a room; written at 44.1 kHz to a WAV file and read back as `choreo beats`
reads a file (decoding and resampling included).

    python bench/heldout.py [--seed N] [--count N]   # the per-song table, then the totals
    python bench/run.py heldout                     # benchmark 14's rows (seed 0, 32 songs)
"""

from __future__ import annotations

import argparse
import sys
from collections.abc import Callable
import tempfile
import wave
from dataclasses import dataclass
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parent.parent
for path in (ROOT, ROOT / "bench"):
    if str(path) not in sys.path:
        sys.path.insert(0, str(path))

from beats import score, table  # noqa: E402
from common import row  # noqa: E402
from songs import Song  # noqa: E402

from choreo.errors import UsageError  # noqa: E402
from choreo.music import beats as choreo_beats  # noqa: E402
from choreo.music.features import read_features  # noqa: E402
from choreo.music.scoring import (  # noqa: E402
    GOAL_BAR_ONE_SHARE,
    GOAL_F_MEAN,
    GOAL_F_MEDIAN,
    GOAL_LEVEL_SHARE,
    SetScore,
    score_set,
)

RATE = 44100


@dataclass(frozen=True)
class Style:
    name: str
    bpm: tuple[float, float]
    meter: int  # beats a bar (6/8: 2)
    steps: int  # pattern steps a beat
    parts: dict[str, str]  # voice -> one bar of steps, digits 1-9 = velocity, '.' = rest
    swing: float = 0.5
    tempo: str = "steady"  # steady, accelerando, wander
    jitter_s: float = 0.0
    room: bool = False


STYLES: tuple[Style, ...] = (
    Style("disco", (112, 124), 4, 4, {"kick": "9...9...9...9...", "clap": "....8.......8...",
          "ohat": "..6...6...6...6.", "bass8": "9.5.9.5.9.5.9.5.", "chords": "7..............."}),
    Style("rock on the ride", (100, 140), 4, 4, {"kick": "9.......9.6.....", "snare": "....9.......9...",
          "ride": "6...5...6...5...", "bass8": "8.5.8.5.8.5.8.5.", "chords": "7......5........"}),
    Style("metal double kick", (140, 170), 4, 4, {"kick": "8888888888888888", "snare": "....9.......9...",
          "crash": "7...............", "chords": "8..............."}),
    Style("ska", (140, 165), 4, 2, {"kick": "8...8...", "snare": "....7...", "chop": ".8.8.8.8",
          "bass8": "8.6.8.6.", "hat": "4.4.4.4."}),
    Style("reggae one-drop", (70, 84), 4, 4, {"kick": "........9.......", "snare": "........8.......",
          "hat": "5.4.5.4.5.4.5.4.", "chop": "....7.......7...", "bass": "8.....6.7......."}),
    Style("arpeggio EDM", (124, 130), 4, 4, {"kick": "9...9...9...9...", "arp": "7565756575657565",
          "chords": "6..............."}),
    Style("jazz swing", (120, 180), 4, 3, {"ride": "8..7.68..7.6", "pedal": "...6.....6..",
          "walk": "8..7..8..7..", "piano": "......5....."}),
    Style("oom-pah-pah waltz", (90, 160), 3, 2, {"bass": "9.....", "piano": "..6.6."}),
    Style("6/8 arpeggios", (50, 70), 2, 3, {"kick": "8.....", "snare": "...7..", "arp": "756656",
          "chords": "6....."}),
    Style("5/4", (160, 180), 5, 2, {"kick": "9.....8...", "snare": "....7...7.", "ride": "6.6.6.6.6.",
          "piano": "7.....5...", "bass": "9.....8..."}),
    Style("folk strum", (90, 120), 4, 2, {"strum": "85758575", "bass": "9...7..."}),
    Style("ambient kick and pads", (118, 126), 4, 1, {"kick": "6666", "pad": "8..."}),
    Style("boom bap, loose", (84, 96), 4, 4, {"kick": "9......8..8.....", "snare": "....9.......9...",
          "hat": "6.5.6.5.6.5.6.5.", "bass": "8......6..7....."}, swing=0.58, jitter_s=0.008),
    Style("accelerando", (96, 110), 4, 4, {"kick": "9.......9.......", "snare": "....8.......8...",
          "hat": "5.5.5.5.5.5.5.5.", "chords": "7...............", "bass": "8.......7......."},
          tempo="accelerando"),
    Style("wide live drift", (100, 130), 4, 4, {"kick": "9.....7.9.......", "snare": "....8.......8...",
          "ride": "6.5.6.5.6.5.6.5.", "chords": "7.......6.......", "bass8": "8.6.8.6.8.6.8.6."},
          tempo="wander", jitter_s=0.005, room=True),
    Style("pop in a room", (90, 120), 4, 4, {"kick": "9.......9.......", "clap": "....8.......8...",
          "shaker": "5354535453545354", "piano": "7.....5.....6...", "bass": "8.......7......."},
          room=True),
)


class Voices:
    """Every instrument as a function of (duration, frequency) -> samples, made from one rng."""

    def __init__(self, rng: np.random.Generator) -> None:
        self.rng = rng
        self.hat_ratios = rng.uniform(0.9, 1.1) * np.array([2.0, 3.0, 4.16, 5.43, 6.79, 8.21]) * 810
        self.made: dict[tuple, np.ndarray] = {}  # pitched and metallic sounds, made once per song

    def once(self, key: tuple, make: Callable[[], object]) -> np.ndarray:
        if key not in self.made:
            self.made[key] = np.asarray(make(), dtype=float)
        return self.made[key]

    def t(self, seconds: float) -> np.ndarray:
        return np.arange(int(seconds * RATE)) / RATE

    def kick(self) -> np.ndarray:
        t = self.t(0.5)
        phase = 2 * np.pi * (45 * t + (130 - 45) * 0.03 * (1 - np.exp(-t / 0.03)))
        return np.sin(phase) * np.exp(-t / 0.25) + 0.3 * self.rng.standard_normal(len(t)) * np.exp(-t / 0.003)

    def snare(self) -> np.ndarray:
        t = self.t(0.3)
        noise = np.diff(self.rng.standard_normal(len(t) + 1))
        return 0.6 * noise * np.exp(-t / 0.07) + 0.6 * np.sin(2 * np.pi * 190 * t) * np.exp(-t / 0.05)

    def clap(self) -> np.ndarray:
        out = np.zeros(int(0.3 * RATE))
        for k, delay in enumerate((0.0, 0.011, 0.023)):
            burst = self.snare()[: int(0.25 * RATE)] * (0.6 if k < 2 else 1.0)
            i = int(delay * RATE)
            out[i:i + len(burst)] += burst[: len(out) - i]
        return 0.6 * out

    def metal(self, decay: float) -> np.ndarray:
        t = self.t(min(1.5, 5 * decay))
        tone = sum(np.sign(np.sin(2 * np.pi * f * t)) for f in self.hat_ratios)
        return 0.08 * np.diff(tone, prepend=0.0) * np.exp(-t / decay)

    def saw(self, hz: float, seconds: float, detune: float = 0.0) -> np.ndarray:
        t = self.t(seconds)
        return 2 * ((hz * (1 + detune) * t) % 1.0) - 1

    def lowpass(self, x: np.ndarray, hz: float) -> np.ndarray:
        a = np.exp(-2 * np.pi * hz / RATE)
        spectrum = np.fft.rfft(x, 2 * len(x))
        freqs = np.fft.rfftfreq(2 * len(x), 1 / RATE)
        response = (1 - a) / np.abs(1 - a * np.exp(-2j * np.pi * freqs / RATE))  # a one-pole low-pass
        return np.fft.irfft(spectrum * response, 2 * len(x))[: len(x)]

    def pluck(self, hz: float, seconds: float) -> np.ndarray:
        t = self.t(seconds)
        return self.lowpass(self.saw(hz, seconds), 900) * np.exp(-t / 0.35) * np.minimum(1, t / 0.004)

    def piano(self, notes: list[float], seconds: float) -> np.ndarray:
        t = self.t(seconds)
        out = sum(np.sin(2 * np.pi * f * h * t) / h ** 1.5 * np.exp(-t * h / 1.2) for f in notes for h in (1, 2, 3, 4))
        return out * np.minimum(1, t / 0.002) / len(notes)

    def pad(self, notes: list[float], seconds: float) -> np.ndarray:
        t = self.t(seconds)
        out = sum(self.saw(f, seconds, d) for f in notes for d in (-0.004, 0.004))
        out = self.lowpass(out, 1400) * np.minimum(1, t / 0.15) * np.minimum(1, (t[-1] - t + 1e-3) / 0.05)
        return 0.5 * out / len(notes)

    def strum(self, notes: list[float], seconds: float, down: bool) -> np.ndarray:
        order = notes if down else notes[::-1]
        out = np.zeros(int(seconds * RATE))
        for k, f in enumerate(order):
            note = self.pluck(2 * f, seconds)
            i = int(k * 0.008 * RATE)
            out[i:] += note[: len(out) - i]
        return out / len(notes)


PROGRESSIONS = ((0, 5, 7, 0), (0, 9, 5, 7), (2, 7, 0, 5), (0, 7, 9, 5), (9, 5, 0, 7))
MINOR = {2, 4, 9, 11}


def chord(root_hz: float, degree: int) -> list[float]:
    third = 3 if degree % 12 in MINOR else 4
    base = root_hz * 2 ** (degree / 12)
    return [base, base * 2 ** (third / 12), base * 2 ** (7 / 12)]


def tempo_curve(style: Style, bpm: float, count: int, rng: np.random.Generator) -> np.ndarray:
    k = np.arange(count)
    if style.tempo == "accelerando":
        return bpm * (1 + 0.12 * k / count)
    if style.tempo == "wander":
        walk = np.cumsum(rng.normal(0, 0.004, count))
        return bpm * (1 + np.clip(walk - walk.mean(), -0.03, 0.03))
    return np.full(count, bpm)


def make(style: Style, seed: int) -> Song:
    rng = np.random.default_rng(seed)
    voices = Voices(rng)
    bpm = round(float(rng.uniform(*style.bpm)), 2)
    start = float(rng.uniform(0.2, 2.5))
    beat_s = 60 / bpm
    bars = max(6, int((float(rng.uniform(26, 40)) - start) / (style.meter * beat_s)))
    curve = tempo_curve(style, bpm, bars * style.meter, rng)
    beats = start + np.concatenate([[0.0], np.cumsum(60 / curve)])
    out = np.zeros(int((beats[-1] + 1.5) * RATE))
    root = 110 * 2 ** (int(rng.integers(12)) / 12)
    progression = PROGRESSIONS[int(rng.integers(len(PROGRESSIONS)))]
    gains = {name: float(rng.uniform(0.5, 1.0)) for name in style.parts}
    for bar in range(bars):
        notes = chord(root, progression[bar % len(progression)])
        for name, pattern in style.parts.items():
            for step, mark in enumerate(pattern):
                if mark == ".":
                    continue
                beat = bar * style.meter + step // style.steps
                fraction = (step % style.steps) / style.steps
                if style.swing != 0.5 and style.steps in (2, 4) and step % 2:
                    fraction += (style.swing - 0.5) / (style.steps / 2)
                at = beats[beat] + fraction * (beats[beat + 1] - beats[beat])
                if style.jitter_s:
                    at += float(np.clip(rng.normal(0, style.jitter_s), -2.5 * style.jitter_s, 2.5 * style.jitter_s))
                sound = _sound(voices, name, notes, root, step, beats, bar, style)
                i = int(round(at * RATE))
                level = gains[name] * int(mark) / 9 * float(rng.uniform(0.85, 1.0))
                out[i:i + len(sound)] += level * sound[: len(out) - i]
    out = _master(out, style, rng)
    truth = beats[:-1]
    return Song(f"{style.name} {seed}", style.name, out.astype(np.float32), tuple(map(float, truth)),
                tuple(map(float, truth[::style.meter])), style.meter, style.steps, bpm,
                tuple(map(float, curve)), (), (), RATE)


def _sound(voices: Voices, name: str, notes: list[float], root: float, step: int, beats: np.ndarray, bar: int,
           style: Style) -> np.ndarray:
    beat_s = float(beats[1] - beats[0])
    bar_s = style.meter * beat_s
    arp_notes = [n * 2 for n in notes] + [notes[0] * 4]
    table = {
        "kick": lambda: voices.kick(), "snare": lambda: voices.snare(), "clap": lambda: voices.clap(),
        "hat": lambda: voices.metal(0.03), "ohat": lambda: voices.metal(0.2), "ride": lambda: voices.metal(0.5),
        "crash": lambda: 2 * voices.metal(0.9), "pedal": lambda: voices.metal(0.02),
        "shaker": lambda: 0.3 * np.diff(voices.rng.standard_normal(int(0.05 * RATE)), prepend=0.0)
        * np.exp(-np.arange(int(0.05 * RATE)) / RATE / 0.015),
        "bass": lambda: voices.pluck(notes[0] / 2, beat_s),
        "bass8": lambda: voices.pluck(notes[0] / (2 if step % 4 else 4), beat_s / 2),
        "walk": lambda: voices.pluck(notes[(step // 3) % 3] / 2, beat_s),
        "chords": lambda: voices.pad(notes, bar_s), "pad": lambda: voices.pad(notes, bar_s),
        "piano": lambda: voices.piano(notes, 1.2 * beat_s), "chop": lambda: 0.7 * voices.strum(notes, 0.12, True),
        "arp": lambda: 0.6 * voices.pluck(arp_notes[step % len(arp_notes)], beat_s / 2),
        "strum": lambda: voices.strum(notes, beat_s / 2, step % 2 == 0),
    }
    if name in ("kick", "snare", "clap", "shaker"):  # a little different at every hit, as played
        return np.asarray(table[name](), dtype=float)
    return voices.once((name, step % 16, round(beat_s, 3), tuple(round(n, 2) for n in notes)), table[name])


def _master(out: np.ndarray, style: Style, rng: np.random.Generator) -> np.ndarray:
    if style.room:
        t = np.arange(int(0.9 * RATE)) / RATE
        echoes = rng.standard_normal(len(t)) * np.exp(-6.9 * t / 0.9)
        size = 1 << int(np.ceil(np.log2(len(out) + len(echoes))))
        wet = np.fft.irfft(np.fft.rfft(out, size) * np.fft.rfft(echoes / np.sqrt(np.sum(echoes ** 2)), size), size)
        out = out + 0.4 * wet[: len(out)]
    out = out / np.max(np.abs(out))
    out = np.tanh(1.8 * out) / np.tanh(1.8)  # a mastering limiter's soft clip
    return 0.9 * out + 10 ** (-55 / 20) * rng.standard_normal(len(out))


def write_wav(path: Path, samples: np.ndarray) -> None:
    with wave.open(str(path), "wb") as out:
        out.setnchannels(2)
        out.setsampwidth(2)
        out.setframerate(RATE)
        out.writeframes((np.repeat(np.clip(samples, -1, 1), 2) * 32000).astype("<i2").tobytes())


def measure(seed: int, count: int, echo: bool = False) -> SetScore:
    """Every song of the held-out set written to a WAV file and found as `choreo beats` finds it,
    scored as benchmark 13 scores its own (`beats.score`)."""
    results = []
    with tempfile.TemporaryDirectory() as folder:
        path = Path(folder) / "song.wav"
        for i in range(count):
            song = make(STYLES[i % len(STYLES)], 7919 * seed + i)
            write_wav(path, song.samples)
            results.append(score(song, lambda played: from_file(path, played.meter)))
    if echo:
        print("\n".join(table(results)))
    return score_set([r.score for r in results])


def from_file(path: Path, meter: int) -> tuple[choreo_beats.BeatEstimate | None, str | None]:
    """What `choreo beats FILE --meter M` finds, or its one-line refusal."""
    try:
        return choreo_beats.estimate(read_features(path), meter=meter), None
    except UsageError as exc:
        return None, str(exc)


def run(quick: bool = False) -> list[dict]:
    """Benchmark 14's rows: the figures on songs never tuned on, beside the tuned set's goals
    (shown, not enforced: a held-out set tells how far the figures carry, it is not the target)."""
    totals = measure(0, len(STYLES) if quick else 2 * len(STYLES))
    n = totals.songs
    return [
        row(f"held-out beats: right tempo level ({n} songs)", round(100 * totals.level_share, 1), "%",
            f"({100 * GOAL_LEVEL_SHARE:g})", None),
        row("held-out beats: bar 1 within 70 ms", round(100 * totals.bar_one_share, 1), "%",
            f"({100 * GOAL_BAR_ONE_SHARE:g})", None),
        row("held-out beats: F-measure (+-70 ms), median", round(totals.f_median, 3), "", f"({GOAL_F_MEDIAN:g})", None),
        row("held-out beats: F-measure (+-70 ms), mean", round(totals.f_mean, 3), "", f"({GOAL_F_MEAN:g})", None),
    ]


def main(argv: list[str]) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--count", type=int, default=2 * len(STYLES))
    args = parser.parse_args(argv)
    totals = measure(args.seed, args.count, echo=True)
    print(f"held-out set, seed {args.seed}, {totals.songs} songs: level {100 * totals.level_share:.1f} %, "
          f"bar 1 {100 * totals.bar_one_share:.1f} %, F median {totals.f_median:.3f} mean {totals.f_mean:.3f}, "
          f"downbeat F {totals.downbeat_f_mean:.3f}")
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
