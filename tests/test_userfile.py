"""Every file a user names is opened one way (choreo.userfile, issue 21 item 6): a folder, a
named pipe, a device, a link to nothing, a loop of links, a name too long or a file too big is
one line saying so, at once (a pipe used to block for ever, a link to /dev/zero was "no such
file"), and a read that fails says it could not read (it used to say it could not write)."""

from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

import pytest

from choreo.errors import InputError, ShowError
from choreo.music.player import AudioError, Song
from choreo.show.load import load_show
from choreo.show.model import Music
from choreo.userfile import listing, open_input, problem, read_input, reading

ROOT = Path(__file__).resolve().parent.parent
needs_fifo = pytest.mark.skipif(not hasattr(os, "mkfifo"), reason="no named pipes here")
needs_dev_zero = pytest.mark.skipif(not os.path.exists("/dev/zero"), reason="no /dev/zero here")


@pytest.fixture
def odd(tmp_path) -> Path:
    """A folder of things that are not regular files, each named like one."""
    (tmp_path / "folder.wav").mkdir()
    (tmp_path / "gone.wav").symlink_to(tmp_path / "nothing.wav")
    (tmp_path / "loop-a.wav").symlink_to(tmp_path / "loop-b.wav")
    (tmp_path / "loop-b.wav").symlink_to(tmp_path / "loop-a.wav")
    if hasattr(os, "mkfifo"):
        os.mkfifo(tmp_path / "fifo.wav")
    if os.path.exists("/dev/zero"):
        (tmp_path / "zero.wav").symlink_to("/dev/zero")
    return tmp_path


KINDS = [
    ("folder.wav", "not a regular file (a folder): give a sound file"),
    ("gone.wav", "cannot read the sound file: it is a link to '{tmp}/nothing.wav', which does not exist"),
    ("loop-a.wav", "cannot read the sound file: a loop of symbolic links"),
    ("missing.wav", "cannot read the sound file: No such file or directory"),
    ("x" * 300 + ".wav", "cannot read the sound file: the name is too long for this system"),
    pytest.param("fifo.wav", "not a regular file (a named pipe): give a sound file", marks=needs_fifo),
    pytest.param("zero.wav", "not a regular file (a device): give a sound file", marks=needs_dev_zero),
]


@pytest.mark.parametrize("name, says", KINDS)
def test_each_kind_of_non_file_is_said_to_be_what_it_is(odd, name, says):
    says = says.format(tmp=odd)
    assert problem(odd / name, "sound file") == says
    with pytest.raises(InputError) as info:
        read_input(odd / name, "sound file", 1024)
    assert str(info.value) == f"{odd / name}: {says}"


@pytest.mark.parametrize("name, says", KINDS)
def test_a_shows_music_is_checked_the_same_way(odd, name, says):
    """It was "no such file" for a pipe or a link to /dev/zero."""
    show = odd / "show.yaml"
    show.write_text(f"version: 1\nmusic: {{file: '{name}'}}\nsteps:\n  - play: 1\n", encoding="utf-8")
    with pytest.raises(ShowError) as info:
        load_show(show)
    assert f"music.file: {name}: {says.format(tmp=odd)} (" in info.value.lines()[0]


@pytest.mark.parametrize("name, says", KINDS)
def test_the_song_of_a_run_is_checked_before_the_decoder_sees_it(odd, name, says):
    with pytest.raises(AudioError) as info:
        Song.open(Music(name, folder=str(odd)), "show.yaml")
    assert str(info.value).startswith(f"show.yaml: music.file {name}: {says.format(tmp=odd)} (")


@needs_fifo
@pytest.mark.parametrize("argv", [["beats"], ["import"], ["validate"], ["log", "summary"], ["log", "frames"],
                                  ["replay"]])
def test_no_command_waits_on_a_named_pipe(tmp_path, argv):
    fifo = tmp_path / "input"
    os.mkfifo(fifo)
    done = subprocess.run([sys.executable, "-m", "choreo", *argv, str(fifo)], capture_output=True, text=True,
                          timeout=30, cwd=ROOT)  # it used to block until the timeout failed the test
    assert (done.returncode, done.stdout) == (2, ""), done.stderr
    assert "not a regular file (a named pipe)" in done.stderr and done.stderr.count("\n") == 1


def test_a_file_over_the_limit_is_refused_before_it_is_read(tmp_path):
    big = tmp_path / "big.h4p"
    big.write_bytes(b"x" * 2048)
    with pytest.raises(InputError, match=r"big.h4p: the file is over 1 KiB, too big for a project$"):
        read_input(big, "project", 1024)
    assert read_input(big, "project", 2048) == b"x" * 2048


def test_a_file_that_grows_past_the_limit_after_it_was_looked_at_is_still_refused(tmp_path, monkeypatch):
    """/proc files say size 0 and then have bytes; a file may grow between fstat and read."""
    path = tmp_path / "grows"
    path.write_bytes(b"x" * 100)
    real_fstat = os.fstat
    monkeypatch.setattr(os, "fstat", lambda fd: os.stat_result((*real_fstat(fd)[:6], 0, *real_fstat(fd)[7:])))
    with pytest.raises(InputError, match="too big"):
        read_input(path, "show file", 50)


@pytest.mark.skipif(not os.path.exists("/proc/self/mem"), reason="no /proc here")
def test_a_failed_read_is_an_input_error_that_says_read():
    """/proc/self/mem is a regular file whose first bytes cannot be read (EIO)."""
    with (open_input("/proc/self/mem", "show file") as stream,
          pytest.raises(InputError, match=r"^/proc/self/mem: cannot read the show file: Input/output error$"),
          reading("/proc/self/mem", "show file")):
        stream.read(10)
    with pytest.raises(InputError, match=r"^/proc/self/mem: cannot read the show file: Input/output error$"):
        read_input("/proc/self/mem", "show file", 1024)


def test_a_file_name_with_control_characters_is_shown_escaped(tmp_path):
    name = tmp_path / "evil\x1b]0;owned\x07\u202e.wav"
    with pytest.raises(InputError) as info:
        read_input(name, "sound file", 10)
    message = str(info.value)
    assert "\x1b" not in message and "\x07" not in message and "\u202e" not in message
    assert "evil\\x1b]0;owned\\x07\\u202e.wav: cannot read the sound file" in message


def test_a_folder_that_cannot_be_listed_is_an_error_not_an_empty_folder(tmp_path):
    assert listing(tmp_path) == []
    with pytest.raises(InputError, match="nope: cannot read the folder: No such file or directory"):
        listing(tmp_path / "nope")
    (tmp_path / "file").write_text("x")
    with pytest.raises(InputError, match=r"file: not a folder \(a file\): give a log folder"):
        listing(tmp_path / "file", "log folder")


def test_a_name_no_file_can_have_is_one_line(tmp_path):
    """A show can spell a NUL (`"a\\0b.wav"`): os.stat raises ValueError, not OSError."""
    says = ("cannot read the sound file: no file can have this name (it holds a NUL or a character the system "
            "cannot encode)")
    assert problem(tmp_path / "a\0b.wav", "sound file") == says
    show = tmp_path / "show.yaml"
    show.write_text('version: 1\nmusic: {file: "a\\0b.wav"}\nsteps:\n  - play: 1\n', encoding="utf-8")
    with pytest.raises(ShowError) as info:
        load_show(show)
    assert f"music.file: a\\x00b.wav: {says} (" in info.value.lines()[0]  # printed escaped
    with pytest.raises(InputError, match=r"cannot read the log folder: no file can have this name"):
        listing(tmp_path / "a\0b", "log folder")


def test_an_output_folder_that_is_a_loop_or_a_link_to_nothing_says_so_in_every_command(tmp_path, capsys):
    """A folder that is a loop of links, or a link to nothing, was 'does not exist' (issue 21):
    every output's folder (--log, -o, --png, --parquet) is judged by userfile.folder_problem."""
    from choreo.cli import main
    from choreo.userfile import folder_problem

    os.symlink(tmp_path / "loop", tmp_path / "loop")
    os.symlink(tmp_path / "gone", tmp_path / "dangling")
    (tmp_path / "file").write_text("x")
    assert folder_problem(tmp_path) is None
    assert folder_problem(tmp_path / "nope") == "does not exist (create it first)"
    assert folder_problem(tmp_path / "loop") == "cannot be used: a loop of symbolic links"
    assert folder_problem(tmp_path / "dangling").startswith("cannot be used: it is a link to ")
    assert folder_problem(tmp_path / "file") == "is not a folder (a file)"
    assert folder_problem(tmp_path / ("n" * 300)) == "cannot be used: the name is too long for this system"
    show = Path("shows/minimal.yaml").resolve()
    for argv in (["run", str(show), "--log", str(tmp_path / "loop" / "x.mcap"), "--port", "sim://", "-q"],
                 ["run", str(show), "--log", str(tmp_path / "dangling" / "x.mcap"), "--port", "sim://", "-q"]):
        assert main(argv) == 2
        err = capsys.readouterr().err.strip().splitlines()
        assert len(err) == 1 and "cannot write: folder" in err[0] and "does not exist (create" not in err[0], err
