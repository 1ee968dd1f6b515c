"""The sound library's noise is silenced at its source, and nothing takes file descriptor 2 from
the rest of the process: the console, OSC and progress lines written while music opens arrive."""

from __future__ import annotations

import contextlib
import ctypes
import os
import sys
import threading
from pathlib import Path

import miniaudio
import pytest

from choreo.cli import main
from choreo.music import alsa
from choreo.music.player import NULL_OUTPUT, AudioError, outputs, try_output
from test_music import music_show, write_song


def guard_fd_2(monkeypatch: pytest.MonkeyPatch) -> list[int]:
    """choreo's code calling os.dup2 onto fd 2 fails the test; returns the descriptors choreo asked
    dup2 to replace (pytest's own output capture dups onto fd 2 too: that is not choreo's)."""
    real = os.dup2
    targets: list[int] = []

    def dup2(fd: int, fd2: int, inheritable: bool = True) -> int:
        if sys._getframe(1).f_globals.get("__name__", "").startswith("choreo"):
            targets.append(fd2)
            if fd2 == 2:
                raise AssertionError("choreo pointed file descriptor 2 elsewhere")
        return real(fd, fd2, inheritable)

    monkeypatch.setattr(os, "dup2", dup2)
    return targets


def test_devices_doctor_and_a_music_run_never_point_fd_2_elsewhere(tmp_path: Path, monkeypatch, capsys):
    targets = guard_fd_2(monkeypatch)
    assert main(["devices"]) == 0
    with contextlib.suppress(AudioError):
        try_output(None)  # the default output: on a machine without a sound card, ALSA's noisiest path
    assert try_output(NULL_OUTPUT) == "Null"
    assert main(["doctor", "--no-probe"]) in (0, 1)  # its audio check opens the default output
    write_song(tmp_path / "song.wav", 0.4)
    show = music_show(tmp_path, "{file: song.wav}", "  - play: 1\n    at: 0.1\n")
    assert main(["run", str(show), "--no-log"]) == 0  # the default output, or null where it will not open
    assert 2 not in targets
    assert "ALSA lib" not in capsys.readouterr().err


def another_thread_writes(line: str) -> None:
    """A line written to sys.stderr and one to fd 2 by another thread, finished before returning:
    what the console or the OSC thread does while the main thread opens the music."""

    def write() -> None:
        sys.stderr.write(f"{line} (sys.stderr)\n")
        sys.stderr.flush()
        os.write(2, f"{line} (fd 2)\n".encode())

    thread = threading.Thread(target=write)
    thread.start()
    thread.join()


def test_a_line_another_thread_writes_while_the_outputs_are_listed_or_opened_arrives(monkeypatch, capfd):
    class Devices:
        backend = "ALSA"

        def __init__(self) -> None:
            another_thread_writes("listing")

        def get_playbacks(self) -> list[dict]:
            return [{"name": "Card", "id": "id"}]

    def playback_device(*args, **kwargs):  # type: ignore[no-untyped-def]
        another_thread_writes("opening")
        raise miniaudio.MiniaudioError("failed to init device", -401)

    monkeypatch.setattr(miniaudio, "Devices", Devices)
    monkeypatch.setattr(miniaudio, "PlaybackDevice", playback_device)
    assert [o.name for o in outputs()] == ["Card", "null"]
    with pytest.raises(AudioError, match="will not open"):
        try_output(None)
    err = capfd.readouterr().err
    for line in ("listing (sys.stderr)", "listing (fd 2)", "opening (sys.stderr)", "opening (fd 2)"):
        assert line in err


def open_unknown_pcm(library: alsa.Alsa) -> None:
    """Ask ALSA for a PCM no configuration names: it writes why it failed through its handler."""
    pcm = ctypes.c_void_p()
    assert library.library.snd_pcm_open(ctypes.byref(pcm), b"choreo_test_no_such_pcm", 0, 0) < 0


def test_alsas_lines_are_dropped_at_their_source_and_its_handler_put_back(capfd):
    library = alsa.alsa()
    if library is None:
        pytest.skip("no libasound on this machine: nothing to silence")
    before = library.handler_address()
    open_unknown_pcm(library)
    if "choreo_test_no_such_pcm" not in capfd.readouterr().err:
        pytest.skip("this libasound says nothing of an unknown PCM")
    with alsa.quiet():
        with alsa.quiet():  # nested (two threads opening outputs): still silent after the inner one
            open_unknown_pcm(library)
        open_unknown_pcm(library)
        assert library.handler_address() != before
    assert capfd.readouterr().err == ""
    assert library.handler_address() == before and library.users == 0
    open_unknown_pcm(library)  # ALSA's own handler again: the line is printed as before
    assert "choreo_test_no_such_pcm" in capfd.readouterr().err


def test_opening_the_default_output_says_nothing_of_alsas_on_stderr(capfd):
    outputs()
    with contextlib.suppress(AudioError):  # no sound card: choreo says so in its own words where it matters
        try_output(None)
    assert "ALSA lib" not in capfd.readouterr().err
