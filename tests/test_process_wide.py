"""Process-wide settings a run changes while other threads run are held by one owner: the
interpreter's switch interval (issue 22: nothing process-wide is left changed, or changed under
another run's feet); and what a run opens for the process (the sound output) is closed by
whoever opened it when its start fails."""

from __future__ import annotations

import sys
import threading

import pytest

from choreo.clock import SWITCH_S, quick_thread_switches

QUICK = pytest.approx(SWITCH_S, abs=1e-6)  # the interpreter keeps it in whole microseconds


def test_overlapping_runs_on_two_threads_keep_switches_quick_until_the_last_ends():
    """Run A (one thread) starts, run B (another) starts, A ends, B ends: each block saving and
    restoring on its own left B's threads switching every 5 ms once A ended, and the process
    at SWITCH_S for good once B ended (it restored what it saw at its start: A's setting)."""
    before = sys.getswitchinterval()
    assert before != QUICK
    a_in, b_in, a_out, b_out = (threading.Event() for _ in range(4))
    seen: dict[str, float] = {}

    def run_a() -> None:
        with quick_thread_switches():
            a_in.set()
            b_in.wait(5)
        a_out.set()

    def run_b() -> None:
        a_in.wait(5)
        with quick_thread_switches():
            b_in.set()
            a_out.wait(5)
            seen["b after a ended"] = sys.getswitchinterval()
        b_out.set()

    threads = [threading.Thread(target=run_a), threading.Thread(target=run_b)]
    for thread in threads:
        thread.start()
    for thread in threads:
        thread.join(10)
    assert b_out.is_set()
    assert seen["b after a ended"] == QUICK
    assert sys.getswitchinterval() == before


def test_nested_blocks_put_back_what_was_there():
    before = sys.getswitchinterval()
    with quick_thread_switches():
        with quick_thread_switches():
            assert sys.getswitchinterval() == QUICK
        assert sys.getswitchinterval() == QUICK
    assert sys.getswitchinterval() == before


def test_an_output_that_opens_but_will_not_start_is_closed_and_said_in_one_line(tmp_path, capsys, monkeypatch):
    """The music player opened the output, then its start failed: the device was left open
    (the run's close of the music was not wired yet) and miniaudio's error came out as a
    traceback. Now the player closes what it opened and the run ends with one line."""
    import miniaudio

    from choreo.cli import main
    from test_music import music_show, write_song

    opened: list[Refusing] = []

    class Refusing:
        backend = "Null"

        def __init__(self, *args: object, **kwargs: object) -> None:
            self.closed = False
            opened.append(self)

        def start(self, generator: object) -> None:
            raise miniaudio.MiniaudioError("failed to start device", -300)

        def close(self) -> None:
            self.closed = True

    monkeypatch.setattr(miniaudio, "PlaybackDevice", Refusing)
    write_song(tmp_path / "song.wav", 0.5)
    show = music_show(tmp_path, "{file: song.wav}", "  - play: 1\n    at: 0.1\n")
    assert main(["run", str(show), "--no-log", "--port", "sim://"]) == 2
    err = capsys.readouterr().err
    assert "Traceback" not in err
    assert err.splitlines()[-1].startswith("the audio output (Null) will not start playing (failed to start device)")
    assert [device.closed for device in opened] == [True]
