"""One song, every format `choreo beats` reads (issue 23: "wav/mp3/flac/ogg at any sample rate,
mono or stereo"): the streaming reader (`choreo.music.features.read_features`) gives the same
beats for a short drum song (tests/drumsong.py, 8 s, 120 bpm, bar 1 at 0.25 s) as WAV 16-bit,
24-bit and 32-bit float, at 8, 22.05, 44.1, 48 and 96 kHz, mono and stereo, and as mp3, flac and
ogg; and hostile files (empty, cut short, text named .mp3, a folder, a named pipe, a header that
declares more than the file holds, a file too big) are one line and exit 2, never a hang.

The WAV files are written here, from the synthesized song. The compressed ones are committed in
tests/data/songs/ (tens of KB each), made once with ffmpeg from the same song:
`python tests/drumsong.py` (mp3 32 kbit/s stereo 44.1 kHz, ogg vorbis q0 mono 22.05 kHz, flac
16-bit mono 8 kHz).
"""

from __future__ import annotations

import errno
import os
import subprocess
import sys
import wave
from pathlib import Path

import numpy as np
import pytest

from drumsong import BPM, START_S, drums, write_wav

from choreo.cli import main
from choreo.errors import Interrupted
from choreo.music import features
from choreo.music.beats import BeatEstimate, estimate
from choreo.music.features import read_features

SONGS = Path(__file__).resolve().parent / "data" / "songs"
WAVS = [  # (rate, channels, encoding)
    (44100, 2, "pcm16"), (44100, 2, "pcm24"), (44100, 2, "float32"), (44100, 1, "pcm16"),
    (8000, 1, "pcm16"), (22050, 1, "pcm24"), (48000, 2, "pcm16"), (96000, 1, "float32"), (96000, 2, "pcm24"),
]
LOSSLESS_S = 0.003  # how far a beat may move between lossless files (resampling, the 8 kHz band limit)
LOSSY_S = 0.012  # an encoder smears attacks: ogg at q0 moves them by several ms


@pytest.fixture(scope="module")
def reference() -> BeatEstimate:
    """The song as the reader would see it were it given the samples themselves."""
    from choreo.music.features import features_of

    return estimate(features_of([drums(22050, 1)[:, 0].astype(np.float32)], 22050, "drums"))


def assert_same_beats(found: BeatEstimate, reference: BeatEstimate, within_s: float) -> None:
    assert found.meter == reference.meter
    assert found.bpm == pytest.approx(reference.bpm, rel=0.005)
    assert found.offset == pytest.approx(reference.offset, abs=within_s)
    times = {(b.bar, b.beat): b.time_s for b in found.beats}
    same = [(times[(b.bar, b.beat)], b.time_s) for b in reference.beats if (b.bar, b.beat) in times]
    assert len(same) >= len(reference.beats) - 1 and abs(len(found.beats) - len(reference.beats)) <= 1
    assert max(abs(a - b) for a, b in same) <= within_s


def test_the_reference_is_the_song_s_truth(reference):
    assert reference.bpm == pytest.approx(BPM, rel=0.003) and reference.offset == pytest.approx(START_S, abs=0.003)
    assert reference.bars == ()


@pytest.mark.parametrize("rate, channels, encoding", WAVS, ids=[f"{r}-{c}ch-{e}" for r, c, e in WAVS])
def test_every_wav_gives_the_same_beats(tmp_path, reference, rate, channels, encoding):
    path = write_wav(tmp_path / "drums.wav", drums(rate, channels), rate, encoding)
    features = read_features(path)
    assert features.duration_s == pytest.approx(8.0, abs=0.001)
    assert_same_beats(estimate(features), reference, LOSSLESS_S)


@pytest.mark.parametrize("name", ["drums.mp3", "drums.flac", "drums.ogg"])
def test_mp3_flac_and_ogg_give_the_same_beats(reference, name):
    path = SONGS / name
    assert path.stat().st_size < 64 * 1024
    features = read_features(path)
    assert features.duration_s == pytest.approx(8.0, abs=0.06)  # an mp3 ends on a whole frame
    assert_same_beats(estimate(features), reference, LOSSLESS_S if name.endswith(".flac") else LOSSY_S)


@pytest.mark.parametrize("name", ["drums.mp3", "drums.flac", "drums.ogg"])
def test_the_click_track_of_each_format_is_the_song_s_length_in_stereo(tmp_path, capsys, name):
    out = tmp_path / "click.wav"
    assert main(["beats", str(SONGS / name), "--click", str(out)]) == 0
    with wave.open(str(out), "rb") as wav:
        assert (wav.getnchannels(), wav.getframerate(), wav.getsampwidth()) == (2, 44100, 2)
        assert wav.getnframes() / 44100 == pytest.approx(8.0, abs=0.06)
    said = capsys.readouterr().err
    assert said.startswith(f"click: {out}: 8.0 s with ") and 14 <= int(said.split()[5]) <= 16, said


def test_a_song_cut_in_half_gives_the_first_half_s_beats(tmp_path, reference):
    half = tmp_path / "half.mp3"
    whole = (SONGS / "drums.mp3").read_bytes()
    half.write_bytes(whole[:len(whole) // 2])
    found = estimate(read_features(half))
    assert 3.5 < found.duration_s < 4.5 and found.offset == pytest.approx(reference.offset, abs=LOSSY_S)
    assert found.bpm == pytest.approx(BPM, rel=0.01)


def huge_header(path: Path) -> Path:
    """A WAV whose header declares 4 GB of data (and a RIFF as long), followed by 1 s of silence."""
    write_wav(path, np.zeros((44100, 2)), 44100)
    data = bytearray(path.read_bytes())
    data[4:8] = data[40:44] = (0xFFFFFFF0).to_bytes(4, "little")
    path.write_bytes(bytes(data))
    return path


def hostile(tmp_path: Path) -> list[tuple[Path, str]]:
    whole = write_wav(tmp_path / "whole.wav", drums(22050, 1), 22050).read_bytes()
    (tmp_path / "empty.wav").write_bytes(b"")
    (tmp_path / "header-only.wav").write_bytes(whole[:40])
    (tmp_path / "cut.flac").write_bytes((SONGS / "drums.flac").read_bytes()[:200])
    (tmp_path / "notes.mp3").write_text("these are my notes, not a song\n" * 20)
    (tmp_path / "folder.ogg").mkdir()
    os.mkfifo(tmp_path / "pipe.wav")
    big = tmp_path / "big.wav"
    with open(big, "wb") as sparse:  # 5 GB of holes: nothing on disk
        sparse.truncate(5 * 1024 ** 3)
    return [(tmp_path / "empty.wav", "the file is empty"),
            (tmp_path / "header-only.wav", "cannot decode"),
            (tmp_path / "cut.flac", "no audio in it"),
            (tmp_path / "notes.mp3", "cannot decode: not a wav, mp3, flac or ogg file"),
            (tmp_path / "folder.ogg", "not a regular file (a folder)"),
            (tmp_path / "pipe.wav", "not a regular file (a named pipe)"),
            (huge_header(tmp_path / "huge.wav"), "silent"),
            (big, "too big for a sound file")]


@pytest.mark.skipif(not hasattr(os, "mkfifo"), reason="no named pipes here")
def test_hostile_files_are_one_line_and_exit_2(tmp_path, capsys):
    for path, says in hostile(tmp_path):
        assert main(["beats", str(path)]) == 2, path
        out, err = capsys.readouterr()
        assert out == "" and err.startswith(f"{path}: ") and err.count("\n") == 1, err
        assert says in err, err


@pytest.mark.skipif(not hasattr(os, "mkfifo"), reason="no named pipes here")
def test_a_named_pipe_with_a_writer_waiting_does_not_hang(tmp_path):
    pipe = tmp_path / "song.mp3"
    os.mkfifo(pipe)
    done = subprocess.run([sys.executable, "-m", "choreo", "beats", str(pipe)], capture_output=True, text=True,
                          timeout=60)
    assert done.returncode == 2 and done.stderr == f"{pipe}: not a regular file (a named pipe): give a sound file\n"


def test_a_song_over_the_length_limit_is_one_line(monkeypatch, capsys):
    monkeypatch.setattr(features, "MAX_SONG_S", 7.2)  # drums.flac is 8 s: the limit counts decoded frames
    assert main(["beats", str(SONGS / "drums.flac")]) == 2
    out, err = capsys.readouterr()
    assert out == "" and err.count("\n") == 1 and "longer than 0.002 hours: give a shorter song" in err, err


class FailingRead:
    """The song's file, whose `at`th read fails with `exc`: a disk error or Ctrl-C mid-decode."""

    def __init__(self, stream, exc: BaseException, at: int) -> None:
        self.stream, self.exc, self.at, self.reads = stream, exc, at, 0

    def __enter__(self):
        return self

    def __exit__(self, *exc_info) -> None:
        self.stream.close()

    def peek(self, size: int) -> bytes:
        return self.stream.peek(size)

    def seek(self, *where) -> int:
        return self.stream.seek(*where)

    def read(self, size: int) -> bytes:
        self.reads += 1
        if self.reads == self.at:
            raise self.exc
        return self.stream.read(size)


@pytest.mark.parametrize("at", [1, 12])  # as the decoder starts, and mid-song (drums.mp3 takes about 30 reads)
def test_a_read_that_fails_mid_decode_is_said_as_such(monkeypatch, capsys, at):
    # miniaudio reads from C: it said 'cannot decode ... a damaged one' for a disk error and for
    # Ctrl-C, and cffi printed a KeyboardInterrupt and went on decoding
    opened = features.open_input
    for exc, code, says in [(OSError(errno.EIO, os.strerror(errno.EIO)), 2, "cannot read the sound file: "
                             "Input/output error"), (Interrupted(), 130, ""), (KeyboardInterrupt(), 130, "")]:
        monkeypatch.setattr(features, "open_input", lambda *args, exc=exc: FailingRead(opened(*args), exc, at))
        assert main(["beats", str(SONGS / "drums.mp3")]) == code
        out, err = capsys.readouterr()
        assert out == "" and says in err and err.count("\n") == 1 and "Traceback" not in err, err


if __name__ == "__main__":
    sys.exit(pytest.main([__file__]))
