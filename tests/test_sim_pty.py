"""`choreo sim` on a pseudo-terminal, talked to with real pyserial as to a board."""

from __future__ import annotations

import contextlib
import os
import signal
import subprocess
import sys
import threading
import time

import pytest
import serial

from choreo.wire import protocol as p
from choreo.sim.board import SimBoard
from choreo.sim.faults import JUNK, FaultPlan
from choreo.sim.pty import PtyServer, ServeEnd, read_settings
from runlog import REPLY_S, wait_for

pytestmark = pytest.mark.skipif(not hasattr(os, "openpty"), reason="needs pseudo-terminals")

STATUS = p.status_frame()
IDLE = p.ram_reply(b"\x02\x00")


@contextlib.contextmanager
def sim_process(*args: str):
    """`choreo sim ARGS` as a subprocess: yields (process, device path); always reaped."""
    proc = subprocess.Popen(
        [sys.executable, "-m", "choreo", "sim", *args],
        stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
    )
    try:
        path = proc.stdout.readline().strip()
        assert path.startswith("/"), f"first line is not a device path: {path!r}; {proc.stderr.read()}"
        yield proc, path
    finally:
        if proc.poll() is None:
            proc.kill()
        proc.communicate(timeout=10)


def finish(proc: subprocess.Popen, sig: int = signal.SIGTERM) -> tuple[int, str, str]:
    proc.send_signal(sig)
    out, err = proc.communicate(timeout=10)
    return proc.returncode, out, err


def exchange(port: serial.Serial, frame: p.Frame) -> bytes:
    port.write(frame.data)
    first = port.read(1)
    if not first or not 3 <= first[0] <= 8:
        return first
    return first + port.read(first[0] - 1)


def read_all(port: serial.Serial, frame: p.Frame, wait: float = 0.3, quiet: float = 0.05) -> bytes:
    """Write a frame and collect whatever comes (junk, short replies too) until the line is quiet.

    Waits up to `wait` for a first byte, then until `quiet` passes without one. Polls in_waiting
    rather than changing the port's timeout: every timeout change is a tcsetattr on the pty.
    `quiet` is far above the wire's gaps (0.1 ms a byte) so that a loaded machine pausing the
    server's thread mid-reply (a fresh clone's CI saw 10 ms) does not cut a reply in two.
    """
    port.write(frame.data)
    got = b""
    deadline = time.monotonic() + wait
    last = None
    while True:
        now = time.monotonic()
        if (last is None and now >= deadline) or (last is not None and now - last >= quiet):
            return got
        waiting = port.in_waiting
        if waiting:
            got += port.read(waiting)
            last = time.monotonic()
        else:
            time.sleep(0.001)


@contextlib.contextmanager
def in_process(board: SimBoard, **kwargs):
    """A PtyServer served from a thread: fast, and its board can be inspected."""
    server = PtyServer(board, **kwargs)
    path = server.open()
    result: list[ServeEnd] = []
    thread = threading.Thread(target=lambda: result.append(server.serve()), daemon=True)
    thread.start()
    try:
        yield server, path, result
    finally:
        server.stop()
        thread.join(5)
        server.close()


# -- the command -------------------------------------------------------------------------------


def test_choreo_sim_serves_the_four_frames_and_exits_0_on_sigterm():
    # a motion long enough to be seen running after a loaded machine's pause between two frames
    with sim_process("--motion-s", "1") as (proc, path):
        with serial.Serial(path, 115200, parity="E", timeout=REPLY_S) as port:
            stop, play, restore = p.play_sequence(3)
            assert exchange(port, stop) == p.ack(p.CMD_MOV)
            assert exchange(port, play) == p.ack(p.CMD_CALL)
            assert exchange(port, restore) == p.ack(p.CMD_MOV)
            # the status is refreshed every 50 ms: the first ones may still show the old one
            assert wait_for(lambda: p.parse_reply(STATUS, exchange(port, STATUS)).executing, REPLY_S, 0.01)
            assert wait_for(lambda: not p.parse_reply(STATUS, exchange(port, STATUS)).executing, REPLY_S, 0.05), \
                "the 1 s motion never ended"
            assert exchange(port, STATUS) == p.ram_reply(b"\x21\x87")
        code, out, err = finish(proc)
    assert code == 0
    assert out == ""  # the path was the only line
    assert "Traceback" not in err


def test_sigint_also_exits_0_and_verbose_logs_frames():
    with sim_process("-v") as (proc, path):
        with serial.Serial(path, 115200, parity="E", timeout=REPLY_S) as port:
            assert exchange(port, STATUS) == IDLE
        time.sleep(0.05)
        code, _, err = finish(proc, signal.SIGINT)
    assert code == 0
    assert "#1 0a 00 20 00 00 00 00 00 02 2c" in err and "05 00 02 00 07" in err


def test_a_client_can_close_and_open_again():
    with sim_process() as (proc, path):
        for _ in range(3):
            with serial.Serial(path, 115200, parity="E", timeout=REPLY_S) as port:
                assert exchange(port, STATUS) == IDLE
        assert finish(proc)[0] == 0


def test_wrong_baud_gets_no_reply_right_baud_does():
    with sim_process("--baud", "625000") as (proc, path):
        with serial.Serial(path, 115200, parity="E", timeout=0.1) as port:
            assert exchange(port, STATUS) == b""
        with serial.Serial(path, 625000, parity="E", timeout=REPLY_S) as port:
            assert exchange(port, STATUS) == IDLE
        assert finish(proc)[0] == 0


@pytest.mark.parametrize("args", [["--drop", "0"], ["--motion-s", "x"], ["--baud", "9600"], ["--durations", "3"]])
def test_bad_options_exit_2_with_one_line(args):
    done = subprocess.run([sys.executable, "-m", "choreo", "sim", *args], capture_output=True, text=True, timeout=20)
    assert done.returncode == 2 and done.stdout == ""
    assert len(done.stderr.strip().splitlines()) == 1 and "Traceback" not in done.stderr


def test_help_documents_the_fault_spelling():
    done = subprocess.run([sys.executable, "-m", "choreo", "sim", "--help"], capture_output=True, text=True, timeout=20)
    assert done.returncode == 0
    for text in ("--drop", "every K-th frame", "probability", "SIGTERM", "sim://"):
        assert text in done.stdout


def test_faults_from_the_command_line():
    with sim_process("--junk", "2", "--nak", "3") as (proc, path):
        with serial.Serial(path, 115200, parity="E", timeout=REPLY_S) as port:
            got = [read_all(port, STATUS, wait=REPLY_S) for _ in range(3)]  # each frame is answered
        assert finish(proc)[0] == 0
    assert got == [IDLE, JUNK + IDLE, p.nak(p.CMD_MOV)]


def test_lose_closes_the_pty_and_exits_3():
    with sim_process("--lose", "2") as (proc, path):
        with serial.Serial(path, 115200, parity="E", timeout=REPLY_S) as port:
            assert exchange(port, STATUS) == IDLE
            with pytest.raises(serial.SerialException):
                exchange(port, STATUS)
                exchange(port, STATUS)
        _, err = proc.communicate(timeout=10)
        assert proc.returncode == 3
    assert "lose" in err and "frame 2" in err and "Traceback" not in err


# -- the server in-process ---------------------------------------------------------------------


def test_reply_bytes_are_written_at_their_wire_time():
    with (in_process(SimBoard(reply_delay_s=0.03)) as (server, path, _),
          serial.Serial(path, 115200, parity="E", timeout=REPLY_S) as port):
        start = time.monotonic()
        assert exchange(port, STATUS) == IDLE
        assert time.monotonic() - start >= 0.029


def _whole_reply(board: SimBoard, port: serial.Serial, number: int, faulted_size: int) -> bytes:
    """The reply to the `number`th status frame, read to the size the board's journal says it
    has: a short reply and a reply the loaded machine paused halfway through look alike on the
    line, and the next frame must not go while the board still replies (it would be ignored)."""
    got = read_all(port, STATUS)
    deadline = time.monotonic() + 5
    entries: list = []
    while not entries and time.monotonic() < deadline:  # a dropped frame has no reply: ask the board
        entries = [e for e in list(board.journal) if e.kind == "frame" and e.number == number]
        time.sleep(0.005)
    size = faulted_size if entries[0].faults else len(IDLE)
    while len(got) < size and time.monotonic() < deadline:
        got += port.read(size - len(got))
    return got


@pytest.mark.parametrize(
    "kind,expected",
    [
        ("drop", b""),
        ("nak", p.nak(p.CMD_MOV)),
        ("badsum", IDLE[:-1] + bytes((IDLE[-1] ^ 0xFF,))),
        ("short", IDLE[:2]),
        ("junk", JUNK + IDLE),
    ],
)
@pytest.mark.parametrize("spelled", ["2", "0.5"])
def test_every_fault_kind_on_the_pty(kind, expected, spelled):
    board = SimBoard(faults=FaultPlan.parse({kind: spelled}, seed=9))
    with in_process(board) as (server, path, _), serial.Serial(path, 115200, parity="E", timeout=REPLY_S) as port:
        got = [_whole_reply(board, port, number, len(expected)) for number in range(1, 7)]
    hits = [e.number - 1 for e in board.journal if e.kind == "frame" and e.faults]
    assert hits and (spelled == "0.5" or hits == [1, 3, 5])
    assert got == [expected if i in hits else IDLE for i in range(6)]


def test_a_frame_sent_before_the_last_reply_was_read_gets_no_reply_on_the_pty():
    board = SimBoard()
    with in_process(board) as (server, path, _), serial.Serial(path, 115200, parity="E", timeout=REPLY_S) as port:
        port.write(STATUS.data + STATUS.data)  # one write: the server reads both at once
        assert port.read(len(IDLE)) == IDLE  # one reply (the journal says the second frame had none)
        assert exchange(port, STATUS) == IDLE  # written after the reply was read: answered
    assert board.frames_received == 2 and board.ignored == 1
    assert [e.kind for e in board.journal] == ["frame", "ignored", "frame"]
    assert "arrived while the board was still replying" in board.journal[1].note


def test_late_on_the_pty():
    board = SimBoard(faults=FaultPlan.parse({"late": "1"}, late_s=0.1))
    with in_process(board) as (server, path, _), serial.Serial(path, 115200, parity="E", timeout=REPLY_S) as port:
        # timed from before the write: a test put off between its write and its read sees the
        # reply at once, but never sooner than it was due
        written = time.monotonic()
        port.write(STATUS.data)
        assert port.read(5) == IDLE
        assert time.monotonic() - written >= 0.1


def test_lose_in_process_ends_serving_with_lost():
    board = SimBoard(faults=FaultPlan.parse({"lose": "0.5"}, seed=4))
    with in_process(board) as (server, path, result):
        with serial.Serial(path, 115200, parity="E", timeout=0.5) as port, pytest.raises(serial.SerialException):
            for _ in range(50):
                exchange(port, STATUS)
        deadline = time.monotonic() + 5
        while not result and time.monotonic() < deadline:
            time.sleep(0.01)
    assert result == [ServeEnd.LOST] and board.lost


def test_a_partial_frame_is_dropped_after_the_gap():
    board = SimBoard()
    with (in_process(board, gap_s=0.01) as (server, path, _),
          serial.Serial(path, 115200, parity="E", timeout=0.1) as port):
        port.write(STATUS.data[:4])
        # the next frame once the server has dropped these bytes: written while it was put off (a
        # loaded machine), they would reach it with the four, as one stream, without a gap
        assert wait_for(lambda: [e.kind for e in list(board.journal)] == ["partial"], REPLY_S, 0.005)
        assert exchange(port, STATUS) == IDLE
    assert [e.kind for e in board.journal] == ["partial", "frame"]


@pytest.mark.parametrize("settings", [dict(baudrate=9600), dict(stopbits=2), dict(parity="O")])
def test_the_server_reads_the_clients_settings(settings):
    board = SimBoard()
    with in_process(board) as (server, path, _):
        kwargs = dict(baudrate=115200, parity="E", timeout=0.1) | settings
        with serial.Serial(path, **kwargs) as port:
            assert exchange(port, STATUS) == b""
            # the server has read the frame (on a loaded machine, maybe only after the read's timeout)
            assert wait_for(lambda: bool(board.journal), REPLY_S, 0.005)
    assert [e.kind for e in board.journal] == ["ignored"]


def test_read_settings_sees_custom_bauds():
    master, slave = os.openpty()
    try:
        with serial.Serial(os.ttyname(slave), 1250000, parity="E", stopbits=2):
            seen = read_settings(slave, parity_visible=False)
        assert seen.baud == 1250000 and seen.stopbits == 2 and seen.parity is None
    finally:
        os.close(master)
        os.close(slave)


def test_command_line_options_mirror_the_url_query():
    from choreo.cli import build_parser
    from choreo.cli.sim import options_from_args
    from choreo.sim.options import parse_options, parse_query

    args = build_parser().parse_args(
        ["sim", "--motion-s", "0.5", "--durations", "3:2.5,7:1.2", "--baud", "625000", "--reply-ms", "0.3",
         "--refresh-ms", "20", "--drop", "5", "--late", "0.1", "--late-ms", "250", "--seed", "4", "--no-wire",
         "--gap-ms", "30", "--hold", "3", "--hold-ms", "15"]
    )
    from_cli = parse_options(options_from_args(args))
    from_url = parse_query(
        "motion_s=0.5&durations=3:2.5,7:1.2&baud=625000&reply_ms=0.3&refresh_ms=20&drop=5&late=0.1&late_ms=250"
        "&seed=4&wire=0&gap_ms=30&hold=3&hold_ms=15"
    )
    assert from_cli == from_url and from_cli.refresh_s == pytest.approx(0.02)
