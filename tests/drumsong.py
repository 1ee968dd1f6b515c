"""A short drum song with known beats, synthesized (for tests/test_song_formats.py and
tests/test_beats_cli.py): kick on 1 and on the "and" of 2, snare on 2 and 4, hi-hats on the
eighths (panned right), a bass note on each bar's 1 whose pitch changes every bar, so that
bar 1 is unambiguous. Deterministic, any sample rate, mono or stereo, a steady tempo or one
that slows down (a ritardando: one tempo does not fit it).
"""

from __future__ import annotations

import numpy as np

START_S = 0.25  # bar 1 beat 1
BPM = 120.0
METER = 4


def beat_times(seconds: float = 8.0, bpm: float = BPM, slow_to: float | None = None) -> np.ndarray:
    """Every beat from bar 1 until 0.3 s before the end; with `slow_to`, the tempo falls
    linearly from `bpm` to `slow_to` over the song."""
    times = [START_S]
    while True:
        share = times[-1] / seconds
        tempo = bpm if slow_to is None else bpm + (slow_to - bpm) * share
        following = times[-1] + 60.0 / tempo
        if following >= seconds - 0.3:
            return np.array(times)
        times.append(following)


def drums(rate: int, channels: int = 2, seconds: float = 8.0, beats: np.ndarray | None = None) -> np.ndarray:
    """(samples, channels) float64 in -1..1 (peak 1/1.1)."""
    beats = beat_times(seconds) if beats is None else beats
    n = int(seconds * rate)
    out = np.zeros((n, 2))
    rng = np.random.default_rng(23)

    def hit(sound: np.ndarray, at: float, pan: float = 0.5) -> None:
        i = int(round(at * rate))
        j = min(n, i + len(sound))
        if i < n:
            out[i:j, 0] += sound[:j - i] * (1 - pan)
            out[i:j, 1] += sound[:j - i] * pan

    def tone(hz_from: float, hz_to: float, length: float, decay: float) -> np.ndarray:
        t = np.arange(int(length * rate)) / rate
        hz = hz_to + (hz_from - hz_to) * np.exp(-t / 0.03)
        return np.sin(2 * np.pi * np.cumsum(hz) / rate) * np.exp(-t / decay)

    def noise(length: float, decay: float, bright: bool) -> np.ndarray:
        t = np.arange(int(length * rate)) / rate
        x = rng.standard_normal(len(t))
        return (np.diff(x, prepend=0.0) if bright else x) * np.exp(-t / decay)

    for k, at in enumerate(beats):
        beat = (beats[k + 1] if k + 1 < len(beats) else at + (at - beats[k - 1])) - at
        if k % 4 == 0:
            hit(tone(150, 50, 0.3, 0.08), at)
            hz = (55.0, 43.65, 65.41, 49.0)[k // 4 % 4]
            hit(0.6 * tone(hz, hz, 4 * beat, 0.6), at)
        if k % 4 == 1:
            hit(0.8 * tone(150, 50, 0.3, 0.08), at + beat / 2)
        if k % 2 == 1:
            hit(0.5 * noise(0.2, 0.05, False) + 0.4 * tone(220, 180, 0.2, 0.04), at)
        for half in (0.0, 0.5):
            hit(0.15 * noise(0.05, 0.012, True), at + half * beat, pan=0.8)
    out /= np.max(np.abs(out)) * 1.1
    return out if channels == 2 else out.mean(axis=1, keepdims=True)


def write_wav(path, samples: np.ndarray, rate: int, encoding: str = "pcm16"):
    """`samples` (frames, channels) as a WAV file: `pcm16`, `pcm24` or `float32` (IEEE float,
    format 3, which the standard library's `wave` does not write)."""
    frames, channels = samples.shape
    if encoding == "float32":
        data, fmt, width = samples.astype("<f4").tobytes(), 3, 4
    elif encoding == "pcm24":
        ints = np.round(samples * (2 ** 23 - 1)).astype("<i4").reshape(-1)
        data, fmt, width = ints.view(np.uint8).reshape(-1, 4)[:, :3].tobytes(), 1, 3
    else:
        data, fmt, width = np.round(samples * 32767).astype("<i2").tobytes(), 1, 2
    header = b"".join([
        b"RIFF", (36 + len(data)).to_bytes(4, "little"), b"WAVE",
        b"fmt ", (16).to_bytes(4, "little"), fmt.to_bytes(2, "little"), channels.to_bytes(2, "little"),
        rate.to_bytes(4, "little"), (rate * channels * width).to_bytes(4, "little"),
        (channels * width).to_bytes(2, "little"), (8 * width).to_bytes(2, "little"),
        b"data", len(data).to_bytes(4, "little")])
    path.write_bytes(header + data)
    return path


def make_fixtures(folder) -> None:
    """The compressed fixtures in tests/data/songs/ (needs ffmpeg; run once, results committed):
    python tests/drumsong.py"""
    import subprocess
    import tempfile
    from pathlib import Path

    with tempfile.TemporaryDirectory() as temp:
        master = write_wav(Path(temp) / "master.wav", drums(44100, 2), 44100)
        for name, args in [("drums.mp3", ["-ac", "2", "-ar", "44100", "-b:a", "32k"]),
                           ("drums.ogg", ["-ac", "1", "-ar", "22050", "-c:a", "libvorbis", "-q:a", "0"]),
                           ("drums.flac", ["-ac", "1", "-ar", "8000", "-sample_fmt", "s16"])]:
            subprocess.run(["ffmpeg", "-y", "-loglevel", "error", "-i", str(master), *args,
                            "-map_metadata", "-1", "-fflags", "+bitexact", str(Path(folder) / name)], check=True)


if __name__ == "__main__":
    from pathlib import Path

    make_fixtures(Path(__file__).resolve().parent / "data" / "songs")
