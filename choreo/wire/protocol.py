"""The RCB-4 frames that play a stored motion, and the replies to them.

Pure: bytes in, values out, no I/O, so that the link, the simulator, the planner and the log
review all agree on one definition of every byte. The source is `rcb4-play-motions.txt` as
corrected by its errata: every frame is `[SIZE][CMD][args...][SUM]`, SIZE counts every byte,
SUM is the low 8 bits of the sum of the bytes before it.
"""

from __future__ import annotations

from dataclasses import dataclass
from enum import Enum

from choreo.errors import MotionRangeError

MOTION_SLOTS = 120
FIRST_SLOT_ADDRESS = 0x0BB8  # Heart to Heart 4 2.0/2.1 layout, which the document's frames match
SLOT_SIZE = 0x0800
MAX_FRAME_SIZE = 128
FRAME_OVERHEAD = 3  # SIZE, CMD and SUM around a frame's (or a reply's) arguments

CMD_MOV = 0x00
CMD_CALL = 0x0C
CMD_ACK_CHECK = 0xFE  # `04 fe 06 08`: the board answers with the same bytes
CMD_VERSION = 0xFD  # `03 fd 00`: the board answers its firmware's version text
MOV_COM_TO_RAM = 0x02
MOV_RAM_TO_COM = 0x20

ACK_BYTE = 0x06
NAK_BYTE = 0x15
EXECUTING_BYTE = 0x23

CONFIG_ADDRESS = 0x0000
RUN_BIT = 0x0002  # config word bit 1, "ROM program run": stop frames clear it, the start frame sets it
CONFIG_BYTES = 2  # the config word: 16 bits, little endian
PROGRAM_COUNTER_ADDRESS = 0x0002  # program counter (3 bytes), return address (3), call depth
RETURN_ADDRESS_ADDRESS = 0x0005  # what a CALL pushed (3 bytes): where the program goes back to
CALL_DEPTH_ADDRESS = 0x0008  # call depth (1 byte): return addresses pushed
ADDRESS_BYTES = 3  # a program address (counter, return address) is 3 bytes, little endian
PROGRAM_STATE_BYTES = 12  # RAM 0x0000-0x000B: config word, counter, return address, depth, 3 more
COUNTER_READ_BYTES = 10  # Kondo's library reads this much at 0x0002 to see whether a motion runs
FIRST_CALLED_ADDRESS = 0x0B80  # hth4-2.2's slot 0, the lowest of any layout: a counter at or above is in one
# The bauds an RCB-4 runs at, each with its code in the config word's COM (bits 7-6) and ICS
# (bits 14-13) baud fields: the one list every check, message and help text is built from.
BAUD_CODES = {115200: 0, 625000: 1, 1250000: 2}
BAUDS = tuple(BAUD_CODES)
DEFAULT_BAUD = 115200  # what a board leaves the factory with, and the document's frames say
BAUD_CODE_BITS = 0b11
COM_BAUD_SHIFT = 6
ICS_BAUD_SHIFT = 13
COM_BAUD_MASK = BAUD_CODE_BITS << COM_BAUD_SHIFT
SUSPENDED_CONFIG = 0x8721  # ROM program run bit (bit 1) cleared: the board stops its program
RESUMED_CONFIG = 0x8723  # run bit set again: the board runs what the CALL pushed
SUSPEND_PROGRAM_COUNTER = 0x0003FD

TYPE1_REPLY_SIZE = 4
STATUS_REPLY_SIZE = 5
REPLY_SIZES = (TYPE1_REPLY_SIZE, STATUS_REPLY_SIZE)  # what a play sequence or a status query gets


def spell_bauds(last: str = ",", *, mark_default: bool = False) -> str:
    """The bauds for a message or a help text, so that none of them types the list again:
    `115200, 625000, 1250000`; `last="or"`: `115200, 625000 or 1250000`; `mark_default`:
    `115200 (default), ...`."""
    words = [f"{baud} (default)" if mark_default and baud == DEFAULT_BAUD else str(baud) for baud in BAUDS]
    if last == ",":
        return ", ".join(words)
    return f"{', '.join(words[:-1])} {last} {words[-1]}"


def baud_of_code(code: int) -> int | None:
    """The baud a config word's 2-bit baud field names (None: code 3, which names none)."""
    return next((baud for baud, known in BAUD_CODES.items() if known == code), None)


def with_baud(word: int, baud: int) -> int:
    """The config word with its COM baud bits (7-6) set to `baud`'s code."""
    return (word & ~COM_BAUD_MASK) | BAUD_CODES[baud] << COM_BAUD_SHIFT


def little_endian(value: int, width: int) -> bytes:
    """A RAM word or address as the board stores it (every multi-byte value is little endian)."""
    return value.to_bytes(width, "little")


def checksum(data: bytes) -> int:
    """The frame's last byte: the low 8 bits of the sum of every byte before it."""
    return sum(data) & 0xFF


def build_frame(command: int, args: bytes) -> bytes:
    """`[SIZE][CMD][args][SUM]`, refusing what the board could not take in one frame."""
    size = len(args) + FRAME_OVERHEAD
    if size > MAX_FRAME_SIZE:
        raise ValueError(f"frame of {size} bytes exceeds the board's {MAX_FRAME_SIZE}-byte limit")
    body = bytes((size, command)) + args
    return body + bytes((checksum(body),))


def mov_write(address: int, data: bytes) -> bytes:
    """MOV COM -> RAM: write the literal bytes at a RAM address."""
    return build_frame(CMD_MOV, bytes((MOV_COM_TO_RAM,)) + little_endian(address, ADDRESS_BYTES) + data)


def mov_read(address: int, count: int) -> bytes:
    """MOV RAM -> COM: ask for `count` bytes of RAM from `address`."""
    return build_frame(CMD_MOV, bytes((MOV_RAM_TO_COM, 0, 0, 0)) + little_endian(address, 2) + bytes((count,)))


def call(address: int, condition: int = 0) -> bytes:
    """CALL a ROM address (condition 0: always)."""
    return build_frame(CMD_CALL, little_endian(address, ADDRESS_BYTES) + bytes((condition,)))


def hexbytes(data: bytes) -> str:
    """Lowercase hex bytes separated by spaces, the one spelling used on screen and in logs."""
    return data.hex(" ")


class FrameKind(str, Enum):
    STOP = "stop"
    PLAY = "play"
    RESTORE = "restore"
    STATUS = "status"
    SYNC = "sync"  # the ACK check, sent by the link after a timeout to learn the line is idle
    COUNTER = "counter"  # hth4-2.2: the program counter set to the main loop before the CALL
    READ = "read"  # a RAM read that is not the status query (`choreo probe`)
    VERSION = "version"  # the firmware version query (`choreo probe`)


@dataclass(frozen=True)
class Frame:
    """A frame choreo sends, with what it is for (the log and the error messages need that)."""

    kind: FrameKind
    data: bytes
    motion: int | None = None

    @property
    def hex(self) -> str:
        return hexbytes(self.data)

    @property
    def command(self) -> int:
        return self.data[1]

    @property
    def reply_sizes(self) -> tuple[int, ...]:
        """Reply sizes the board may answer with: a bad frame gets a 4-byte NAK whatever it asked."""
        if self.kind in (FrameKind.STATUS, FrameKind.READ):
            return (TYPE1_REPLY_SIZE, self.data[8] + FRAME_OVERHEAD)  # MOV RAM->COM: the bytes asked, framed
        if self.kind is FrameKind.VERSION:
            return tuple(range(TYPE1_REPLY_SIZE, MAX_FRAME_SIZE + 1))
        return (TYPE1_REPLY_SIZE,)

    @property
    def answers_with_data(self) -> bool:
        """A frame whose good answer carries data (a RAM read, the version), not an ACK."""
        return self.kind in (FrameKind.STATUS, FrameKind.READ, FrameKind.VERSION)

    def __str__(self) -> str:
        return f"play {self.motion}" if self.kind is FrameKind.PLAY else self.kind.value


def check_motion(motion: object) -> int:
    """The motion number as an int, or a MotionRangeError a user can act on."""
    if isinstance(motion, bool) or not isinstance(motion, int):
        raise MotionRangeError(f"motion {motion!r} is not a whole number 0..{MOTION_SLOTS - 1}")
    if not 0 <= motion < MOTION_SLOTS:
        raise MotionRangeError(f"motion {motion} is out of range 0..{MOTION_SLOTS - 1}")
    return motion


def motion_address(motion: int) -> int:
    """ROM address of a motion slot: 0x0BB8 + N * 0x800."""
    return FIRST_SLOT_ADDRESS + check_motion(motion) * SLOT_SIZE


_STATUS = mov_read(CONFIG_ADDRESS, CONFIG_BYTES)
_SYNC = build_frame(CMD_ACK_CHECK, bytes((ACK_BYTE,)))
_VERSION = build_frame(CMD_VERSION, b"")


def baud_refusal(baud: int, named: str = "baud") -> str:
    """Why `baud` will not do, in the words every refusal uses (`named`: how the user gave it,
    `--baud` or `baud`): `--baud 9600: the RCB-4 runs at 115200, 625000, 1250000 baud`."""
    return f"{named} {baud}: the RCB-4 runs at {spell_bauds()} baud"


def check_baud(baud: int) -> int:
    """`baud` if an RCB-4 runs at it, else a ValueError that lists the bauds it runs at."""
    if baud not in BAUD_CODES:
        raise ValueError(baud_refusal(baud))
    return baud


def stop_frame(baud: int = DEFAULT_BAUD, motion: int | None = None) -> Frame:
    """Step 1, stop and save: config word 0x8721 (its COM baud bits `baud`'s code), program
    counter 0x0003FD, and zeros: 12 bytes at RAM 0x0000."""
    state = (little_endian(with_baud(SUSPENDED_CONFIG, check_baud(baud)), CONFIG_BYTES)
             + little_endian(SUSPEND_PROGRAM_COUNTER, ADDRESS_BYTES))
    return Frame(FrameKind.STOP, mov_write(CONFIG_ADDRESS, state.ljust(PROGRAM_STATE_BYTES, b"\0")), motion)


def play_frame(motion: int) -> Frame:
    """Step 2: CALL the motion's slot."""
    return Frame(FrameKind.PLAY, call(motion_address(motion)), motion)


def restore_frame(baud: int = DEFAULT_BAUD, motion: int | None = None) -> Frame:
    """Step 3: config word 0x8723, the run bit set again (and `baud`'s code): the board runs
    what the CALL pushed."""
    word = with_baud(RESUMED_CONFIG, check_baud(baud))
    return Frame(FrameKind.RESTORE, mov_write(CONFIG_ADDRESS, little_endian(word, CONFIG_BYTES)), motion)


def play_sequence(motion: int, baud: int = DEFAULT_BAUD) -> tuple[Frame, ...]:
    """Steps 1-3 of the document: stop and save, CALL the slot, restore, sent as one unit, each
    frame carrying the motion for the log. These are the seed layout's frames
    (`choreo.wire.layouts.SEED`, which builds on this module; the other layouts live there).

    The document's config words say 115200 in bits 7-6; at another baud they carry that baud's
    code, because whether the board switches its speed the moment the word is written is not
    documented (docs/hardware.md, "Layouts: The config word's baud bits"): choreo never writes a
    speed other than the one it talks at.
    """
    return (stop_frame(baud, motion), play_frame(motion), restore_frame(baud, motion))


def status_frame() -> Frame:
    return Frame(FrameKind.STATUS, _STATUS)


def sync_frame() -> Frame:
    """The ACK check: its reply is the only one with command byte FE, so reading it back proves
    that every late reply before it has arrived and the board is listening again."""
    return Frame(FrameKind.SYNC, _SYNC)


def read_frame(address: int, count: int) -> Frame:
    """Read `count` bytes of RAM (what `choreo probe` asks; it never writes)."""
    return Frame(FrameKind.READ, mov_read(address, count))


def version_frame() -> Frame:
    """Ask the firmware's version text (`03 fd 00`)."""
    return Frame(FrameKind.VERSION, _VERSION)


class ReplyKind(str, Enum):
    ACK = "ack"
    NAK = "nak"
    STATUS = "status"
    TIMEOUT = "timeout"
    INVALID = "invalid"


@dataclass(frozen=True)
class Reply:
    """What came back for one frame: a verdict, the raw bytes, and for a status the answer."""

    kind: ReplyKind
    data: bytes = b""
    executing: bool | None = None
    status: int | None = None  # the config word read by a status query
    error: str | None = None
    stale: bytes = b""  # well-formed replies to earlier frames, read and set aside before this one

    @property
    def hex(self) -> str:
        return hexbytes(self.data)

    @property
    def ok(self) -> bool:
        return self.kind in (ReplyKind.ACK, ReplyKind.STATUS)

    def describe(self) -> str:
        """What a user reads in an error line: `NAK (04 0c 15 25)`, `nothing`, ..."""
        if self.kind is ReplyKind.TIMEOUT:
            return f"no complete reply ({self.hex})" if self.data else "no reply"
        if self.kind is ReplyKind.INVALID:
            return f"an invalid reply ({self.hex}): {self.error}"
        return f"{self.kind.value.upper()} ({self.hex})"


def invalid(data: bytes, error: str) -> Reply:
    return Reply(ReplyKind.INVALID, bytes(data), error=error)


def timeout(data: bytes = b"") -> Reply:
    return Reply(ReplyKind.TIMEOUT, bytes(data), error="no complete reply before the timeout")


def is_stale(frame: Frame, data: bytes) -> bool:
    """A well-formed reply that cannot answer `frame`: a late answer to an earlier frame.

    The protocol has no sequence numbers; a reply that arrives after its frame was given up on
    would otherwise be taken for the answer to the next frame and shift every reply after it.
    """
    data = bytes(data)
    if len(data) not in (TYPE1_REPLY_SIZE, STATUS_REPLY_SIZE) or data[0] != len(data):
        return False
    if checksum(data[:-1]) != data[-1]:
        return False
    if data[1] != frame.command or len(data) not in frame.reply_sizes:
        return True
    # A read is answered with its data or a NAK, never an ACK: an ACK is a late answer to an
    # earlier write (the restore, say).
    return frame.answers_with_data and len(data) == TYPE1_REPLY_SIZE and data[2] == ACK_BYTE


def parse_reply(frame: Frame, data: bytes) -> Reply:
    """Judge the bytes read for a frame by size byte, command byte and checksum, then meaning."""
    data = bytes(data)
    problem = _form_problem(frame, data)
    if problem is not None:
        return invalid(data, problem)
    if frame.kind is FrameKind.STATUS and len(data) > TYPE1_REPLY_SIZE:
        return _status(frame, data)
    if frame.answers_with_data and len(data) > TYPE1_REPLY_SIZE:
        return Reply(ReplyKind.STATUS, data)  # the data asked for, framed
    if data[2] == ACK_BYTE and frame.answers_with_data:
        return invalid(data, f"an ACK where the {frame.kind.value} was expected")
    if data[2] == ACK_BYTE:
        return Reply(ReplyKind.ACK, data)
    if data[2] == NAK_BYTE:
        return Reply(ReplyKind.NAK, data, error="the board refused the frame (NAK)")
    return invalid(data, f"third byte {data[2]:02x} is neither ACK (06) nor NAK (15)")


def _form_problem(frame: Frame, data: bytes) -> str | None:
    """What makes `data` no well-formed reply to `frame` (None: nothing)."""
    if len(data) < TYPE1_REPLY_SIZE:
        return f"short reply: {len(data)} bytes, expected at least {TYPE1_REPLY_SIZE}"
    if data[0] != len(data):
        return f"size byte says {data[0]} but {len(data)} bytes came"
    if data[0] not in frame.reply_sizes:
        return f"a {data[0]}-byte reply to a {frame.kind.value} frame"
    if checksum(data[:-1]) != data[-1]:
        return f"bad checksum: {data[-1]:02x}, expected {checksum(data[:-1]):02x}"
    if data[1] != frame.command:
        return f"reply for command {data[1]:02x}, expected {frame.command:02x}"
    return None


def _status(frame: Frame, data: bytes) -> Reply:
    """A status read's answer: what it says about a running motion depends on what was read.

    The config word (2 bytes at 0x0000, the document's query): low byte 0x23 while a motion runs.
    The program counter (10 bytes at 0x0002, Kondo's rule): a motion runs while the counter is
    inside the slots and the return address and call depth after it are not all zero.
    """
    command = parse_command(frame.data)
    if command.address == PROGRAM_COUNTER_ADDRESS and len(data) >= FRAME_OVERHEAD + _CALL_STATE_BYTES:
        ram = data[2:-1]
        counter = int.from_bytes(ram[:ADDRESS_BYTES], "little")
        return Reply(ReplyKind.STATUS, data, executing=in_called_motion(ram), status=counter)
    return Reply(ReplyKind.STATUS, data, executing=data[2] == EXECUTING_BYTE, status=config_word(data))


def config_word(data: bytes) -> int:
    """The config word in a framed reply to a read at CONFIG_ADDRESS (size, command, word...)."""
    return int.from_bytes(data[2:2 + CONFIG_BYTES], "little")


# What the running rule looks at from 0x0002: the counter, the return address, the call depth and
# the byte after it (0x0009), as Kondo's library does.
_CALL_STATE_BYTES = 8


def in_called_motion(counter_ram: bytes) -> bool:
    """Kondo's rule for "a motion runs", on RAM read from 0x0002: the program counter inside
    the slots, with a return address or a call depth pushed after it."""
    counter = int.from_bytes(counter_ram[:ADDRESS_BYTES], "little")
    return counter >= FIRST_CALLED_ADDRESS and any(counter_ram[ADDRESS_BYTES:_CALL_STATE_BYTES])


@dataclass(frozen=True)
class ProgramState:
    """The board's program as RAM 0x0000-0x000B shows it: what tells a motion that never started
    from one that started (and perhaps already ended)."""

    config: int
    counter: int  # where the program is
    return_address: int  # what a CALL pushed: where the program goes back to
    depth: int  # call depth: return addresses pushed

    @property
    def run(self) -> bool:
        return bool(self.config & RUN_BIT)


def program_state(data: bytes) -> ProgramState | None:
    """The state in a read of PROGRAM_STATE_BYTES at 0x0000 (the framed reply), or None when the
    reply does not hold that many bytes."""
    ram = bytes(data)[2:-1]
    if len(ram) < PROGRAM_STATE_BYTES:
        return None
    def word(at: int, size: int) -> int:
        return int.from_bytes(ram[at - CONFIG_ADDRESS:at - CONFIG_ADDRESS + size], "little")

    return ProgramState(config=word(CONFIG_ADDRESS, CONFIG_BYTES), counter=word(PROGRAM_COUNTER_ADDRESS, ADDRESS_BYTES),
                        return_address=word(RETURN_ADDRESS_ADDRESS, ADDRESS_BYTES), depth=word(CALL_DEPTH_ADDRESS, 1))


def ack(command: int) -> bytes:
    """The board's type 1 ACK to a command (`04 00 06 0a` for MOV, `04 0c 06 16` for CALL)."""
    body = bytes((TYPE1_REPLY_SIZE, command, ACK_BYTE))
    return body + bytes((checksum(body),))


def nak(command: int) -> bytes:
    body = bytes((TYPE1_REPLY_SIZE, command, NAK_BYTE))
    return body + bytes((checksum(body),))


def ram_reply(data: bytes) -> bytes:
    """The board's answer to MOV RAM -> COM: the bytes read, framed (`05 00 LO HI SUM`)."""
    return build_frame(CMD_MOV, data)


@dataclass(frozen=True)
class Command:
    """A frame as the board reads it: what the simulator executes and the log review explains."""

    command: int
    move_type: int | None = None
    address: int | None = None
    payload: bytes = b""
    count: int | None = None
    condition: int | None = None


def parse_command(data: bytes) -> Command:
    """Decode a frame sent to the board; ValueError says why it is not one."""
    data = bytes(data)
    if len(data) < 3 or data[0] != len(data):
        raise ValueError(f"size byte does not match the {len(data)} bytes")
    if checksum(data[:-1]) != data[-1]:
        raise ValueError(f"bad checksum {data[-1]:02x}, expected {checksum(data[:-1]):02x}")
    cmd, args = data[1], data[2:-1]
    if cmd == CMD_CALL and len(args) == 4:
        return Command(cmd, address=int.from_bytes(args[:3], "little"), condition=args[3])
    if cmd == CMD_MOV and args[:1] == bytes((MOV_COM_TO_RAM,)) and len(args) >= 4:
        return Command(cmd, MOV_COM_TO_RAM, int.from_bytes(args[1:4], "little"), bytes(args[4:]))
    if cmd == CMD_MOV and args[:1] == bytes((MOV_RAM_TO_COM,)) and len(args) == 7:
        return Command(cmd, MOV_RAM_TO_COM, int.from_bytes(args[4:6], "little"), count=args[6])
    return Command(cmd, payload=bytes(args))
