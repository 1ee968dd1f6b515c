"""A scripted Ableton Link peer for the Link tests: another app in the session (Live, a DJ's
deck), doing on cue what the test asks and printing what it did and saw as JSON lines.

Run it inside a test's network namespace (linkns.py), beside the choreo hosts it plays with:

    python tests/linkpeer.py --tempo 120 --start-with-peers 1 --tempo-change 1.5:150 --leave 3

Its times (`--tempo-change`, `--leave`) count from the moment it saw the session's transport
play (its own start, or another's), so a loaded machine's slow start of a choreo process moves
them all together rather than past the show. A test can also cue it by signal, on what the
choreo hosts print: SIGUSR1 sets the tempo to `--tempo-to`, SIGUSR2 starts the transport (with
`--start-on-signal`), SIGTERM makes it leave. It leaves
after `--timeout` seconds whatever happens, so a test never waits on it for ever.

Each line is {"event": ..., "t": seconds since it joined, "link_us": Link's clock, "beat": its
beat, "phase": within the quantum, "tempo": ..., "peers": ..., "playing": ...} and what the event
adds: "joined", "started" (this peer started the transport: "at_us" and "at_beat", a bar line),
"playing" / "stopped" (it saw the transport change), "peers" (the count changed), "tempo" (the
session's tempo changed), "tempo_set" (this peer set it), "left".
"""

from __future__ import annotations

import argparse
import asyncio
import json
import math
import signal
import sys
import time
from datetime import timedelta

SAMPLE_S = 0.005


def _parse(argv: list[str]) -> argparse.Namespace:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--tempo", type=float, default=120.0, help="the tempo it joins with")
    parser.add_argument("--quantum", type=int, default=4)
    parser.add_argument("--start-with-peers", type=int, metavar="N",
                        help="start the transport once N other peers are seen, on a bar line --lead s ahead")
    parser.add_argument("--start-on-signal", action="store_true",
                        help="start the transport on SIGUSR2 (and with --start-with-peers, once they are seen)")
    parser.add_argument("--lead", type=float, default=0.5, help="how far ahead its start's bar line is (s)")
    parser.add_argument("--start-late-ms", type=float, default=0.0,
                        help="start the transport this long after the bar line (an app a hair late)")
    parser.add_argument("--tempo-change", metavar="S:BPM", help="set the tempo S s after the transport played")
    parser.add_argument("--tempo-to", type=float, help="the tempo SIGUSR1 sets")
    parser.add_argument("--leave", type=float, metavar="S", help="leave S s after the transport played")
    parser.add_argument("--timeout", type=float, default=20.0, help="leave after this long whatever happens")
    return parser.parse_args(argv)


class Peer:
    def __init__(self, args: argparse.Namespace) -> None:
        from aalink import Link  # the test extra installs it; made in the running loop, as aalink needs
        self.args = args
        self.link = Link(args.tempo)
        self.link.quantum = args.quantum
        self.link.start_stop_sync_enabled = True
        self.t0 = time.monotonic()
        self.played_at: float | None = None  # monotonic time it saw the transport play
        self.leaving = False  # SIGTERM
        self.tempo_asked = False  # SIGUSR1
        self.start_asked = False  # SIGUSR2

    def _set_tempo(self, bpm: float) -> None:
        self.link.tempo = bpm
        self.say("tempo_set", to=bpm)

    def say(self, event: str, **more: object) -> None:
        link = self.link
        line = {"event": event, "t": round(time.monotonic() - self.t0, 4),
                "link_us": link.time / timedelta(microseconds=1), "beat": link.beat, "phase": link.phase,
                "tempo": link.tempo, "peers": link.num_peers, "playing": link.playing, **more}
        print(json.dumps(line), flush=True)

    def start(self) -> None:
        """Start the transport on the first bar line at least --lead s ahead."""
        link = self.link
        now_us, beat, tempo = link.time / timedelta(microseconds=1), link.beat, link.tempo
        q = self.args.quantum
        at_beat = math.ceil((beat + self.args.lead * tempo / 60) / q) * q + self.args.start_late_ms / 1e3 * tempo / 60
        at_us = now_us + (at_beat - beat) * 60e6 / tempo
        link.set_is_playing_and_request_beat_at_time(True, timedelta(microseconds=at_us), at_beat)
        self.say("started", at_us=at_us, at_beat=at_beat)

    async def run(self) -> None:
        args, link = self.args, self.link
        loop = asyncio.get_running_loop()
        loop.add_signal_handler(signal.SIGTERM, lambda: setattr(self, "leaving", True))
        loop.add_signal_handler(signal.SIGUSR1, lambda: setattr(self, "tempo_asked", True))
        loop.add_signal_handler(signal.SIGUSR2, lambda: setattr(self, "start_asked", True))
        link.enabled = True
        self.say("joined")
        tempo_s, tempo_bpm = (float(x) for x in args.tempo_change.split(":")) if args.tempo_change else (None, None)
        seen = (link.num_peers, link.playing, link.tempo)
        started = False
        while time.monotonic() - self.t0 < args.timeout and not self.leaving:
            await asyncio.sleep(SAMPLE_S)
            seen = self._changes(seen)
            if self.tempo_asked and args.tempo_to is not None:
                self.tempo_asked = False
                self._set_tempo(args.tempo_to)
                seen = (seen[0], seen[1], link.tempo)
            if not started and self._may_start():
                started = True
                self.start()
            since = time.monotonic() - self.played_at if self.played_at is not None else None
            if since is None:
                continue
            if tempo_s is not None and since >= tempo_s:
                tempo_s = None
                self._set_tempo(tempo_bpm)
                seen = (seen[0], seen[1], link.tempo)
            if args.leave is not None and since >= args.leave:
                break
        link.enabled = False
        self.say("left")

    def _may_start(self) -> bool:
        """Start now? A peer starts a transport only once the peers it starts are known to it
        (Link tells a peer that joins later nothing of a transport already playing)."""
        args = self.args
        if args.start_with_peers is None and not args.start_on_signal:
            return False
        asked = self.start_asked or not args.start_on_signal
        return asked and (args.start_with_peers is None or self.link.num_peers >= args.start_with_peers)

    def _changes(self, seen: tuple[int, bool, float]) -> tuple[int, bool, float]:
        link = self.link
        peers, playing, tempo = link.num_peers, link.playing, link.tempo
        if peers != seen[0]:
            self.say("peers", was=seen[0])
        if playing != seen[1]:
            self.say("playing" if playing else "stopped")
            if playing and self.played_at is None:
                self.played_at = time.monotonic()
        if abs(tempo - seen[2]) > 1e-6:
            self.say("tempo", was=seen[2])
        return peers, playing, tempo


async def _main(args: argparse.Namespace) -> None:
    await Peer(args).run()


def main(argv: list[str]) -> None:
    asyncio.run(_main(_parse(argv)))


if __name__ == "__main__":
    main(sys.argv[1:])
