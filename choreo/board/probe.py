"""`choreo probe`: what board answers on a port, read without changing anything.

It finds the baud the board answers at (the ACK check at each of the RCB-4's bauds, even
parity), then reads the firmware's version text, the config word (RAM 0x0000) and the 10 bytes
at RAM 0x0002 (program counter, return address, call depth). It never writes RAM and never sends
a CALL: probing a robot must not move it. What the program counter suggests about the board's
memory layout is a hint, never a fact: the same address can mean different things on boards
written by different Heart to Heart 4 versions.
"""

from __future__ import annotations

from collections.abc import Iterable
from dataclasses import dataclass, field

from choreo.board.link import DEFAULT_TIMEOUT_S, Link
from choreo.clock import RunClock, SystemTime, TimeSource
from choreo.errors import LinkError
from choreo.wire import protocol
from choreo.wire.layouts import HTH4_22, SEED
from choreo.wire.protocol import ReplyKind

FRAME_PERIODS_MS = (10, 15, 20, 25)  # config bits 5-4
MAIN_LOOP_HTH4_1 = SEED.main_loop  # HTH4 1.x's, and what the document's stop frame writes
MAIN_LOOP_HTH4_2 = HTH4_22.main_loop  # HTH4 2.0 and later (Kondo's library writes it)


@dataclass(frozen=True)
class ConfigWord:
    """The board's config word, bit by bit (docs/hardware.md, "Errata: The config word": RAM 0x0000, little endian)."""

    word: int

    def bit(self, n: int) -> bool:
        return bool(self.word >> n & 1)

    @property
    def flags(self) -> dict[str, bool]:
        """The on/off bits by name (`probe --json`'s keys), in the order `lines` shows them."""
        return {"rom_run": self.bit(1), "ics": self.bit(0), "end_message": self.bit(2),
                "vector_jump": self.bit(3), "green_led": self.bit(15)}

    @property
    def frame_ms(self) -> int:
        return FRAME_PERIODS_MS[self.word >> 4 & 0b11]

    def baud_code(self, shift: int) -> int:
        """The 2-bit baud field at `shift` (protocol's COM_BAUD_SHIFT or ICS_BAUD_SHIFT)."""
        return self.word >> shift & protocol.BAUD_CODE_BITS

    @property
    def com_baud(self) -> int | None:
        return protocol.baud_of_code(self.baud_code(protocol.COM_BAUD_SHIFT))

    @property
    def ics_baud(self) -> int | None:
        return protocol.baud_of_code(self.baud_code(protocol.ICS_BAUD_SHIFT))

    def lines(self) -> list[str]:
        def baud(value: int | None, code: int) -> str:
            return f"{value} baud" if value else f"unknown code {code:02b}"

        on = {True: "on", False: "off"}
        flags = self.flags
        return [
            f"config    0x{self.word:04x}",
            f"  ROM program run      {on[flags['rom_run']]}"
            + ("" if flags["rom_run"] else " (the board's program is stopped)"),
            f"  ICS servo bus        {on[flags['ics']]}",
            f"  end-of-move message  {on[flags['end_message']]}",
            f"  vector jump          {on[flags['vector_jump']]}",
            f"  servo frame period   {self.frame_ms} ms",
            f"  COM baud             {baud(self.com_baud, self.baud_code(protocol.COM_BAUD_SHIFT))}",
            f"  ICS baud             {baud(self.ics_baud, self.baud_code(protocol.ICS_BAUD_SHIFT))}",
            f"  green LED            {on[flags['green_led']]}",
        ]


@dataclass(frozen=True)
class Counter:
    """The 10 bytes at RAM 0x0002: where the board's program is."""

    data: bytes

    @property
    def program_counter(self) -> int:
        return int.from_bytes(self.data[:protocol.ADDRESS_BYTES], "little")

    @property
    def in_call(self) -> bool:
        """Kondo's rule for 'a motion is running': inside the slots with a return pushed."""
        return protocol.in_called_motion(self.data)


@dataclass
class BoardInfo:
    """What the probe read; None where the board did not answer that question."""

    port: str
    baud: int
    version: str | None = None
    config: ConfigWord | None = None
    counter: Counter | None = None
    notes: list[str] = field(default_factory=list)

    def hints(self) -> list[str]:
        """What the readings suggest, each marked as a hint (never a fact)."""
        hints = []
        if self.counter is not None:
            hints += _counter_hints(self.counter)
        if self.config is not None and self.config.com_baud not in (None, self.baud):
            hints.append(f"the config word's COM baud bits say {self.config.com_baud} but the board "
                         f"answered at {self.baud}: the word may not be what the board runs on")
        return [f"hint: {h}" for h in hints]

    def lines(self) -> list[str]:
        lines = [f"board     answers on {self.port} at {self.baud} baud, 8E1 (ACK check)"]
        lines.append(f"version   {self.version!r}" if self.version is not None else "version   not answered")
        lines += self.config.lines() if self.config else ["config    not answered"]
        if self.counter is not None:
            pc = self.counter.program_counter
            pushed = protocol.hexbytes(self.counter.data[protocol.ADDRESS_BYTES:])
            lines.append(f"program   counter 0x{pc:06x}, then {pushed}"
                         f" ({'inside a called motion' if self.counter.in_call else 'not in a call'})")
        else:
            lines.append("program   not answered")
        return lines + self.notes + self.hints()


def _counter_hints(counter: Counter) -> list[str]:
    pc = counter.program_counter
    choose = "choose with `robot.layout` in the show or `--layout` (docs/hardware.md: Board layouts)"
    if pc == MAIN_LOOP_HTH4_2:
        return [f"the program is in the main loop at 0x{pc:06x}, where Heart to Heart 4 2.0 and "
                f"later put it: a board set up with HTH4 2.2 or later uses layout hth4-2.2 (2.0/2.1: "
                f"seed); {choose}"]
    if pc == MAIN_LOOP_HTH4_1:
        return [f"the program counter is 0x{pc:06x}, HTH4 1.x's main loop, which the seed layout's "
                f"stop frame also writes: the board was set up with HTH4 1.x or last played by a "
                f"seed-layout show; {choose}"]
    if counter.in_call:
        return [f"a motion is running (counter 0x{pc:06x}): "
                f"{_slot_words(pc, HTH4_22.first_slot, HTH4_22.name)}; "
                f"{_slot_words(pc, SEED.first_slot, SEED.name)}; probe again when the robot is still"]
    return [f"the program counter 0x{pc:06x} is not a main loop choreo knows: no layout hint"]


def _slot_words(pc: int, first: int, layout: str) -> str:
    if pc < first:
        return f"before {layout}'s first slot"
    slot, offset = divmod(pc - first, protocol.SLOT_SIZE)
    return f"{layout}: slot {slot} + {offset} bytes" if slot < protocol.MOTION_SLOTS else f"past {layout}'s slots"


def probe(url: str, *, bauds: Iterable[int] = protocol.BAUDS, timeout: float = DEFAULT_TIMEOUT_S,
          time_source: TimeSource | None = None) -> BoardInfo:
    """Find the baud that answers, then read what the board says; LinkError if none answers."""
    clock = RunClock(time_source or SystemTime())
    tried: list[str] = []
    refused: list[LinkError] = []  # a baud the port (a pty, an adapter) will not take: the next may do
    for baud in bauds:
        try:
            link = Link.open(url, baud, timeout=timeout, tries=2, clock=clock)
        except LinkError as exc:
            refused.append(exc)
            continue
        try:
            answer = _answers(link)
            if answer is not None:
                notes = [f"note: {exc}: not tried at that baud" for exc in refused]
                return _read(link, url, baud, notes, refused_all=answer is ReplyKind.NAK)
        finally:
            link.close()
        tried.append(str(baud))
    if refused and not tried:
        raise refused[0]  # no baud opens: the port itself is the problem
    also = "".join(f"; {exc}" for exc in refused)
    raise LinkError(f"port {url}: no answer to the ACK check (04 fe 06 08) at {', '.join(tried)} "
                    "baud, even parity: check that the board is powered, the adapter (Kondo's USB "
                    f"adapter, or 5 V inverted logic without it), the cable, and the parity (8E1){also}")


def _answers(link: Link) -> ReplyKind | None:
    """Two ACK checks; any well-formed answer (ACK or NAK, which it was) means a board listens
    at this baud; None if neither was answered."""
    for attempt in (1, 2):
        reply = link.send(protocol.sync_frame(), attempt)
        if reply.kind in (ReplyKind.ACK, ReplyKind.NAK):
            return reply.kind
    return None


def _read(link: Link, url: str, baud: int, notes: list[str], refused_all: bool = False) -> BoardInfo:
    info = BoardInfo(url, baud, notes=notes)
    asked = len(notes)
    version = _ask(link, protocol.version_frame(), info, "version")
    if version is not None:
        info.version = version[2:-1].decode("ascii", "replace").strip()
    config = _ask(link, protocol.read_frame(protocol.CONFIG_ADDRESS, protocol.CONFIG_BYTES), info, "config word")
    if config is not None:
        info.config = ConfigWord(protocol.config_word(config))
    counter = _ask(link, protocol.read_frame(protocol.PROGRAM_COUNTER_ADDRESS, protocol.COUNTER_READ_BYTES),
                   info, "program counter")
    if counter is not None:
        info.counter = Counter(counter[2:-1])
    if info.version is None and info.config is None and info.counter is None:
        raise _no_board(url, baud, info.notes[asked:], refused_all)
    return info


def _no_board(url: str, baud: int, notes: list[str], refused_all: bool = False) -> LinkError:
    """An ACK check answered and nothing after it: the ACK's reply is its own bytes, so a line
    that echoes what is sent (TX joined to RX, a half-duplex adapter) or a device that repeats
    one answer passes it. That is no board to report as found (nor for `doctor` to call ok).
    A NAK to the ACK check is no echo: something refuses every frame it hears (garbled)."""
    first = notes[0].removeprefix("note: ") if notes else "no answer"
    if refused_all:
        return LinkError(f"port {url}: something at {baud} baud NAKs the ACK check and answers no question "
                         "after it (version, config word, program counter): it hears every frame garbled: "
                         "check the parity (8E1), the cable and that no other program talks on the port; "
                         f"first: {first}")
    return LinkError(f"port {url}: something answers the ACK check at {baud} baud but no question after it "
                     "(version, config word, program counter), so it is not a board: a line that echoes what "
                     f"is sent (TX joined to RX) answers the ACK check with its own bytes; first: {first}")


def _ask(link: Link, frame: protocol.Frame, info: BoardInfo, what: str) -> bytes | None:
    """One question; a board that will not answer it is noted, not an error (the rest may)."""
    try:
        reply = link.exchange(frame)
    except LinkError as exc:
        info.notes.append(f"note: the {what} was not read: {exc}")
        return None
    return reply.data
