"""The keys of the live console: the terminal put in a key mode and given back, the bytes it
sends read apart into keys, and the thread that reads them.

Apart from `console` (what is drawn and what it means) because this half is the terminal's own
protocol: termios modes, escape and paste sequences, 7- and 8-bit controls, a read that never
blocks the run's way out. It knows nothing of a show; the console hands it a callback for a key.
"""

from __future__ import annotations

import os
import select
import termios
import threading
from collections.abc import Callable

ESCAPE_WAIT_S = 0.03  # a byte this soon after Esc makes it an escape sequence (an arrow key), not Esc
PASTE_WAIT_S = 0.5  # a paste's rest may come this late (a big paste over ssh) and still be a paste
KEY_POLL_S = 0.05  # how often the key reader looks up from the terminal to see whether to stop
PASTE_KEYS = 8  # keys typed in one read that make it a paste the terminal did not mark (no hand types so fast)


# Keys the terminal itself would act on, each taken from it while the console reads: Ctrl-Z
# (and BSD's delayed Ctrl-Y) would suspend the show mid-motion, Ctrl-\ kill it without its abort
# motion or a closed log. Only Ctrl-C (VINTR) keeps its signal: it is the documented stop.
_TAKEN_KEYS = tuple(getattr(termios, name) for name in ("VQUIT", "VSUSP", "VDSUSP") if hasattr(termios, name))


class TerminalMode:
    """The terminal in cbreak without echo (a key arrives when pressed, and is not printed over
    the console), Ctrl-C's signal left on (it stops the show) and no other key the terminal
    acts on: no suspend or quit key (`_TAKEN_KEYS`), no flow control (Ctrl-S would freeze the
    screen), no extended input processing (Ctrl-V, Ctrl-O). Those bytes reach the key parser,
    which ignores them. `restore` puts back the settings exactly as they were."""

    def __init__(self, fd: int) -> None:
        self.fd = fd
        self._saved: list | None = None

    def enter(self) -> None:
        saved = termios.tcgetattr(self.fd)
        mode = [*saved[:6], list(saved[6])]
        mode[0] &= ~(termios.IXON | termios.IXOFF)
        mode[3] &= ~(termios.ICANON | termios.ECHO | termios.IEXTEN)
        mode[6][termios.VMIN] = 1
        mode[6][termios.VTIME] = 0
        disabled = bytes([_vdisable(self.fd)])
        for key in _TAKEN_KEYS:
            mode[6][key] = disabled
        termios.tcsetattr(self.fd, termios.TCSANOW, mode)
        # keys typed while choreo loaded were meant for no console (a Space then would start a
        # show run with --wait-start as soon as the keys are read): dropped, as at the end (not
        # by TCSAFLUSH, which would first wait for an output stopped with Ctrl-S)
        termios.tcflush(self.fd, termios.TCIFLUSH)
        self._saved = saved

    def restore(self) -> None:
        """Unread keys are dropped (TCSAFLUSH): a GO pressed once too often must not land on
        the shell's prompt."""
        saved, self._saved = self._saved, None
        if saved is not None:
            termios.tcsetattr(self.fd, termios.TCSAFLUSH, saved)


def _vdisable(fd: int) -> int:
    """The byte that turns a terminal key off (0 on Linux, 0xff on BSD and macOS)."""
    try:
        value = os.fpathconf(fd, "PC_VDISABLE")
    except (OSError, ValueError):
        value = -1
    return value if 0 <= value <= 0xFF else 0


def in_foreground(fd: int) -> bool:
    """Whether this process has the terminal's foreground: a background job that set the
    terminal's mode would be stopped by SIGTTOU, and its keys go to the shell anyway."""
    try:
        return os.tcgetpgrp(fd) == os.getpgrp()
    except OSError:
        return True  # not our controlling terminal: no job control to get in the way


KEYS = {ord(" "): "space", ord("\r"): "enter", ord("\n"): "enter",
        0x7F: "backspace", 0x08: "backspace", 0x15: "ctrl-u"}  # Ctrl-U: clear what was typed
ARROWS = {b"[A": "up", b"[B": "down", b"OA": "up", b"OB": "down"}  # CSI and SS3 (7- or 8-bit), no modifier
ESC = 0x1B
LONGEST_SEQUENCE = 256  # bytes of a sequence kept: past this, its start and its last bytes (it reads on to its end)
PASTE_START = b"[200~"  # bracketed paste: the text between is not keys, up to an end marker
PASTE_ENDS = (b"\x1b[201~", b"\x9b201~", b"\xc2\x9b201~")  # 7-bit, 8-bit, 8-bit as UTF-8
# A terminal set to send 8-bit controls (VT220 and up, xterm after S8C1T) starts a sequence with
# one byte (or its UTF-8 form, U+0080-U+009F): CSI, SS3, DCS, SOS, OSC, PM, APC, as ESC and this.
EIGHT_BIT = {0x9B: ord("["), 0x8F: ord("O"), 0x90: ord("P"), 0x98: ord("X"), 0x9D: ord("]"), 0x9E: ord("^"),
             0x9F: ord("_")}
EIGHT_BIT_ST = 0x9C  # ends a string an 8-bit control began
PASTE_ON, PASTE_OFF = "\x1b[?2004h", "\x1b[?2004l"  # ask the terminal to bracket what is pasted


class KeyParser:
    """Key bytes in, key names out (`space`, `enter`, `escape`, `up`, `down`, `backspace`,
    `ctrl-u`, or a character as typed: `Q` is `Q`, `ロ` is `ロ`, a cue's label may hold them): no
    I/O and no clock, so every sequence a terminal sends can be tried on it.

    Esc also starts what other keys send: arrows and function keys (CSI `ESC [ ... final`, SS3
    `ESC O ...`), Alt+key (`ESC key`), Alt+arrow and Alt+F-key (`ESC ESC [ D`, `ESC ESC O P`),
    terminal replies (`ESC ] ... BEL`, `ESC P ... ESC \\`), mouse reports and bracketed pastes.
    Each is read whole; Up and Down without a modifier (`ARROWS`) are keys, every other one is
    ignored: only a bare Esc panics, an Esc with nothing after it before
    the reader's wait runs out (`timeout`). Esc pressed twice (`ESC ESC` and nothing) is still
    Esc, and a third Esc right after makes that pair one. A paste is text up to its end marker
    (`ESC [201~`), whatever it holds (Esc, half sequences, spaces, q and y), skipped whole and
    fast (a megabyte costs the show nothing). A pause (`timeout`) also ends any sequence or
    paste cut short, so the next key is read afresh whatever came before; control bytes other
    than Enter are not keys, and an 8-bit control (`EIGHT_BIT`) begins a
    sequence as its ESC form does."""

    def __init__(self) -> None:
        self._sequence = bytearray()  # the escape sequence read so far, after its ESC
        self._in_escape = False
        self._eight_bit = 0  # the sequence began with an 8-bit control: 1 raw (0x9C ends it), 2 UTF-8 (C2 9C)
        self._pasting = False
        self._paste_tail = b""  # a paste's last bytes: its end marker may be split across reads
        self._utf8 = (0, 0)  # a UTF-8 character under way: its first byte, continuation bytes to come
        self._char = bytearray()  # its bytes so far
        self._alt = False  # it came with Alt (`ESC` first): no key, as Alt and any key

    @property
    def pending(self) -> bool:
        """Whether a sequence or a paste is under way: the reader waits a moment for the rest
        and calls `timeout` if nothing comes."""
        return self._in_escape or self._pasting

    @property
    def pasting(self) -> bool:
        """A paste is under way (and no sequence): the reader may wait longer for its rest."""
        return self._pasting and not self._in_escape

    def feed(self, data: bytes) -> list[str]:
        keys: list[str] = []
        at = 0
        while at < len(data):
            if self._pasting:
                at = self._skip_paste(data, at)
                continue
            key = self._byte(data[at])
            at += 1
            if key is not None:
                keys.append(key)
        return keys

    def timeout(self) -> list[str]:
        """Nothing more came: a bare Esc (or Esc twice) is Esc; any other sequence is over,
        and so is a paste cut short."""
        bare = self._in_escape and not self._eight_bit and bytes(self._sequence) in (b"", b"\x1b")
        self._sequence.clear()
        self._in_escape = self._pasting = False
        self._eight_bit = 0
        self._paste_tail = b""
        self._utf8 = (0, 0)
        return ["escape"] if bare else []

    def _skip_paste(self, data: bytes, at: int) -> int:
        """Where keys start again in `data` after the paste's end marker (its end if none)."""
        tail = self._paste_tail
        seen = tail + data[at:]
        found = [(end, len(marker)) for marker in PASTE_ENDS if (end := seen.find(marker)) >= 0]
        if not found:
            self._paste_tail = seen[-(max(map(len, PASTE_ENDS)) - 1):]
            return len(data)
        end, length = min(found)
        self._pasting = False
        self._paste_tail = b""
        return at + end + length - len(tail)

    def _byte(self, byte: int) -> str | None:
        if not self._in_escape:
            if byte == ESC:
                self._in_escape = True
                return None
            if byte >= 0x80:
                return self._high(byte)
            self._utf8 = (0, 0)  # an ASCII byte ends a UTF-8 character cut short
            return KEYS.get(byte, chr(byte) if 0x20 < byte < 0x7F else None)
        if byte == ESC and self._sequence == b"\x1b" and not self._pasting:
            self._sequence.clear()  # ESC ESC ESC: Esc twice, and a new sequence starts
            return "escape"
        self._sequence.append(byte)
        if len(self._sequence) >= LONGEST_SEQUENCE:
            # a long reply (a clipboard's, a capability list, a long CSI) is read to its end,
            # however long: only its kind and its last two bytes (`ESC \\` ends a string) are kept
            head = len(self._sequence) - len(self._sequence.lstrip(b"\x1b")) + 1
            del self._sequence[head:-2]
        sequence = bytes(self._sequence)
        if _complete(sequence) or self._eight_bit_end(sequence):
            self._sequence.clear()
            self._in_escape = False
            self._eight_bit = 0
            return self._ended(sequence)
        return None

    def _eight_bit_end(self, sequence: bytes) -> bool:
        """A string an 8-bit control began ends with 8-bit ST, in the same form (a raw 0x9C
        inside UTF-8 text is a continuation byte, not an end)."""
        if not self._eight_bit or sequence[-1] != EIGHT_BIT_ST or not _is_string(sequence):
            return False
        return self._eight_bit == 1 or sequence[-2:-1] == b"\xc2"

    def _high(self, byte: int) -> str | None:
        """A byte past ASCII outside a sequence: part of a UTF-8 character (the character, as
        typed, once whole: a cue's label after `j` may be `お辞儀`), or an 8-bit control, raw
        or as UTF-8 (`C2 9B`), which begins a sequence."""
        lead, left = self._utf8
        if left and 0x80 <= byte <= 0xBF:
            self._utf8 = (lead, left - 1)
            self._char.append(byte)
            if lead == 0xC2 and byte in EIGHT_BIT:  # U+0080-U+009F: a C1 control
                self._begin_eight_bit(byte, 2)
                return None
            if left > 1:
                return None
            alt, self._alt = self._alt, False
            try:
                char = self._char.decode()
            except UnicodeDecodeError:  # overlong, a surrogate, past U+10FFFF: no character
                return None
            return char if char.isprintable() and not alt else None
        self._char[:] = bytes([byte])
        self._alt = False
        if 0xC2 <= byte <= 0xF4:
            self._utf8 = (byte, 1 if byte < 0xE0 else 2 if byte < 0xF0 else 3)
            return None
        self._utf8 = (0, 0)
        if byte in EIGHT_BIT:
            self._begin_eight_bit(byte, 1)
        return None

    def _begin_eight_bit(self, byte: int, form: int) -> None:
        self._in_escape = True
        self._eight_bit = form
        self._sequence[:] = bytes([EIGHT_BIT[byte]])

    def _ended(self, sequence: bytes) -> str | None:
        """A whole sequence: an arrow key's name, or nothing (what it starts is noted)."""
        if sequence in ARROWS:
            return ARROWS[sequence]
        if sequence == PASTE_START:
            self._pasting = True
        elif len(sequence) == 1 and sequence[0] >= 0x80:
            self._high(sequence[0])  # Alt and a non-ASCII key: the rest of its UTF-8 follows
            self._alt = True
        elif len(sequence) > 1 and sequence[-1] == ESC and not _is_string(sequence):
            self._in_escape = True  # a sequence broken off by an Esc: that Esc starts the next
        return None


def _is_string(sequence: bytes) -> bool:
    """OSC, DCS, SOS, PM, APC: a terminal's reply, ended by BEL or ST (`ESC \\`)."""
    return sequence[:1] in (b"]", b"P", b"X", b"^", b"_")


def _complete(sequence: bytes) -> bool:
    """Whether the bytes after an ESC make a whole sequence, or one broken off (a byte that
    does not belong in it ends it there)."""
    head, body = sequence[:1], sequence[1:]
    if head == b"\x1b":  # ESC ESC: Alt with a sequence of its own (Alt+Left: ESC ESC [ D)
        return body != b"" and _complete(body)
    if _is_string(sequence):
        return body.endswith((b"\x07", b"\x1b\\"))
    if 0x21 <= head[0] <= 0x2F:  # intermediates, then a final byte (`ESC ( B`, `ESC # 8`); `ESC SP` is Alt+Space
        return body != b"" and not 0x20 <= body[-1] <= 0x2F
    if head not in (b"[", b"O", b"N"):
        return True  # Alt and a key: one byte
    if not body or (head == b"[" and body == b"["):  # the Linux console's F1: ESC [ [ A
        return False
    if head == b"[" and body[:1] == b"M":  # an X10 mouse report: three raw bytes after the M
        return len(body) >= 4
    return not 0x20 <= body[-1] <= 0x3F  # CSI, SS3, SS2: parameters, intermediates, a final byte


def unmarked_paste(keys: list[str]) -> list[str]:
    """The keys of one read, or `paste` for them all if they are more text than a hand types
    between two reads (PASTE_KEYS): a terminal that does not mark pastes (the Linux console,
    some serial and web terminals) sends one as typed keys, and every space in it would be a
    GO, its `s` a skip, its `q` and `y` a stop. Arrows and Esc are not counted (held Down
    repeats one at a time, a hurried Esc must still panic)."""
    typed = [key for key in keys if key not in ("up", "down", "escape")]
    if len(typed) < PASTE_KEYS:
        return keys
    return ["paste"] + (["escape"] if "escape" in keys else [])


class KeyReader:
    """Reads the terminal in a thread of its own and hands each key to `on_key` by name
    (`KeyParser` tells keys from sequences): it waits ESCAPE_WAIT_S after an Esc for the rest
    of a sequence before taking it for the Esc key, and PASTE_WAIT_S for the rest of a paste
    (a pause in a big one must not turn its spaces into GOs). A read judged an unmarked paste
    (`unmarked_paste`) makes all that follows it without a pause of PASTE_WAIT_S paste too: a
    paste longer than one read must not end in keys. `text_wanted` says whether text is being
    typed (the console's `j` prompt): then keys are handed on as they come, an input method's
    whole word in one write no paste, up to the key that ends the typing."""

    def __init__(self, fd: int, on_key: Callable[[str], None], escape_wait_s: float = ESCAPE_WAIT_S,
                 paste_wait_s: float = PASTE_WAIT_S, text_wanted: Callable[[], bool] | None = None) -> None:
        self.fd = fd
        self.on_key = on_key
        self.escape_wait_s = escape_wait_s
        self.paste_wait_s = paste_wait_s
        self.text_wanted = text_wanted if text_wanted is not None else (lambda: False)
        self.parser = KeyParser()
        self._unmarked = False  # an unmarked paste is under way: what comes before a pause is paste
        self._done = threading.Event()
        self._thread = threading.Thread(target=self._loop, name="choreo-keys", daemon=True)

    def start(self) -> None:
        self._thread.start()

    def close(self) -> None:
        self._done.set()
        if self._thread.is_alive() and self._thread is not threading.current_thread():
            self._thread.join(1.0)

    def _loop(self) -> None:
        while not self._done.is_set():
            pending, pasting = self.parser.pending, self.parser.pasting or self._unmarked
            data = self._read(self.paste_wait_s if pasting else self.escape_wait_s if pending else KEY_POLL_S,
                              4096 if pasting else 64)
            if data is None and self._unmarked:
                self._unmarked = False  # the pause that ends an unmarked paste
            keys = self.parser.feed(data) if data is not None else self.parser.timeout() if pending else []
            self._hand_on(keys)

    def _hand_on(self, keys: list[str]) -> None:
        """The keys of one read to `on_key`: typed text as it comes, else by the paste rule."""
        while keys and not self._unmarked and self.text_wanted():
            self.on_key(keys.pop(0))  # Enter or Esc may end the typing: the rest are command keys
        if not keys:
            return
        if self._unmarked:  # the rest of a paste: no key of it but a hurried Esc
            if "escape" in keys:
                self.on_key("escape")
            return
        judged = unmarked_paste(keys)
        self._unmarked = judged[:1] == ["paste"]
        for key in judged:
            self.on_key(key)

    def _read(self, timeout: float, size: int) -> bytes | None:
        """What the terminal has (None if nothing came within `timeout`); the end of input
        stops the reader."""
        try:
            ready, _, _ = select.select([self.fd], [], [], timeout)
            if not ready:
                return None
            data = os.read(self.fd, size)
        except (OSError, ValueError):
            data = b""
        if not data:
            self._done.set()
            return None
        return data
