"""Board memory layouts: where Heart to Heart 4 put the motions, and the frames that play one.

Heart to Heart 4 (HTH4) writes motions into the board's ROM at addresses that changed between
its versions, and the frame that plays motion N must CALL the first byte of that motion's slot:
a CALL a few bytes off jumps into the middle of motion data. A layout is data: the first slot,
the main loop address, how the stop and start frames are made (from the board's own config word,
or fixed), and which status read says "still running". Nothing here does I/O.

- `seed`: the source document's frames, byte for byte (slots at 0x0BB8 + N*0x800, one 12-byte
  write that stops the program, config 0x8723 to run it, status = low byte 0x23 of the config).
  At another baud than 115200 its fixed config words carry that baud in bits 7-6 (see
  `protocol.play_sequence`, which builds them).
- `hth4-2.2`: what Kondo's own library sends for boards written by HTH4 2.2 and later (slots at
  0x0B80 + N*0x800). Suspend and resume are the board's config word, read once when the port
  opens, with only bits 0-3 changed; the program counter is set to the main loop 0x00044B; a
  motion runs while the program counter is inside the slots with a return address pushed.

Both layouts leave the board in one known state just before the frame that starts the motion
(run bit clear, counter at the slot, the main loop pushed, depth 1): `Layout.start_state` reads a
lost start reply's outcome from that (see `StartState`).
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from enum import Enum
from functools import lru_cache

from choreo.wire import protocol as p
from choreo.wire.protocol import Frame, FrameKind

# The config word a real HTH4 2.2+ project saves (docs/hardware.md, "Layouts: Two ways to play a
# motion"): what `choreo plan` and `choreo frames` show for hth4-2.2 when no board has been read.
EXAMPLE_CONFIG = 0x821B
RUN_BITS_MASK = 0x000F  # bits 0-3: ICS, program run, end-of-move message, vector jump
RESUME_SET = 0x000B  # ICS, program run, vector jump
RESUME_CLEAR = 0x0004  # end-of-move message off


@dataclass(frozen=True)
class Layout:
    """One memory layout (see the module's docstring)."""

    name: str
    source: str  # where its bytes come from, for `choreo plan` and docs/hardware.md, "Board layouts"
    first_slot: int
    main_loop: int
    reads_config: bool  # the play sequence is built from the config word read from the board
    status: Frame  # the read whose answer says whether a motion is still running
    build: Callable[[Layout, int, int, int], tuple[Frame, ...]]  # (layout, motion, config, baud)
    # After a start frame whose reply was lost: the read whose answer `start_state` judges.
    start_read: Frame = p.read_frame(p.CONFIG_ADDRESS, p.PROGRAM_STATE_BYTES)

    def slot_address(self, motion: int) -> int:
        return self.first_slot + p.check_motion(motion) * p.SLOT_SIZE

    def slot_of(self, address: int) -> int | None:
        """The slot a CALL address starts, or None if it is not the first byte of one."""
        offset = address - self.first_slot
        if offset < 0 or offset % p.SLOT_SIZE or offset // p.SLOT_SIZE >= p.MOTION_SLOTS:
            return None
        return offset // p.SLOT_SIZE

    def play_sequence(self, motion: int, config: int | None = None,
                      baud: int = p.DEFAULT_BAUD) -> tuple[Frame, ...]:
        """The frames that play `motion`, sent as one unit; all carry the motion for the log.

        `config`: the board's config word (hth4-2.2; None: EXAMPLE_CONFIG, for plans).
        """
        p.check_baud(baud)
        word = EXAMPLE_CONFIG if config is None else config
        return _sequence(self, p.check_motion(motion), word & 0xFFFF if self.reads_config else 0, baud)

    def play_frame(self, motion: int) -> Frame:
        return Frame(FrameKind.PLAY, p.call(self.slot_address(motion)), motion)

    def start_state(self, motion: int, reply: bytes) -> StartState:
        """What the answer to `start_read` says of a start frame whose reply was lost.

        Every frame before the start frame was acknowledged, so the board was left with the run
        bit clear, the counter at the slot, the main loop pushed as the return address, depth 1.
        Only the start frame sets the run bit, and only a started motion moves the counter: that
        state unchanged is a start frame never carried out. The read goes out one status refresh
        after the start frame, so it cannot show the state from before the CALL.
        """
        state = p.program_state(reply)
        if state is None:
            return StartState.UNCLEAR
        if state.run:
            return StartState.RUNNING
        if (state.counter, state.return_address, state.depth) == (self.slot_address(motion), self.main_loop, 1):
            return StartState.NOT_STARTED
        if state.counter < p.FIRST_CALLED_ADDRESS and state.depth == 0:
            # The call returned (Kondo's rule: outside the slots, nothing pushed), and the board
            # cleared the run bit at the motion's end.
            return StartState.DONE
        return StartState.UNCLEAR


class StartState(str, Enum):
    """A lost start reply's outcome, as the board's program state shows it."""

    NOT_STARTED = "never started"  # the state the frames before the start frame left, unchanged
    RUNNING = "running"  # the run bit the start frame sets is set
    DONE = "started and already over"  # back outside the slots, nothing pushed: the call returned
    UNCLEAR = "unclear"  # none of these: the cautious case, counted as started

    @property
    def started(self) -> bool:
        """Only a provably never-started motion may be sent again: a robot never moves twice."""
        return self is not StartState.NOT_STARTED


@lru_cache(maxsize=1024)
def _sequence(layout: Layout, motion: int, config: int, baud: int) -> tuple[Frame, ...]:
    # Built once per (slot, config, baud): a cue's frames are ready before its due time.
    return layout.build(layout, motion, config, baud)


def _seed_sequence(layout: Layout, motion: int, config: int, baud: int) -> tuple[Frame, ...]:
    """The document's frames, which the protocol module holds (the seed layout's slots are the
    ones its CALL names)."""
    return p.play_sequence(motion, baud)


def _hth4_sequence(layout: Layout, motion: int, config: int, baud: int) -> tuple[Frame, ...]:
    def config_write(word: int) -> bytes:
        return p.mov_write(p.CONFIG_ADDRESS, p.little_endian(word, p.CONFIG_BYTES))

    main_loop = p.little_endian(layout.main_loop, p.ADDRESS_BYTES).ljust(p.COUNTER_READ_BYTES, b"\0")
    return (Frame(FrameKind.STOP, config_write(config & ~RUN_BITS_MASK), motion),
            Frame(FrameKind.COUNTER, p.mov_write(p.PROGRAM_COUNTER_ADDRESS, main_loop), motion),
            layout.play_frame(motion),
            Frame(FrameKind.RESTORE, config_write((config | RESUME_SET) & ~RESUME_CLEAR), motion))


SEED = Layout(
    name="seed",
    source="the source document (RoboSavvy, 2012): HTH4 2.0/2.1 slots, HTH4 1.x main loop",
    first_slot=p.FIRST_SLOT_ADDRESS,
    main_loop=p.SUSPEND_PROGRAM_COUNTER,
    reads_config=False,
    status=p.status_frame(),
    build=_seed_sequence,
)
HTH4_22 = Layout(
    name="hth4-2.2",
    source="Kondo's Rcb4BaseLib (HTH4 2.2 and later): config word read from the board",
    first_slot=p.FIRST_CALLED_ADDRESS,  # the lowest slot of any layout, which the running rule reads
    main_loop=0x00044B,  # HTH4 2.0 and later
    reads_config=True,
    status=Frame(FrameKind.STATUS, p.mov_read(p.PROGRAM_COUNTER_ADDRESS, p.COUNTER_READ_BYTES)),
    build=_hth4_sequence,
)
LAYOUTS: dict[str, Layout] = {layout.name: layout for layout in (SEED, HTH4_22)}
DEFAULT_LAYOUT = SEED.name  # what a show, a log and the simulator assume when none is named
LAYOUT_NAMES = tuple(LAYOUTS)


def layout_named(name: str) -> Layout:
    """The layout called `name`, or a ValueError that lists the names."""
    try:
        return LAYOUTS[name]
    except KeyError:
        raise ValueError(f"layout {name!r}: choose {' or '.join(LAYOUT_NAMES)}") from None


def layout_of_call(address: int) -> tuple[Layout, int] | None:
    """Which layout's slot start a CALL address is, with the slot (the log review's words)."""
    for layout in LAYOUTS.values():
        slot = layout.slot_of(address)
        if slot is not None:
            return layout, slot
    return None
