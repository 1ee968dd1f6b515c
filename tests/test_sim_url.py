"""`sim://` through pyserial's own `serial_for_url`, read the way a client reads a board."""

from __future__ import annotations

import time

import pytest
import serial

from choreo.clock import VirtualTime
from choreo.wire import protocol as p
from choreo.board.link import register_url_handlers
from choreo.sim.faults import JUNK, FaultPlan
from choreo.sim.board import SimBoard

register_url_handlers()

STATUS = p.status_frame()
IDLE = p.ram_reply(b"\x02\x00")


def open_sim(query: str = "", **kwargs) -> serial.SerialBase:
    settings = dict(baudrate=115200, bytesize=8, parity="E", stopbits=1, timeout=0.2)
    settings.update(kwargs)
    return serial.serial_for_url("sim://" + (f"?{query}" if query else ""), **settings)


def open_virtual(query: str = "", **kwargs) -> serial.SerialBase:
    """`open_sim` on virtual time (`port.time_source`): the board's schedule (a reply's delay, a
    late reply, a motion's end) against the reads is the same on any machine. On the machine's
    clock a test thread put off between a write and a read (a loaded machine) saw a reply that
    should still have been on its way."""
    port = open_sim(query, do_not_open=True, **kwargs)
    port.time_source = VirtualTime()
    port.open()
    return port


def exchange(port: serial.SerialBase, frame: p.Frame) -> bytes:
    """Write a frame, read the size byte, then the rest: what a careful client does."""
    port.write(frame.data)
    first = port.read(1)
    if not first or not 3 <= first[0] <= 8:
        return first
    return first + port.read(first[0] - 1)


@pytest.fixture
def port():
    with open_virtual("motion_s=0.15") as port:
        yield port


def test_serial_for_url_opens_the_simulator(port):
    assert type(port).__module__ == "choreo.sim.protocol_sim"
    assert port.is_open and port.board.baud == 115200


def test_the_four_frames_play_a_motion_that_ends(port):
    stop, play, restore = p.play_sequence(3)
    assert exchange(port, stop) == p.ack(p.CMD_MOV)
    assert exchange(port, play) == p.ack(p.CMD_CALL)
    assert exchange(port, restore) == p.ack(p.CMD_MOV)
    clock = port.time_source
    clock.sleep(0.06)  # the status is refreshed every 50 ms: sooner may still show the old one
    verdict = p.parse_reply(STATUS, exchange(port, STATUS))
    assert verdict.kind is p.ReplyKind.STATUS and verdict.executing
    deadline = clock.now() + 2.0
    while p.parse_reply(STATUS, exchange(port, STATUS)).executing:
        assert clock.now() < deadline, "the 0.15 s motion never ended"
        clock.sleep(0.05)
    assert port.board.config(clock.now()) == 0x8721
    frames = [e for e in port.board.journal if e.kind == "frame"]
    assert [e.data for e in frames[:4]] == [stop.data, play.data, restore.data, STATUS.data]
    assert all(e.reply is not None for e in frames)


def test_durations_per_slot_in_the_url():
    with open_sim("motion_s=5&durations=2:0.05") as port:
        for frame in p.play_sequence(2):
            exchange(port, frame)
        time.sleep(0.05 + 0.06)  # the motion, then a status refresh (every 50 ms) after its end
        assert not p.parse_reply(STATUS, exchange(port, STATUS)).executing


def test_read_waits_for_the_reply_on_the_boards_schedule():
    with open_virtual("reply_ms=40") as port:
        port.write(STATUS.data)
        assert port.in_waiting == 0
        assert port.read(5) == IDLE  # blocks until the bytes are on the wire
        entry = port.board.journal[-1]
        assert port.time_source.now() >= entry.reply_at


def test_read_honours_the_timeout_without_spinning():
    with open_sim("drop=1", timeout=0.15) as port:
        port.write(STATUS.data)
        wall, cpu = time.monotonic(), time.process_time()
        assert port.read(5) == b""
        wall, cpu = time.monotonic() - wall, time.process_time() - cpu
    assert 0.14 <= wall < 2.0
    assert cpu < 0.5 * wall + 0.02  # sleeps, does not busy-wait


def test_timeout_zero_returns_what_has_arrived():
    with open_virtual("reply_ms=30", timeout=0) as port:
        port.write(STATUS.data)
        assert port.read(5) == b""
        port.time_source.sleep(0.05)
        assert port.in_waiting == 5
        assert port.read(5) == IDLE


def test_in_waiting_and_reset_input_buffer():
    with open_sim("wire=0&reply_ms=0") as port:
        port.write(STATUS.data)
        assert port.in_waiting == 5
        port.reset_input_buffer()
        assert port.in_waiting == 0
        assert port.read(1) == b""


def test_reset_input_buffer_keeps_bytes_still_on_the_wire():
    with open_virtual("reply_ms=50") as port:
        port.write(STATUS.data)
        port.reset_input_buffer()  # nothing has arrived yet
        assert port.read(5) == IDLE


@pytest.mark.parametrize(
    "settings",
    [dict(baudrate=9600), dict(parity="N"), dict(parity="O"), dict(stopbits=2), dict(bytesize=7)],
)
def test_the_board_does_not_answer_a_port_with_other_settings(settings):
    with open_sim(timeout=0.05, **settings) as port:
        assert exchange(port, STATUS) == b""
        assert port.board.frames_received == 0
        assert port.board.journal[-1].kind == "ignored"


def test_changing_the_ports_settings_after_open_applies():
    with open_sim(timeout=0.05, baudrate=9600) as port:
        assert exchange(port, STATUS) == b""
        port.baudrate = 115200
        assert exchange(port, STATUS) == IDLE


@pytest.mark.parametrize("baud", [625000, 1250000])
def test_board_baud_option(baud):
    with open_sim(f"baud={baud}", baudrate=baud) as port:
        assert exchange(port, STATUS) == IDLE
    with open_sim(f"baud={baud}", baudrate=115200, timeout=0.05) as port:
        assert exchange(port, STATUS) == b""


@pytest.mark.parametrize(
    "url,message",
    [
        ("sim://?colour=red", "unknown option 'colour'"),
        ("sim://?drop=0", "drop=0"),
        ("sim://?motion_s=fast", "motion_s"),
        ("sim://board1", "options only after"),
    ],
)
def test_bad_urls_raise_valueerror_naming_the_problem(url, message):
    with pytest.raises(ValueError, match=message):
        serial.serial_for_url(url, baudrate=115200, parity="E")


def test_the_handler_module_imports_cleanly():
    # serial_for_url swallows an ImportError from the handler and reports an unknown scheme.
    import importlib

    module = importlib.import_module("choreo.sim.protocol_sim")
    assert issubclass(module.Serial, serial.SerialBase)


def test_closed_port_refuses_io(port):
    port.close()
    with pytest.raises(serial.PortNotOpenError):
        port.write(STATUS.data)
    with pytest.raises(serial.PortNotOpenError):
        port.read(1)


def test_a_frame_split_over_a_long_gap_is_dropped():
    with open_sim("gap_ms=5", timeout=0.05) as port:
        stop = p.stop_frame().data
        port.write(stop[:7])
        time.sleep(0.03)
        port.write(stop[7:])
        assert port.read(4) != p.ack(p.CMD_MOV)
        assert any(e.kind == "partial" for e in port.board.journal)


# -- faults through the port -------------------------------------------------------------------

EXPECTED = {
    "drop": b"",
    "nak": p.nak(p.CMD_MOV),
    "badsum": IDLE[:-1] + bytes((IDLE[-1] ^ 0xFF,)),
    "short": IDLE[:2],
    "junk": JUNK + IDLE,
}


def read_all(port: serial.SerialBase, frame: p.Frame) -> bytes:
    """Write a frame and read whatever comes until the line is quiet (junk, short replies too)."""
    port.write(frame.data)
    got = b""
    while True:
        more = port.read(64)
        if not more:
            return got
        got += more


@pytest.mark.parametrize("kind", sorted(EXPECTED))
def test_every_kth_fault_through_the_port(kind):
    with open_sim(f"{kind}=2", timeout=0.01) as port:
        got = [read_all(port, STATUS) for _ in range(4)]
    assert got == [IDLE, EXPECTED[kind], IDLE, EXPECTED[kind]]


@pytest.mark.parametrize("kind", sorted(EXPECTED))
def test_probability_fault_through_the_port_matches_the_board_model(kind):
    model = SimBoard(faults=FaultPlan.parse({kind: "0.4"}, seed=5), wire=False)
    expected_hits = []
    for i in range(12):
        model.receive(STATUS.data, float(i))
        if model.journal[-1].faults:
            expected_hits.append(i)
    assert 0 < len(expected_hits) < 12
    with open_sim(f"{kind}=0.4&seed=5", timeout=0.01) as port:
        got = [read_all(port, STATUS) for _ in range(12)]
    assert [i for i, data in enumerate(got) if data != IDLE] == expected_hits
    assert all(got[i] == EXPECTED[kind] for i in expected_hits)


def test_late_reply_arrives_after_late_ms():
    with open_virtual("late=1&late_ms=120", timeout=0.05) as port:
        port.write(STATUS.data)
        assert port.read(5) == b""
        port.timeout = 1.0
        assert port.read(5) == IDLE


def test_late_with_probability():
    with open_virtual("late=0.5&late_ms=60&seed=3", timeout=0.03) as port:
        got = [read_all(port, STATUS) for _ in range(8)]
        lates = [e.number for e in port.board.journal if e.faults == ("late",)]
    assert lates
    # a late reply is missed by its own read and shows up in the next read, so replies shift
    assert got != [IDLE] * 8


@pytest.mark.parametrize("spelled", ["3", "0.3"])
def test_lose_makes_every_read_and_write_fail_from_that_frame_on(spelled):
    with open_sim(f"lose={spelled}&seed=2", timeout=0.05) as port:
        with pytest.raises(serial.SerialException, match="port lost"):
            for _ in range(100):
                assert exchange(port, STATUS) == IDLE
        lost_at = port.board.lost_at_frame
        assert lost_at == 3 if spelled == "3" else lost_at >= 1
        for action in (lambda: port.read(1), lambda: port.write(STATUS.data), lambda: port.in_waiting):
            with pytest.raises(serial.SerialException, match="port lost"):
                action()
    assert port.board.frames_received == lost_at


# -- one reply at a time, and the return-address stack ------------------------------------------


def test_a_frame_written_before_the_last_reply_was_read_gets_no_reply():
    """The errata: the reply must be read before the next frame is sent. Wire time on (the
    default): the second frame's first byte reaches the board while it is still replying."""
    with open_sim(timeout=0.05) as port:
        assert port.board.wire
        # back to back on the wire, without reading the first reply: one write, so that no pause
        # of this thread between two writes (a loaded machine) lets the reply end first
        port.write(STATUS.data + STATUS.data)
        assert read_all_quiet(port) == IDLE  # one reply, to the first frame only
        board = port.board
        assert board.frames_received == 1 and board.ignored == 1
        entry = [e for e in board.journal if e.kind == "ignored"][0]
        assert "arrived while the board was still replying" in entry.note and entry.data == STATUS.data
        assert exchange(port, STATUS) == IDLE  # read, then write: answered again
        assert board.frames_received == 2


def test_a_whole_play_sequence_written_at_once_loses_the_call_and_plays_nothing():
    """The CALL arrives while the stop frame's ACK is going out; the restore comes after it and
    is answered: two ACKs, as a careless client expects, and no motion."""
    with open_sim(timeout=0.05) as port:
        port.write(b"".join(f.data for f in p.play_sequence(3)))
        assert read_all_quiet(port) == p.ack(p.CMD_MOV) * 2
        board = port.board
        assert board.frames_received == 2 and board.ignored == 1
        assert [e.data for e in board.journal if e.kind == "ignored"] == [p.play_frame(3).data]
        assert board.running(time.monotonic()) is None and board.stack_depth == 0


def test_a_raw_call_call_pair_pushes_a_second_return_address():
    with open_sim() as port:
        stop, play, _ = p.play_sequence(3)
        assert exchange(port, stop) == p.ack(p.CMD_MOV)
        assert exchange(port, play) == p.ack(p.CMD_CALL)
        assert port.board.stack_faults == 0
        assert exchange(port, play) == p.ack(p.CMD_CALL)  # re-sent alone: ACKed all the same
        assert port.board.stack_faults == 1
        assert [e.kind for e in port.board.journal][-1] == "stack"


def read_all_quiet(port: serial.SerialBase) -> bytes:
    """Everything that arrives until a read times out."""
    got = b""
    while more := port.read(64):
        got += more
    return got


# -- one object reads and writes sim:// URLs ---------------------------------------------------


def test_sim_url_reads_the_options_and_writes_them_back_amended_by_name():
    from choreo.sim.options import SimUrl

    url = SimUrl.parse("sim://?drop=5&motion_s=0.5")
    assert url.options.motion_s == 0.5 and url.options.faults.describe() != "no faults"
    assert url.says("drop") and not url.says("baud")
    assert str(url) == "sim://?drop=5&motion_s=0.5"
    assert str(url.with_text(motion_s="0.25", wire="0")) == "sim://?drop=5&motion_s=0.25&wire=0"
    assert str(url.unless_given(motion_s="9", baud="625000")) == "sim://?drop=5&motion_s=0.5&baud=625000"
    assert str(SimUrl.parse("sim://")) == "sim://" and SimUrl.parse("SIM://?seed=3").says("seed")
    written = url.with_text(durations="3:2.5,7:1.2")
    assert SimUrl.parse(str(written)).options.durations == {3: 2.5, 7: 1.2}


@pytest.mark.parametrize("url, message", [
    ("sim://?drop=5&drop=6", "'drop' is given twice"),
    ("sim://?bogus=1", "unknown option 'bogus'"),
    ("loop://", "expected a URL like sim://"),
    ("sim://host", "options only after '?'"),
    ("sim://?motion_s=-1", "motion_s='-1'"),
])
def test_sim_url_refuses_what_the_simulator_refuses(url, message):
    from choreo.sim.options import SimUrl

    with pytest.raises(ValueError, match=message.replace("?", r"\?")):
        SimUrl.parse(url)


def test_a_runs_port_gets_what_its_url_leaves_unsaid_and_keeps_what_it_says():
    from choreo.errors import UsageError
    from choreo.wire.layouts import SEED, Layout, layout_named
    from choreo.run.settings import LinkSettings
    from choreo.sim.options import SimUrl

    def port(given: str, baud: int = 115200, layout: Layout = SEED) -> str:
        return LinkSettings("robot", given, "command line", baud, 0.2, 3, layout).port

    hth4 = layout_named("hth4-2.2")
    url = port("sim://?baud=625000&drop=5", 625000, hth4)
    assert url == "sim://?baud=625000&drop=5&layout=hth4-2.2"  # the user's baud once, layout added
    assert port("sim://?drop=5") == "sim://?drop=5"  # nothing to add
    assert port("/dev/ttyUSB0", 625000, hth4) == "/dev/ttyUSB0"
    assert SimUrl.parse(url).options.layout is hth4
    with pytest.raises(UsageError, match=r"--port sim://\?drop=5&drop=6: sim://: option 'drop' is given twice"):
        port("sim://?drop=5&drop=6")
