"""What `choreo beats` shows its user (issue 23): the `tempo:` block, a tempo map when one tempo
does not fit (it loads in a show and puts every bar and beat where the estimate heard it),
`--json` and `--beats` with the map, `--click OUT.wav` (the song with a click on every beat,
written in blocks) and `--png OUT.png`, and output files that cannot be written: one line, exit 2,
nothing half-written left behind, never the song overwritten."""

from __future__ import annotations

import errno
import io
import json
import os
import shutil
import subprocess
import sys
import wave
from pathlib import Path

import miniaudio
import numpy as np
import pytest

from drumsong import BPM, START_S, beat_times, drums, write_wav
from test_log_disk import tmpfs  # noqa: F401 the 1 MiB disk fixture, one copy for both files

from choreo.cli import main
from choreo.errors import Interrupted
from choreo.cli.beats import CLICK_FORMAT, MAP_WIDTH, tempo_lines, text_lines
from choreo.music import beats, click, picture
from choreo.music.beats import Beat, BeatEstimate, estimate, one_tempo_miss
from choreo.music.features import MAX_SONG_S, read_features
from choreo.show.load import load_show_bytes

RATE = 22050
STEPS = "steps:\n  - play: 1\n    at: {bar: 1}\n"


@pytest.fixture(scope="module")
def steady(tmp_path_factory) -> Path:
    return write_wav(tmp_path_factory.mktemp("songs") / "steady.wav", drums(RATE, 1), RATE)


@pytest.fixture(scope="module")
def slowing(tmp_path_factory) -> Path:
    """20 s slowing from 120 to 110 bpm: a straight line misses the first and last beats by 100+ ms."""
    beats = beat_times(20.0, BPM, slow_to=110.0)
    return write_wav(tmp_path_factory.mktemp("songs") / "slowing.wav", drums(RATE, 1, 20.0, beats), RATE)


def run(capsys, *argv: str) -> tuple[int, str, str]:
    code = main(["beats", *map(str, argv)])
    out, err = capsys.readouterr()
    return code, out, err


def show_with(block: str):
    return load_show_bytes(f"version: 1\n{block}{STEPS}".encode(), "dance.yaml")


def a_map(bars: tuple[float, ...], meter: int = 4) -> BeatEstimate:
    """An estimate whose beats lie linearly within each bar of `bars`, as the tracker gives them."""
    beats = []
    for bar, (start, end) in enumerate(zip(bars[:-1], bars[1:], strict=True), 1):
        beats += [Beat(round(start + (end - start) * k / meter, 9), bar, k + 1) for k in range(meter)]
    curve = tuple((b.time_s, 60.0 / (c.time_s - b.time_s)) for b, c in zip(beats[:-1], beats[1:], strict=True))
    return BeatEstimate(bpm=100.0, offset=bars[0], meter=meter, beats=tuple(beats), duration_s=bars[-1] + 1,
                        confirmed=len(beats), timing_rms_ms=1.0, downbeat_contrast=2.0, downbeat_by="bass",
                        other_beat=3, other_offset=bars[0] + 1.0, bars=bars, curve=curve)


# -- the tempo block ----------------------------------------------------------------------------


def test_a_steady_song_prints_the_one_line_block_and_it_loads(steady, capsys):
    code, out, err = run(capsys, steady)
    assert code == 0 and err == ""
    *comments, block = out.splitlines()
    assert block.startswith("tempo: {bpm: ") and all(line.startswith("# ") for line in comments)
    tempo = show_with(block + "\n").tempo
    assert tempo is not None and tempo.bars == ()
    assert tempo.bpm == pytest.approx(BPM, rel=0.003) and tempo.seconds(1) == pytest.approx(START_S, abs=0.005)


def test_a_long_map_is_wrapped_under_100_columns_and_loads_bar_for_bar():
    bars = tuple(round(0.512 + 2.0 * k + 0.001 * k * k, 3) for k in range(150))  # 150 bars, slowing
    found = a_map(bars)
    lines = tempo_lines(found)
    assert len(lines) > 10 and all(len(line) <= MAP_WIDTH for line in lines)
    assert lines[0].startswith("tempo: {meter: 4, bars: [0.512, 2.513, ") and lines[-1].endswith("]}")
    assert all(line.startswith("  ") and line[2] != " " for line in lines[1:])
    tempo = show_with("\n".join(lines) + "\n").tempo
    assert tempo is not None and tempo.bars == bars and tempo.meter == 4
    for beat in found.beats:
        assert tempo.seconds(beat.bar, beat.beat) == pytest.approx(beat.time_s, abs=1e-9)


def test_the_map_says_why_one_tempo_does_not_fit():
    found = a_map((1.0, 3.0, 5.2, 7.6, 10.2))  # 120 bpm slowing to about 92
    miss_s, at_s = one_tempo_miss(found)
    assert 0.05 < miss_s < 0.5 and at_s in (1.0, found.beats[-1].time_s)
    lines = text_lines("song.wav", found, with_beats=False)
    why = [line for line in lines if "one tempo does not fit" in line or "tempo map" in line]
    assert len(why) == 2 and f"{1000 * miss_s:.0f} ms off" in why[0]
    assert "from 92.3 to 120.0 bpm" in why[1] and "(4 bars and where the next would begin)" in why[1]
    assert lines[0].startswith("# song.wav (11.2 s): 100 bpm (the median of the map); ")


def test_a_slowing_song_prints_a_map_a_show_follows_beat_for_beat(slowing, capsys):
    found = estimate(read_features(slowing))
    assert len(found.bars) >= 2, "the tracker found one tempo for a song slowing from 120 to 110 bpm"
    code, out, _ = run(capsys, slowing, "--beats")
    lines = out.splitlines()
    start = next(i for i, line in enumerate(lines) if line.startswith("tempo:"))
    end = next(i for i in range(start, len(lines)) if lines[i].endswith("]}")) + 1
    assert any("one tempo does not fit" in line for line in lines[:start])
    tempo = show_with("\n".join(lines[:end]) + "\n").tempo  # pasted as printed, comments and all
    assert tempo is not None and tempo.bars == found.bars
    listed = lines[end:]
    assert len(listed) == len(found.beats)
    for line, beat in zip(listed, found.beats, strict=True):
        time_s, _, _, bar, _, number = line.split()[:6]
        assert (int(bar), int(number)) == (beat.bar, beat.beat)
        assert beat.time_s == pytest.approx(tempo.seconds(beat.bar, beat.beat), abs=1e-6)
        assert float(time_s) == pytest.approx(beat.time_s, abs=0.00051)  # printed to the millisecond
    truth = beat_times(20.0, BPM, slow_to=110.0)
    heard = np.array([b.time_s for b in found.beats if b.bar < len(found.bars) - 1])  # the last bar ends the song
    assert len(heard) >= 32 and np.max(np.abs(heard - truth[:len(heard)])) < 0.02


def test_json_gives_the_map_and_the_tempo_beat_by_beat(slowing, capsys):
    code, out, _ = run(capsys, slowing, "--json")
    record = json.loads(out)
    found = estimate(read_features(slowing))
    assert code == 0 and record["tempo"]["bars"] == list(found.bars) and record["tempo"]["meter"] == 4
    assert len(record["curve"]) == len(found.curve) and all(len(point) == 2 for point in record["curve"])
    tempi = [bpm for _, bpm in record["curve"]]
    assert min(tempi) > 100 and max(tempi) < 130


def test_json_of_a_steady_song_has_no_bars(steady, capsys):
    record = json.loads(run(capsys, steady, "--json")[1])
    assert "bars" not in record["tempo"] and set(record["tempo"]) == {"bpm", "offset", "meter"}


def test_a_hostile_song_name_cannot_break_the_block_the_json_or_the_terminal(steady, tmp_path, capsys):
    name = os.fsdecode(b"a\nsteps: []\r'\"\\u0041#{x}: [y] \x1b[31m\xff\x07\xc2\x85\xe2\x80\xa8.wav")
    song = tmp_path / name
    song.write_bytes(steady.read_bytes())
    code, out, _ = run(capsys, song)
    assert code == 0 and len(out.splitlines()) == 4 and all(line.isprintable() for line in out.splitlines())
    assert show_with(out).tempo is not None  # comments and all, as printed
    code, out, _ = run(capsys, song, "--json")
    # json.dumps leaves U+0085 and U+2028 raw; choreo's stdout writes them as \\uXXXX, which JSON reads back
    assert code == 0 and json.loads(out)["song"] == str(song) and out[:-1].isascii() and out[:-1].isprintable()


# -- the click track ----------------------------------------------------------------------------


def read_wav(path: Path) -> tuple[int, int, np.ndarray]:
    with wave.open(str(path), "rb") as wav:
        assert wav.getsampwidth() == 2
        data = np.frombuffer(wav.readframes(wav.getnframes()), dtype="<i2").astype(np.float64) / 32767
        return wav.getframerate(), wav.getnchannels(), data.reshape(-1, wav.getnchannels())


@pytest.mark.parametrize("rate, channels", [(44100, 2), (8000, 1)])
def test_the_click_track_is_the_song_with_a_click_on_every_beat_accented_on_the_one(tmp_path, capsys, rate,
                                                                                   channels):
    # a CD-rate stereo song is copied sample for sample; a 8 kHz mono one resampled: clicks on the beat in both
    steady = write_wav(tmp_path / "song.wav", drums(rate, channels), rate)
    out_path = tmp_path / "click.wav"
    code, out, err = run(capsys, steady, "--click", out_path, "--json")
    assert code == 0 and err.startswith(f"click: {out_path}: 8.0 s with ")
    found = json.loads(out)
    rate, channels, mixed = read_wav(out_path)
    assert (rate, channels) == (click.CLICK_RATE, click.CLICK_CHANNELS)
    heard = np.array([b["time_s"] for b in found["beats"]])
    assert len(heard) >= 14 and np.abs(heard - beat_times()[:len(heard)]).max() < 0.002  # the song's beats
    song = np.frombuffer(miniaudio.decode_file(str(steady), miniaudio.SampleFormat.FLOAT32, 2, rate).samples,
                         dtype=np.float32).reshape(-1, 2)
    assert len(mixed) == len(song)
    clicks = mixed[:, 0] - click.SONG_GAIN * song[:, 0]  # what was added: the clicks alone
    sounding = np.abs(clicks) > 0.02
    quiet_before = np.convolve(sounding, np.ones(400))[:len(clicks) - 1] == 0  # nothing in the 9 ms before
    starts = np.flatnonzero(sounding[1:] & quiet_before) + 1
    times = [beat["time_s"] for beat in found["beats"]]
    assert len(starts) == len(times)
    assert np.max(np.abs(starts / rate - times)) < 0.001  # each click starts on its beat
    loud = [np.max(np.abs(clicks[s:s + 200])) for s in starts]
    ones = np.array([beat["beat"] == 1 for beat in found["beats"]])
    assert ones.sum() >= 4 and np.min(np.array(loud)[ones]) > 1.5 * np.max(np.array(loud)[~ones])


def test_a_click_across_a_block_boundary_is_whole_whatever_the_blocks():
    song = np.zeros(44100 * 2 * 2, dtype=np.float32)  # 2 s of stereo
    beats = [(0.5, True), (1.0, False), (1.4999, False), (2.5, True)]  # the last after the song's end
    written = []
    for size in (44100 * 2, 22051, 1000, 7):
        out = io.BytesIO()
        count = click.write_click_track((song[i:i + size * 2] for i in range(0, len(song), size * 2)), beats, out)
        written.append(out.getvalue())
        assert count == click.ClickCount(88200, 3)
    assert len(set(written)) == 1


@pytest.fixture
def song_copy(steady, tmp_path) -> Path:
    copy = tmp_path / "song.wav"
    copy.write_bytes(steady.read_bytes())
    return copy


def assert_one_line_and_nothing_left(capsys, argv, says: str, folder: Path, before: set[str]) -> str:
    code, out, err = run(capsys, *argv)
    assert code == 2 and out == "" and err.count("\n") == 1, err
    assert says in err, err
    assert {p.name for p in folder.iterdir()} == before  # no temporary file, no half-written output
    return err


@pytest.mark.parametrize("option", ["--click", "--png"])
def test_the_song_itself_is_never_an_output(song_copy, tmp_path, capsys, option):
    original = song_copy.read_bytes()
    link = tmp_path / "link.wav"
    link.symlink_to(song_copy)
    os.link(song_copy, tmp_path / "hard.wav")
    before = {p.name for p in tmp_path.iterdir()}
    for target in (song_copy, link, tmp_path / "hard.wav", tmp_path / "." / "song.wav"):
        assert_one_line_and_nothing_left(capsys, [song_copy, option, target], "that is the song itself",
                                         tmp_path, before)
    assert song_copy.read_bytes() == original


@pytest.mark.skipif(not hasattr(os, "mkfifo"), reason="no named pipes here")
@pytest.mark.parametrize("option", ["--click", "--png"])
def test_outputs_that_are_not_files_are_one_line(song_copy, tmp_path, capsys, option):
    os.mkfifo(tmp_path / "fifo.wav")
    (tmp_path / "folder").mkdir()
    before = {p.name for p in tmp_path.iterdir()}
    for target, says in [(tmp_path / "fifo.wav", "cannot write: it is a named pipe, not a file"),
                         (tmp_path / "folder", "cannot write: it is a folder, not a file"),
                         (tmp_path / "nowhere" / "out.wav", "does not exist (create it first)"),
                         (f"{tmp_path}/new/", "that names a folder (it ends with a slash)"),
                         (tmp_path / "song.wav" / "out.wav", "is not a folder")]:
        err = assert_one_line_and_nothing_left(capsys, [song_copy, option, target], says, tmp_path, before)
        assert err.startswith(f"{option} {target}: ")


def test_an_output_in_a_folder_that_cannot_be_written_is_one_line(song_copy, tmp_path, capsys):
    locked = tmp_path / "locked"
    locked.mkdir()
    locked.chmod(0o500)
    try:
        if os.access(locked, os.W_OK):  # root: /sys refuses new files even to root
            locked = Path("/sys")
            if not locked.is_dir() or os.access(locked / "x", os.F_OK):
                pytest.skip("this user may write anywhere, and there is no /sys")
        before = {p.name for p in locked.iterdir()}
        assert_one_line_and_nothing_left(capsys, [song_copy, "--click", locked / "out.wav"],
                                         f"--click {locked / 'out.wav'}: cannot write: Permission denied",
                                         locked, before)
    finally:
        (tmp_path / "locked").chmod(0o700)


def test_a_read_only_output_is_left_alone(song_copy, tmp_path, capsys):
    kept = tmp_path / "kept.wav"
    kept.write_bytes(b"keep me")
    kept.chmod(0o444)
    if os.access(kept, os.W_OK):
        pytest.skip("this user may write any file (root)")
    before = {p.name for p in tmp_path.iterdir()}
    assert_one_line_and_nothing_left(capsys, [song_copy, "--click", kept], "cannot write: the file is read-only",
                                     tmp_path, before)
    assert kept.read_bytes() == b"keep me"


def test_a_disk_that_fills_leaves_the_old_file_and_no_part(song_copy, tmp_path, capsys, monkeypatch):
    out_path = tmp_path / "click.wav"
    out_path.write_bytes(b"yesterday's click track")
    calls = []

    def full(self, data):
        calls.append(len(data))
        if len(calls) > 1:
            raise OSError(errno.ENOSPC, os.strerror(errno.ENOSPC))

    monkeypatch.setattr(wave.Wave_write, "writeframes", full)
    before = {p.name for p in tmp_path.iterdir()}
    assert_one_line_and_nothing_left(capsys, [song_copy, "--click", out_path],
                                     f"--click {out_path}: cannot write: No space left on device", tmp_path, before)
    assert out_path.read_bytes() == b"yesterday's click track"


def test_a_song_that_will_not_decode_leaves_no_output(tmp_path, capsys):
    notes = tmp_path / "notes.mp3"
    notes.write_text("not a song\n")
    before = {p.name for p in tmp_path.iterdir()}
    err = assert_one_line_and_nothing_left(capsys, [notes, "--click", tmp_path / "c.wav", "--png", tmp_path / "p.png"],
                                           "cannot decode", tmp_path, before)
    assert err.startswith(f"{notes}: ")


def test_ctrl_c_while_writing_leaves_the_old_file_and_no_part(song_copy, tmp_path, capsys, monkeypatch):
    out_path = tmp_path / "click.wav"
    out_path.write_bytes(b"yesterday's click track")

    def interrupted(self, data):
        raise KeyboardInterrupt

    monkeypatch.setattr(wave.Wave_write, "writeframes", interrupted)
    before = {p.name for p in tmp_path.iterdir()}
    assert main(["beats", str(song_copy), "--click", str(out_path)]) == Interrupted.exit_code
    assert {p.name for p in tmp_path.iterdir()} == before and out_path.read_bytes() == b"yesterday's click track"
    capsys.readouterr()


def test_an_output_folder_that_vanishes_while_writing_is_one_line(song_copy, tmp_path, capsys, monkeypatch):
    folder = tmp_path / "out"
    folder.mkdir()
    write = wave.Wave_write.writeframes

    def vanishing(self, data):
        shutil.rmtree(folder, ignore_errors=True)
        write(self, data)

    monkeypatch.setattr(wave.Wave_write, "writeframes", vanishing)
    before = {p.name for p in tmp_path.iterdir()} - {"out"}
    assert_one_line_and_nothing_left(capsys, [song_copy, "--click", folder / "click.wav"],
                                     f"--click {folder / 'click.wav'}: cannot write: No such file or directory",
                                     tmp_path, before)


@pytest.mark.parametrize("option", ["--click", "--png"])
def test_a_dash_is_refused_not_written_as_a_file_named_dash(song_copy, tmp_path, capsys, monkeypatch, option):
    monkeypatch.chdir(tmp_path)
    before = {p.name for p in tmp_path.iterdir()}
    assert_one_line_and_nothing_left(capsys, [song_copy, option, "-"], f"{option} -: give a file name", tmp_path,
                                     before)


def test_the_longest_song_s_click_track_fits_a_wav_header():
    # the wave module packs sizes as 32-bit; readers that take them as signed stop at 2 GiB
    most = int(MAX_SONG_S * click.CLICK_RATE) * click.CLICK_CHANNELS * 2 + 44
    assert most < 2 ** 31


def test_a_real_full_disk_is_one_line_and_leaves_nothing(song_copy, tmpfs, capsys):  # noqa: F811 the fixture
    # the click track of 8 s is 1.4 MB: it cannot fit on a 1 MiB disk
    assert_one_line_and_nothing_left(capsys, [song_copy, "--click", tmpfs / "click.wav"],
                                     "cannot write: No space left on device", tmpfs, set())


# -- the picture --------------------------------------------------------------------------------


def test_the_png_is_drawn_beside_the_click_track(steady, tmp_path, capsys):
    png, wav = tmp_path / "beats.png", tmp_path / "click.wav"
    code, out, err = run(capsys, steady, "--png", png, "--click", wav)
    assert code == 0 and out.splitlines()[-1].startswith("tempo: ")
    assert png.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n" and wav.stat().st_size > 44
    assert err.splitlines()[-1].startswith(f"png: {png}: ") and sorted(p.name for p in tmp_path.iterdir()) == [
        "beats.png", "click.wav"]


def test_the_same_file_for_both_outputs_is_refused(steady, tmp_path, capsys):
    code, _, err = run(capsys, steady, "--png", tmp_path / "x", "--click", tmp_path / "x")
    assert code == 2 and "the same file as --click" in err and list(tmp_path.iterdir()) == []


def test_without_matplotlib_png_says_what_to_install_and_writes_nothing(steady, tmp_path, capsys, monkeypatch):
    monkeypatch.setitem(sys.modules, "matplotlib", None)
    code, out, err = run(capsys, steady, "--png", tmp_path / "beats.png")
    assert code == 2 and out == "" and err.startswith("beats --png needs matplotlib: pip install 'choreo[plot]'")
    assert list(tmp_path.iterdir()) == []


def test_an_hour_is_drawn_with_bounded_lines_and_points():
    fps, hour = 22050 / 256, 3600.0
    strength = np.zeros(int(hour * fps))
    strength[::43] = 1.0  # an onset every half second
    bars = tuple(round(0.5 + 2.0 * k, 3) for k in range(1800))
    found = a_map(bars)
    out = io.BytesIO()
    drawn = picture.render_png(strength, fps, found, "an hour", out)
    assert out.getvalue()[:4] == b"\x89PNG"
    assert drawn.beats == 0 and drawn.bars <= picture.MAX_BAR_LINES and drawn.labels <= picture.MAX_BAR_LABELS
    times, values = picture.peaks(strength, fps, picture.MAX_POINTS)
    assert len(times) <= picture.MAX_POINTS and values.max() == 1.0 and times[-1] < hour + 1


def test_a_song_name_with_dollars_is_drawn_as_written_not_as_tex():
    # matplotlib reads $...$ in a text as mathtext: this name stopped --png with a traceback
    drawn = picture.render_png(np.ones(100), 10.0, a_map((1.0, 3.0, 5.0)), "x$\\foo{$y.wav: 120 bpm", io.BytesIO())
    assert drawn.bars == 2


def test_peaks_keep_a_lone_onset_at_its_height():
    values = np.zeros(10_001)
    values[5_000] = 3.0
    times, highest = picture.peaks(values, 100.0, 100)
    assert len(highest) == 100 and highest.max() == 3.0
    assert abs(times[highest.argmax()] - 50.0) < 0.6


def test_choreo_help_does_not_load_numpy_miniaudio_or_matplotlib():
    code = ("import sys; from choreo.cli import build_parser; build_parser(); "
            "print(sorted({'numpy', 'miniaudio', 'matplotlib'} & set(sys.modules)))")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=60, check=True).stdout
    assert out.strip() == "[]"


def test_help_says_what_the_click_track_is():
    done = subprocess.run([sys.executable, "-m", "choreo", "beats", "--help"], capture_output=True, text=True,
                          timeout=60, check=True, env={**os.environ, "COLUMNS": "200"})
    assert CLICK_FORMAT in " ".join(done.stdout.split()) and "--png OUT.png" in done.stdout
    # the help is built without numpy, so it spells the writer's figures: they must agree
    written = f"16-bit PCM WAV, {click.CLICK_RATE} Hz {'stereo' if click.CLICK_CHANNELS == 2 else 'mono'}"
    assert written == CLICK_FORMAT
    (lo, hi), (fewest, most) = beats.BPM_RANGE, beats.METER_LIMITS
    assert f"(default {lo:g}..{hi:g})" in done.stdout and f"{fewest}..{most} (default 4)" in done.stdout
