"""choreo/music/features.py: a song reduced, block by block, to what beat finding hears. The
blocks' sizes must not change a single value (a song decoded 64 Ki samples at a time must give
what it gives whole), the features must place sounds where they are (a click's attack to the
millisecond, a kick in the low bands, a chord's notes in its pitch classes), and what is kept is
a small share of the samples."""

from __future__ import annotations

import wave
from pathlib import Path

import numpy as np
import pytest

from choreo.errors import UsageError
from choreo.music import features
from choreo.music.features import Features, features_of, read_features

RATE = features.SAMPLE_RATE


def clicks(times: list[float], seconds: float, hz: float = 3000.0, rate: int = RATE) -> np.ndarray:
    """Short bright tone bursts starting exactly at `times`."""
    out = np.zeros(int(seconds * rate), dtype=np.float32)
    t = np.arange(int(0.03 * rate)) / rate
    burst = (np.sin(2 * np.pi * hz * t) * np.exp(-t / 0.008)).astype(np.float32)
    for at in times:
        i = int(round(at * rate))
        out[i:i + len(burst)] += burst[: len(out) - i]
    return out


def in_blocks(samples: np.ndarray, size: int) -> list[np.ndarray]:
    return [samples[i:i + size] for i in range(0, len(samples), size)]


def test_block_sizes_change_nothing():
    rng = np.random.default_rng(1)
    samples = (clicks([0.5, 1.0, 1.75], 3.0) + 0.01 * rng.standard_normal(int(3.0 * RATE))).astype(np.float32)
    whole = features_of([samples])
    for size in (31, 777, 4097, 65536):
        parts = features_of(in_blocks(samples, size))
        for name in ("bands", "chroma", "bass_chroma", "attack"):
            np.testing.assert_allclose(getattr(parts, name), getattr(whole, name), rtol=1e-5, atol=1e-6,
                                       err_msg=f"{name} with blocks of {size}")
        assert parts.duration_s == whole.duration_s == len(samples) / RATE


def test_frames_cover_the_song_from_its_first_sample_to_its_last():
    found = features_of([np.zeros(RATE, dtype=np.float32)])
    assert len(found.bands) == RATE // found.hop + 1  # frame j is centred on sample j * hop
    assert len(found.chroma) == RATE // (found.hop * found.chroma_every) + 1
    assert found.fps == pytest.approx(RATE / 256) and found.peak == 0.0
    assert not np.any(found.bands) and not np.any(found.attack)  # silence: no onsets out of nothing


def test_the_attack_envelope_places_a_click_within_two_milliseconds():
    times = [0.3127, 0.8, 1.4551, 2.0003]
    found = features_of([clicks(times, 2.5)])
    step_s = found.attack_hop / RATE
    peaks = np.sort(np.argsort(found.attack)[-len(times):])
    np.testing.assert_allclose((peaks - 0.5) * step_s, times, atol=0.002)


def test_a_kick_sounds_in_the_low_bands_and_a_hat_in_the_high_ones():
    t = np.arange(int(0.3 * RATE)) / RATE
    kick = np.zeros(RATE, dtype=np.float32)
    kick[RATE // 2:RATE // 2 + len(t)] = np.sin(2 * np.pi * 55 * t) * np.exp(-t / 0.1)
    hat = clicks([0.5], 1.0, hz=8000.0)
    low, high = (features_of([x]).band_range(*hz) for x, hz in ((kick, (30, 150)), (hat, (5000, 11025))))
    kick_bands, hat_bands = features_of([kick]).bands, features_of([hat]).bands
    assert kick_bands[:, low].max() > 5 * kick_bands[:, high].max()
    assert hat_bands[:, high].max() > 5 * hat_bands[:, low].max()


def test_a_chord_sounds_in_its_pitch_classes():
    t = np.arange(2 * RATE) / RATE
    c_major = sum(np.sin(2 * np.pi * hz * t) for hz in (261.63, 329.63, 392.00)).astype(np.float32)
    bass_g = np.sin(2 * np.pi * 98.0 * t).astype(np.float32)
    found = features_of([c_major + bass_g])
    assert set(np.argsort(found.chroma[5:-5].mean(axis=0))[-3:]) == {0, 4, 7}  # C, E, G
    assert int(np.argmax(found.bass_chroma[5:-5].mean(axis=0))) == 7  # G


def test_levels_are_relative_to_the_songs_own_peak():
    song = clicks([0.5, 1.0], 1.5)
    loud, quiet = features_of([song]), features_of([0.01 * song])
    np.testing.assert_allclose(loud.bands, quiet.bands, rtol=1e-4, atol=1e-5)


def test_what_is_kept_is_a_small_share_of_the_samples():
    seconds = 60.0
    found = features_of(in_blocks(np.zeros(int(seconds * RATE), dtype=np.float32), 65536))
    kept = sum(getattr(found, name).nbytes for name in ("bands", "chroma", "bass_chroma", "attack"))
    assert kept < 0.4 * seconds * RATE * 4  # well under the float32 samples themselves


def write_wav(path: Path, samples: np.ndarray, rate: int, channels: int = 1) -> None:
    with wave.open(str(path), "wb") as out:
        out.setnchannels(channels)
        out.setsampwidth(2)
        out.setframerate(rate)
        out.writeframes((np.repeat(samples, channels) * 30000).astype("<i2").tobytes())


def test_a_file_is_read_in_blocks_at_the_analysis_rate_whatever_its_own(tmp_path):
    song = clicks([0.25, 0.75, 1.25], 1.5, rate=44100)
    write_wav(tmp_path / "song.wav", song, 44100, channels=2)
    found = read_features(tmp_path / "song.wav")
    assert isinstance(found, Features) and found.sample_rate == RATE
    assert found.duration_s == pytest.approx(1.5, abs=0.001)
    peaks = np.sort(np.argsort(found.attack)[-3:])
    np.testing.assert_allclose((peaks - 0.5) * found.attack_hop / RATE, [0.25, 0.75, 1.25], atol=0.003)


@pytest.mark.parametrize("content, says", [(b"", "empty"), (b"not a song at all" * 10, "cannot decode")])
def test_an_unreadable_file_is_one_line(tmp_path, content, says):
    path = tmp_path / "song\nname.wav"
    path.write_bytes(content)
    with pytest.raises(UsageError) as error:
        read_features(path)
    assert says in str(error.value) and "\n" not in str(error.value)


def test_a_folder_is_refused_without_decoding(tmp_path):
    with pytest.raises(UsageError, match="not a regular file"):
        read_features(tmp_path)
