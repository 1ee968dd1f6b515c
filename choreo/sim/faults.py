"""Faults the simulated board injects on request, so that every failure a wire can produce is testable.

Kinds (what the client sees for the frame the fault hits):

- ``lose``: the port is lost, like an unplugged USB adapter: that frame and everything after it
  fails (sim:// raises ``serial.SerialException`` on every read and write; ``choreo sim`` closes
  its pseudo-terminal and exits non-zero). It happens once.
- ``drop``: no reply at all. The frame never reached the board, so it had no effect.
- ``nak``: a NAK (``04 CMD 15 SUM``). The board refused the frame, so it had no effect.
- ``badsum``: the reply with a wrong checksum (its last byte inverted). The frame took effect.
- ``short``: only the first half of the reply (2 bytes of a 4-byte ACK). The frame took effect.
- ``junk``: three garbage bytes (``ff 00 aa``) before the reply. The frame took effect.
- ``late``: the reply comes ``late_ms`` (default 500 ms, longer than a link's usual timeout)
  after it was due. The frame took effect. The board is still replying until the late reply's
  last byte is on the wire: a frame sent meanwhile is not answered (see ``SimBoard.receive``).
- ``lose_start``: no reply to a frame that starts a motion (the restore or resume with a motion
  armed), although the motion does start: the case where a client must not play it twice.
  Counted over motion starts, not frames: ``lose_start=2`` hits the 2nd, 4th... start.
- ``hold``: the frame reaches the board ``hold_ms`` (default 40 ms) after the client's write
  returned, as when the client's OS or USB adapter holds written bytes (a write returns once
  they are buffered, not once they are on the wire; no source bounds how long). The frame takes
  effect and is answered on arrival. Counted over the frames the client writes (one write call
  a frame, as a client must), not over frames received.

Spelling (the same in a ``sim://`` query and on the ``choreo sim`` command line): the value is
either a whole number K >= 1, meaning every K-th frame (frames K, 2K, 3K... counted from 1 over
every frame the board received, which leaves out frames it ignored because it was still
replying; for ``lose``, only frame K), or a probability 0 < P < 1 written
with a decimal point, meaning each frame independently with probability P, drawn from a random
generator seeded with ``seed`` (default 0), so a run is repeatable. ``drop=5`` drops frames 5, 10,
15...; ``drop=0.2`` drops a fifth of them at random; ``drop=1`` drops every frame. ``1.0`` and
``0`` are refused (write ``1`` for every frame; leave the option out for never).

``faults_on`` (``faults_on=restore``, ``--faults-on play,restore``) aims the frame faults at
frames of the named kinds only, as the board reads them: ``stop`` (a config write that clears
the run bit), ``counter`` (a write of the program counter alone, hth4-2.2), ``play`` (a CALL),
``restore`` (a config write that sets the run bit: the frame that starts a motion), ``read`` (a
RAM read: status queries, the state read after a lost start reply, the config read at open),
``sync`` (the ACK check), ``other``. K then counts only those frames (``drop=2&faults_on=play``
drops every second CALL), a probability is drawn only for them, and every other frame is spared.

Several kinds may be given at once. When more than one hits the same frame: ``lose`` wins over
everything, then ``drop`` (nothing is sent), then the reply is built in the order ``nak``,
``badsum``, ``short``, ``junk``, ``late`` (so ``junk`` + ``late`` gives a late, junk-prefixed reply).
Each kind draws from its own random generator, seeded from ``seed`` and the kind's name, once on
every frame: ``drop=0.2&seed=1`` drops the same frames whether or not ``junk=0.1`` is also given.
"""

from __future__ import annotations

import random
from collections.abc import Mapping
from dataclasses import dataclass, field

from choreo.wire import protocol as p
from choreo.numtext import whole_number
from choreo.wire.protocol import nak

# Order matters: precedence when several hit one frame, and the order of random draws.
FRAME_FAULTS: tuple[str, ...] = ("lose", "drop", "nak", "badsum", "short", "junk", "late")
# Counted over the frames that start a motion (a restore or resume with a motion armed), not
# over every frame: `lose_start=2` loses the reply to every second start.
START_FAULTS: tuple[str, ...] = ("lose_start",)
# Decided when the client writes a frame, before the board sees it: counted over writes.
WRITE_FAULTS: tuple[str, ...] = ("hold",)
FAULT_KINDS: tuple[str, ...] = FRAME_FAULTS + START_FAULTS + WRITE_FAULTS
JUNK = bytes((0xFF, 0x00, 0xAA))  # 0xff is no valid size byte: a careful reader notices at once
DEFAULT_LATE_S = 0.5
DEFAULT_HOLD_S = 0.04  # most of a 50 ms status refresh: a read sent a refresh after the write can come first

# Faults after which the board did not execute the frame (it never got it, or refused it).
NOT_EXECUTED = frozenset({"lose", "drop", "nak"})
# What `faults_on` may name: a frame's kind as the board reads it (see `frame_kind`).
FRAME_KINDS: tuple[str, ...] = ("stop", "counter", "play", "restore", "read", "sync", "other")


def frame_kind(data: bytes) -> str:
    """What a frame is to the board, from its bytes alone (the layout does not matter): the
    play sequence's frames by what they write, reads, the ACK check; `other` for the rest."""
    try:
        command = p.parse_command(data)
    except ValueError:
        return "other"
    if command.command == p.CMD_CALL and command.address is not None:
        return "play"
    if command.move_type == p.MOV_RAM_TO_COM:
        return "read"
    if command.move_type == p.MOV_COM_TO_RAM and command.payload:
        if command.address == p.CONFIG_ADDRESS:
            return "restore" if command.payload[0] & p.RUN_BIT else "stop"
        if command.address == p.PROGRAM_COUNTER_ADDRESS:
            return "counter"
    if bytes(data) == p.sync_frame().data:
        return "sync"
    return "other"


def parse_frame_kinds(text: str) -> frozenset[str]:
    """`play,restore` -> the frame kinds `faults_on` names; ValueError lists the kinds."""
    kinds = frozenset(part.strip() for part in text.split(",") if part.strip())
    if not kinds:
        raise ValueError(f"no frame kind (known: {', '.join(FRAME_KINDS)})")
    check_frame_kinds(kinds)
    return kinds


def check_frame_kinds(kinds: frozenset[str]) -> None:
    """ValueError naming the first kind that is not a frame kind, and the known ones."""
    unknown = sorted(kinds - set(FRAME_KINDS))
    if unknown:
        raise ValueError(f"unknown frame kind {unknown[0]!r} (known: {', '.join(FRAME_KINDS)})")


@dataclass(frozen=True)
class Trigger:
    """When a fault hits: every `every`-th frame, or with `probability` on each frame."""

    every: int | None = None
    probability: float | None = None

    def __post_init__(self) -> None:
        if (self.every is None) == (self.probability is None):
            raise ValueError("a fault trigger needs exactly one of every=K or probability=P")
        if self.every is not None and self.every < 1:
            raise ValueError(f"every {self.every}: K must be a whole number >= 1")
        if self.probability is not None and not 0 < self.probability < 1:
            raise ValueError(f"probability {self.probability}: P must be strictly between 0 and 1")

    @classmethod
    def parse(cls, text: str) -> Trigger:
        """`5` -> every 5th frame, `0.2` -> probability 0.2 (see the module docstring)."""
        text = text.strip()
        every = whole_number(text)
        if every is not None:
            if every < 1:
                raise ValueError("every K-th frame needs K >= 1 (leave the fault out for never)")
            return cls(every=every)
        try:
            probability = float(text)
        except ValueError:
            raise ValueError("neither a whole number K (every K-th frame) nor a probability like 0.2") from None
        if not 0 < probability < 1:
            raise ValueError("a probability must be strictly between 0 and 1 (for every K-th frame write K, e.g. 1)")
        return cls(probability=probability)

    def hits(self, number: int, draw: float | None) -> bool:
        """Whether frame `number` (1-based) is hit, given this frame's random draw if any."""
        if self.every is not None:
            return number % self.every == 0
        return draw is not None and draw < (self.probability or 0.0)

    def __str__(self) -> str:
        if self.every is not None:
            return "every frame" if self.every == 1 else f"every {self.every}th frame"
        return f"probability {self.probability:g}"


@dataclass(frozen=True)
class FaultPlan:
    """Which faults to inject and how: a value object, parsed once from options."""

    triggers: Mapping[str, Trigger] = field(default_factory=dict)
    seed: int = 0
    late_s: float = DEFAULT_LATE_S
    on: frozenset[str] = frozenset()  # frame kinds the frame faults hit (see `frame_kind`); empty: all
    hold_s: float = DEFAULT_HOLD_S

    def __post_init__(self) -> None:
        unknown = sorted(set(self.triggers) - set(FAULT_KINDS))
        if unknown:
            raise ValueError(f"unknown fault kind {unknown[0]!r} (known: {', '.join(FAULT_KINDS)})")
        check_frame_kinds(self.on)
        if self.late_s < 0:
            raise ValueError(f"late_ms must be >= 0, not {self.late_s * 1000:g}")
        if self.hold_s < 0:
            raise ValueError(f"hold_ms must be >= 0, not {self.hold_s * 1000:g}")

    @classmethod
    def parse(cls, values: Mapping[str, str], seed: int = 0, late_s: float = DEFAULT_LATE_S,
              on: frozenset[str] = frozenset(), hold_s: float = DEFAULT_HOLD_S) -> FaultPlan:
        """Triggers from their spelled values, each error naming its fault kind."""
        triggers = {}
        for kind, text in values.items():
            try:
                triggers[kind] = Trigger.parse(text)
            except ValueError as exc:
                raise ValueError(f"{kind}={text}: {exc}") from None
        return cls(triggers, seed, late_s, on, hold_s)

    def describe(self) -> str:
        if not self.triggers:
            return "no faults"
        aimed = f" {'/'.join(k for k in FRAME_KINDS if k in self.on)} frame" if self.on else " frame"
        parts = [f"{kind} {self.triggers[kind]}".replace(" frame", " start" if kind in START_FAULTS else aimed)
                 for kind in FAULT_KINDS if kind in self.triggers]
        return ", ".join(parts) + (f" (seed {self.seed})" if self.uses_random else "")

    @property
    def uses_random(self) -> bool:
        return any(t.probability is not None for t in self.triggers.values())


@dataclass(frozen=True)
class Damage:
    """What faults did to one frame's reply."""

    kinds: tuple[str, ...]
    reply: bytes | None  # None: nothing is sent back
    extra_delay_s: float = 0.0
    executed: bool = True
    lost: bool = False


class FaultInjector:
    """Decides, frame by frame, which faults hit, and damages the reply accordingly.

    It owns its random generators (one a kind, seeded from the plan) so two boards with the same
    plan and the same frames behave identically: tests can name the exact frames a fault will hit.
    """

    def __init__(self, plan: FaultPlan | None = None) -> None:
        self.plan = plan or FaultPlan()
        self._rngs = {kind: random.Random(f"{self.plan.seed}:{kind}") for kind in FAULT_KINDS}
        self._lost = False
        self._aimed = 0  # frames of the kinds `faults_on` names, so far
        self._written = 0  # frames the client wrote (of the kinds `faults_on` names), for `hold`

    def decide(self, number: int, data: bytes = b"") -> tuple[str, ...]:
        """The fault kinds that hit frame `number` (1-based; `data`, its bytes), in
        `FAULT_KINDS` order. With `faults_on`, only frames of its kinds count and are hit."""
        if self.plan.on:
            if frame_kind(data) not in self.plan.on:
                return ()
            self._aimed += 1
            number = self._aimed
        hit = []
        for kind in FRAME_FAULTS:
            trigger = self.plan.triggers.get(kind)
            if trigger is None:
                continue
            draw = self._rngs[kind].random() if trigger.probability is not None else None
            if kind == "lose":
                if self._lost:
                    continue
                hits = number == trigger.every if trigger.every is not None else trigger.hits(number, draw)
                if hits:
                    self._lost = True
                    hit.append(kind)
                continue
            if trigger.hits(number, draw):
                hit.append(kind)
        return tuple(hit)

    def held_s(self, data: bytes) -> float:
        """How long the client's side holds this write before its first byte leaves (`hold`)."""
        trigger = self.plan.triggers.get("hold")
        if trigger is None or (self.plan.on and frame_kind(data) not in self.plan.on):
            return 0.0
        self._written += 1
        draw = self._rngs["hold"].random() if trigger.probability is not None else None
        return self.plan.hold_s if trigger.hits(self._written, draw) else 0.0

    def start_lost(self, start: int) -> bool:
        """Whether the reply to the `start`-th motion start (1-based) is lost (`lose_start`)."""
        trigger = self.plan.triggers.get("lose_start")
        if trigger is None:
            return False
        draw = self._rngs["lose_start"].random() if trigger.probability is not None else None
        return trigger.hits(start, draw)

    def damage(self, kinds: tuple[str, ...], command: int, reply: bytes) -> Damage:
        """Apply the faults that hit a frame to the reply the board would have sent."""
        if "lose" in kinds:
            return Damage(kinds, None, executed=False, lost=True)
        if "drop" in kinds:
            return Damage(kinds, None, executed=False)
        data = nak(command) if "nak" in kinds else reply
        if "badsum" in kinds and data:
            data = data[:-1] + bytes((data[-1] ^ 0xFF,))
        if "short" in kinds and data:
            data = data[: max(1, len(data) // 2)]
        if "junk" in kinds:
            data = JUNK + data
        delay = self.plan.late_s if "late" in kinds else 0.0
        return Damage(kinds, data, delay, executed="nak" not in kinds)
