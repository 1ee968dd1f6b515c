"""One conversation with an RCB-4 board over any pyserial port.

The link owns the I/O the protocol module refuses to do: it writes each frame in one call (the
board drops a frame whose bytes arrive more than ~150 us apart), reads the reply size byte
first and then the rest, judges it with `protocol.parse_reply`, retries within a bound, and
reports every frame and every reply (or timeout) to its listeners, the log recorder among them.
A play sequence that fails part-way is retried from its stop frame: re-sending a CALL alone
could push a second return address on the board.
"""

from __future__ import annotations

import os
import stat
import statistics
from collections import deque
from collections.abc import Callable, Iterable, Iterator
from contextlib import contextmanager, suppress
from dataclasses import dataclass, replace
from typing import TYPE_CHECKING, Protocol, runtime_checkable

from choreo.board import usb
from choreo.clock import RunClock, TimeSource
from choreo.errors import Interrupted, LinkError
from choreo.events import LinkListener, Listeners, RxEvent, Subscription, Tag, TxEvent, never
from choreo.wire import protocol
from choreo.wire.layouts import SEED, Layout, StartState
from choreo.wire.protocol import DEFAULT_BAUD, Frame, FrameKind, Reply, ReplyKind

if TYPE_CHECKING:
    import serial

DEFAULT_TIMEOUT_S = 0.2
DEFAULT_TRIES = 3
QUIET_S = 0.01  # after a bad reply, the line counts as settled once this long passes with no byte
STATUS_SPACING_S = 0.05  # the board refreshes its status every 50 ms: never query faster
MAX_STALE = 3  # late replies to earlier frames set aside while waiting for one frame's reply
SYNC_TRIES = 3  # ACK checks after a timeout: one may reach a board still sending a late reply

try:
    from termios import error as _TermiosError

    _TERMIOS_ERRORS: tuple[type[Exception], ...] = (_TermiosError,)
except ImportError:  # Windows: pyserial raises only OSError there
    _TERMIOS_ERRORS = ()
# Everything a port raises when its device fails or refuses a setting, at open, at a baud
# change or mid-exchange: OSError (pyserial's SerialException is one), termios.error (pyserial
# lets tcsetattr's and tcflush's through, and it is not an OSError) and ValueError (pyserial: a
# baud or setting the driver refuses). The link turns each into one line naming the port.
PORT_ERRORS: tuple[type[Exception], ...] = (OSError, ValueError, *_TERMIOS_ERRORS)


@dataclass(frozen=True)
class Played:
    """How a play sequence went: tries it took, and when the one that worked began (monotonic)."""

    tries: int
    began: float
    # Set when the start frame's reply was lost but the board's state showed the motion started
    # (or could not tell): the play counts as done and was not sent again (the run's warning).
    recovered: str | None = None
    started: float | None = None  # monotonic time the frame that starts the motion was written


# The lead is the median of the last LEAD_PLAYS measured plays: one play slowed by a busy machine
# (a thread put off for milliseconds) must not make the next few start early, as a running mean did.
LEAD_PLAYS = 9
REPLY_DELAY_GUESS_S = 0.0005  # a board's reply delay before any play has been measured


@runtime_checkable
class KeepsTime(Protocol):
    """A port that keeps time itself (the in-process simulator's): it is handed the run's time
    source before it opens, so its board and the link agree on every instant. The board layer
    names the capability, not the simulator that has it."""

    time_source: TimeSource


class PortLost(Exception):
    """The port failed under us mid-exchange (adapter unplugged, device gone)."""


# pyserial's `serial_for_url` imports `protocol_<scheme>` from each package named in
# `serial.protocol_handler_packages`: the simulator's `sim://` is found by its package's name, so
# the board layer never imports the simulator.
NETWORK_URLS = ("socket://", "rfc2217://")  # pyserial's ports over the network: HOST:PORT
URL_HANDLER_PACKAGES = ("choreo.sim",)


def register_url_handlers() -> None:
    """Let pyserial open choreo's own URLs (`sim://`); idempotent."""
    import serial

    for package in URL_HANDLER_PACKAGES:
        if package not in serial.protocol_handler_packages:
            serial.protocol_handler_packages.append(package)


def open_port(url: str, baud: int = DEFAULT_BAUD, *, timeout: float = DEFAULT_TIMEOUT_S,
              exclusive: bool = True, clock: RunClock | None = None) -> serial.SerialBase:
    """Open any pyserial URL (and `sim://`) with the board's line settings, or a LinkError.

    A port that keeps time itself (the in-process simulator) runs on the run's clock, so its
    board and the link agree on every instant; on virtual time nothing else can keep up.
    """
    import serial

    register_url_handlers()
    if own_terminal(url):
        raise LinkError(f"port {url}: is the terminal choreo runs in, not a board's adapter (opening it would "
                        "set it raw at the board's baud and write frames into it): `choreo ports` lists the "
                        "serial ports")
    try:
        port = serial.serial_for_url(
            url, baudrate=baud, bytesize=serial.EIGHTBITS, parity=serial.PARITY_EVEN,
            stopbits=serial.STOPBITS_ONE, timeout=timeout, write_timeout=max(1.0, timeout),
            exclusive=exclusive, do_not_open=True,
        )
        if isinstance(port, KeepsTime):
            port.time_source = (clock or RunClock()).source  # the port's own setting, given before it opens
        elif clock is not None and clock.virtual:
            raise ValueError("only the in-process simulator (sim://) runs on virtual time")
        port.open()
        return port
    except PORT_ERRORS as exc:
        raise LinkError(f"port {url}: cannot open: {_reason(exc)} (at {baud} baud, 8E1){_open_hint(exc)}") from None


CONTROLLING_TERMINAL = "/dev/tty"


def own_terminal(path: str) -> bool:
    """Whether `path` is the terminal choreo runs in: its controlling terminal or a standard
    stream's. A board is never there (a mistyped --port, `choreo sim`'s path taken from the
    wrong window), and the operator's terminal would be left raw at 115200 8E1 with frames in it."""
    if os.name != "posix" or "://" in path:
        return False
    try:
        device = os.stat(path)
    except (OSError, ValueError):
        return False  # opening it says why
    if not stat.S_ISCHR(device.st_mode):
        return False
    return device.st_rdev in _terminals()


def _terminals() -> set[int]:
    """The device numbers of this process's terminals: /dev/tty itself, the standard streams'
    and the controlling terminal's (Linux tells it in /proc/self/stat)."""
    found: set[int] = set()
    with suppress(OSError):
        found.add(os.stat(CONTROLLING_TERMINAL).st_rdev)
    for fd in (0, 1, 2):
        with suppress(OSError):
            if os.isatty(fd):
                found.add(os.fstat(fd).st_rdev)
    with suppress(OSError, ValueError, IndexError):
        with open("/proc/self/stat", encoding="ascii", errors="replace") as status:
            tty_nr = int(status.read().rpartition(")")[2].split()[4])
        if tty_nr:
            found.add(os.makedev((tty_nr >> 8) & 0xFFF, (tty_nr & 0xFF) | ((tty_nr >> 12) & 0xFFF00)))
    return found


def usb_latency_note(port: serial.SerialBase) -> str | None:
    """Ask a real serial device's driver for low latency; if its FTDI latency timer still holds
    replies over 1 ms, what that costs and the command that fixes it (said once, at open)."""
    device = str(getattr(port, "port", "") or "")
    if not device.startswith("/dev/"):
        return None  # a URL port (sim://, socket://): no USB adapter of its own
    usb.ask_low_latency(port)
    timer = usb.latency_timer_ms(device)
    if timer is None or timer <= usb.LOW_LATENCY_MS:
        return None
    return (f"port {device}: the USB adapter's latency timer is {timer} ms: {usb.latency_cost(timer)}; "
            f"fix: {usb.latency_fix(device)}")


def _reason(exc: BaseException) -> str:
    """The first line of what went wrong; termios.error's (errno, text) pair as its text."""
    if len(exc.args) == 2 and isinstance(exc.args[0], int) and isinstance(exc.args[1], str):
        text = exc.args[1].strip()
    else:
        text = str(exc).strip()
    return (text or type(exc).__name__).splitlines()[0]


def _open_hint(exc: BaseException) -> str:
    text = str(exc).lower()
    if "lock" in text or "busy" in text or "resource temporarily unavailable" in text:
        return " (another program has the port open: close it, or stop the other choreo)"
    if "permission" in text:
        return " (no permission: add yourself to the dialout group, or check the device's mode)"
    if "no such file" in text or "not found" in text:
        return " (no such device: is the adapter plugged in? `choreo ports` lists what is there)"
    return ""


class Link:
    """Frames out, replies in, with bounded retries; every event goes to the listeners."""

    def __init__(self, port: serial.SerialBase, *, name: str | None = None,
                 timeout: float = DEFAULT_TIMEOUT_S, tries: int = DEFAULT_TRIES,
                 clock: RunClock | None = None, listeners: Iterable[LinkListener] = (),
                 layout: Layout = SEED, latency_note: str | None = None) -> None:
        if tries < 1:
            raise ValueError("a link needs at least one try per frame")
        self.port = port
        self.name = name or str(port.port)
        self.timeout = timeout
        self.tries = tries
        self.clock = clock or RunClock()
        # Who hears every frame and reply: those given here for the link's life (the log), and
        # those a run attaches for itself (`subscribe`).
        self.listeners: Listeners[LinkListener] = Listeners(tuple(listeners))
        self.layout = layout
        self.config: int | None = None  # the board's config word, read at open where the layout needs it
        # Checked before each frame: a stop request lets the frame in flight get its reply, then
        # no further frame goes out (a run gives its own for its time: `stopping_on`).
        self._should_stop: Callable[[], bool] = never
        self.last_tx_mono = 0.0  # monotonic time of the last write: polls are spaced from it
        self.last_write_end = 0.0  # when that write returned: the board has the frame by then
        self._last_status_mono = float("-inf")  # the last status query's write
        # The board refreshes its status every 50 ms. Only a faster simulator (a replay at
        # --speed X on sim://) may be polled more often.
        self.status_spacing_s = STATUS_SPACING_S
        # Whether any frame of a play sequence reached the board: only then has the show moved
        # the robot, and only then does a stopped show play its abort motion.
        self.moved = False
        self._late_replies = 0  # replies set aside as late during the current frame's tries
        # Bytes read while waiting for the line to go quiet: logged with the next frame's reply.
        self._set_aside = b""
        self._seq = 0
        self.latency_note = latency_note  # the adapter's latency timer, when it costs time
        self._lead_s: float | None = None  # see `start_lead_s`
        self._leads: deque[float] = deque(maxlen=LEAD_PLAYS)  # the last plays' measured leads
        self._lost_write: PortLost | None = None  # a write that failed (see `_raise_lost_write`)

    @classmethod
    def open(cls, url: str, baud: int = DEFAULT_BAUD, *, timeout: float = DEFAULT_TIMEOUT_S,
             tries: int = DEFAULT_TRIES, clock: RunClock | None = None,
             listeners: Iterable[LinkListener] = (), exclusive: bool = True,
             layout: Layout = SEED) -> Link:
        """Open the port; a layout built from the board's config word reads it now (after an
        ACK check), once, as Kondo's library does."""
        clock = clock or RunClock()
        port = open_port(url, baud, timeout=timeout, exclusive=exclusive, clock=clock)
        link = cls(port, name=url, timeout=timeout, tries=tries, clock=clock, listeners=listeners,
                   layout=layout, latency_note=usb_latency_note(port))
        if layout.reads_config:
            try:
                link.read_config()
            except BaseException:
                link.close()
                raise
        return link

    def read_config(self) -> int:
        """The ACK check, then the config word (2 bytes at RAM 0x0000): the word the hth4-2.2
        suspend and resume frames are made from."""
        self.exchange(protocol.sync_frame(), Tag(None, "open"))
        reply = self.exchange(protocol.read_frame(protocol.CONFIG_ADDRESS, protocol.CONFIG_BYTES), Tag(None, "open"))
        self.config = protocol.config_word(reply.data)
        return self.config

    @property
    def baud(self) -> int:
        return int(self.port.baudrate)

    def close(self) -> None:
        with suppress(Exception):  # closing a lost port may fail again; there is nothing left to save
            self.port.close()

    def __enter__(self) -> Link:
        return self

    def refresh_faster(self, speed: float) -> None:
        """The board on the other end runs `speed` times faster (a replay at --speed X on the
        simulator): its status refreshes, and so may be polled, that much more often."""
        self.status_spacing_s = STATUS_SPACING_S / speed

    def subscribe(self, listener: LinkListener) -> Subscription:
        """Attach `listener` to every frame and reply from now until the subscription closes
        (use it in a `with` block: whoever attaches a listener detaches it)."""
        return self.listeners.subscribe(listener)

    @contextmanager
    def stopping_on(self, should_stop: Callable[[], bool]) -> Iterator[None]:
        """For the block's time, `should_stop` is checked before each frame (a stop request lets
        the frame in flight get its reply, then no further frame goes out); after it, what was
        checked before is again. A run gives its stop request; its abort motion, `never`."""
        before, self._should_stop = self._should_stop, should_stop
        try:
            yield
        finally:
            self._should_stop = before

    def __exit__(self, *exc_info: object) -> None:
        self.close()

    # -- the sequences a show uses ---------------------------------------------------------

    def play(self, motion: int, tag: Tag | None = None,
             before_start: Callable[[Callable[[], None]], int | None] | None = None) -> Played:
        """Stop, CALL the slot, restore; a failure anywhere retries the whole sequence.

        The sequence is one unit for a stop request too: it is checked before the stop frame
        only, because a sequence cut after its stop frame leaves the board's program halted.
        `before_start` is handed the write of the frame that starts the motion (the last) and
        may make it itself, returning when (monotonic ns): several robots' links hand theirs to
        one thread that writes them back to back, so that their motions start together.
        Returns how many tries it took and when the sequence that worked began.
        """
        frames = self.layout.play_sequence(motion, self.config, self.baud)
        what = f"play {motion}"
        self._late_replies = 0
        for attempt in range(1, self.tries + 1):
            self._check_stop(what)
            for frame in frames:
                together = before_start if frame is frames[-1] else None
                reply = self.send(frame, attempt, tag, what=what, write=together)
                self.moved = True
                if frame is frames[0]:
                    began = self.last_tx_mono
                start_at, start_sent = self.last_tx_mono, self.last_write_end  # the last frame's: the start
                if not reply.ok:
                    break
            else:
                started = self.last_tx_mono
                if attempt == 1:
                    self._learn_lead(started - began)
                return Played(attempt, began, started=started)
            if frame is frames[-1] and reply.kind is not ReplyKind.NAK:
                # The start frame may have been carried out with only its answer lost.
                state = self._start_state(motion, start_sent, tag, what)
                if state.started:
                    lost = f"the reply to '{what}' ({frame.kind.value} frame) was lost ({reply.describe()})"
                    return Played(attempt, began, recovered=_not_sent_again(lost, motion, state),
                                  started=start_at)
                # The state's answer came after any late reply: the line is idle for the retry.
            elif attempt < self.tries and not self._settle(reply, tag, what):
                raise self._failed(what, frame, reply, tag, attempt, silent=True)
        raise self._failed(what, frame, reply, tag, self.tries)

    def start_lead_s(self, motion: int) -> float:
        """How long after a play's first frame its start frame goes out: the exchanges before
        it. A running estimate from this link's own plays, seeded from the wire time at the
        baud (each frame and its ACK, 11 bits a byte) and a short reply delay."""
        if self._lead_s is None:
            frames = self.layout.play_sequence(motion, self.config, self.baud)[:-1]
            byte_s = 11 / self.baud
            self._lead_s = sum((len(f.data) + 4) * byte_s + REPLY_DELAY_GUESS_S for f in frames)
        return self._lead_s

    def _learn_lead(self, measured_s: float) -> None:
        """The first measured play replaces the seed; then the median of the last LEAD_PLAYS."""
        if measured_s > 0:
            self._leads.append(measured_s)
            self._lead_s = statistics.median(self._leads)

    def _start_state(self, motion: int, start_sent: float, tag: Tag | None, what: str) -> StartState:
        """Did the start frame whose reply was lost start the motion? Ask the board.

        The board may have carried out the frame and only its answer got lost: sending the
        sequence again would start the same motion twice. A NAK is a refusal (the frame was
        not carried out), so only silence or a garbled answer needs asking. The read of the
        program state (the layout's `start_state` judges it: running, over, never started)
        waits one status refresh after the start frame, so it cannot show the state from before
        the CALL (acknowledged before the start frame went out), and goes out at once after that
        (no ACK check first: a late ACK cannot be taken for a read's answer, it is set aside). A
        motion already over by then still counts as started.

        "Never started" is believed only from a second read one refresh after the first one's
        answer: a write returns before its bytes are on the wire (the OS and a USB adapter may
        hold them), so the first read may be shown the board's state from just before a start
        frame that arrived late; the board takes frames in order, so by the first read's answer
        the start frame had arrived (or never will). Running and over need no second look: only
        the start frame sets the run bit or lets the call return.
        """
        read = replace(self.layout.start_read, motion=motion)  # the log tells which motion it asks about
        since = start_sent
        for _ in range(2):
            self._check_stop(what)
            self.clock.sleep_until(since + self.status_spacing_s)
            state = self.layout.start_state(motion, self.exchange(read, tag).data)
            if state.started:
                return state
            since = self.clock.mono()  # the board had the start frame by this answer, if ever
        return state

    def halt(self, tag: Tag | None = None) -> Reply:
        """The play sequence's stop frame alone: the board's program halts, and the motion with
        it, where it is (the operator's panic on a robot with no abort motion)."""
        stop = self.layout.play_sequence(0, self.config, self.baud)[0]
        return self.exchange(replace(stop, motion=None), tag)  # it stops whatever plays: no motion of its own

    def query_status(self, tag: Tag | None = None) -> Reply:
        """Ask whether a motion is executing; the reply's `executing` says."""
        return self.exchange(self.layout.status, tag)

    def exchange(self, frame: Frame, tag: Tag | None = None) -> Reply:
        """One frame, retried alone until the board accepts it or the tries run out."""
        reply = protocol.timeout()
        self._late_replies = 0
        for attempt in range(1, self.tries + 1):
            self._check_stop(str(frame))
            reply = self.send(frame, attempt, tag)
            if reply.ok:
                return reply
            if attempt < self.tries and not self._settle(reply, tag, str(frame)):
                raise self._failed(str(frame), frame, reply, tag, attempt, silent=True)
        raise self._failed(str(frame), frame, reply, tag, self.tries)

    def _check_stop(self, what: str) -> None:
        """A stop request is honoured between exchanges, never inside one: before a frame (or a
        play sequence's first frame), before each retry and before each ACK check."""
        if self._should_stop():
            raise Interrupted(f"stopped before '{what}'")

    # -- one try ---------------------------------------------------------------------------

    def send(self, frame: Frame, attempt: int = 1, tag: Tag | None = None, what: str | None = None,
             write: Callable[[Callable[[], None]], int | None] | None = None) -> Reply:
        """Write one frame, read and judge its reply; no retry.

        Port loss is a LinkError. Bytes already waiting (a late reply to an earlier frame) are
        read to the end and kept with this frame's reply as stale, never cut in half. A status
        query goes out no sooner than STATUS_SPACING_S after the one before, retries included:
        the board only refreshes its status that often.
        """
        try:
            stray, self._set_aside = self._set_aside + self._stray_input(), b""
        except PortLost as exc:
            raise self._lost(exc, frame, tag, what) from None
        if frame.kind is FrameKind.STATUS:
            self.clock.sleep_until(self._last_status_mono + self.status_spacing_s)
        self._seq += 1
        seq = self._seq
        sent, lost = self._put(frame, write)
        # Listeners hear of the frame once it is out: their work never delays a cue's first byte.
        event = TxEvent(seq, frame, attempt, self.clock.wall_ns(sent), tag)
        for listener in self.listeners:
            listener.on_tx(event)
        try:
            if lost is not None:
                raise lost
            reply = self._read_reply(frame)
        except PortLost as exc:
            self._report(seq, frame, protocol.timeout(), sent, tag, error=f"port lost: {exc}")
            raise self._lost(exc, frame, tag, what) from None
        if stray:
            reply = replace(reply, stale=stray + reply.stale)
        if reply.stale:
            self._late_replies += 1
        self._report(seq, frame, reply, sent, tag)
        return reply

    def _put(self, frame: Frame,
             write: Callable[[Callable[[], None]], int | None] | None) -> tuple[int, PortLost | None]:
        """Write the frame here, or hand its write to `write` (another thread writes it, with
        other robots'); when it went (monotonic ns, taken just before the write) and the port's
        failure if the write failed (raised once the listeners have heard of the frame)."""
        written = write(self._write_for(frame.data)) if write is not None else None
        lost: PortLost | None = None
        try:
            if written is None:
                sent = self.clock.mono_ns()  # the frame's time: just before the write
                self._write(frame.data)
            else:
                sent = written  # written by another thread, with other robots' (see `play`)
                self._raise_lost_write()
        except PortLost as exc:
            lost = exc
        self.last_tx_mono = sent / 1e9
        # Spacing is measured from when the write returned, not from the time taken before it:
        # a write delayed by a busy machine must not bring the next query closer on the wire.
        self.last_write_end = self.clock.mono()
        if frame.kind is FrameKind.STATUS:
            self._last_status_mono = self.last_write_end
        return sent, lost

    def _report(self, seq: int, frame: Frame, reply: Reply, sent_ns: int, tag: Tag | None,
                error: str | None = None) -> None:
        if error is not None:
            reply = Reply(ReplyKind.TIMEOUT, reply.data, error=error)
        done = self.clock.mono_ns()
        event = RxEvent(seq, frame, reply, self.clock.wall_ns(done), (done - sent_ns) / 1e9, tag)
        for listener in self.listeners:
            listener.on_rx(event)

    def _read_reply(self, frame: Frame) -> Reply:
        """Size byte first (a NAK to a status query is 4 bytes, not 5), then the rest.

        A well-formed reply to another command is a late answer to an earlier frame: it is set
        aside (and logged with the reply) and the read goes on for this frame's own answer.
        """
        stale = b""
        for _ in range(MAX_STALE + 1):
            first = self._read(1)
            if not first:
                return replace(protocol.timeout(), stale=stale)
            size = first[0]
            if size not in frame.reply_sizes and size not in protocol.REPLY_SIZES:
                junk = first + self._drain(QUIET_S)
                return replace(protocol.invalid(junk, f"junk: size byte {size:02x} is not a reply "
                                                      f"to a {frame.kind.value} frame"), stale=stale)
            data = first + self._read(size - 1)
            if len(data) < size:
                return replace(protocol.invalid(data, f"short reply: {len(data)} of {size} bytes "
                                                      "before the timeout"), stale=stale)
            if not protocol.is_stale(frame, data):
                return replace(protocol.parse_reply(frame, data), stale=stale)
            stale += data
        return replace(protocol.invalid(b"", f"only stale replies ({protocol.hexbytes(stale)})"), stale=stale)

    def _stray_input(self) -> bytes:
        """Bytes already waiting before a frame goes out cannot be its reply: read them to the
        end (the board must finish a reply before it takes the next frame) and set them aside."""
        try:
            waiting = self._waiting()
        except PORT_ERRORS as exc:
            raise PortLost(_reason(exc)) from None
        return self._drain(QUIET_S) if waiting else b""

    def _waiting(self) -> int:
        """Bytes the port holds unread (a PORT_ERRORS exception if the device failed)."""
        return int(self.port.in_waiting)  # type: ignore[attr-defined]  # pyserial's stub declares it on each platform's class, not on SerialBase

    def _write(self, data: bytes) -> None:
        """One write call for the whole frame: the board drops a frame with gaps in it."""
        try:
            self.port.write(data)
        except PORT_ERRORS as exc:
            raise PortLost(_reason(exc)) from None

    def _write_for(self, data: bytes) -> Callable[[], None]:
        """The write of `data` as another thread makes it: a failure is kept for this link's
        own thread to raise (see `_raise_lost_write`)."""
        def write_now() -> None:
            try:
                self._write(data)
            except PortLost as exc:
                self._lost_write = exc
        return write_now

    def _raise_lost_write(self) -> None:
        """A write another thread made for this link failed: fail here, as if written here."""
        lost, self._lost_write = self._lost_write, None
        if lost is not None:
            raise lost

    def _read(self, count: int) -> bytes:
        try:
            return bytes(self.port.read(count))
        except PORT_ERRORS as exc:
            raise PortLost(_reason(exc)) from None

    def _drain(self, quiet_s: float, limit_s: float | None = None) -> bytes:
        """Read and keep whatever arrives until the line has been quiet for `quiet_s`."""
        clock = self.clock
        limit = clock.mono() + (self.timeout if limit_s is None else limit_s)
        got = bytearray()
        last = clock.mono()
        while True:
            now = clock.mono()
            if now - last >= quiet_s or now >= limit:
                return bytes(got)
            try:
                waiting = self._waiting()
            except PORT_ERRORS as exc:
                raise PortLost(_reason(exc)) from None
            if waiting:
                got += self._read(waiting)
                last = clock.mono()
            else:
                clock.sleep(min(0.001, quiet_s))

    def _settle(self, reply: Reply, tag: Tag | None, what: str) -> bool:
        """Before a retry, make sure no late reply is still coming; False if the line is silent.

        The protocol has no sequence numbers, and a late ACK to a restore is byte for byte an
        ACK to a stop: taken for the retried stop frame's answer, it would send the CALL with
        no stop before it (a second return address on the board). So after a timeout the link
        sends the ACK check, whose reply is unique, and reads up to it: every late reply has
        then arrived (set aside as stale) and the board is listening. Any answer to an ACK
        check, a NAK or a garbled one included, proves the board is there; only silence to
        every check is a dead line. After a bad reply a short quiet spell is enough.
        """
        try:
            if reply.kind is not ReplyKind.TIMEOUT:
                self._set_aside += self._drain(quiet_s=QUIET_S)
                return True
        except PortLost as exc:
            raise LinkError(f"port {self.name}: lost while recovering from a bad reply: {exc}: "
                            "check the cable and the adapter") from None
        try:
            # most late replies come now
            self._set_aside += self._drain(quiet_s=self.timeout, limit_s=self.timeout)
        except PortLost as exc:
            raise LinkError(f"port {self.name}: lost while waiting for a late reply: {exc}: "
                            "check the cable and the adapter") from None
        sync = protocol.sync_frame()
        for attempt in range(1, SYNC_TRIES + 1):
            self._check_stop(what)
            answer = self.send(sync, attempt, tag, what="sync")
            if answer.kind in (ReplyKind.ACK, ReplyKind.NAK):
                return True  # the check's own answer: everything before it has arrived
            if answer.kind is not ReplyKind.TIMEOUT:
                self._set_aside += self._drain(quiet_s=QUIET_S)  # garbled, but an answer: alive
                return True
        return False

    def _lost(self, exc: PortLost, frame: Frame, tag: Tag | None, what: str | None) -> LinkError:
        return LinkError(f"port {self.name}:{_where(tag)} lost while sending '{what or frame}' "
                         f"({frame.kind.value} frame): {exc}: check the cable and the adapter")

    def _failed(self, what: str, frame: Frame, reply: Reply, tag: Tag | None, tries: int,
                silent: bool = False) -> LinkError:
        """The one line a user reads: the step, the frame, what came back, what to check.

        `silent`: the board did not answer the ACK checks after a timeout either, so the
        remaining tries were not spent on a line that is not answering at all.
        """
        came = {
            ReplyKind.TIMEOUT: "no reply",
            ReplyKind.NAK: f"NAK ({reply.hex})",
        }.get(reply.kind, f"an invalid reply ({reply.hex}: {reply.error})")
        count = f"{tries} tries" if tries != 1 else "1 try"
        after = f"{count} and {SYNC_TRIES} unanswered ACK checks" if silent else count
        return LinkError(f"port {self.name}:{_where(tag)} {came} to '{what}' ({frame.kind.value} frame) "
                         f"after {after}: {self._hint(reply)}")

    def _hint(self, reply: Reply) -> str:
        if self._late_replies:
            return (f"replies came too late ({self._late_replies} set aside after the "
                    f"{self.timeout:g} s timeout): the board answers slower than --timeout allows; "
                    "give a longer --timeout, or check the adapter's latency")
        settings = f"check baud ({self.baud}), even parity"
        if reply.kind is ReplyKind.TIMEOUT:
            return f"{settings}, and the adapter (5 V inverted logic without Kondo's USB adapter)"
        if reply.kind is ReplyKind.NAK:
            return f"the board refused the frame: {settings}, and the cable (noise corrupts bytes)"
        return f"{settings}, the cable, and that no other program talks on the port"


def _not_sent_again(lost: str, motion: int, state: StartState) -> str:
    """The run's warning for a play counted as done although its start reply was lost."""
    if state is StartState.UNCLEAR:
        return (f"{lost}, and the board's program state shows neither motion {motion} running, "
                "over, nor never started: counted as started (a robot never moves twice), it was "
                "not sent again: check the robot")
    return f"{lost}, but the board shows motion {motion} {state.value}: it was not sent again"


def _where(tag: Tag | None) -> str:
    """` step 4 'spin':` in an error line, when the frame belongs to a show step."""
    return f" {tag}:" if tag and tag.step is not None else ""
