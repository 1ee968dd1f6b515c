"""A song with a click on every beat (`choreo beats SONG --click OUT.wav`), to check the beats by ear.

Reading the printed times against the music tells little; hearing a click on each beat tells at
once whether the tracker found the beat, the off-beat, double or half time, and whether bar 1 is
the one (its click is higher and louder). The song is mixed with the clicks block by block as it
is decoded, and written as it goes, so an hour-long song takes a few megabytes of memory, not the
600 MB its samples would.
"""

from __future__ import annotations

import wave
from collections.abc import Iterable, Sequence
from dataclasses import dataclass
from typing import BinaryIO

import numpy as np

CLICK_RATE = 44100  # Hz: what the click track is written at, whatever the song's rate
CLICK_CHANNELS = 2  # stereo, the song's mono mixed to both sides
SONG_GAIN = 0.6  # the song under the clicks: room for the clicks without clipping
CLICK_S = 0.03  # a click's length: short enough to mark a moment, long enough to hear a pitch
DOWNBEAT = (1760.0, 0.4)  # Hz (A6) and level of the click on beat 1 of a bar: higher and louder
BEAT = (880.0, 0.22)  # Hz (A5) and level of the click on the other beats
_DECAY_S = 0.006  # how fast a click dies away: it starts at once, so its attack is the beat


@dataclass(frozen=True)
class ClickCount:
    """What was written: sample frames of audio, and clicks in them."""

    frames: int
    clicks: int


def click_sound(sample_rate: int, hz: float, level: float) -> np.ndarray:
    """One click: a sine that starts at full level and decays, `CLICK_S` long."""
    t = np.arange(int(round(CLICK_S * sample_rate))) / sample_rate
    return (level * np.sin(2.0 * np.pi * hz * t) * np.exp(-t / _DECAY_S)).astype(np.float32)


def write_click_track(blocks: Iterable[np.ndarray], beats: Sequence[tuple[float, bool]], out: BinaryIO,
                      sample_rate: int = CLICK_RATE, channels: int = CLICK_CHANNELS) -> ClickCount:
    """Write the song that arrives in `blocks` (float32, `channels` interleaved, at `sample_rate`)
    with a click at each of `beats` (seconds, and whether it is a downbeat) as 16-bit PCM WAV to
    `out`, a seekable binary file (the header's length is filled in at the end)."""
    starts = np.array([round(time * sample_rate) for time, _ in beats], dtype=np.int64)
    sounds = {True: click_sound(sample_rate, *DOWNBEAT), False: click_sound(sample_rate, *BEAT)}
    accents = [accented for _, accented in beats]
    length = len(sounds[True])
    written = clicked = 0
    with wave.open(out, "wb") as wav:
        wav.setnchannels(channels)
        wav.setsampwidth(2)
        wav.setframerate(sample_rate)
        for block in blocks:
            frames = np.asarray(block, dtype=np.float32).reshape(-1, channels) * np.float32(SONG_GAIN)
            first = int(np.searchsorted(starts, written - length, side="right"))
            last = int(np.searchsorted(starts, written + len(frames), side="left"))
            for index in range(first, last):
                _mix(frames, sounds[accents[index]], int(starts[index]) - written)
            clicked = max(clicked, last)
            written += len(frames)
            wav.writeframes(_pcm16(frames))
    return ClickCount(written, clicked)


def _mix(frames: np.ndarray, sound: np.ndarray, at: int) -> None:
    """Add `sound` to every channel of `frames` from frame `at` (which may lie before the block:
    a click that began in the previous one goes on here)."""
    begin, end = max(at, 0), min(at + len(sound), len(frames))
    if begin < end:
        frames[begin:end] += sound[begin - at:end - at, None]


def _pcm16(frames: np.ndarray) -> bytes:
    """Clipped first: a click on a loud peak would otherwise wrap around to the opposite sign."""
    return (np.clip(frames, -1.0, 1.0) * 32767.0).round().astype("<i2").tobytes()
