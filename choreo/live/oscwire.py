"""OSC on the wire, choreo's own: packets decoded into messages, messages encoded, and the two
ways a TCP stream frames packets (SLIP, OSC 1.1, as QLab sends; a 4-byte big-endian length,
OSC 1.0, as liblo sends: Pure Data, SuperCollider, Max). Pure: bytes in, values out.

Why not python-osc's parser: a bundle element whose size is 0 or negative sends it into an
endless loop, it executes a message whose type tags it cannot read, and it logs through the root
logger (setting up logging for the whole process). Here every size is checked against what
remains before it is used, nesting, element and argument counts are bounded (`OscLimits`), so the work a
packet costs is linear in its length; any fault makes the whole packet malformed, with the
reason, and nothing is executed from it.
"""

from __future__ import annotations

import re
import struct
from collections.abc import Sequence
from dataclasses import dataclass, field
from typing import Union

from choreo.live.osclimits import LIMITS, OscLimits

Arg = Union[str, int, float, bool, bytes, None]
BUNDLE = b"#bundle\x00"
END, ESC, ESC_END, ESC_ESC = b"\xc0", b"\xdb", b"\xdc", b"\xdd"
_FIXED = {"i": ">i", "f": ">f", "h": ">q", "d": ">d", "t": ">Q", "c": ">I", "r": ">I"}
_NO_DATA: dict[str, Arg] = {"T": True, "F": False, "N": None, "I": None}
# what carries no packet is skipped at C speed: a stream of ENDs or of zero lengths costs a
# Python step per 4 or 1 bytes otherwise (a second of CPU for 8 MB: 8 connections of ENDs held
# a GO 200 ms)
_SLIP_FRAMES = re.compile(b"[^\xc0]+")
_ZEROS = re.compile(b"\x00*")


@dataclass(frozen=True)
class Message:
    """One OSC message: its address and arguments (`m` MIDI and `b` blobs as bytes; `t` time
    tags, `c` characters and `r` colours as their integer; `I` impulse as None)."""

    address: str
    args: tuple[Arg, ...] = ()


@dataclass(frozen=True)
class Decoded:
    """A packet's messages in order, or (`error` set) why the whole packet is refused; `address`
    is the refused message's address when it could be read (to answer the sender)."""

    messages: tuple[Message, ...] = ()
    error: str | None = None
    address: str | None = None


class _Malformed(Exception):
    def __init__(self, why: str, address: str | None = None) -> None:
        super().__init__(why)
        self.why = why
        self.address = address


def decode_packet(packet: bytes, limits: OscLimits = LIMITS) -> Decoded:
    """The messages of one OSC packet (a message or a bundle); never raises."""
    if not packet:
        return Decoded(error="an empty packet")
    if len(packet) > limits.max_message:
        return Decoded(error=f"a packet of {len(packet)} bytes (the limit is {limits.max_message})")
    messages: list[Message] = []
    try:
        _element(bytes(packet), 0, len(packet), 0, messages, [0, 0], limits)  # elements, arguments
    except _Malformed as bad:
        return Decoded(error=bad.why, address=bad.address)
    return Decoded(tuple(messages))


def _element(data: bytes, start: int, end: int, depth: int, out: list[Message], count: list[int],
             limits: OscLimits) -> None:
    count[0] += 1
    if count[0] > limits.max_bundle_elements:
        raise _Malformed(f"more than {limits.max_bundle_elements} elements in one packet")
    if (end - start) % 4:
        raise _Malformed(f"an element of {end - start} bytes (OSC comes in 4-byte units)")
    if data[start:start + len(BUNDLE)] == BUNDLE:
        _bundle(data, start, end, depth + 1, out, count, limits)
    else:
        out.append(_message(data, start, end, count, limits))


def _bundle(data: bytes, start: int, end: int, depth: int, out: list[Message], count: list[int],
            limits: OscLimits) -> None:
    """`#bundle`, a time tag (not waited for: a sleeping reader would hold the next GO), then
    elements, each an int32 size and that many bytes."""
    if depth > limits.max_bundle_depth:
        raise _Malformed(f"bundles nested more than {limits.max_bundle_depth} deep")
    at = start + len(BUNDLE) + 8
    if at > end:
        raise _Malformed("a bundle without its time tag")
    while at < end:
        if end - at < 4:
            raise _Malformed("a bundle element without its size")
        (size,) = struct.unpack_from(">i", data, at)
        at += 4
        if size <= 0 or size > end - at:
            raise _Malformed(f"a bundle element's size {size} (1 to the {end - at} bytes that remain)")
        _element(data, at, at + size, depth, out, count, limits)
        at += size


def _message(data: bytes, start: int, end: int, count: list[int], limits: OscLimits) -> Message:
    """`count[1]`: the packet's arguments so far, bounded before any is read (a 64 KB packet of
    13,000 arguments took 10 ms to read; no command takes more than one)."""
    reader = _Reader(data, start, end)
    address = reader.string("address")
    if not address.startswith("/"):
        raise _Malformed("not an OSC message (its address does not start with /)")
    if reader.at == end:
        return Message(address)  # an old sender's message without type tags: no arguments
    try:
        tags = reader.string("type tags")
        if not tags.startswith(","):
            raise _Malformed("type tags that do not start with ','")
        count[1] += len(tags) - 1
        if count[1] > limits.max_arguments:
            raise _Malformed(f"more than {limits.max_arguments} arguments in one packet")
        args = tuple(reader.arg(tag) for tag in tags[1:])
        if reader.at != end:
            raise _Malformed(f"{end - reader.at} bytes after the arguments")
    except _Malformed as bad:
        raise _Malformed(bad.why, address) from None
    return Message(address, args)


class _Reader:
    """Reads one message's fields, each checked against the message's end before it is read."""

    def __init__(self, data: bytes, start: int, end: int) -> None:
        self.data = data
        self.at = start
        self.end = end

    def take(self, size: int, what: str) -> bytes:
        if size < 0 or size > self.end - self.at:
            raise _Malformed(f"{what} past the end of the message")
        value = self.data[self.at:self.at + size]
        self.at += size
        return value

    def padded(self, size: int, what: str) -> bytes:
        value = self.take(size, what)
        self.take(-size % 4, what)
        return value

    def string(self, what: str) -> str:
        zero = self.data.find(b"\x00", self.at, self.end)  # searched in place: no copy of the rest
        if zero < 0:
            raise _Malformed(f"{what} without the zero that ends a string")
        try:
            return self.padded(zero + 1 - self.at, what)[:-1].decode("utf-8")
        except UnicodeDecodeError:
            raise _Malformed(f"{what}: not UTF-8") from None

    def arg(self, tag: str) -> Arg:
        if tag in _FIXED:
            fmt = _FIXED[tag]
            (value,) = struct.unpack(fmt, self.take(struct.calcsize(fmt), f"argument '{tag}'"))
            return value
        if tag in _NO_DATA:
            return _NO_DATA[tag]
        if tag in "sS":
            return self.string("a string argument")
        if tag == "b":
            (size,) = struct.unpack(">i", self.take(4, "a blob's size"))
            return self.padded(size, "a blob")
        if tag == "m":
            return bytes(self.take(4, "a MIDI argument"))
        raise _Malformed(f"type tag {tag!r}, which choreo does not take (it takes {_TAKEN})")


_TAKEN = " ".join([*_FIXED, *"sSbm", *_NO_DATA])


# -- encoding ------------------------------------------------------------------------------------


def encode_message(address: str, args: Sequence[Arg] = ()) -> bytes:
    """One OSC message: str as `s`, bool `T`/`F`, None `N`, int `i` (`h` past 32 bits), float
    `f` (as QLab and python-osc send them), bytes `b`."""
    tags, body = [","], bytearray()
    for arg in args:
        tag, data = _encode_arg(arg)
        tags.append(tag)
        body += data
    return _string(address) + _string("".join(tags)) + bytes(body)


def _encode_arg(arg: Arg) -> tuple[str, bytes]:
    if isinstance(arg, bool):
        return ("T" if arg else "F"), b""
    if arg is None:
        return "N", b""
    if isinstance(arg, int):
        return ("i", struct.pack(">i", arg)) if -2**31 <= arg < 2**31 else ("h", struct.pack(">q", arg))
    if isinstance(arg, float):
        return "f", struct.pack(">f", arg)
    if isinstance(arg, bytes):
        return "b", struct.pack(">i", len(arg)) + arg + b"\x00" * (-len(arg) % 4)
    if isinstance(arg, str):
        return "s", _string(arg)
    raise TypeError(f"an OSC argument cannot be {type(arg).__name__}")


def _string(text: str) -> bytes:
    """Zero-ended and padded; a zero inside would end it early, so it is sent as U+FFFD."""
    data = text.replace("\x00", "\ufffd").encode("utf-8") + b"\x00"
    return data + b"\x00" * (-len(data) % 4)


def encode_bundle(elements: Sequence[bytes], time_tag: int = 1) -> bytes:
    """A bundle of encoded messages or bundles (time tag 1: at once)."""
    body = b"".join(struct.pack(">i", len(element)) + element for element in elements)
    return BUNDLE + struct.pack(">Q", time_tag) + body


# -- TCP framing ---------------------------------------------------------------------------------


@dataclass
class Fed:
    """What a piece of a TCP stream gave: whole packets, frames dropped (why), and `fatal` when
    the stream cannot go on (the connection is to be closed)."""

    packets: list[bytes] = field(default_factory=list)
    bad: list[str] = field(default_factory=list)
    fatal: str | None = None
    filler: int = 0  # bytes that framed nothing (ENDs past the two around a frame, zero lengths)


class FrameReader:
    """Packets out of one TCP connection's bytes, framed as its first byte says: 0xC0 (END) or
    an OSC packet's first byte (`/`, `#`) is SLIP; 0x00 is a length prefix (within the limit, a
    length's first byte is 0). Bounded: a frame longer than the limit is fatal."""

    def __init__(self, max_message: int = LIMITS.max_message) -> None:
        self.max_message = max_message
        self.framing: str | None = None  # slip | length, once the first byte came
        self._buffer = bytearray()
        self._scanned = 0  # SLIP: no END before this offset of the buffer

    @property
    def pending(self) -> bool:
        """A message begun and not finished (bytes past the last frame's end)."""
        return bool(self._buffer)

    def feed(self, data: bytes) -> Fed:
        if self.framing is None and data:
            self.framing = "length" if data[0] == 0 else "slip"
        self._buffer += data
        return self._slip() if self.framing == "slip" else self._length()

    def frame(self, packet: bytes) -> bytes:
        """A packet (a reply) framed as this connection frames its own."""
        if self.framing == "length":
            return struct.pack(">I", len(packet)) + packet
        return slip_encode(packet)

    def _slip(self) -> Fed:
        fed = Fed()
        last = self._buffer.rfind(END, self._scanned)
        if last >= 0:
            frames = _SLIP_FRAMES.findall(self._buffer, 0, last)  # ENDs in a row frame nothing
            fed.filler = max(0, last + 1 - sum(map(len, frames)) - 2 * len(frames))
            for frame in frames:
                packet = slip_decode(bytes(frame))
                if packet is None:
                    fed.bad.append("a SLIP frame with a bad escape")
                else:
                    fed.packets.append(packet)
            del self._buffer[:last + 1]
        self._scanned = len(self._buffer)
        if len(self._buffer) > 2 * self.max_message:  # every byte escaped: twice the packet
            fed.fatal = f"a SLIP frame over {2 * self.max_message} bytes without its end"
        return fed

    def _length(self) -> Fed:
        fed, start = Fed(), 0
        while len(self._buffer) - start >= 4:
            (size,) = struct.unpack_from(">i", self._buffer, start)
            if size < 0 or size > self.max_message:
                fed.fatal = f"a length prefix of {size} (0 to {self.max_message} taken)"
                break
            if size == 0:  # empty packets: nothing to do, however many
                zeros = _ZEROS.match(self._buffer, start)
                empty = (zeros.end() - start) // 4 * 4 if zeros else 4
                fed.filler += empty
                start += empty
                continue
            if len(self._buffer) - start < 4 + size:
                break
            fed.packets.append(bytes(self._buffer[start + 4:start + 4 + size]))
            start += 4 + size
        del self._buffer[:start]
        return fed


def slip_encode(packet: bytes) -> bytes:
    """END, the packet with END and ESC escaped, END (double-END framing, as OSC 1.1 says)."""
    return END + packet.replace(ESC, ESC + ESC_ESC).replace(END, ESC + ESC_END) + END


def slip_decode(frame: bytes) -> bytes | None:
    """A frame (between ENDs) unescaped, or None: an ESC not followed by ESC_END or ESC_ESC."""
    first, *rest = frame.split(ESC)
    out = bytearray(first)
    for part in rest:
        if part[:1] == ESC_END:
            out += END
        elif part[:1] == ESC_ESC:
            out += ESC
        else:
            return None
        out += part[1:]
    return bytes(out)
