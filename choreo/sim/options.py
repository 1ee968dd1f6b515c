"""The simulator's options, one parser for the `sim://` query string and `choreo sim`'s arguments.

Every option is spelled `name=value` in a URL (`sim://?motion_s=0.5&drop=5`) and `--name value`
with dashes on the command line (`--motion-s 0.5 --drop 5`), and both go through
`parse_options`, so they accept and refuse exactly the same values with the same messages.

| option | meaning | default |
|---|---|---|
| baud | the board's baud: one the RCB-4 runs at (`protocol.BAUDS`) | `protocol.DEFAULT_BAUD` |
| motion_s | how long every motion runs, seconds | 1.0 |
| durations | per-slot durations, `SLOT:SECONDS,...` (`3:2.5,7:1.2`) | none |
| reply_ms | the board's delay between a frame's last byte and its reply | 0.2 |
| refresh_ms | status refresh period: a status read shows the config as of the last tick; 0: live | 50 |
| wire | 1: bytes take 11 bit times at the baud; 0: bytes take no time | 1 |
| gap_ms | an inter-byte gap longer than this drops a partial frame | 0.15 (sim://), 20 (pty) |
| seed | seed of the random faults | 0 |
| late_ms | how late a `late` reply is | 500 |
| layout | the board's memory layout: `seed` or `hth4-2.2` (where its motion slots start) | seed |
| config | the config word at power-on, e.g. `0x821b` (what an HTH4 2.2+ project saves) | 0x0002 |
| baud_switch | 1: a config write whose COM baud bits name another baud switches the board to it | 0 |
| latency_ms | an FTDI USB adapter's latency timer (below); 0: no adapter | 0 |
| lose, drop, nak, badsum, short, junk, late | faults: K (every K-th frame) or P (probability) | none |
| lose_start | no reply to the frame that starts a motion (it still starts): K-th start or P | none |
| hold | the client's OS or adapter holds a written frame `hold_ms` before it leaves: K-th write or P | none |
| hold_ms | how long a `hold` fault holds a frame | 40 |
| faults_on | the frame faults hit (and count) only frames of these kinds (below) | every frame |

latency_ms: reply bytes reach the client at the adapter's next tick (every MS ms), or at once
when 62 are waiting. faults_on: comma-separated, of `stop`, `counter`, `play`, `restore`,
`read`, `sync`, `other`.
"""

from __future__ import annotations

from collections.abc import Callable, Mapping
from dataclasses import dataclass, field, replace
from typing import Any, TypeVar
from urllib.parse import parse_qsl, urlencode, urlsplit

from choreo.show.model import SIM_SCHEME, SIM_URL
from choreo.wire.layouts import SEED, Layout, layout_named
from choreo.wire.protocol import BAUDS, DEFAULT_BAUD, MOTION_SLOTS, spell_bauds
from choreo.sim.board import (
    DEFAULT_MOTION_S,
    DEFAULT_REFRESH_S,
    DEFAULT_REPLY_DELAY_S,
    POWER_ON_CONFIG,
    SimBoard,
)
from choreo.sim.faults import DEFAULT_HOLD_S, DEFAULT_LATE_S, FAULT_KINDS, FaultPlan, parse_frame_kinds

SETTINGS = ("baud", "motion_s", "durations", "reply_ms", "refresh_ms", "wire", "gap_ms", "seed", "late_ms",
            "layout", "config", "baud_switch", "latency_ms", "faults_on", "hold_ms")
OPTION_NAMES: tuple[str, ...] = SETTINGS + FAULT_KINDS


@dataclass(frozen=True)
class SimOptions:
    """Everything that configures a simulated board and its line."""

    baud: int = DEFAULT_BAUD
    motion_s: float = DEFAULT_MOTION_S
    durations: Mapping[int, float] = field(default_factory=dict)
    reply_s: float = DEFAULT_REPLY_DELAY_S
    refresh_s: float = DEFAULT_REFRESH_S
    wire: bool = True
    gap_s: float | None = None  # None: the transport's own default
    faults: FaultPlan = field(default_factory=FaultPlan)
    layout: Layout = SEED
    config: int = POWER_ON_CONFIG
    baud_switch: bool = False
    latency_s: float = 0.0  # an FTDI adapter's latency timer between the board and the client (0: none)

    def board(self, **kwargs: Any) -> SimBoard:  # SimBoard's own keywords, checked by SimBoard
        """A fresh board with these options (kwargs: `on_entry`, `journal_size`, `power_on`)."""
        return SimBoard(
            baud=self.baud,
            reply_delay_s=self.reply_s,
            refresh_s=self.refresh_s,
            motion_s=self.motion_s,
            durations=dict(self.durations),
            faults=self.faults,
            wire=self.wire,
            layout=self.layout,
            power_on_config=self.config,
            baud_switch=self.baud_switch,
            **kwargs,
        )

    def describe(self) -> str:
        """One line for a banner: `115200 baud 8E1, motions 1 s, status every 50 ms, no faults`."""
        slots = ", ".join(f"{slot}: {sec:g} s" for slot, sec in sorted(self.durations.items()))
        motions = f"motions {self.motion_s:g} s" + (f" ({slots})" if slots else "")
        status = f"status every {self.refresh_s * 1000:g} ms" if self.refresh_s > 0 else "status live"
        board = f"layout {self.layout.name}, config 0x{self.config:04x}" + (", baud switch" if self.baud_switch else "")
        adapter = f", USB latency timer {self.latency_s * 1e3:g} ms" if self.latency_s else ""
        return f"{self.baud} baud 8E1, {board}, {motions}, {status}{adapter}, {self.faults.describe()}"


@dataclass(frozen=True)
class SimUrl:
    """A `sim://` URL as the options it spells out, in their order: read through the same
    checks as the simulator's, and amended by name rather than by editing the text.

    Choreo fills in what a user's URL leaves unsaid (the show's durations, the run's baud and
    layout) and a replay rescales it; both go through `unless_given` and `with_text`, so an
    option the user wrote is never lost or doubled, and the URL written back parses to what
    was meant.
    """

    said: tuple[tuple[str, str], ...] = ()

    @classmethod
    def parse(cls, url: str) -> SimUrl:
        """ValueError names what is wrong: not a `sim://` URL, an unknown option, a bad value."""
        parts = urlsplit(url)
        if parts.scheme.lower() != SIM_SCHEME:
            raise ValueError(f"{url!r}: expected a URL like sim://?motion_s=0.5&drop=5")
        if parts.netloc or parts.path.strip("/") or parts.fragment:
            raise ValueError(f"{url!r}: sim:// takes options only after '?', like sim://?motion_s=0.5")
        try:
            parsed = cls(_pairs(parts.query))
            parse_options(dict(parsed.said))  # every value checked now, not when first used
        except ValueError as exc:
            raise ValueError(f"sim://: {exc}") from None
        return parsed

    @property
    def options(self) -> SimOptions:
        return parse_options(dict(self.said))

    def says(self, name: str) -> bool:
        return any(given == name for given, _ in self.said)

    def with_text(self, **values: str) -> SimUrl:
        """These options set to these texts: in place where the URL says them, else after."""
        kept = [(name, values.pop(name, text)) for name, text in self.said]
        return replace(self, said=tuple(kept + list(values.items())))

    def unless_given(self, **values: str) -> SimUrl:
        """These options added, except where the URL already says them: the user's word wins."""
        return self.with_text(**{name: text for name, text in values.items() if not self.says(name)})

    def __str__(self) -> str:
        return SIM_URL + (f"?{urlencode(self.said, safe=':,')}" if self.said else "")


def durations_text(durations: Mapping[int, float]) -> str:
    """{3: 2.5, 7: 1.2} -> `3:2.5,7:1.2`: what `parse_durations` reads back."""
    return ",".join(f"{slot}:{seconds:.9g}" for slot, seconds in sorted(durations.items()))


def ms_text(seconds: float) -> str:
    """Seconds as the milliseconds an `_ms` option takes."""
    return f"{seconds * 1e3:.9g}"


def parse_query(query: str) -> SimOptions:
    """Options from a URL query string (`motion_s=0.5&drop=5`); ValueError says what is wrong."""
    return parse_options(dict(_pairs(query)))


def _pairs(query: str) -> tuple[tuple[str, str], ...]:
    pairs = tuple(parse_qsl(query, keep_blank_values=True))
    names = [name for name, _ in pairs]
    twice = next((name for name in names if names.count(name) > 1), None)
    if twice is not None:
        raise ValueError(f"option {twice!r} is given twice")
    return pairs


def parse_options(values: Mapping[str, str]) -> SimOptions:
    """Options from `name -> text`; every error names the option and what it accepts."""
    unknown = [name for name in values if name not in OPTION_NAMES]
    if unknown:
        raise ValueError(f"unknown option {unknown[0]!r} (known: {', '.join(OPTION_NAMES)})")
    faults = {kind: values[kind] for kind in FAULT_KINDS if kind in values}
    seed = _parsed(values, "seed", _whole, 0)
    late_s = _parsed(values, "late_ms", _milliseconds, DEFAULT_LATE_S)
    hold_s = _parsed(values, "hold_ms", _milliseconds, DEFAULT_HOLD_S)
    aimed = _parsed(values, "faults_on", parse_frame_kinds, frozenset[str]())
    try:
        plan = FaultPlan.parse(faults, seed=seed, late_s=late_s, on=aimed, hold_s=hold_s)
    except ValueError as exc:
        raise ValueError(f"fault {exc}") from None
    return SimOptions(
        baud=_parsed(values, "baud", parse_baud, DEFAULT_BAUD),
        motion_s=_parsed(values, "motion_s", _seconds, DEFAULT_MOTION_S),
        durations=_parsed(values, "durations", parse_durations, {}),
        reply_s=_parsed(values, "reply_ms", _milliseconds, DEFAULT_REPLY_DELAY_S),
        refresh_s=_parsed(values, "refresh_ms", _refresh, DEFAULT_REFRESH_S),
        wire=_parsed(values, "wire", _flag, True),
        gap_s=_parsed(values, "gap_ms", _positive_milliseconds, None),
        faults=plan,
        layout=_parsed(values, "layout", layout_named, SEED),
        config=_parsed(values, "config", _word, POWER_ON_CONFIG),
        baud_switch=_parsed(values, "baud_switch", _flag, False),
        latency_s=_parsed(values, "latency_ms", _latency, 0.0),
    )


T = TypeVar("T")


def _parsed(values: Mapping[str, str], name: str, parse: Callable[[str], T], default: T) -> T:
    if name not in values:
        return default
    try:
        return parse(values[name])
    except ValueError as exc:
        raise ValueError(f"option {name}={values[name]!r}: {exc}") from None


def parse_baud(text: str) -> int:
    try:
        baud = int(text)
    except ValueError:
        baud = None
    if baud not in BAUDS:
        raise ValueError(f"the board's baud is one of {spell_bauds()}")
    return baud


def parse_durations(text: str) -> dict[int, float]:
    """`3:2.5,7:1.2` -> {3: 2.5, 7: 1.2}: how long the motion in each named slot runs."""
    durations: dict[int, float] = {}
    for item in filter(None, (part.strip() for part in text.split(","))):
        slot_text, sep, seconds_text = item.partition(":")
        if not sep:
            raise ValueError(f"{item!r} is not SLOT:SECONDS (e.g. 3:2.5)")
        try:
            slot = int(slot_text)
        except ValueError:
            raise ValueError(f"{item!r}: slot {slot_text!r} is not a whole number") from None
        if not 0 <= slot < MOTION_SLOTS:
            raise ValueError(f"{item!r}: slot {slot} is out of range 0..{MOTION_SLOTS - 1}")
        if slot in durations:
            raise ValueError(f"slot {slot} is given twice")
        try:
            durations[slot] = _seconds(seconds_text)
        except ValueError as exc:
            raise ValueError(f"{item!r}: {exc}") from None
    return durations


def _number(text: str) -> float:
    try:
        value = float(text)
    except ValueError:
        raise ValueError("not a number") from None
    if value != value or value in (float("inf"), float("-inf")):
        raise ValueError("not a finite number")
    return value


def _seconds(text: str) -> float:
    value = _number(text)
    if value < 0:
        raise ValueError("seconds must be >= 0")
    return value


def _milliseconds(text: str) -> float:
    value = _number(text)
    if value < 0:
        raise ValueError("milliseconds must be >= 0")
    return value / 1000


def _positive_milliseconds(text: str) -> float:
    value = _milliseconds(text)
    if value <= 0:
        raise ValueError("milliseconds must be > 0")
    return value


def _refresh(text: str) -> float:
    """0 (live) or a period a tick count can be taken of: 1e-320 ms made time / period infinite."""
    value = _milliseconds(text)
    if 0 < value < 1e-9:
        raise ValueError("a refresh period is 0 (live) or at least 0.000001 ms")
    return value


def _latency(text: str) -> float:
    """An FTDI latency timer: 0 (no adapter) or 1..255 ms, as the chip takes."""
    value = _number(text)
    if value != 0 and not 1 <= value <= 255:
        raise ValueError("an FTDI latency timer is 1..255 ms (0: no adapter)")
    return value / 1000


def _whole(text: str) -> int:
    try:
        return int(text)
    except ValueError:
        raise ValueError("not a whole number") from None


def _word(text: str) -> int:
    """A 16-bit word, in hex (0x821b) or decimal."""
    try:
        value = int(text, 0)
    except ValueError:
        raise ValueError("not a 16-bit word (write it like 0x821b)") from None
    if not 0 <= value <= 0xFFFF:
        raise ValueError("not a 16-bit word: 0x0000..0xffff")
    return value


def _flag(text: str) -> bool:
    lowered = text.strip().lower()
    if lowered in ("1", "true", "yes", "on"):
        return True
    if lowered in ("0", "false", "no", "off"):
        return False
    raise ValueError("not 1 or 0")
