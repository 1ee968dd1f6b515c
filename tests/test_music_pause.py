"""Pausing the music's clock (`p`, `/choreo/pause`): show time stands, the song is silent without
moving on, and both go on from where the listener heard them.

The clock and feed are driven by hand here, as a device would (a fake pace, fake time), so the
frame the song resumes at and the show time at each moment are exact; one show runs for real on
miniaudio's null output, paused from another thread, with bounds generous for a loaded machine.
"""

from __future__ import annotations

import itertools
import math
import random
import threading
import time
from pathlib import Path

import pytest

from choreo.clock import PAUSED, RUNNING, PausableShowClock
from choreo.events import StopRequest
from choreo.music.player import LATENCY_S, REWIND_S, Feed, MusicClock, Song
from choreo.run.session import Session
from choreo.run.settings import RunRequest
from choreo.show.model import Music
from runlog import read_log, started_on_cue, write_show
from test_music import RATE, frames_of, write_song

PERIOD = 80  # frames a request: 10 ms at RATE
LEAD_IN = 800  # 0.1 s of silence before the show's first moment
FIRST_SHOW_S = -0.1  # the lead-in's first frame


class Device:
    """A sound card on a perfect crystal pulling from a feed: request n comes when its buffer
    has room (at `start` + n periods, up to `jitter_s` late); device frame d is heard at
    `heard0` + d / RATE. `out` is every frame it played (the left channel)."""

    def __init__(self, tmp_path: Path, jitter_s: float = 0.0, seconds: float = 1.0) -> None:
        music = Music("song.wav", folder=str(write_song(tmp_path / "song.wav", seconds).parent))
        self.t = 100.0
        self.heard0 = self.t + LATENCY_S
        self.clock = MusicClock(RATE, FIRST_SHOW_S, now=lambda: self.t, wake=self._woken)
        self.feed = Feed(Song(music, RATE, seconds), self.clock, LEAD_IN / RATE, 0.0, now=lambda: self.t)
        self.pull = self.feed.generator()
        next(self.pull)
        self.out: list[int] = []
        self.wakes = 0
        self.jitter_s = jitter_s
        self._rng = random.Random(3)

    def _woken(self) -> None:
        self.wakes += 1

    def play(self, requests: int) -> None:
        for _ in range(requests):
            due = self.heard0 + len(self.out) / RATE - LATENCY_S
            self.t = due + self._rng.random() * self.jitter_s
            self.out += frames_of(self.pull.send(PERIOD))

    def at(self, mono: float) -> float:
        """The operator's thread acts at `mono` (between requests)."""
        self.t = mono
        return mono

    def heard_at(self, mono: float) -> int:
        """The device frame heard at `mono`."""
        return math.floor((mono - self.heard0) * RATE + 1e-6)


def song_frame(show_s: float) -> int:
    """The file's frame heard at show time `show_s` (the song starts after the lead-in)."""
    return math.floor((show_s - FIRST_SHOW_S) * RATE + 1e-6) - LEAD_IN


def test_the_music_clock_pauses_and_resumes_where_it_was_heard(tmp_path):
    device = Device(tmp_path)
    clock = device.clock
    assert isinstance(clock, PausableShowClock) and clock.state == RUNNING
    device.play(50)  # 0.5 s handed: show frames 0..3999
    pause_mono = device.at(device.heard0 + 0.4751)  # show time 0.3751 is heard: file frame 3000
    stood = clock.pause()
    assert stood == pytest.approx(0.3751, abs=1e-9) and clock.state == PAUSED
    assert clock.pause() == stood  # twice: harmless, the same time
    device.play(30)  # 0.3 s of the pause
    assert device.out[4000:6400] == [0] * 2400 and device.feed.paused == 2400  # silence, the song's place kept
    assert device.feed.position == 4000 and device.feed.handed == 6400
    for mono in (pause_mono, device.t, device.t + 5.0):
        assert clock.show_at(mono) == stood  # show time stands
    assert clock.mono_at(stood + 0.001) == math.inf  # a later cue never comes while paused
    assert clock.mono_at(0.2) == pytest.approx(device.heard0 + 0.3)  # an earlier one came when it was heard
    resume_mono = device.at(device.t + 0.005)
    clock.resume()
    assert clock.state == RUNNING and device.wakes == 1
    device.play(30)
    # the song goes on from the frame heard at the pause, at the first device frame after the resume
    resumed = device.out[6400:8800]
    assert resumed == list(range(3000, 5400)) and device.out[800:4000] == list(range(3200))
    # show time stood until that frame was heard, then runs with what is heard, never backwards
    restart = device.heard0 + 6400 / RATE
    assert clock.show_at(resume_mono) == stood and clock.show_at(restart - 0.001) == stood
    assert clock.mono_at(0.375) == pytest.approx(restart)
    for mono in [restart + k * 0.0173 for k in range(1, 12)]:
        show_s = clock.show_at(mono)
        assert song_frame(show_s) == device.out[device.heard_at(mono)]
    times = [clock.show_at(pause_mono - 0.1 + k * 0.001) for k in range(1000)]
    assert times == sorted(times)


def test_resumed_show_time_agrees_with_what_is_heard_through_wake_up_jitter(tmp_path):
    """The clock's estimate is kept on the device's frames, pause silence included: after a
    resume it is as good as before (it does not start over, nor keep the pause in it)."""
    device = Device(tmp_path, jitter_s=0.004, seconds=4.0)
    clock = device.clock
    device.play(150)
    device.at(device.t + 0.003)
    stood = clock.pause()
    device.play(73)
    device.at(device.t + 0.007)
    clock.resume()
    device.play(150)
    for mono in [device.t - k * 0.0371 for k in range(1, 30)]:
        heard = device.out[device.heard_at(mono)]
        assert heard > song_frame(stood) or clock.show_at(mono) == stood
        assert clock.show_at(mono) == pytest.approx((heard + LEAD_IN) / RATE + FIRST_SHOW_S, abs=2e-4)


def test_a_second_pause_and_a_pause_in_the_lead_in(tmp_path):
    device = Device(tmp_path)
    clock = device.clock
    device.play(12)  # 120 ms handed: the lead-in and 40 ms of song
    device.at(device.heard0 + 0.05)
    assert clock.pause() == pytest.approx(-0.05)  # in the lead-in: show frame 400
    device.play(10)
    clock.resume()
    device.play(20)  # the rest of the lead-in, then the song from its first frame
    assert device.out[960:2160] == [0] * 1200 and device.out[2160:3360] == list(range(1200))
    mono = device.at(device.t + 0.0013)
    second = clock.pause()
    frame = song_frame(second)
    assert frame == device.out[device.heard_at(mono)] > 0
    device.play(5)
    clock.resume()
    device.play(10)
    assert device.out[3360:3760] == [0] * 400 and device.out[3760:4560] == list(range(frame, frame + 800))
    assert device.feed.paused == 1200 and device.feed.handed == 4560 and device.wakes == 2


def test_resume_when_not_paused_does_nothing(tmp_path):
    device = Device(tmp_path)
    clock = device.clock
    device.play(20)
    before = clock.show_at(device.t)
    clock.resume()
    assert clock.state == RUNNING and device.wakes == 0 and clock.show_at(device.t) == before
    device.play(20)
    assert device.out[800:2400] == list(range(1600)) and device.feed.paused == 0



def test_pauses_from_another_thread_never_tear_the_song_or_the_clock(tmp_path):
    """The operator's thread pauses and resumes at any moment while the audio thread hands
    chunks and a runner reads show time: the song only ever goes on or steps back to where a
    pause was heard, show time never goes back, and afterwards the clock still says what is heard."""
    device = Device(tmp_path, seconds=3.0)
    clock = device.clock
    device.play(20)
    done = threading.Event()
    times: list[float] = []

    def operator() -> None:
        while not done.is_set():
            clock.pause()
            time.sleep(0.0005)
            clock.resume()
            time.sleep(0.0005)

    def runner() -> None:
        while not done.is_set():
            times.append(clock.show_at(device.t))
            time.sleep(0)

    threads = [threading.Thread(target=operator), threading.Thread(target=runner)]
    for thread in threads:
        thread.start()
    try:
        for _ in range(150):
            device.play(1)
            time.sleep(0.0003)
    finally:
        done.set()
        for thread in threads:
            thread.join()
    clock.resume()
    device.play(30)
    assert times == sorted(times) and device.wakes > 0
    song = [frame for n, frame in enumerate(device.out) if n >= LEAD_IN and frame]  # the pause's silence out
    steps = {after - before for before, after in itertools.pairwise(song)}
    assert all(step == 1 or -REWIND_S * RATE <= step <= 0 for step in steps), sorted(steps)
    assert device.feed.paused > 0
    for mono in [device.t - k * 0.0037 for k in range(20)]:
        assert song_frame(clock.show_at(mono)) == device.out[device.heard_at(mono)]


# --------------------------------------------------------------------------- for real


PAUSED_SHOW = """\
version: 1
music: {file: song.wav}
motions:
  bow: {number: 1, duration: 0.05}
steps:
  - play: bow
    at: 0.1
    label: first
  - play: bow
    at: 0.5
    label: after
"""


class PauseAtFirstStep:
    """Pauses the show's music clock as its first step starts and resumes it `pause_s` later,
    from other threads; notes when (machine time) each thing happened."""

    def __init__(self, session: Session, pause_s: float) -> None:
        self.session = session
        self.pause_s = pause_s
        self.events: list[tuple[str, float]] = []
        self.stood: float | None = None
        self.feed: Feed | None = None

    def on_step(self, event) -> None:  # type: ignore[no-untyped-def]
        self.events.append((f"{event.event} {event.step.label}", time.monotonic()))
        if event.event == "start" and event.step.label == "first":
            threading.Thread(target=self._pause).start()

    def on_log(self, *args) -> None:  # type: ignore[no-untyped-def]
        pass

    def _pause(self) -> None:
        player = self.session.player
        assert player is not None and player.clock is not None
        self.feed = player.feed
        self.stood = player.clock.pause()
        self.events.append(("pause", time.monotonic()))
        time.sleep(self.pause_s)
        self.events.append(("resume", time.monotonic()))
        player.clock.resume()
        self.events.append(("resumed", time.monotonic()))  # the resume lies between the two


def test_a_music_show_paused_for_a_moment_goes_on_from_where_it_stood(tmp_path):
    write_song(tmp_path / "song.wav", 1.0)
    log_path = tmp_path / "run.mcap"
    session = Session.prepare(RunRequest(str(write_show(tmp_path, PAUSED_SHOW)), log_path=str(log_path),
                                         audio_device="null"))
    pauser = PauseAtFirstStep(session, 0.3)
    with session:
        assert session.run([pauser], StopRequest()).outcome == "done"
    order = [name for name, _ in sorted(pauser.events, key=lambda e: e[1])]
    assert order.index("pause") < order.index("resume") < order.index("start after"), order
    assert pauser.stood is not None and 0.05 < pauser.stood < 0.5
    assert pauser.feed is not None and pauser.feed.paused > 0  # silence handed while paused
    when = dict(pauser.events)
    paused_for = when["resume"] - when["pause"]
    log = read_log(log_path)
    steps = log.topic("/choreo/step")
    # the step after the pause started on its cue on the music's clock, not the pause late
    after = next(m for m in steps if m["event"] == "end" and m["label"] == "after")
    assert started_on_cue(steps, after), steps
    # show time went on from where it stood: over the run, the machine's clock got ahead of
    # the show by the pause (and the wait for the resumed song to be heard, a few buffers)
    clock = [m for m in log.topic("/choreo/clock") if m["monotonic_ns"] / 1e9 > when["resume"] + 0.1]
    assert clock, log.topic("/choreo/clock")
    for sample in clock:
        # bracketed by the instants before and after resume() (a thread put off between them
        # on a loaded machine moves neither bound the wrong way)
        went_on = sample["show_s"] - pauser.stood
        ahead = [sample["monotonic_ns"] / 1e9 - when[at] - went_on for at in ("resume", "resumed")]
        assert ahead[0] > -0.05 and ahead[1] < 0.1, (ahead, paused_for)  # a clock that ran through the pause: -0.3


def test_a_pause_in_the_musics_play_out_stands_it_still_and_a_stop_ends_it(tmp_path):
    """The last step is done and the song plays out (the show is over on stage, not in the
    sound): a pause stands the music and show time still, as anywhere in the show; a stop
    then ends the run at once, the music stopped (state only: real time, the null output)."""
    from choreo.clock import PAUSED
    from runlog import LiveRun, wait_for

    write_song(tmp_path / "song.wav", 30.0)
    body = "version: 1\nmusic: {file: song.wav}\nsteps:\n  - play: 1\n    label: only\n"

    class PlayOut:
        """Hears the run's steps and when the music's play-out begins."""

        def __init__(self) -> None:
            self.began = threading.Event()

        def on_step(self, event) -> None:  # type: ignore[no-untyped-def]
            pass

        def on_log(self, *args) -> None:  # type: ignore[no-untyped-def]
            pass

        def on_play_out(self, end_s: float) -> None:
            self.began.set()

    out = PlayOut()
    run = LiveRun(tmp_path, body, cues=True, audio_device="null", attach=lambda live: [out])
    assert out.began.wait(10)
    assert run.go("pause").ok and run.live.show is not None and run.live.show.state == PAUSED
    stood = run.live.status()["show_s"]
    assert wait_for(lambda: run.session.player is not None and run.session.player.feed is not None
                    and run.session.player.feed.paused > 0, 5, 0.005)  # silence handed: the song stands
    assert run.live.status()["show_s"] == stood and run.thread.is_alive()
    assert run.go("stop").ok
    run.finish(5)
    assert run.error is None and run.result is not None and run.result.outcome == "done"
    assert run.session.player is None  # the music was stopped and closed
