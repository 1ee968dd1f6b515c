"""One `choreo run`: settle the settings, open the log then the port, run, close both.

The order is the safety contract: the show is loaded and checked before anything is opened
(a bad file never moves the robot), the log is created before the port (a log that cannot be
written stops the run before any frame), and whatever happens the log is finished with the
run's outcome in its metadata.
"""

from __future__ import annotations

import contextlib
import threading
from collections.abc import Iterator, Sequence
from dataclasses import dataclass, field, replace
from pathlib import Path
from types import TracebackType

from choreo.clock import (MachineShowClock, PausableShowClock, RunClock, ShowClock, SystemTime, TimeSource,
                          quick_thread_switches, sleep_until_show)
from choreo.errors import UsageError
from choreo.events import Command, PlayOutListener, RunListener, RunResult, StopRequest
from choreo.live.controls import HoldingShowClock, Live
from choreo.live.limits import LIMITS, Rate, ReportGate
from choreo.log.format import CLOCK_EVERY_S, INFO, LINK_PREFIX, WARNING, ClockRecord, Result, result_metadata
from choreo.log.recorder import Recorder
from choreo.music.player import LEAD_IN_S, Player
from choreo.run.ensemble import Ensemble, Part
from choreo.run.runner import Runner
from choreo.run.sections import section_end
from choreo.run.settings import RunRequest, RunSettings
from choreo.run.stage import Stage
from choreo.show.model import LINK, MACHINE, NOMINAL_BPM
from choreo.sync.clock import LinkShowClock
from choreo.sync.session import LinkEvent, LinkSession, LinkSnapshot
from choreo.sync.start import LinkStart, find_start, next_bar

LINK_LEAD_S = 0.25  # a show on the Link clock starts on a bar line at least this far ahead (the runners' preroll)
REALIGN_LEAD_S = 0.05  # a start moved by the session's bars is at least this far ahead (the first frame's lead)


@dataclass
class Session:
    """A prepared run: its settings, settled once before anything opens, and what running it
    opens (the stage) and leaves (the result, the robots that dropped out)."""

    settings: RunSettings
    clock: RunClock = field(default_factory=RunClock)
    stage: Stage | None = None
    result: RunResult | None = None
    dropouts: list = field(default_factory=list)  # robots that dropped out (on_fault: continue)
    player: Player | None = None  # while the music plays
    link: LinkSession | None = None  # this host's Link peer while the session is open (a show on the Link clock)
    _first_bar: float | None = None  # the session's beat the show starts on, once found

    @classmethod
    def prepare(cls, request: RunRequest, time_source: TimeSource | None = None) -> Session:
        """Load and check the show and settle the settings; opens nothing.

        `time_source`: what the run's clock reads, the machine's time unless given (virtual
        time drives only the in-process simulator: a real port is then refused at open)."""
        return cls(RunSettings.settle(request, time_source), RunClock(time_source or SystemTime()))

    @property
    def log_path(self) -> Path | None:
        """The log the run writes (once open, with the suffix a taken default name got)."""
        return self.stage.log_path if self.stage is not None else self.settings.log_path

    # -- opening and closing ---------------------------------------------------------------

    @property
    def recorder(self) -> Recorder | None:
        """The run's log while the session is open (None: --no-log, or not open)."""
        return self.stage.recorder if self.stage is not None else None

    def __enter__(self) -> Session:
        settings = self.settings
        if settings.link is not None:
            if self.clock.virtual:
                raise UsageError("the Link clock runs in real time, as its peers do: not on virtual time "
                                 "(rehearse a Link show with --clock machine)")
            # joined before anything opens (a missing binding stops the run with nothing open),
            # and early: peers are found while the ports open
            self.link = LinkSession(settings.link.meter, settings.link.bpm).open()
        self.stage = Stage(settings.run_info(self.clock.wall_anchor_ns), settings.log_path, self.clock,
                           list(settings.links.values()), unique_log=settings.unique_log, named=settings.show.ensemble)
        try:
            self.stage.__enter__()
        except BaseException:
            self._leave_link()  # what opened first is closed too: the with statement never reaches __exit__
            raise
        return self

    def __exit__(self, exc_type: type[BaseException] | None, exc: BaseException | None,
                 tb: TracebackType | None) -> None:
        try:
            if self.stage is not None:
                self.stage.__exit__(exc_type, exc, tb)
        finally:
            self._leave_link()

    def _leave_link(self) -> None:
        if self.link is not None:
            self.link.close()
            self.link = None

    # -- running ---------------------------------------------------------------------------

    def run(self, listeners: Sequence[RunListener] = (), stop: StopRequest | None = None,
            live: Live | None = None) -> RunResult:
        """Play the show (with --loop, its section again and again until stopped); a log that
        cannot take more stops it like a stop request (the exchange in flight, then the abort
        motion) and its LogError is the run's outcome. `live`: the operator's controls (GO cues
        wait on them; --wait-start waits for start)."""
        assert self.stage is not None, "open the session first (with session:)"
        if live is not None and stop is not None and stop is not live.stop:
            # one stop request a run: the one given would never be read (a Ctrl-C through it lost)
            raise ValueError("give the run one stop request: the live controls' own, or none")
        stop = live.stop if live is not None else stop if stop is not None else StopRequest()
        # the live controls hear the steps too: which cues ran, for the playhead and skips
        everyone: list[RunListener] = ([self.recorder] if self.recorder else []) + list(listeners) \
            + ([live] if live is not None else [])
        try:
            return self._run(everyone, stop, live)
        finally:  # the log's metadata names who stopped the run, however it ended (a panic then a fault)
            if stop():
                self.stage.add_to_outcome({Result.STOP_REASON: stop.reason})

    def _run(self, everyone: list[RunListener], stop: StopRequest, live: Live | None) -> RunResult:
        """The run, its log wired to the stop request and the live controls for its time."""
        assert self.stage is not None
        with contextlib.ExitStack() as wiring:  # the log's wiring, for the run's time only
            if self.recorder is not None:
                wiring.enter_context(self.recorder.stopping(stop))
            if live is not None:
                # commands are taken from now on: the log hears each (subscribed by `recording`,
                # under the lock a panic given as the show opens takes, so it hears that once)
                wiring.enter_context(live.recording(self.recorder))
                if self.recorder is not None:
                    wiring.callback(live.flush_reports, force=True)  # held-back commands summed up while it hears
                live.use_section(self.settings.sections.starts, self.settings.sections.ends)
            if not self._await_start(everyone, stop, live):
                self.result = RunResult("aborted", 0, 0, 0.0)
            else:
                self.result = self._run_passes(everyone, stop, live)
        if self.recorder is not None:
            self.recorder.check()
        self.stage.finished(result_metadata(self.result))
        return self.result

    def _await_start(self, everyone: list[RunListener], stop: StopRequest, live: Live | None) -> bool:
        """Wait for the show's start (--wait-start: the operator's; on the Link clock the first
        bar line the session's transport or this host starts on); False if stopped first."""
        if self.link is None:
            return live is None or live.await_start()
        waits = (live is not None and not live.started) or bool(self.settings.show.hosts)
        how = LinkStart(waits, self.settings.link.bpm if self.settings.link else None, LINK_LEAD_S)
        self._first_bar = find_start(self.link, how, started=lambda: live is not None and live.started,
                                     stop=stop, tell=lambda message: self._tell(everyone, INFO, LINK_PREFIX + message))
        if self._first_bar is not None and live is not None and not live.started:
            live.command(Command("start", "link session"))  # the session started it: the log and status say so
        return self._first_bar is not None

    def _run_passes(self, everyone: list[RunListener], stop: StopRequest, live: Live | None) -> RunResult:
        """One pass of the show, or with --loop as many of its section as run before a stop."""
        result = self._run_pass(everyone, stop, live)
        passes, steps, late = 1, result.steps_run, result.late_steps
        # A loop ends only when stopped: a stop between passes is seen by the next pass's
        # runners, which play the abort motions as on any stop.
        loop = self.settings.sections.loop
        while loop is not None and result.outcome == "done":
            passes += 1
            self._tell(everyone, INFO, f"loop: pass {passes} from {loop[0]!r} to {loop[1]!r}")
            if live is not None:
                live.new_pass()  # its GO cues wait again
            result = self._run_pass(everyone, stop, live)
            steps, late = steps + result.steps_run, late + result.late_steps
        return RunResult(result.outcome, steps, late, result.show_s)

    def _run_pass(self, everyone: list[RunListener], stop: StopRequest, live: Live | None) -> RunResult:
        """The runners from the start (or --from, --loop's first step) to the end (or --loop's
        last step), on a show clock started for them."""
        runners = self._runners(everyone, stop, live)
        ensemble = self._ensemble(runners, stop, everyone) if self.settings.show.ensemble else None
        solo = next(iter(runners.values()))  # a one-robot show's only runner
        preroll = ensemble.preroll_s() if ensemble is not None else solo.preroll_s()
        with contextlib.ExitStack() as music:
            show = self._start_show_clock(preroll, everyone, music, holding=live is not None)
            if live is not None:
                live.use_clock(show, self.clock.source.notify)  # a stop or panic ends the runners' dozes
            sampler = ClockSampler(self.recorder, self.clock, show, self._clock_source()) \
                if self.recorder is not None else None
            if isinstance(show, LinkShowClock):
                music.enter_context(self._hearing_link(show, sampler, everyone))
            if sampler is not None and live is not None:
                # the log marks each change of the clock's state (a GO cue holds it, a GO, a pause, a
                # resume): the reviews draw holds and pauses, and place later frames, by them
                music.enter_context(live.on_clock_change(lambda: sampler.sample(force=True)))
            if sampler is not None:
                sampler.sample(force=True)  # on the Link clock, none until the start (`ClockSampler.sample`)
            result = solo.run(show, on_idle=sampler) if ensemble is None \
                else self._run_ensemble(ensemble, show, sampler)
            if result.outcome == "done" and self.settings.sections.loop is None:
                self._play_out(show, stop, sampler, everyone)
            elif result.outcome == "done":
                self._end_of_section(show, stop)
            elif isinstance(show, LinkShowClock) and self.clock.mono() < show.mono_at(show.origin_s):
                self._stop_transport(everyone)
            if sampler is not None:
                sampler.sample(force=True)
            return result

    def _runners(self, everyone: list[RunListener], stop: StopRequest, live: Live | None) -> dict[str, Runner]:
        """A runner a robot for one pass, each from its start to its end (--from, --loop)."""
        assert self.stage is not None
        settings, show, sections = self.settings, self.settings.show, self.settings.sections
        return {name: Runner(settings.plans[name], self.stage.links[name], clock=self.clock, listeners=everyone,
                             start=sections.starts[name], on_abort=show.abort_motion(name), stop=stop,
                             robot=name if show.ensemble else None, live=live, end=sections.ends.get(name))
                for name in settings.links}

    def _ensemble(self, runners: dict[str, Runner], stop: StopRequest, listeners: list[RunListener]) -> Ensemble:
        parts = [Part(name, runner, self.settings.links[name].on_fault) for name, runner in runners.items()]
        first = next(iter(self.settings.links))  # shared steps: every robot's plan says the same
        unison = self.settings.plans[first].unison
        return Ensemble(parts, self.clock, stop, unison=unison, origin=self.settings.sections.origin,
                        log=lambda level, message: self._tell(listeners, level, message))

    def _run_ensemble(self, ensemble: Ensemble, show: ShowClock, on_idle: ClockSampler | None) -> RunResult:
        try:
            return ensemble.run(show, on_idle).combined()
        finally:
            self.dropouts = ensemble.dropouts

    # -- the show clock --------------------------------------------------------------------

    def _start_show_clock(self, preroll: float, listeners: list[RunListener], music: contextlib.ExitStack,
                          holding: bool = False) -> ShowClock:
        """The music's clock, its song started a lead-in before the run's first moment (a play
        cued at the very start goes out ahead of the first sample by its lead) and stopped when
        `music` closes, else the machine's, with the run's first moment `preroll` from now. The
        log's metadata gets show time 0 as wall-clock and monotonic nanoseconds either way."""
        assert self.stage is not None
        song, origin = self.settings.song, self.settings.sections.origin
        if self.link is not None:
            show: ShowClock = self._link_clock(origin)
        elif song is None:
            zero = self.clock.mono() - (origin - preroll)
            # live, the machine's clock holds while a GO cue waits
            show = HoldingShowClock(zero, self.clock.mono, self.clock.source.notify) if holding \
                else MachineShowClock(zero)
        else:
            # a resume wakes the runners dozing towards a cue at once (not a sleep slice later)
            self.player = Player(song, self.settings.output, origin, max(LEAD_IN_S, preroll + LEAD_IN_S),
                                 wake=self.clock.source.notify)
            show = self.player.start()
            music.callback(self._stop_music, listeners)
            # The audio thread shares the interpreter: spinning towards a cue yields to it, and
            # Python hands its lock over quickly.
            self.clock.source.admit(1)
            music.callback(self.clock.source.leave)
            music.enter_context(quick_thread_switches())
            if self.player.note is not None:
                self._tell(listeners, WARNING, self.player.note)
            self._tell(listeners, INFO, f"music: {self.player.describe()}")
        self.stage.add_to_outcome({Result.CLOCK: self._clock_source()})
        self._note_zero(show)
        if song is not None:
            self.stage.add_to_outcome({Result.MUSIC_FILE: song.music.file, Result.MUSIC_START: f"{song.music.start:g}",
                                       Result.AUDIO_BACKEND: self.player.backend if self.player else ""})
        return show

    @contextlib.contextmanager
    def _hearing_link(self, show: LinkShowClock, sampler: ClockSampler | None,
                      listeners: list[RunListener]) -> Iterator[None]:
        """For a pass: each change of the session (a peer's tempo, peers, the transport, a
        jump) is a clock sample and a log line, and wakes the runners sleeping towards a cue in
        bars (where it falls has moved)."""
        gate = _LinkEventGate(LIMITS.link_events, LIMITS.summary_every_s)

        def record(kind: str | None, level: int, message: str) -> None:
            if sampler is not None:
                sampler.sample(force=True, event=kind)
            self._tell(listeners, level, LINK_PREFIX + message)

        def heard(event: LinkEvent) -> None:
            if event.kind in ("jump", "tempo") and \
                    show.realign(self.clock.mono() + REALIGN_LEAD_S, tempo_changed=event.kind == "tempo"):
                # before the show began: it starts on the session's bar line as it now stands
                what = "tempo changed" if event.kind == "tempo" else "bars moved"
                self._tell(listeners, INFO, f"{LINK_PREFIX}the session's {what} before the start: the show starts "
                                            f"on its bar line {show.zero - self.clock.mono():.3f} s from now")
                self._note_zero(show)
            self.clock.source.notify()  # the runners follow every change, logged or not
            if gate.passes(event.kind):
                record(event.kind, WARNING if event.kind in ("jump", "stopped") else INFO, event.message)
            summary = gate.due(event.snapshot)
            if summary is not None:
                record(None, INFO, summary)
        undo = show.session.subscribe(heard)
        try:
            yield
        finally:
            undo()
            summary = gate.due(show.session.snapshot(), force=True)
            if summary is not None:
                record(None, INFO, summary)

    def _stop_transport(self, listeners: list[RunListener]) -> None:
        """Stopped in the count-in: the transport this host started is stopped again (a Live
        following start/stop would play on for a show that never began); one another app started
        is left alone."""
        assert self.link is not None
        if self.link.stop_playing():
            self._tell(listeners, WARNING, f"{LINK_PREFIX}stopped before the show's start: the session's transport "
                                           "this host started is stopped again")

    def _note_zero(self, show: ShowClock) -> None:
        """The log's metadata gets show time 0 as monotonic and wall-clock ns (again when a
        change of the Link session before the start moved it)."""
        assert self.stage is not None
        zero_ns = round(show.mono_at(0.0) * 1e9)
        self.stage.add_to_outcome({Result.SHOW_ZERO_MONOTONIC_NS: str(zero_ns),
                                   Result.SHOW_ZERO_WALL_NS: str(self.clock.wall_ns(zero_ns))})

    def _clock_source(self) -> str:
        return LINK if self.link is not None else "music" if self.player else MACHINE

    def _link_clock(self, origin: float) -> LinkShowClock:
        """The show clock on the session for a pass: its start (show time `origin`: 0, or
        --from's step) on the bar line found for the first pass, or for a --loop pass after it
        the session's next bar line (the transport is not started again). A start off beat 1
        (--from a step at bar 3 beat 2) plays on that beat of a session bar, so every later bar
        of the show is a bar of the session."""
        assert self.link is not None and self.settings.link is not None
        meter = self.settings.link.meter
        bar = self._first_bar
        self._first_bar = None
        if bar is None:
            bar = next_bar(self.link, LINK_LEAD_S)
        beats_in = self._beats_to(origin, meter)
        phase = beats_in % meter
        start = self.link.snapshot().mono_of_beat(bar + phase)
        return LinkShowClock(self.link, start, bar + phase, meter, origin, beats_in)

    def _beats_to(self, origin: float, meter: int) -> float:
        """The show's beats before show time `origin` as the plan counts them (its tempo, or
        the nominal one a show on the session's tempo is planned at)."""
        tempo = self.settings.show.tempo
        if not origin:
            return 0.0
        if tempo is None:
            return origin * NOMINAL_BPM / 60.0
        bar, beat = tempo.position(origin)
        return (bar - 1) * meter + (beat - 1)

    def _play_out(self, show: ShowClock, stop: StopRequest, sampler: ClockSampler | None,
                  listeners: list[RunListener]) -> None:
        """The show's last step is done: its music plays to the end (Ctrl-C stops it there; the
        show itself is done). Listeners with `on_play_out(end_s)` hear when it will end."""
        if self.player is None:
            return
        end = self.player.end_show_s
        if show.show_at(self.clock.mono()) < end:
            for listener in listeners:
                if isinstance(listener, PlayOutListener):
                    listener.on_play_out(end)
        while show.show_at(self.clock.mono()) < end and not stop():
            self.clock.sleep(min(0.05, max(0.0, show.mono_at(end) - self.clock.mono())))
            if sampler is not None:
                sampler()

    def _end_of_section(self, show: ShowClock, stop: StopRequest) -> None:
        """A --loop pass lasts until the step after its last one is planned (or the last
        motion's expected end): the section's last motion plays out before the next pass."""
        sleep_until_show(self.clock, show, section_end(self.settings.plans, self.settings.sections.ends), stop)

    def _stop_music(self, listeners: list[RunListener]) -> None:
        if self.player is None:
            return
        self.player.close()
        problem = self.player.feed.problem if self.player.feed is not None else None
        if problem is not None:
            self._tell(listeners, WARNING, f"music: {self.player.song.music.file} stopped decoding early "
                                           f"({problem}); the show clock ran on in silence")
        self.player = None

    def _tell(self, listeners: list[RunListener], level: int, message: str) -> None:
        for listener in listeners:
            listener.on_log(level, message, self.clock.wall_ns())


class ClockSampler:
    """Samples the show clock against the monotonic clock into the log's /choreo/clock every
    CLOCK_EVERY_S of show time; it rides on the runners' idle time (when they sleep towards a
    step), so it never delays a frame, and with the log's own idle work after it."""

    def __init__(self, recorder: Recorder, clock: RunClock, show: ShowClock, source: str,
                 every_s: float = CLOCK_EVERY_S) -> None:
        self._link = show if isinstance(show, LinkShowClock) else None  # its samples carry the session
        self.recorder = recorder
        self.clock = clock
        self.show = show
        self.source = source
        self.every_s = every_s
        self._last: float | None = None
        self._started = False  # on the Link clock: the start's sample written
        self._lock = threading.Lock()
        # asked once: a runtime-checkable protocol's isinstance costs tens of microseconds, and a
        # forced sample is taken as a GO releases the runners
        self._pausable = show if isinstance(show, PausableShowClock) else None

    def __call__(self) -> None:
        self.sample()
        self.recorder.on_idle()

    def sample(self, force: bool = False, event: str | None = None) -> None:
        """A sample now; `event`: what it marks on the Link clock.

        On the Link clock, none before the show's start: until then a change of the session may
        still move where show time stands (`LinkShowClock.realign`), which would leave earlier
        samples telling another clock. The first sample at or after the start is preceded by
        the `start` sample, placed on the start's very instant."""
        with self._lock:
            mono_ns = self.clock.mono_ns()
            show_s = self.show.show_at(mono_ns / 1e9)
            if self._link is not None and self._before_start(show_s):
                return
            if not force and self._last is not None and show_s - self._last < self.every_s:
                return
            self._last = show_s
            state = self._pausable.state if self._pausable is not None else None  # running | held | paused
            # queued under the lock (a queue's append): a runner's sample and the operator's forced
            # one at a pause reach the log in the order they were read, never the older one last
            record = ClockRecord(round(show_s, 6), mono_ns, self.source, state)
            if self._link is not None:
                record = self._with_session(record, self._link, mono_ns, event)
            self.recorder.on_clock(record, self.clock.wall_ns(mono_ns))

    def _before_start(self, show_s: float) -> bool:
        """Before the Link show's start: no sample. The first one after: the start's sample
        first (the lock is held)."""
        link = self._link
        assert link is not None
        if show_s < link.origin_s:
            return True
        if not self._started:
            self._started = True
            start_ns = round(link.mono_at(link.origin_s) * 1e9)
            record = self._with_session(ClockRecord(round(link.origin_s, 6), start_ns, self.source), link,
                                        start_ns, "start")
            # the start is on its beat by definition: the session's timeline read back a moment
            # later puts it within a few microseconds of a beat, which is the sample's noise
            assert record.beat is not None and record.session_beat is not None
            off = record.beat - link.origin_beats
            record = replace(record, beat=round(link.origin_beats, 6), session_beat=round(record.session_beat - off, 6))
            self.recorder.on_clock(record, self.clock.wall_ns(start_ns))
        return False

    @staticmethod
    def _with_session(record: ClockRecord, link: LinkShowClock, mono_ns: int, event: str | None) -> ClockRecord:
        """The sample with the session as this host saw it at that instant."""
        snapshot = link.session.snapshot()
        beat = snapshot.beat_at_mono(mono_ns / 1e9)
        return replace(record, link_us=snapshot.link_us_at_mono(mono_ns / 1e9), beat=round(beat - link.first_bar, 6),
                       session_beat=round(beat + snapshot.shift, 6), tempo=round(snapshot.tempo, 6),
                       peers=snapshot.peers, event=event)


class _LinkEventGate:
    """How many of a Link session's changes are logged one by one: a peer changing its tempo
    every 10 ms would otherwise write a clock sample and a line each (and print the line).
    Past the budget they are counted, and summed up in one line a `every_s` at most: the OSC
    commands' `ReportGate`, whose lock also serves the Link thread and the pass's end alike."""

    def __init__(self, rate: Rate, every_s: float) -> None:
        self._gate = ReportGate(replace(LIMITS, reported=rate, summary_every_s=every_s))

    def passes(self, kind: str = "change") -> bool:
        return self._gate.passes(kind, "link session", ok=False)

    def due(self, snapshot: LinkSnapshot, force: bool = False) -> str | None:
        """The summary of the changes held back, once `every_s` has passed (or `force`)."""
        held = self._gate.due(force)
        if held is None:
            return None
        return (f"{held.count} more session change{'s' if held.count != 1 else ''} not logged one by one "
                f"(now {snapshot.tempo:.2f} bpm, {snapshot.peers} peers, "
                f"{'playing' if snapshot.playing else 'stopped'})")
