"""The show's music: its file checked before the stage opens, played through miniaudio, and the
show clock read from the playing song.

Show time is the position of the sample leaving the sound device, not the machine's clock: a
sound card's crystal drifts against the computer's by tens of parts per million (a few ms over
a song), and the audience hears the card. Each time the device asks for more samples (every
`PERIOD_MS`), the feed notes how many it has handed over and when; handed-over samples wait
`latency_s` in the device's buffer before they are heard. A late callback (the thread woke
late) would make the music seem late, an early one cannot happen, so the clock takes the
earliest reading of the last `WINDOW_S`: that follows drift and ignores wake-up jitter.

The Python binding of miniaudio does not report the device's own latency; the clock takes the
buffer choreo asks for ((periods - 1) x period, 20 ms) as the latency. Output stages beyond the
sound card (a Bluetooth speaker, a mixing desk's processing) add their own delay, which no
computer can see; `--audio-latency` (not yet) would be the place for it.

Pausing (`p`, `/choreo/pause`) stops the song and the show time with it; the device plays on,
handed silence, so the clock's estimate is kept on the device's frames (silence included): the
card's position does not stop, and neither does its reading. Show time is that position less
the silence handed since the show began. Samples already handed when the pause comes are heard
after it (up to `latency_s` and a period, 20-30 ms): the song resumes where the listener heard
it at the pause, not where it had been handed, so the last few ms before the pause are heard
twice. That is the faithful choice for a show: the show time stood at the heard position, and
on resume it goes on with the music from there, every cue after it on its beat; resuming where
the song was handed would put the show clock that far behind the music for the rest of the show,
or make it jump forward over the cues in between.

miniaudio is imported only here and only when music plays, so `choreo validate` and
`choreo --help` do not pay for it.
"""

from __future__ import annotations

import contextlib
import math
import threading
import time
from collections import deque
from collections.abc import Callable, Generator, Iterator
from dataclasses import dataclass, field
from typing import Any

from choreo.clock import PAUSED, RUNNING
from choreo.errors import ChoreoError, UsageError
from choreo.music import alsa
from choreo.numtext import whole_number
from choreo.show.model import MUSIC_FORMATS_TEXT, Music
from choreo.userfile import problem

PERIOD_MS = 10  # how much the device asks for at a time
PERIODS = 3  # periods in the device's buffer
LATENCY_S = (PERIODS - 1) * PERIOD_MS / 1000  # how long a sample handed over waits to be heard
WINDOW_S = 2.0  # the clock's earliest reading over this long is its estimate
LOCK_CALLBACKS = PERIODS + 4  # readings before the clock is trusted: past the buffer's prefill
LOCK_S = 0.1  # and machine time they must span: long enough to see an output that is not real time
LOCK_TIMEOUT_S = 2.0
# An output that takes samples faster or slower than this against the machine's clock is not
# playing them in real time (ALSA's "Discard all samples" takes them as fast as they come): its
# position would be no clock. Sound cards drift by parts per million, not per cent.
RATE_TOLERANCE = 0.05
LEAD_IN_S = 0.25  # silence before the show's first moment: time for the clock to settle
CHANNELS = 2
# How far back a pause may put the song: the samples handed but not yet heard (the buffer, a
# period, the estimate's error) are far less; the feed keeps this much of the song it handed.
REWIND_S = 0.25
NULL_DEVICE = "null"  # --audio-device null: miniaudio's null backend, silent, in real time


class AudioError(ChoreoError):
    """The music cannot play: a file that does not decode, a device that does not open (exit 2:
    nothing was sent to any robot)."""

    exit_code = 2


# --------------------------------------------------------------------------- the file


@dataclass(frozen=True)
class Song:
    """A show's music file, decodable, with what playing it needs to know."""

    music: Music
    sample_rate: int
    duration_s: float

    @property
    def path(self) -> str:
        return str(self.music.path)

    @property
    def end_show_s(self) -> float:
        """The show time at which the song's last sample is heard."""
        return self.duration_s - self.music.start

    @classmethod
    def open(cls, music: Music, show_path: str) -> Song:
        """The song's facts, read from its header; AudioError naming the show if it will not
        decode or `start` is past its end (before any port opens)."""
        import miniaudio

        where = f"{show_path}: music.file {music.file}"
        unreadable = problem(music.path, "sound file")  # a pipe or a device would hang the decoder
        if unreadable is not None:
            raise AudioError(f"{where}: {unreadable} ({music.path})")
        try:
            info = miniaudio.get_file_info(str(music.path))
        except (miniaudio.DecodeError, OSError) as exc:
            raise AudioError(f"{where}: cannot decode it ({_reason(exc)}): "
                             f"is it a {MUSIC_FORMATS_TEXT} file?") from None
        if info.sample_rate <= 0 or info.num_frames <= 0:
            raise AudioError(f"{where}: the file holds no sound")
        song = cls(music, int(info.sample_rate), info.num_frames / info.sample_rate)
        if music.start >= song.duration_s:
            raise AudioError(f"{show_path}: music.start {music.start:g} s is past the end of {music.file} "
                             f"({song.duration_s:.1f} s long)")
        return song

    def frames(self, seconds: float) -> int:
        return round(seconds * self.sample_rate)


def _reason(exc: BaseException) -> str:
    return " ".join(str(arg) for arg in exc.args if isinstance(arg, str)) or type(exc).__name__


# --------------------------------------------------------------------------- the clock


@dataclass(frozen=True)
class _Course:
    """Where show time stands against the device's frames, swapped whole (one attribute read
    is atomic): the runners read it without a lock, and never half of a pause or a resume."""

    paused: bool = False
    gap_s: float = 0.0  # the device's seconds of pause silence before the show's current stretch
    floor_s: float = -math.inf  # show time never goes below the time the last pause stood at


def _nothing() -> None:
    pass


@dataclass
class MusicClock:
    """Show time from the playing music (see the module's docstring); a `PausableShowClock`.

    `first_show_s`: the show time of the first sample handed to the device (the lead-in's
    first, a little before the show's start). `now` times a pause; `wake` (the run's time
    source's `notify`) is called on resume, so runners dozing towards a later cue, whose time
    was out of reach while paused, look again at once rather than a sleep slice later.

    The audio thread tells `handed_over` and asks `chunk`; the operator's thread calls `pause`
    and `resume`; the runners read `show_at` and `mono_at`. The lock is held for a few
    sums, never while a sample is decoded: the audio callback never waits long."""

    sample_rate: int
    first_show_s: float
    latency_s: float = LATENCY_S
    window_s: float = WINDOW_S
    readings: int = 0
    first_mono: float | None = None  # when the device first asked
    handed_s: float = 0.0  # the samples handed over so far (pause silence too), in seconds
    last_mono: float | None = None  # when the device last asked
    now: Callable[[], float] = time.monotonic
    wake: Callable[[], None] = _nothing
    _zero: float | None = None  # monotonic time the device's first sample is heard (estimate)
    _window: deque = field(default_factory=deque)  # (mono, zero) with increasing zeros
    _course: _Course = field(default_factory=_Course)
    _lock: threading.Lock = field(default_factory=threading.Lock, repr=False)
    _next_frame: int = 0  # the device's frames handed, the chunk being handed included
    _gap_frames: int = 0  # the device's frames of pause silence before the current stretch
    _resume_frame: int = 0  # while paused: the show's frame (from the first handed) to go on from

    def handed_over(self, mono: float, frames_before: int) -> None:
        """The device asked for samples at `mono`, `frames_before` having been handed over
        already (pause silence included: the device's frames): the sample handed over now is
        heard `latency_s` later."""
        zero = mono - frames_before / self.sample_rate + self.latency_s
        if self.first_mono is None:
            self.first_mono = mono
        self.last_mono, self.handed_s = mono, frames_before / self.sample_rate
        window = self._window
        while window and window[-1][1] >= zero:
            window.pop()  # a later reading that is also earlier: the old ones can never win again
        window.append((mono, zero))
        while window[0][0] < mono - self.window_s:
            window.popleft()
        self._zero = window[0][1]
        self.readings += 1

    def chunk(self, frames_before: int, frames: int) -> int | None:
        """The device takes `frames` frames after `frames_before`: the show's frame (counted
        from the first handed, the lead-in's) they begin at, or None while paused (silence)."""
        with self._lock:
            self._next_frame = frames_before + frames
            return None if self._course.paused else frames_before - self._gap_frames

    @property
    def state(self) -> str:
        """RUNNING or PAUSED: the music cannot hold for a GO cue (it plays on)."""
        return PAUSED if self._course.paused else RUNNING

    def pause(self) -> float:
        """Stand show time still now, and the song with it from the next chunk on; the show
        time it stands at (twice: the same). The song will go on from the frame heard now:
        the frames handed after it still play out of the buffer, and play again on resume."""
        with self._lock:
            course = self._course
            if course.paused:
                return course.floor_s
            show_s = self._show_at(course, self.now())
            handed = self._next_frame - self._gap_frames  # the show's frames handed so far
            frame = math.floor((show_s - self.first_show_s) * self.sample_rate + 1e-6)  # the one heard now
            rewind = round(REWIND_S * self.sample_rate)
            self._resume_frame = max(0, handed - rewind, min(frame, handed))
            self._course = _Course(True, course.gap_s, show_s)
            return show_s

    def resume(self) -> None:
        """The song goes on from the next chunk the device takes; show time stands until its
        first sample is heard, then runs with it. Not paused: nothing to do (as a machine
        clock not held)."""
        with self._lock:
            course = self._course
            if not course.paused:
                return
            self._gap_frames = self._next_frame - self._resume_frame
            self._course = _Course(False, self._gap_frames / self.sample_rate, course.floor_s)
        self.wake()

    @property
    def locked(self) -> bool:
        return self.readings >= LOCK_CALLBACKS and self.span_s >= LOCK_S

    @property
    def span_s(self) -> float:
        """Machine time between the device's first request and its last."""
        return 0.0 if self.first_mono is None or self.last_mono is None else self.last_mono - self.first_mono

    def real_time(self) -> bool:
        """Whether the output takes samples at the pace it plays them: what it was handed,
        less its buffer, against the machine time that passed."""
        played = self.handed_s - self.latency_s  # a request comes as a period's room frees
        return abs(played - self.span_s) <= RATE_TOLERANCE * self.span_s + 2 * PERIOD_MS / 1000

    @property
    def zero(self) -> float:
        """The monotonic time of show time 0 (for the show's current stretch, since the last
        resume)."""
        return self._zero_of(self._course)

    def _zero_of(self, course: _Course) -> float:
        if self._zero is None:
            raise AudioError("the music's clock has not started")
        return self._zero + course.gap_s - self.first_show_s

    def mono_at(self, show_s: float) -> float:
        """While paused, a show time after the one it stands at never comes (+inf)."""
        course = self._course
        if course.paused and show_s > course.floor_s + 1e-9:
            return math.inf
        return self._zero_of(course) + show_s

    def show_at(self, mono: float) -> float:
        return self._show_at(self._course, mono)

    def _show_at(self, course: _Course, mono: float) -> float:
        """Never below where the last pause stood: after a resume, show time stands there
        until the song's first sample after the pause is heard."""
        if course.paused:
            return course.floor_s
        return max(course.floor_s, mono - self._zero_of(course))


# --------------------------------------------------------------------------- the feed


class Feed:
    """The samples the device plays: a lead-in of silence, the song from the show's first
    moment, then silence for as long as the show runs on (its clock keeps the card's time).
    While the clock is paused, silence that is no part of the show: `handed` counts every
    frame the device took, `position` the show's (lead-in, song, silence after it), `paused`
    the pause's silence."""

    def __init__(self, song: Song, clock: MusicClock, lead_in_s: float, skip_s: float,
                 now: Callable[[], float] = time.monotonic) -> None:
        self.song = song
        self.clock = clock
        self.now = now
        self.frame_bytes = 2 * CHANNELS  # signed 16-bit, stereo
        self.lead_in = song.frames(lead_in_s)
        self.skip = song.frames(song.music.start + skip_s)  # where in the file the show starts
        self.handed = 0  # frames handed over so far, the pause's silence included
        self.position = 0  # the show's frames handed over: the next one's, from the lead-in's first
        self.paused = 0  # frames of the pause's silence handed over
        self.ended_at: int | None = None  # the show's frame being handed when the file ran out
        self.problem: str | None = None  # why the file stopped decoding early
        self._source: Iterator[Any] | None = None
        self._pending = bytearray()
        self._kept: deque[tuple[int, bytes]] = deque()  # (show frame, the song's bytes from it) of the last REWIND_S

    def generator(self) -> Generator[bytes, int, None]:
        """What miniaudio's device pulls from: sent a frame count, yields that many frames."""
        wanted = yield b""
        while True:
            frames = int(wanted)
            self.clock.handed_over(self.now(), self.handed)
            start = self.clock.chunk(self.handed, frames)
            if start is None:
                chunk = bytes(frames * self.frame_bytes)
                self.paused += frames
            else:
                chunk = self._take(frames, start)
            self.handed += frames
            wanted = yield chunk

    def _take(self, frames: int, start: int) -> bytes:
        """The show's `frames` frames from its frame `start` (where the last ended, but after a
        pause where it was heard)."""
        if start != self.position:
            self._seek(start)
        silent = min(frames, max(0, self.lead_in - self.position))
        out = bytearray(silent * self.frame_bytes)
        song = self._song(frames - silent)
        if song:
            self._keep(self.position + silent, song)
        out += song
        out += bytes((frames - silent) * self.frame_bytes - len(song))  # the file ran out
        self.position += frames
        return bytes(out)

    def _song(self, frames: int) -> bytes:
        """Up to `frames` of the song's next frames (fewer once the file has run out)."""
        need = frames * self.frame_bytes
        while len(self._pending) < need and self.ended_at is None:
            self._decode_more()
        take = min(need, len(self._pending))
        song = bytes(self._pending[:take])
        del self._pending[:take]
        return song

    def _keep(self, frame: int, song: bytes) -> None:
        """Keep the song handed over for REWIND_S: a pause may put the song back that far."""
        self._kept.append((frame, song))
        oldest = frame + len(song) // self.frame_bytes - self.song.frames(REWIND_S)
        while self._kept and self._kept[0][0] + len(self._kept[0][1]) // self.frame_bytes <= oldest:
            self._kept.popleft()

    def _seek(self, start: int) -> None:
        """Go back to the show's frame `start` (the clock resumes where the pause was heard):
        the song's frames handed from there are put back before those still to hand; forward
        (never asked), the frames between are passed over."""
        if start > self.position:
            self._song(max(0, start - max(self.position, self.lead_in)))
            self.position = start
            return
        back = bytearray()
        while self._kept and self._kept[-1][0] + len(self._kept[-1][1]) // self.frame_bytes > start:
            frame, song = self._kept.pop()
            cut = max(0, start - frame) * self.frame_bytes
            back[0:0] = song[cut:]
            if cut:
                self._kept.append((frame, song[:cut]))
        self._pending[0:0] = back
        self.position = start

    def _decode_more(self) -> None:
        try:
            if self._source is None:
                self._source = self._open()
            chunk = next(self._source)
        except StopIteration:
            chunk = None
        except Exception as exc:  # noqa: BLE001 - the audio thread must never die: the show's clock runs on it
            self.problem = _reason(exc)
            chunk = None
        if not chunk:
            self.ended_at = self.position
            return
        self._pending += memoryview(chunk).cast("B")  # miniaudio's array of samples, as its bytes

    def _open(self) -> Iterator[Any]:
        import miniaudio

        return miniaudio.stream_file(self.song.path, output_format=miniaudio.SampleFormat.SIGNED16,
                                     nchannels=CHANNELS, sample_rate=self.song.sample_rate,
                                     frames_to_read=self.song.frames(PERIOD_MS / 1000) or 1,
                                     seek_frame=self.skip)


# --------------------------------------------------------------------------- outputs


@dataclass(frozen=True)
class Output:
    """An audio output `choreo devices` lists and `--audio-device` picks."""

    number: int  # 1-based, as listed; 0 for the null output
    name: str
    backend: str
    device_id: Any = None  # miniaudio's id (None: the backend's default)


NULL_OUTPUT = Output(0, NULL_DEVICE, "Null")


def output_name(output: Output | None) -> str:
    """How messages name an output (None: the system's default)."""
    return output.name if output is not None else "the default output"


def outputs() -> list[Output]:
    """The playback devices miniaudio finds on this machine (none where it finds no sound
    system), and the null output last, which every machine has."""
    import miniaudio

    found: list[Output] = []
    with alsa.quiet():  # ALSA's own lines about cards it cannot open: see choreo.music.alsa
        try:
            devices = miniaudio.Devices()
            found = [Output(n, str(d["name"]), devices.backend, d["id"])
                     for n, d in enumerate(devices.get_playbacks(), 1)]
        except miniaudio.MiniaudioError:
            pass
    return found + [NULL_OUTPUT]


def pick_output(given: str | None, listed: Callable[[], list[Output]] | None = None) -> Output | None:
    """`--audio-device`: a number or a name (any unique part of it, any case) from
    `choreo devices`, or `null`; None: the system's default output."""
    if given is None:
        return None
    if given.strip().lower() == NULL_DEVICE:
        return NULL_OUTPUT
    choices = [o for o in (listed or outputs)() if o.name != NULL_DEVICE]
    number = whole_number(given)
    if number is not None:
        match = [o for o in choices if o.number == number]
    else:
        match = [o for o in choices if given.strip().lower() in o.name.lower()]
    names = "; ".join(f"{o.number}: {o.name}" for o in choices) or "none found"
    if not match:
        raise UsageError(f"--audio-device {given}: no such output (outputs: {names}; or null for none)")
    if len(match) > 1:
        raise UsageError(f"--audio-device {given}: names {len(match)} outputs ({names}): give its number")
    return match[0]


def open_device(output: Output | None, sample_rate: int) -> Any:
    """A miniaudio playback device on `output` (None: the system's default), not started;
    miniaudio's MiniaudioError if it will not open."""
    import miniaudio

    null = output is not None and output.name == NULL_DEVICE
    with alsa.quiet():
        return miniaudio.PlaybackDevice(output_format=miniaudio.SampleFormat.SIGNED16, nchannels=CHANNELS,
                                        sample_rate=sample_rate, buffersize_msec=PERIOD_MS, callback_periods=PERIODS,
                                        device_id=None if output is None or null else output.device_id,
                                        backends=[miniaudio.Backend.NULL] if null else None, app_name="choreo")


def try_output(output: Output | None = None) -> str:
    """Open `output` (None: the default) without playing, and say what opened: what `choreo
    doctor` checks. AudioError if it will not open."""
    import miniaudio

    try:
        device = open_device(output, 48000)
    except miniaudio.MiniaudioError as exc:
        raise AudioError(f"it will not open ({_reason(exc)})") from None
    try:
        return device.backend
    finally:
        device.close()


# --------------------------------------------------------------------------- playing


@dataclass
class Player:
    """The song playing on an output, and the show clock it keeps."""

    song: Song
    output: Output | None = None  # None: the default output, the null one if there is none
    origin: float = 0.0  # the show time the run starts at (--from's step), 0 for a whole show
    lead_in_s: float = LEAD_IN_S
    wake: Callable[[], None] = _nothing  # the run's time source's notify: the clock calls it on resume
    clock: MusicClock | None = None
    feed: Feed | None = None
    backend: str = ""
    note: str | None = None  # what the user should hear (no sound output: the null one plays)
    _device: Any = None

    def start(self) -> MusicClock:
        """Open the output, start playing and return the clock once it is trusted."""
        import miniaudio

        self.clock = MusicClock(self.song.sample_rate, self.origin - self.lead_in_s, wake=self.wake)
        self.feed = Feed(self.song, self.clock, self.lead_in_s, self.origin)
        self._device = self._open_device()
        try:  # what it opened, it closes if the start fails: the run has not wired its close yet
            generator = self.feed.generator()
            next(generator)
            self._device.start(generator)
        except miniaudio.MiniaudioError as exc:
            self.close()
            raise AudioError(f"the audio output ({self.backend}) will not start playing ({_reason(exc)}): "
                             "see `choreo devices`, or run with --no-music") from None
        except BaseException:
            self.close()
            raise
        self._await_lock()
        return self.clock

    def _open_device(self) -> Any:
        import miniaudio

        try:
            device = open_device(self.output, self.song.sample_rate)
        except miniaudio.MiniaudioError as exc:
            if self.output is not None:
                raise AudioError(f"audio output {self.output.name!r} will not open ({_reason(exc)}): "
                                 "see `choreo devices`, or run with --no-music") from None
            self.note = ("the default sound output does not open: the music's clock runs on the null output "
                         "(silent, in real time); `choreo devices` lists the outputs, --audio-device picks one")
            device = open_device(NULL_OUTPUT, self.song.sample_rate)
        self.backend = device.backend
        return device

    def _await_lock(self) -> None:
        assert self.clock is not None
        deadline = time.monotonic() + LOCK_TIMEOUT_S
        while not self.clock.locked:
            if time.monotonic() > deadline:
                self.close()
                raise AudioError(f"the audio output ({self.backend}) did not start playing within "
                                 f"{LOCK_TIMEOUT_S:g} s: see `choreo devices`, or run with --no-music")
            time.sleep(0.002)
        if not self.clock.real_time():
            pace = self.clock.handed_s / max(self.clock.span_s, 1e-6)
            self.close()
            raise AudioError(f"audio output {self.output_name!r} ({self.backend}) takes samples at {pace:.1f}x "
                             "real time: it cannot keep the show's time; pick another (choreo devices) "
                             "or --audio-device null")

    @property
    def output_name(self) -> str:
        return output_name(self.output)

    @property
    def end_show_s(self) -> float:
        return self.song.end_show_s

    def close(self) -> None:
        if self._device is not None:
            device, self._device = self._device, None
            with contextlib.suppress(Exception):
                device.close()

    def describe(self) -> str:
        """`song.wav from 0.0 s on ALSA`: what the run's first lines say."""
        start = self.song.music.start + self.origin
        return f"{self.song.music.file} from {start:.1f} s on {self.output_name} ({self.backend})"
