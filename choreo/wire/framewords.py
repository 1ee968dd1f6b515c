"""Frames and replies in words, as a board layout reads them: the one decoder of the bytes on the
wire for people, used by the log reviews (`logformat.frame_meaning`, `reply_meaning`) and the
simulator's journal (`choreo sim -v`).

Pure: bytes and a layout in, words out. The bytes of a play sequence differ between layouts
(slots 0x38 apart, other stop and start frames, another status read), so a frame is only read
right with the layout it was made for; None is a layout this choreo does not know, and a CALL is
then named by whichever known layout's slot it fits.
"""

from __future__ import annotations

from typing import TypeGuard

from choreo.wire import protocol as p
from choreo.wire.layouts import Layout, layout_of_call


def describe_frame(data: bytes, layout: Layout | None) -> str:
    """A frame sent to the board, in words, as `layout` builds its frames (None: not known)."""
    try:
        command = p.parse_command(data)
    except ValueError as exc:
        return f"not a frame: {exc}"
    if data == p.sync_frame().data:
        return "ACK check"
    if data == p.version_frame().data:
        return "version query"
    if command.command == p.CMD_CALL:
        return f"CALL 0x{command.address:06x}: {_called(command.address or 0, layout)}"
    if command.move_type == p.MOV_COM_TO_RAM:
        return f"MOV COM->RAM 0x{command.address:04x} <- {p.hexbytes(command.payload)}: {_written(data, layout)}"
    if command.move_type == p.MOV_RAM_TO_COM:
        return f"MOV RAM->COM 0x{command.address:04x} x{command.count}: {_read_name(data, layout)}"
    return f"command {command.command:02x}"


def _called(address: int, layout: Layout | None) -> str:
    """`motion N` when the address starts one of the layout's slots; else whose slot it is."""
    slot = layout.slot_of(address) if layout is not None else None
    if slot is not None:
        return f"motion {slot}"
    fits = layout_of_call(address)
    if fits is None:
        return "not a motion slot"
    other, slot = fits
    if layout is None:
        return f"motion {slot} (a slot of the {other.name} layout)"
    return f"not a motion slot of the {layout.name} layout (motion {slot}'s slot in {other.name})"


def _written(data: bytes, layout: Layout | None) -> str:
    """Which frame of the layout's play sequence a write is (at any baud, from any config word:
    the layout builds them), or `write`."""
    kind = _sequence_kind(data, layout) if layout is not None else None
    if kind is None or layout is None:
        return "write"
    word = int.from_bytes(data[6:8], "little")
    if kind is p.FrameKind.COUNTER:
        return f"program counter to the main loop 0x{layout.main_loop:06x}"
    if not layout.reads_config:
        return "stop and save status" if kind is p.FrameKind.STOP else "restore status"
    return f"{'suspend' if kind is p.FrameKind.STOP else 'resume'}: config 0x{word:04x}"


def _sequence_kind(data: bytes, layout: Layout) -> p.FrameKind | None:
    word = int.from_bytes(data[6:8], "little") if len(data) >= 8 else 0
    for baud in p.BAUD_CODES:
        for frame in layout.play_sequence(0, word, baud):
            if frame.kind is not p.FrameKind.PLAY and frame.data == data:
                return frame.kind
    return None


def _read_name(data: bytes, layout: Layout | None) -> str:
    if layout is not None and data == layout.status.data:
        return "status query"
    if layout is not None and data == layout.start_read.data:
        return "program state read (did the motion start?)"
    if layout is not None and layout.reads_config and data == _CONFIG_READ:
        return "config word read"
    return "read"


_CONFIG_READ = p.read_frame(p.CONFIG_ADDRESS, p.CONFIG_BYTES).data  # the hth4-2.2 link reads it at open
# What the RAM a frame can read holds (address, bytes, name): the config word, then the program
# counter, the return address a CALL pushed, and the call depth.
_RAM_FIELDS = ((p.CONFIG_ADDRESS, p.CONFIG_BYTES, "config"),
               (p.PROGRAM_COUNTER_ADDRESS, p.ADDRESS_BYTES, "program counter"),
               (p.RETURN_ADDRESS_ADDRESS, p.ADDRESS_BYTES, "return address"),
               (p.CALL_DEPTH_ADDRESS, 1, "depth"))


def describe_reply(data: bytes, frame: bytes | None, layout: Layout | None, motion: int | None = None) -> str:
    """A reply in words: `ACK`, `NAK`, a RAM read's fields (`config 0x821b`), for the layout's
    status query whether a motion is executing, and for its program state read after a lost
    start reply what the link concluded of `motion` (the layout's `start_state`).
    `frame`: what it answers (None: unknown)."""
    if not data:
        return "no reply"
    if len(data) == p.TYPE1_REPLY_SIZE and data[0] == len(data) and p.checksum(data[:3]) == data[3]:
        return {p.ACK_BYTE: "ACK", p.NAK_BYTE: "NAK"}.get(data[2], f"type 1 reply {data[2]:02x}")
    if data[0] != len(data) or p.checksum(data[:-1]) != data[-1]:
        return f"invalid: {p.hexbytes(data)}"
    try:
        command = p.parse_command(frame) if frame is not None else None
    except ValueError:
        command = None
    if command is None or command.move_type != p.MOV_RAM_TO_COM or len(data) != (command.count or 0) + p.FRAME_OVERHEAD:
        return f"{len(data)}-byte reply: {p.hexbytes(data)}"
    if layout is not None and frame == layout.status.data:
        return _status_words(data, frame, layout)
    ram = data[2:-1]
    words = _ram_words(command.address or 0, ram, layout) or f"{len(ram)} bytes: {p.hexbytes(ram)}"
    if layout is not None and frame == layout.start_read.data and is_slot(motion):
        return f"{words}: motion {motion} {layout.start_state(motion, data).value}"
    return words


def is_slot(motion: object) -> TypeGuard[int]:
    """A motion number a layout can judge (a log another program wrote may hold anything)."""
    return type(motion) is int and 0 <= motion < p.MOTION_SLOTS


def _status_words(data: bytes, frame: bytes, layout: Layout) -> str:
    """The layout's status query answered: what it reads, and the layout's running rule on it."""
    executing = p.parse_reply(p.Frame(p.FrameKind.STATUS, frame), data).executing
    state = "executing" if executing else "not executing"
    if data[2:-1] and frame == p.status_frame().data:
        return f"status 0x{data[2]:02x}: {state}"  # the document's words for its config read
    command = p.parse_command(frame)
    return f"{_ram_words(command.address or 0, data[2:-1], layout)}: {state}"


def _ram_words(address: int, ram: bytes, layout: Layout | None) -> str:
    """The known fields of RAM read from `address`: `config 0x821b, program counter 0x001380
    (motion 1), ...`; empty if the read holds none whole."""
    words = []
    for start, size, name in _RAM_FIELDS:
        if address <= start and start + size <= address + len(ram):
            value = int.from_bytes(ram[start - address:start - address + size], "little")
            words.append(f"{name} {value}" if name == "depth" else
                         f"{name} 0x{value:0{size * 2}x}{_in_slot(value, layout) if size == p.ADDRESS_BYTES else ''}")
    return ", ".join(words)


def _in_slot(address: int, layout: Layout | None) -> str:
    """` (motion 1)` where a program address lies inside one of the layout's slots."""
    if layout is None:
        return ""
    offset = address - layout.first_slot
    if 0 <= offset < p.MOTION_SLOTS * p.SLOT_SIZE:
        return f" (motion {offset // p.SLOT_SIZE})"
    return ""
