"""A deterministic model of an RCB-4 board as the play-motion sequence sees it.

Time is explicit: every call takes `now` (seconds, any monotonic clock), and the board never
sleeps or starts threads. That makes it exact under test (a motion of 1.0 s started at t=2.0 runs
at t=2.999 and not at t=3.0) and lets the same model serve the in-process `sim://` port (clock:
`time.monotonic()`) and the pseudo-terminal server.

What it models, following the spec and its errata:

- RAM (`RAM_SIZE` bytes) with the config word at 0x0000, power-on value 0x0002 (only bit 1,
  "ROM program run", set).
- MOV COM->RAM writes the literal bytes; MOV RAM->COM answers `05 00 LO HI SUM`-style
  (`ram_reply`) with the bytes read. A write that touches the program counter (RAM 0x0002-0x0004,
  as the stop frame does) resets the program: it forgets an armed slot (the board would resume
  at the written address) and empties the return-address stack.
- Status refresh: the board updates the motion execution status only every `refresh_s` (50 ms)
  of board time, counted from power-on (`power_on`, the board's creation). A read of the config
  word (RAM 0x0000-0x0001, what the status query reads) returns the word as of the last refresh
  tick, so a motion's end shows up to 50 ms late, a query sent less than 50 ms after the restore
  may still see the word from before it, and two queries within one period get the same value.
  Writes change the real word at once; only the read is stale. A tick at the very instant a
  frame arrives sees the board as it was before the frame. `refresh_s` 0: reads are live.
- A layout (`seed` or `hth4-2.2`, `choreo.wire.layouts`) says where its motion slots start. CALL of a
  slot's start address arms that slot: the program counter (RAM 0x0002-0x0004) moves there and
  the old counter is pushed as the return address (0x0005-0x0007), the call depth at 0x0008.
  A CALL of any other address (another layout's slot, say) is ACKed, journalled as a `stray`
  call (counted in `stray_calls`) and plays nothing (the real board would jump into motion
  data). When a motion ends, the counter goes back to the return address and the return
  address and depth are cleared: Kondo's "still running" rule reads exactly that. At power-on
  the counter is at the layout's main loop and the config word is `power_on_config`. Every CALL
  pushes a return address: a CALL while one is already pushed (a second CALL with no stop frame
  between, as a client re-sending a CALL alone would) is journalled as a `stack` event and
  counted in `stack_faults`. It is still ACKed and arms its slot: the real board gives no sign
  either.
- A write that sets the config run bit (the restore frame, 0x8723) starts the armed motion, which
  runs for its slot's duration; while it runs, the status read shows the config low byte 0x23.
  When it ends, the board clears the run bit (0x8721: low byte 0x21).
- A write that clears the run bit (the stop frame, 0x8721) stops a running motion at once.
- A run-bit write with nothing armed and nothing running runs nothing, so the run bit clears at
  once: the program it would resume has already returned. A status read then shows 0x21.
- A frame with a bad checksum, a malformed frame, a command the model does not implement, or an
  address outside the modelled RAM gets a NAK `04 CMD 15 SUM`. Bytes that cannot be a frame at
  all (a size byte below 3 or above 128) get a NAK with the command byte that followed, or 00.
- The status refresh covers RAM 0x0000-0x000B (the config word and the program state, what
  both layouts' status reads and the link's read after a lost start reply look at): the sources
  only say the status is refreshed every 50 ms, so the cautious model shows the program state
  as late as the config word.
- `baud_switch`: a config write whose COM baud bits (7-6) name another baud switches the
  board to it at once, its ACK included (lost to a client at the old baud). Kondo does not
  document what a board does; this is the worst case.
- `lose_start` (a fault): the reply to a frame that starts a motion is lost, the motion starts.
- ACK check (`04 fe 06 08`) is answered with the same 4 bytes, as the real board does.
- The version query (`03 fd 00`) is answered with `VERSION_TEXT`, framed like any answer.
- One reply at a time: a frame (or a burst of noise) whose first byte arrives before the board
  has put the last byte of its previous reply on the wire (still waiting out its reply delay,
  a `late` fault's delay included, or still transmitting) is not answered, not executed and not
  counted: it is journalled as `ignored`. The errata: the reply must be read before the next
  frame is sent. (A real board may then stop answering altogether; that is not modelled.)

Wire time: a reply's first byte starts `reply_delay_s` after the frame's last byte arrived (and
not before the board finished sending its previous reply: one serial line, in order), and each
byte takes 11 bit times (start, 8 data, even parity, stop) at the board's baud. `Transmission`
carries, per byte, the time it has fully arrived at the client.
"""

from __future__ import annotations

import math
from collections import deque
from collections.abc import Callable, Mapping
from dataclasses import dataclass, field, replace

from choreo.wire import protocol as p
from choreo.wire.framewords import describe_frame
from choreo.wire.layouts import SEED, Layout
from choreo.sim.faults import NOT_EXECUTED, FaultInjector, FaultPlan

RAM_SIZE = 0x0400
POWER_ON_CONFIG = 0x0002
RUN_BIT = p.RUN_BIT  # config bit 1: ROM program run
# where the stop frame saves the program counter
PROGRAM_COUNTER = range(p.PROGRAM_COUNTER_ADDRESS, p.PROGRAM_COUNTER_ADDRESS + p.ADDRESS_BYTES)
RETURN_ADDRESS = range(p.RETURN_ADDRESS_ADDRESS, p.RETURN_ADDRESS_ADDRESS + p.ADDRESS_BYTES)  # what a CALL pushes
CALL_DEPTH = p.CALL_DEPTH_ADDRESS
STATUS_SPAN = p.PROGRAM_STATE_BYTES  # RAM the status refresh covers: the config word and the program state
BITS_PER_BYTE = 11  # start + 8 data + even parity + stop
DEFAULT_REPLY_DELAY_S = 0.0002
DEFAULT_MOTION_S = 1.0
DEFAULT_REFRESH_S = 0.05  # the spec: the controller updates the execution status every 50 ms
CMD_ACK_CHECK = 0xFE
# The simulator's answer to the version query. Real firmware answers its own text (JSK's rcb4
# reads `CB-4 V1.0      090715          ` from an RCB-4mini): this one says what it is.
VERSION_TEXT = b"RCB-4 simulator (choreo)        "


@dataclass(frozen=True)
class Transmission:
    """Bytes the board sends, with the time each one has fully arrived at the client."""

    data: bytes
    times: tuple[float, ...]

    @property
    def start(self) -> float:
        return self.times[0] if self.times else 0.0

    @property
    def end(self) -> float:
        return self.times[-1] if self.times else 0.0


@dataclass(frozen=True)
class JournalEntry:
    """One thing that happened on the board, for tests and for `choreo sim -v`.

    kind: `frame` (a frame or a burst of noise the board answered or ignored), `partial`
    (an incomplete frame dropped after an inter-byte gap), `ignored` (bytes sent with the wrong
    line settings, which a real board cannot read, or a frame that arrived while the board was
    still replying), `motion` (a motion ended by itself), `stack` (a CALL pushed a second
    return address).
    """

    kind: str
    at: float  # board time: the frame's last byte arrived, or the event happened
    data: bytes = b""
    number: int | None = None  # 1-based frame count, the one faults are scheduled on
    reply: bytes | None = None  # what was sent back (after faults); None: nothing
    reply_at: float | None = None  # when the reply's last byte arrives at the client
    faults: tuple[str, ...] = ()
    note: str = ""

    def __str__(self) -> str:
        return self.line()

    def line(self, origin: float = 0.0) -> str:
        """One line of text; times are seconds since `origin` (the server's start, say)."""
        head = f"{self.at - origin:10.6f} "
        if self.kind != "frame":
            return head + f"{self.kind}: {self.note}" + (f" [{p.hexbytes(self.data)}]" if self.data else "")
        sent = "no reply" if self.reply is None else f"-> {p.hexbytes(self.reply)}"
        tags = f" [fault: {', '.join(self.faults)}]" if self.faults else ""
        return head + f"#{self.number} {p.hexbytes(self.data)} ({self.note}) {sent}{tags}"


@dataclass
class _Running:
    slot: int
    started: float
    ends: float


@dataclass(frozen=True)
class _Outcome:
    reply: bytes
    note: str
    command: int
    events: tuple[JournalEntry, ...] = ()  # journalled after the frame itself
    started: bool = False  # the frame started a motion (what `lose_start` hits)


@dataclass(eq=False)
class SimBoard:
    """The board: RAM, an armed slot, a running motion, a reply line, faults and a journal."""

    baud: int = p.DEFAULT_BAUD
    reply_delay_s: float = DEFAULT_REPLY_DELAY_S
    motion_s: float = DEFAULT_MOTION_S
    durations: Mapping[int, float] = field(default_factory=dict)
    refresh_s: float = DEFAULT_REFRESH_S  # status refresh period; 0: a status read is live
    power_on: float = 0.0  # board time of power-on: refresh ticks are power_on + k * refresh_s
    faults: FaultPlan = field(default_factory=FaultPlan)
    wire: bool = True  # emulate 11 bits a byte at `baud`; False: bytes take no time
    journal_size: int = 100_000
    on_entry: Callable[[JournalEntry], None] | None = None
    layout: Layout = SEED  # where its motions start: a CALL anywhere else is a stray call
    power_on_config: int = POWER_ON_CONFIG  # the config word at power-on
    # A config write whose COM baud bits name another baud switches the board's speed (the
    # worst case: Kondo does not document it).
    baud_switch: bool = False

    def __post_init__(self) -> None:
        if self.baud not in p.BAUDS:
            raise ValueError(p.baud_refusal(self.baud))
        if self.reply_delay_s < 0:
            raise ValueError(f"reply delay must be >= 0, not {self.reply_delay_s}")
        if not self.refresh_s >= 0:
            raise ValueError(f"status refresh period must be >= 0 s, not {self.refresh_s}")
        self.durations = dict(self.durations)
        for slot, seconds in [(None, self.motion_s), *self.durations.items()]:
            if seconds < 0:
                raise ValueError(f"motion duration must be >= 0 s, not {seconds}")
            if slot is not None and not 0 <= slot < p.MOTION_SLOTS:
                raise ValueError(f"duration for slot {slot}: slots are 0..{p.MOTION_SLOTS - 1}")
        if not 0 <= self.power_on_config <= 0xFFFF:
            raise ValueError(f"config word 0x{self.power_on_config:x} is not 16 bits")
        self.ram = bytearray(RAM_SIZE)
        self.ram[0:2] = self.power_on_config.to_bytes(2, "little")
        self.ram[2:5] = self.layout.main_loop.to_bytes(3, "little")  # the main loop runs
        self.armed: int | None = None
        self.frames_received = 0
        self.lost = False
        self.lost_at_frame: int | None = None
        self.ignored = 0  # frames not answered: they came while the board was still replying
        self.stack_depth = 0  # return addresses pushed by CALLs since the last stop frame
        self.stack_faults = 0  # CALLs that pushed a second return address
        self.stray_calls = 0  # CALLs to an address that is not the start of one of the layout's slots
        self.starts = 0  # motions started (what `lose_start` counts)
        self.journal: deque[JournalEntry] = deque(maxlen=self.journal_size)
        self._running: _Running | None = None
        self._injector = FaultInjector(self.faults)
        self._tx_free = float("-inf")  # when the board's last reply byte is on the wire
        self._now = float("-inf")
        self._tick = 0  # the last refresh tick taken (0: the one at power-on)
        self._shown = bytes(self.ram[:STATUS_SPAN])  # what a status read returns until the next tick

    # -- time and state ----------------------------------------------------------------------

    @property
    def byte_time(self) -> float:
        """Seconds one byte occupies the line (11 bits at the board's baud), 0 without wire time."""
        return BITS_PER_BYTE / self.baud if self.wire else 0.0

    def duration(self, slot: int) -> float:
        return self.durations.get(slot, self.motion_s)

    def config(self, now: float) -> int:
        """The config word at RAM 0x0000 as of `now` (a look: changes nothing)."""
        word = self.ram[0] | self.ram[1] << 8
        return word & ~RUN_BIT if self._ended_by(now) else word

    def status(self, now: float) -> int:
        """The config word a status read at `now` would return: as of the last refresh tick
        (a look: changes nothing; for `now` at or after the board's time)."""
        shown = self.status_bytes(now)
        return shown[0] | shown[1] << 8

    def status_bytes(self, now: float) -> bytes:
        """RAM 0x0000-0x000B as a status read at `now` would return it (a look)."""
        if self.refresh_s <= 0:
            return self._state_at(now)
        tick = self._tick_index(now)
        if tick <= self._tick or now < self._now:
            return self._shown
        return self._state_at(self._tick_time(tick))

    def running(self, now: float) -> int | None:
        """The slot whose motion is running at `now`, or None (a look: changes nothing)."""
        if self._running is None or self._ended_by(now):
            return None
        return self._running.slot

    def motion_end(self) -> float | None:
        """When the running motion will end (board time), or None."""
        return self._running.ends if self._running else None

    def advance(self, now: float) -> None:
        """Let time pass up to `now`: a motion whose time is over ends, clears the run bit and is
        journalled. Frames do this themselves; a server calls it to journal an end on time.

        The board's time only moves forward: an earlier `now` changes nothing.
        """
        if now <= self._now:
            return
        if self.refresh_s > 0:
            tick = self._tick_index(now)
            if tick > self._tick:  # nothing was written since `_now`: the state at the tick is known
                self._shown = self._state_at(self._tick_time(tick))
                self._tick = tick
        self._now = now
        run = self._running
        if run is not None and now >= run.ends:
            self._running = None
            # The program goes back to the return address; `stack_depth` still counts the CALL
            # (cautious: only a stop frame resets the program, so a CALL with no stop frame
            # before it is a stack fault even after the motion ended).
            self.ram[:STATUS_SPAN] = _returned(self.ram[:STATUS_SPAN])
            self._record(JournalEntry("motion", run.ends, note=f"motion {run.slot} ended, run bit "
                                                                "cleared, back at the return address"))

    def _ended_by(self, now: float) -> bool:
        return self._running is not None and now >= self._running.ends

    def _state_at(self, at: float) -> bytes:
        """RAM 0x0000-0x000B at `at`, no later than the next frame (as it is, less a motion end)."""
        state = bytes(self.ram[:STATUS_SPAN])
        return _returned(state) if self._ended_by(at) else state

    def _tick_index(self, now: float) -> int:
        # The nanosecond of slack keeps exact tick times (0.15 / 0.05) on their tick.
        return math.floor((now - self.power_on) / self.refresh_s + 1e-9)

    def _tick_time(self, tick: int) -> float:
        return self.power_on + tick * self.refresh_s

    # -- frames ------------------------------------------------------------------------------

    def receive(self, data: bytes, now: float, first: float | None = None) -> Transmission | None:
        """Take one frame (or one burst of noise) whose last byte arrived at `now`.

        `first`: when its first byte had arrived; by default, the bytes came back to back
        (`now` less the wire time of all but one). A frame whose first byte came before the
        board's previous reply was all on the wire is not answered (journalled as `ignored`).

        Returns what the board sends back, timed, or None when it sends nothing (a `drop` or
        `lose` fault, or an ignored frame). After a `lose` fault, `lost` is True and every later
        frame is refused with a ValueError: the transport must stop using the port.
        """
        if self.lost:
            raise ValueError(f"the simulated port was lost at frame {self.lost_at_frame}")
        if now < self._now:
            raise ValueError(f"frame at {now} arrived before the board's time {self._now}: frames come in order")
        self.advance(now)
        data = bytes(data)
        if first is None:
            first = now - max(len(data) - 1, 0) * self.byte_time
        if first < self._tx_free:
            self.ignored += 1
            self._record(JournalEntry(
                "ignored", now, data,
                note=f"{_described(data, self.layout)} arrived while the board was still replying "
                     f"(its reply ends at {self._tx_free:.6f}): not answered",
            ))
            return None
        self.frames_received += 1
        number = self.frames_received
        kinds, outcome = self._answer(data, now, number)
        reply, command, note, events = outcome.reply, outcome.command, outcome.note, outcome.events
        damage = self._injector.damage(kinds, command, reply)
        if damage.lost:
            self.lost = True
            self.lost_at_frame = number
            note = _described(data, self.layout) + ": port lost"
        sent = None
        if damage.reply:  # b"": the reply was lost on the way (lose_start, a baud switch)
            sent = self._schedule(damage.reply, now + self.reply_delay_s + damage.extra_delay_s)
        self._record(
            JournalEntry(
                "frame", now, data, number,
                reply=sent.data if sent else None,
                reply_at=sent.end if sent else None,
                faults=kinds, note=note,
            )
        )
        for event in events:
            self._record(event)
        return sent

    def _answer(self, data: bytes, now: float, number: int) -> tuple[tuple[str, ...], _Outcome]:
        """The faults that hit frame `number`, and what the board makes of it before any damage
        on the way back: carried out, or not (never reached the board, or refused)."""
        kinds = self._injector.decide(number, data)
        if not NOT_EXECUTED.isdisjoint(kinds):
            return kinds, _Outcome(b"", _described(data, self.layout) + ": not executed", _command_byte(data))
        outcome = self._execute(data, now)
        if outcome.started:
            self.starts += 1
            if self._injector.start_lost(self.starts):
                kinds += ("lose_start",)
                outcome = replace(outcome, reply=b"", note=f"{outcome.note}; its reply is lost (lose_start)")
        return kinds, outcome

    def held_s(self, data: bytes) -> float:
        """How long the client's OS or adapter holds this write before it leaves (`hold` fault)."""
        return self._injector.held_s(bytes(data))

    def note(self, kind: str, at: float, data: bytes, text: str) -> None:
        """Journal something the transport saw that never became a frame (partial, ignored)."""
        self._record(JournalEntry(kind, at, bytes(data), note=text))

    def _schedule(self, data: bytes, ready: float) -> Transmission:
        start = max(ready, self._tx_free)
        bt = self.byte_time
        times = tuple(start + (i + 1) * bt for i in range(len(data)))
        self._tx_free = times[-1] if times else start
        return Transmission(data, times)

    def _record(self, entry: JournalEntry) -> None:
        self.journal.append(entry)
        if self.on_entry is not None:
            self.on_entry(entry)

    def _execute(self, data: bytes, now: float) -> _Outcome:
        """What the board does with a frame, and the reply it would send."""
        if not data or not 3 <= data[0] <= p.MAX_FRAME_SIZE:
            cmd = data[1] if len(data) > 1 else 0x00
            size = f"{data[0]:02x}" if data else "none"
            return _Outcome(p.nak(cmd), f"not a frame (size byte {size}): NAK", cmd)
        try:
            command = p.parse_command(data)
        except ValueError as exc:
            return _Outcome(p.nak(data[1]), f"{exc}: NAK", data[1])
        cmd = command.command
        if cmd == p.CMD_CALL and command.address is not None:
            return self._call(command, data, now)
        if command.move_type == p.MOV_COM_TO_RAM:
            return self._write(command, now)
        if command.move_type == p.MOV_RAM_TO_COM:
            return self._read(command)
        if cmd == CMD_ACK_CHECK and command.payload == bytes((p.ACK_BYTE,)):
            return _Outcome(p.ack(cmd), "ACK check: ACK", cmd)
        if cmd == p.CMD_VERSION and not command.payload:
            return _Outcome(p.build_frame(p.CMD_VERSION, VERSION_TEXT), "version query", cmd)
        return _Outcome(p.nak(cmd), f"command {cmd:02x} is not modelled: NAK", cmd)

    def _call(self, command: p.Command, data: bytes, now: float) -> _Outcome:
        address = command.address or 0
        slot = self.layout.slot_of(address)
        self.armed = slot
        what = f"motion {slot} armed" if slot is not None else "not a slot start, nothing armed"
        events: tuple[JournalEntry, ...] = ()
        if slot is None:
            self.stray_calls += 1
            events = (JournalEntry(
                "stray", now, data, number=self.frames_received,
                note=f"CALL 0x{address:06x} is not the first byte of a {self.layout.name} slot: "
                     f"it would jump into motion data; nothing played (stray call {self.stray_calls})",
            ),)
        else:  # the program will run the slot: the counter moves there, the return is pushed
            self.ram[RETURN_ADDRESS.start:RETURN_ADDRESS.stop] = self.ram[PROGRAM_COUNTER.start:PROGRAM_COUNTER.stop]
            self.ram[PROGRAM_COUNTER.start:PROGRAM_COUNTER.stop] = address.to_bytes(3, "little")
        self.stack_depth += 1
        self.ram[CALL_DEPTH] = min(self.stack_depth, 0xFF)
        if self.stack_depth > 1:
            self.stack_faults += 1
            what += f", return stack depth {self.stack_depth}"
            events += (JournalEntry(
                "stack", now, data, number=self.frames_received,
                note=f"second return address pushed: CALL re-sent without a stop frame "
                     f"(depth {self.stack_depth}, stack fault {self.stack_faults})",
            ),)
        return _Outcome(p.ack(p.CMD_CALL), f"CALL 0x{address:06x}: {what}", p.CMD_CALL, events)

    def _write(self, command: p.Command, now: float) -> _Outcome:
        address, payload = command.address or 0, command.payload
        if address + len(payload) > RAM_SIZE:
            return _Outcome(
                p.nak(p.CMD_MOV),
                f"write of {len(payload)} bytes at 0x{address:06x} is outside the modelled RAM: NAK",
                p.CMD_MOV,
            )
        was_running = self.ram[0] & RUN_BIT
        self.ram[address : address + len(payload)] = payload
        written = range(address, address + len(payload))
        notes = [f"RAM 0x{address:04x} <- {p.hexbytes(payload)}"]
        if any(a in written for a in PROGRAM_COUNTER):
            if self.armed is not None:
                notes.append(f"program counter rewritten, motion {self.armed} disarmed")
                self.armed = None
            if self.stack_depth:
                notes.append(f"program counter rewritten, return stack ({self.stack_depth}) emptied")
                self.stack_depth = 0
        started = False
        if 0 in written:
            note = self._config_written(bool(was_running), now)
            started = " started" in note
            notes.append(note)
        outcome = _Outcome(p.ack(p.CMD_MOV), ", ".join(n for n in notes if n), p.CMD_MOV,
                           started=started)
        if 0 in written and self.baud_switch:
            return self._switch_baud(outcome)
        return outcome

    def _switch_baud(self, outcome: _Outcome) -> _Outcome:
        """The config's COM baud bits name another baud: from now on the board talks at that one,
        its answer to this very write included (garbage to a client at the old baud, so none)."""
        code = (self.ram[0] & p.COM_BAUD_MASK) >> p.COM_BAUD_SHIFT
        baud = p.baud_of_code(code)
        if baud is None or baud == self.baud:
            return outcome
        old, self.baud = self.baud, baud
        note = f"{outcome.note}, COM baud bits say {baud}: the board switched from {old} baud"
        return replace(outcome, reply=b"", note=note)

    def _config_written(self, was_running: bool, now: float) -> str:
        """React to a write of the config word's low byte: start or stop a motion."""
        if not self.ram[0] & RUN_BIT:
            if self._running is not None:
                slot, self._running = self._running.slot, None
                return f"run bit cleared: motion {slot} stopped"
            return "run bit cleared"
        if self.armed is not None:
            slot, self.armed = self.armed, None
            seconds = self.duration(slot)
            self._running = _Running(slot, now, now + seconds)
            return f"run bit set: motion {slot} started, runs {seconds:g} s"
        if self._running is not None:
            return f"run bit set: motion {self._running.slot} keeps running"
        self.ram[0] &= ~RUN_BIT & 0xFF
        return "run bit set with nothing armed: nothing to run, run bit cleared at once"

    def _read(self, command: p.Command) -> _Outcome:
        address, count = command.address or 0, command.count or 0
        if count == 0 or count > p.MAX_FRAME_SIZE - 3 or address + count > RAM_SIZE:
            return _Outcome(
                p.nak(p.CMD_MOV), f"read of {count} bytes at 0x{address:04x} is not possible: NAK", p.CMD_MOV
            )
        ram = bytearray(self.ram[address : address + count])
        if self.refresh_s > 0:  # the config word and program state as of the last refresh tick
            for a in range(address, min(address + count, STATUS_SPAN)):
                ram[a - address] = self._shown[a]
        data = bytes(ram)
        what = f"RAM 0x{address:04x} x{count} -> {p.hexbytes(data)}"
        if address == 0 and count >= 1:
            state = "executing" if data[0] == p.EXECUTING_BYTE else "not executing"
            as_of = f", as of the refresh at {self._tick_time(self._tick):.6f}" if self.refresh_s > 0 else ""
            what += f" (status: {state}{as_of})"
        return _Outcome(p.ram_reply(data), what, p.CMD_MOV)


def _returned(state: bytes | bytearray) -> bytes:
    """The program state after a motion ends: run bit cleared, the program counter back at the
    return address, the return address and call depth cleared."""
    ram = bytearray(state)
    ram[0] &= ~RUN_BIT & 0xFF
    ram[PROGRAM_COUNTER.start:PROGRAM_COUNTER.stop] = ram[RETURN_ADDRESS.start:RETURN_ADDRESS.stop]
    ram[RETURN_ADDRESS.start:CALL_DEPTH + 1] = bytes(CALL_DEPTH + 1 - RETURN_ADDRESS.start)
    return bytes(ram)


def _command_byte(data: bytes) -> int:
    return data[1] if len(data) > 1 else 0x00


def _described(data: bytes, layout: Layout) -> str:
    """A frame in the journal's words, read as the board's own layout makes its frames."""
    return describe_frame(data, layout) if data and 3 <= data[0] <= p.MAX_FRAME_SIZE else "noise"
