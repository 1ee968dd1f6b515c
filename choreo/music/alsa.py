"""ALSA's own error lines, silenced where they are made.

ALSA's library (libasound, which miniaudio loads on Linux to list and open outputs) reports every
failed step of opening a device by writing to file descriptor 2: on a machine with no sound
card one failed open of the default output is some 35 lines (`ALSA lib confmisc.c:855:
(parse_card) cannot find card '0'`, ...). choreo says what failed in its own words, so those
lines are noise. Pointing fd 2 at /dev/null to hide them would hide, for as long as it lasts,
every line any other thread writes (the console, OSC, the progress line): fd 2 is the whole
process's. ALSA lets a program install its own error handler instead
(`snd_lib_error_set_handler`); `quiet()` installs one that drops ALSA's lines and puts back the
one before it when it ends. Nothing else is touched. Where there is no libasound (macOS,
Windows, a Linux without ALSA) there is nothing to silence and `quiet()` does nothing.
"""

from __future__ import annotations

import contextlib
import ctypes
import ctypes.util
import functools
import threading
from collections.abc import Iterator
from dataclasses import dataclass, field
from typing import Any

# void (*snd_lib_error_handler_t)(const char *file, int line, const char *function, int err,
#                                 const char *fmt, ...): the variadic tail is never read.
HANDLER = ctypes.CFUNCTYPE(None, ctypes.c_char_p, ctypes.c_int, ctypes.c_char_p, ctypes.c_int, ctypes.c_char_p)


def _drop(file: bytes | None, line: int, function: bytes | None, err: int, fmt: bytes | None) -> None:
    """ALSA's line, not printed: choreo reports the failure it causes itself."""


@dataclass
class Alsa:
    """The loaded libasound and whether choreo's handler is in force.

    The handler is the C library's own process-wide setting, so one object stands for it: two
    threads opening outputs at once install it once and the last one out restores it."""

    library: Any  # ctypes.CDLL of libasound
    drop: Any = field(default_factory=lambda: HANDLER(_drop))  # kept alive: ALSA holds only its address
    lock: threading.Lock = field(default_factory=threading.Lock)
    users: int = 0
    saved: int | None = None  # the handler in force before (its address); None: ALSA's default

    def handler_address(self) -> int | None:
        """The address of the handler ALSA calls now (None: it exports no `snd_lib_error`)."""
        try:
            return ctypes.c_void_p.in_dll(self.library, "snd_lib_error").value
        except ValueError:
            return None

    def enter(self) -> None:
        with self.lock:
            if self.users == 0:
                self.saved = self.handler_address()
                self.library.snd_lib_error_set_handler(self.drop)
            self.users += 1

    def leave(self) -> None:
        with self.lock:
            self.users -= 1
            if self.users == 0:
                # NULL puts back ALSA's default handler, which is what was there unless someone
                # else installed one: then that one goes back.
                previous = None if self.saved is None else ctypes.cast(ctypes.c_void_p(self.saved), HANDLER)
                self.library.snd_lib_error_set_handler(previous)


@functools.lru_cache(maxsize=1)
def alsa() -> Alsa | None:
    """The process's libasound, or None where there is none. Loaded once; it is the library
    miniaudio opens (its build dlopens `libasound.so.2`, else `libasound.so`: one library in the
    process, one handler), so the handler set here is the one miniaudio's calls report through."""
    name = ctypes.util.find_library("asound")
    if name is None:
        return None
    try:
        library = ctypes.CDLL(name)
        library.snd_lib_error_set_handler.argtypes = [HANDLER]
        library.snd_lib_error_set_handler.restype = ctypes.c_int
    except (OSError, AttributeError):
        return None
    return Alsa(library)


@contextlib.contextmanager
def quiet() -> Iterator[None]:
    """ALSA's error lines dropped while the block runs (see the module's docstring)."""
    library = alsa()
    if library is None:
        yield
        return
    library.enter()
    try:
        yield
    finally:
        library.leave()
