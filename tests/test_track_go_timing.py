"""A GO in one robot's track never delays another track's timed cues (issue 21, item 5).

On the machine's clock a GO cue holds the one show clock for every track; when the GO comes the
clock goes on, and another track's cue falls due at its (moved) time at once: the runner asleep
towards it is woken by the clock going on, not left to the end of a 50 ms sleep slice. Tested on
virtual time with threads, as the ensemble's runners share it: exact, and no real waiting.
"""

from __future__ import annotations

import threading

from hypothesis import given, settings
from hypothesis import strategies as st

from choreo.clock import RunClock, VirtualTime, sleep_until_show
from choreo.live.controls import HoldingShowClock

TOLERANCE_S = 0.001


def _share(source: VirtualTime, *bodies) -> None:  # type: ignore[no-untyped-def]
    """Run `bodies` as threads sharing `source`'s time (each ends with `source.leave()`)."""
    threads = [threading.Thread(target=body) for body in bodies]
    source.admit(len(threads))
    for thread in threads:
        thread.start()
    for thread in threads:
        thread.join(10)
    assert not any(thread.is_alive() for thread in threads)


def _track_cues(hold_s: float, go_s: float, cues: list[float]) -> tuple[list[float], float, float]:
    """Robot A's track reaches a GO cue at show time `hold_s` and gets its GO at monotonic
    `go_s` after the start; robot B's thread sleeps towards each of its timed `cues` as its
    runner does. Returns when B woke for each (monotonic), the show's zero, and the GO's time."""
    source = VirtualTime()
    clock = RunClock(source)
    zero = clock.mono()
    show = HoldingShowClock(zero, clock.mono, source.notify)
    woke: list[float] = []
    went: list[float] = []

    def track_a() -> None:
        source.sleep(hold_s)
        show.hold_at(hold_s)  # A reaches its GO cue: the clock holds for every track
        source.sleep(zero + go_s - clock.mono())
        went.append(clock.mono())
        show.release()  # the operator's GO
        source.leave()

    def track_b() -> None:
        for cue in cues:
            assert sleep_until_show(clock, show, cue)
            woke.append(clock.mono())
        source.leave()

    _share(source, track_a, track_b)
    return woke, zero, went[0]


def _due(cue: float, hold_s: float, zero: float, go: float) -> float:
    """Where a cue falls: its own time before the hold; after it, moved by the time held."""
    return zero + cue if cue <= hold_s else go + (cue - hold_s)


def test_another_tracks_cue_just_after_the_hold_is_on_time_when_the_go_comes() -> None:
    hold_s, go_s = 0.5, 0.98
    cues = [0.3, 0.51, 0.7]
    woke, zero, go = _track_cues(hold_s, go_s, cues)
    assert abs(go - (zero + go_s)) < 1e-6
    for cue, at in zip(cues, woke, strict=True):
        assert abs(at - _due(cue, hold_s, zero, go)) <= TOLERANCE_S, (cue, at - _due(cue, hold_s, zero, go))


@given(hold_s=st.floats(0.05, 1.0), held_s=st.floats(0.0, 1.5),
       offsets=st.lists(st.floats(-0.2, 0.4), min_size=1, max_size=4))
@settings(max_examples=60, deadline=None)
def test_another_tracks_cues_keep_their_times_while_a_go_waits_and_when_it_comes(
        hold_s: float, held_s: float, offsets: list[float]) -> None:
    hold_s = round(hold_s, 3)  # show times in milliseconds, as a show file writes them
    cues = sorted(max(0.0, round(hold_s + offset, 4)) for offset in offsets)
    woke, zero, go = _track_cues(hold_s, hold_s + held_s, cues)
    for cue, at in zip(cues, woke, strict=True):
        due = _due(cue, hold_s, zero, go)
        assert abs(at - due) <= TOLERANCE_S, (cue, at - due)
        if cue > hold_s:
            assert at >= go - 1e-9  # never before the GO: the clock holds for every track


def test_notify_ends_a_doze_at_once_and_leaves_a_sleep_alone() -> None:
    source = VirtualTime()
    start = source.now()
    ended: dict[str, float] = {}

    def dozer() -> None:
        source.doze(1.0)
        ended["doze"] = source.now() - start
        source.leave()

    def sleeper() -> None:
        source.sleep(2.0)
        ended["sleep"] = source.now() - start
        source.leave()

    def notifier() -> None:
        source.sleep(0.25)
        source.notify()
        source.leave()

    _share(source, dozer, sleeper, notifier)
    assert ended == {"doze": 0.25, "sleep": 2.0}


class _GoInTheGap:
    """A held clock whose first 'not yet' answer is followed at once by the GO, before the
    asker has begun to doze: the moment a loaded machine may switch threads at."""

    def __init__(self, show: HoldingShowClock) -> None:
        self.show = show
        self.gone = False

    def mono_at(self, show_s: float) -> float:
        due = self.show.mono_at(show_s)
        if due == float("inf") and not self.gone:
            self.gone = True
            threading.Thread(target=self.show.release).start()  # the operator's GO, from its own thread
            time_to_run = threading.Event()
            time_to_run.wait(0.05)  # real time: the GO's thread runs (virtual time stands still)
        return due

    def show_at(self, mono: float) -> float:
        return self.show.show_at(mono)


def test_a_go_between_reading_the_held_time_and_dozing_still_wakes_the_doze() -> None:
    """The GO's wake-up came before the other track's runner dozed: it was lost, and the cue due
    just after the GO waited out the rest of a 50 ms sleep slice."""
    source = VirtualTime()
    clock = RunClock(source)
    zero = clock.mono()
    show = HoldingShowClock(zero, clock.mono, source.notify)
    show.hold_at(0.5)
    source.advance(0.7)  # the GO cue has waited 0.2 s
    woke: list[float] = []

    def track_b() -> None:
        assert sleep_until_show(clock, _GoInTheGap(show), 0.501)  # type: ignore[arg-type]
        woke.append(clock.mono())
        source.leave()

    def company() -> None:  # another robot's thread, so that time is shared (a doze is not a sleep)
        source.sleep(1.0)
        source.leave()

    _share(source, track_b, company)
    go = zero + 0.7
    assert woke and abs(woke[0] - (go + 0.001)) <= TOLERANCE_S, woke[0] - (go + 0.001)


def test_panic_or_stop_while_a_go_cue_holds_ends_every_other_tracks_doze_at_once() -> None:
    """Another track dozes towards a cue past the held time: a panic (or stop) given then ends
    its doze at that instant, not at the end of its 50 ms sleep slice."""
    for command in ("panic", "stop"):
        ended, given = _doze_ended_by(command)
        assert ended and ended[0] - given <= TOLERANCE_S, (command, ended[0] - given)


def _doze_ended_by(command: str) -> tuple[list[float], float]:
    """When another track's doze ended (its monotonic times), and when `command` was given."""
    from choreo.live.controls import Live
    from choreo.events import Command
    from choreo.events import StopRequest

    source = VirtualTime()
    clock = RunClock(source)
    zero = clock.mono()
    show = HoldingShowClock(zero, clock.mono, source.notify)
    stop = StopRequest()
    live = Live(stop, now=clock.mono)
    live.use_clock(show)
    show.hold_at(0.5)
    ended: list[float] = []

    def track_b() -> None:
        assert not sleep_until_show(clock, show, 0.8, stop)
        ended.append(clock.mono())
        source.leave()

    def operator() -> None:
        source.sleep(0.6123)  # the GO cue has waited 0.1123 s
        assert live.command(Command(command, "test")).ok
        source.leave()

    _share(source, track_b, operator)
    return ended, zero + 0.6123
