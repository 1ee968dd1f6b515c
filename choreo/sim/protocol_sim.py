"""`sim://`: a simulated RCB-4 board behind pyserial's own API, in-process.

`choreo.board.link.register_url_handlers()` makes `serial.serial_for_url("sim://?motion_s=0.5&drop=5")`
open one; anything that talks to a pyserial port (the link, a test) then talks to the board
model exactly as to a real board over a USB adapter, without hardware or threads.

URL: `sim://` followed by an optional query with the options of `choreo.sim.options`
(`baud`, `motion_s`, `durations`, `reply_ms`, `refresh_ms`, `wire`, `gap_ms`, `seed`, `late_ms` and the fault
kinds `lose`, `drop`, `nak`, `badsum`, `short`, `junk`, `late`). An unknown option or a bad value
raises ValueError naming it.

Faithful where it matters: the board answers only a port set to its baud with 8 data bits, even
parity and 1 stop bit (a real board cannot read anything else), replies arrive byte by byte on
the board's schedule (wire time and reply delay), `reset_input_buffer` drops only what has
already arrived, a frame written before the previous reply has all arrived is not answered,
the status refreshes every 50 ms of the board's time from the port's opening (its power-on), and
after a `lose` fault every read and write raises `SerialException`, as an unplugged adapter
does. The board is on `port.board`, its line on `port.line`.
"""

from __future__ import annotations

import numbers
from typing import TYPE_CHECKING, Any

from serial.serialutil import PortNotOpenError, SerialBase, SerialException
from serial.serialutil import to_bytes  # type: ignore[attr-defined]  # pyserial's own; its stubs leave it out

from choreo.clock import SystemTime, TimeSource
from choreo.sim.board import SimBoard
from choreo.sim.options import SimOptions, SimUrl
from choreo.sim.line import REAL_GAP_S, Line, LineSettings

if TYPE_CHECKING:
    from _typeshed import ReadableBuffer

_MAX_SLEEP_S = 0.05  # upper bound of one sleep while waiting, so a closed port is noticed


class Serial(SerialBase):
    """A pyserial port whose other end is a `SimBoard`."""

    def __init__(self, *args: Any, **kwargs: Any) -> None:  # SerialBase's arguments, passed on
        self.board: SimBoard | None = None
        self.line: Line | None = None
        self.options: SimOptions | None = None
        # The board's clock: the machine's, or the run's (virtual time in tests), set before open.
        self.time_source: TimeSource = SystemTime()
        super().__init__(*args, **kwargs)

    # -- opening -----------------------------------------------------------------------------

    def open(self) -> None:
        if self.is_open:
            raise SerialException("Port is already open.")
        if self.port is None:
            raise SerialException("Port must be configured before it can be used.")
        self.options = self.from_url(self.port)
        self.board = self.options.board(power_on=self.time_source.now())
        self.line = Line(self.board, self.options.gap_s or REAL_GAP_S, self.options.latency_s)
        self.is_open = True
        self._reconfigure_port()

    @staticmethod
    def from_url(url: str) -> SimOptions:
        """The options in a `sim://?...` URL; ValueError names what is wrong."""
        return SimUrl.parse(url).options

    def _reconfigure_port(self) -> None:
        """Record the client's settings: the board ignores a line it cannot read."""
        baud = self.baudrate
        if not isinstance(baud, numbers.Integral) or not 0 < int(baud) < 2**32:
            raise ValueError(f"invalid baudrate: {baud!r}")
        if self.line is not None:
            self.line.settings = LineSettings(int(baud), int(self.bytesize), str(self.parity), float(self.stopbits))

    def close(self) -> None:
        self.is_open = False
        super().close()

    # -- data --------------------------------------------------------------------------------

    def _live(self) -> Line:
        if not self.is_open or self.line is None:
            raise PortNotOpenError()
        if self.line.board.lost:
            raise SerialException(
                f"{self.port}: port lost (simulated unplug, fault 'lose' at frame "
                f"{self.line.board.lost_at_frame})"
            )
        return self.line

    @property
    def in_waiting(self) -> int:
        line = self._live()
        now = self.time_source.now()
        line.poll(now)
        return line.available(now)

    def read(self, size: int = 1) -> bytes:
        """Up to `size` bytes, waiting for them on the board's schedule until the port's timeout.

        timeout None waits for all `size` bytes; 0 returns what has arrived at once.
        """
        line = self._live()
        clock = self.time_source
        timeout = self.timeout
        deadline = None if timeout is None else clock.now() + timeout
        data = bytearray()
        while len(data) < size:
            now = clock.now()
            line.poll(now)
            data += line.take(now, size - len(data))
            if len(data) >= size or (deadline is not None and now >= deadline):
                break
            wake = line.next_event()
            wait = _MAX_SLEEP_S if wake is None else max(wake - now, 0.0)
            if deadline is not None:
                wait = min(wait, deadline - now)
            clock.sleep(min(max(wait, 1e-6), _MAX_SLEEP_S))  # time must pass, on any clock
            line = self._live()
        return bytes(data)

    def write(self, data: ReadableBuffer, /) -> int:
        """Put the bytes on the wire to the board at once (write each frame in one call)."""
        line = self._live()
        frame: bytes = to_bytes(data)
        line.send(frame, self.time_source.now())
        self._live()  # a `lose` fault on this frame: the write itself fails, as on an unplug
        return len(frame)

    def reset_input_buffer(self) -> None:
        """Drop the reply bytes already received; those still on the wire arrive later."""
        line = self._live()
        now = self.time_source.now()
        line.poll(now)
        line.discard(now)

    def reset_output_buffer(self) -> None:
        """Nothing waits to be sent: `write` puts everything on the wire at once."""
        self._live()

    @property
    def out_waiting(self) -> int:
        self._live()
        return 0

    # -- modem lines: a board has none; answer like a plain three-wire adapter ----------------

    def _update_break_state(self) -> None:
        pass

    def _update_rts_state(self) -> None:
        pass

    def _update_dtr_state(self) -> None:
        pass

    @property
    def cts(self) -> bool:
        self._live()
        return True

    @property
    def dsr(self) -> bool:
        self._live()
        return True

    @property
    def ri(self) -> bool:
        self._live()
        return False

    @property
    def cd(self) -> bool:
        self._live()
        return True
