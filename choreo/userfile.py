"""Opening a file a user named: a show, a project, a song, a log. The one way choreo does it.

A name on the command line or in a show may be anything: a folder, a named pipe (an open
would wait for a writer for ever), a device (`/dev/zero` never ends; opening a serial port
toggles its lines), a link to nothing or a loop of links, a name the system refuses as too
long, a file too big to hold in memory. Each gets one line that says what it is, as an
`InputError` (exit 2), before anything reads it.

The name is looked at first (`os.stat`, which never opens anything), then opened without
blocking and looked at again through the open descriptor (`fstat`), so that a file swapped
between the two looks is still never a pipe or a device. A read that fails later (a disk
error, `/proc/self/mem`) is an `InputError` too, saying it could not be *read*: a failure to
write the output is a different message (`choreo.cli.output`).
"""

from __future__ import annotations

import errno
import io
import os
import stat
from collections.abc import Iterator
from contextlib import suppress
from contextlib import contextmanager
from pathlib import Path

from choreo.errors import InputError, UsageError
from choreo.textfit import visible

_KINDS = ((stat.S_ISDIR, "a folder"), (stat.S_ISFIFO, "a named pipe"), (stat.S_ISCHR, "a device"),
          (stat.S_ISBLK, "a device"), (stat.S_ISSOCK, "a socket"))
_OPEN_FLAGS = os.O_RDONLY | getattr(os, "O_NONBLOCK", 0) | getattr(os, "O_NOCTTY", 0) | getattr(os, "O_BINARY", 0)


def kind_of(mode: int) -> str:
    """`a folder`, `a named pipe`, `a device`...: what a non-regular file is, in words."""
    return next((name for test, name in _KINDS if test(mode)), "not a file")


def size_text(count: int) -> str:
    """`16 MiB`, `256 KiB`: a size limit as a user reads it."""
    if count >= 1024 * 1024 and count % (1024 * 1024) == 0:
        return f"{count // (1024 * 1024)} MiB"
    return f"{count // 1024} KiB" if count >= 1024 and count % 1024 == 0 else f"{count} bytes"


def problem(path: str | os.PathLike[str], what: str, limit: int | None = None) -> str | None:
    """Why `path` cannot be read as a `what` (`show file`, `song`), in words; None if it can.

    For a file another library opens by name (a song miniaudio decodes): the name is checked
    here first, so that its failure is not a bare decoder code or a hang.
    """
    try:
        open_input(path, what, limit).close()
    except InputError as exc:
        return exc.reason
    return None


def open_input(path: str | os.PathLike[str], what: str, limit: int | None = None) -> io.BufferedReader:
    """`path` open for reading if it is a regular file of at most `limit` bytes; `InputError`
    (exit 2, one line naming the file and `what` it should be) if not. Its reads are the
    standard library's own, fast ones: read it inside `reading(path, what)`, so that a read that
    fails is an `InputError` too."""
    name = os.fspath(path)
    try:
        _check_mode(name, os.stat(name).st_mode, what)
        fd = os.open(name, _OPEN_FLAGS)
    except OSError as exc:
        raise InputError(name, _os_reason(name, exc, what)) from None
    except ValueError:  # a NUL, or a character the file system's encoding has no bytes for
        raise InputError(name, f"cannot read the {what}: {_UNNAMEABLE}") from None
    try:
        info = os.fstat(fd)
        _check_mode(name, info.st_mode, what)
        if limit is not None and info.st_size > limit:
            raise InputError(name, f"the file is over {size_text(limit)}, too big for a {what}")
        os.set_blocking(fd, True)
        return io.BufferedReader(io.FileIO(fd, "rb"), buffer_size=256 * 1024)  # what open(fd, "rb", ...) builds
    except BaseException:
        os.close(fd)
        raise


@contextmanager
def reading(path: str | os.PathLike[str], what: str) -> Iterator[None]:
    """A read that fails inside the block (a disk error, `/proc/self/mem`) as an `InputError`
    that says it could not *read* the file (an OSError would not say which file, nor whether
    it was a read or a write)."""
    try:
        yield
    except InputError:
        raise
    except OSError as exc:
        raise InputError(os.fspath(path), f"cannot read the {what}: {exc.strerror or exc}") from None


def read_input(path: str | os.PathLike[str], what: str, limit: int) -> bytes:
    """The whole of `path` (see `open_input`), at most `limit` bytes: a file that grew past
    `limit` since it was looked at is refused too, never read on without end."""
    name = os.fspath(path)
    with open_input(name, what, limit) as stream, reading(name, what):
        data = stream.read(limit + 1)
    if len(data) > limit:
        raise InputError(name, f"the file is over {size_text(limit)}, too big for a {what}")
    return data


def _check_mode(name: str, mode: int, what: str) -> None:
    if not stat.S_ISREG(mode):
        raise InputError(name, f"not a regular file ({kind_of(mode)}): give a {what}")


_UNNAMEABLE = "no file can have this name (it holds a NUL or a character the system cannot encode)"
# What the system's words for these errors mean to someone who named a file.
_OS_REASONS = {errno.ELOOP: "a loop of symbolic links", errno.ENAMETOOLONG: "the name is too long for this system"}


def _os_reason(name: str, exc: OSError, what: str) -> str:
    """What an `os.stat` or `os.open` error means for the user who named the file."""
    if exc.errno == errno.ENOENT and os.path.islink(name):
        why = f"it is a link to {_link_target(name)}, which does not exist"
    else:
        why = _OS_REASONS.get(exc.errno or 0, exc.strerror or str(exc))
    return f"cannot read the {what}: {why}"


def _link_target(name: str) -> str:
    try:
        return repr(visible(os.readlink(name)))
    except OSError:
        return "nothing"


def listing(folder: str | os.PathLike[str], what: str = "folder") -> list[Path]:
    """The entries of a folder the user named; `InputError` if it cannot be listed (not there,
    not a folder, not readable), never "nothing in it"."""
    name = os.fspath(folder)
    try:
        with os.scandir(name) as entries:
            return [Path(entry.path) for entry in entries]
    except NotADirectoryError:
        raise InputError(name, f"not a folder ({_kind_at(name)}): give a {what}") from None
    except OSError as exc:
        raise InputError(name, _os_reason(name, exc, what)) from None
    except ValueError:
        raise InputError(name, f"cannot read the {what}: {_UNNAMEABLE}") from None


def _kind_at(name: str) -> str:
    try:
        mode = os.stat(name).st_mode
    except (OSError, ValueError):
        return "not a folder"
    return "a file" if stat.S_ISREG(mode) else kind_of(mode)


def folder_problem(folder: str | os.PathLike[str]) -> str | None:
    """Why an output cannot go into `folder`, said after its name (`folder runs/ does not exist
    (create it first)`), or None for a folder. The one wording for every output's folder: "does
    not exist" alone hid a loop of links and a link to nothing behind a name the user could see."""
    name = os.fspath(folder)
    try:
        mode = os.stat(name).st_mode
    except OSError as exc:
        if exc.errno == errno.ENOENT and not os.path.islink(name):
            return "does not exist (create it first)"
        why = _os_reason(name, exc, "folder").removeprefix("cannot read the folder: ")
        return f"cannot be used: {why}"
    except ValueError:
        return f"cannot be used: {_UNNAMEABLE}"
    return None if stat.S_ISDIR(mode) else f"is not a folder ({_kind_at(name)})"


def modified_if_regular(path: Path) -> float | None:
    """When the regular file reached from `path` (links followed) was last modified; None for
    anything else: a link to nothing, a loop, a folder, a pipe, a device, a name too long."""
    try:
        info = path.stat()
    except (OSError, ValueError):
        return None
    return info.st_mtime if stat.S_ISREG(info.st_mode) else None


def same_file(one: str | os.PathLike[str], other: str | os.PathLike[str]) -> bool:
    """The same file, by name or (when it exists) by identity: a link, `./x`, a hard link. An
    output a command is about to write must not be the file it reads: opened for writing first,
    the input is gone before it is read (`log export LOG --csv LOG` emptied the log)."""
    try:
        if os.path.realpath(one) == os.path.realpath(other):
            return True
        return os.path.samefile(one, other)
    except (OSError, ValueError):
        return False


NEW_FILE = os.O_WRONLY | os.O_CREAT | os.O_EXCL | getattr(os, "O_BINARY", 0)  # EXCL: never through a link


def write_why(exc: OSError | ValueError) -> str:
    """Why a file cannot be written, in the OS's words except where they mislead: ValueError is
    a name with a NUL byte."""
    if isinstance(exc, ValueError):
        return "no file can have this name"
    return "a loop of symbolic links" if exc.errno == errno.ELOOP else (exc.strerror or str(exc))


@contextmanager
def written_whole(target: Path, said: str) -> Iterator[io.BufferedRandom]:
    """A new file for `target` (checked by the caller), written beside it and renamed over it
    when the block ends without an error: a command that fails half way (a full disk, a bad
    input found late) leaves no half-written file, and whatever was there before stays. Every
    OS failure is one line (UsageError, `said: cannot write: why`), the temporary file removed."""
    import secrets  # here, not at the top: its hmac and OpenSSL would slow every `choreo --help`

    temp = target.parent / f".{target.name[:64]}.{secrets.token_hex(4)}.part"
    try:
        file = os.fdopen(os.open(temp, NEW_FILE, 0o666), "w+b")
    except (OSError, ValueError) as exc:
        raise UsageError(f"{said}: cannot write: {write_why(exc)}") from None
    done = False
    try:
        yield file
        file.close()
        os.replace(temp, target)
        done = True
    except OSError as exc:
        raise UsageError(f"{said}: cannot write: {write_why(exc)}") from None
    finally:
        if not done:
            with suppress(OSError):
                file.close()
            with suppress(OSError):
                temp.unlink()
