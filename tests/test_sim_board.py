"""The simulated board, exactly: explicit time, no sleeping, every answer and every fault."""

from __future__ import annotations

import pytest

from choreo.wire import protocol as p
from choreo.wire.layouts import HTH4_22, SEED
from choreo.sim.board import RAM_SIZE, SimBoard, Transmission
from choreo.sim.faults import FAULT_KINDS, JUNK, FaultPlan, Trigger
from choreo.sim.options import parse_durations, parse_options, parse_query
from choreo.sim.line import Framer, Line, LineSettings

STOP = p.stop_frame().data
RESTORE = p.restore_frame().data
STATUS = p.status_frame().data
ACK_MOV = bytes.fromhex("0400060a")
ACK_CALL = bytes.fromhex("040c0616")


def board(**kwargs) -> SimBoard:
    """An ideal board for exact tests of the motion model: no wire time, no reply delay and a
    live status (the 50 ms refresh has tests of its own, below)."""
    kwargs.setdefault("wire", False)
    kwargs.setdefault("reply_delay_s", 0.0)
    kwargs.setdefault("refresh_s", 0.0)
    return SimBoard(**kwargs)


def reply(b: SimBoard, frame: bytes, now: float) -> bytes | None:
    sent = b.receive(frame, now)
    return None if sent is None else sent.data


def status_low(b: SimBoard, now: float) -> int:
    data = reply(b, STATUS, now)
    assert data is not None and len(data) == 5 and data[:2] == b"\x05\x00"
    assert data[4] == p.checksum(data[:4])
    return data[2]


def play(b: SimBoard, motion: int, now: float) -> None:
    assert reply(b, STOP, now) == ACK_MOV
    assert reply(b, p.play_frame(motion).data, now) == ACK_CALL
    assert reply(b, RESTORE, now) == ACK_MOV


# -- the board model ---------------------------------------------------------------------------


def test_power_on_config_has_only_the_run_bit():
    b = board()
    assert b.config(0.0) == 0x0002
    assert len(b.ram) >= 0x0400
    assert reply(b, STATUS, 0.0) == p.ram_reply(b"\x02\x00")


def test_play_sequence_runs_the_motion_for_its_duration_then_clears_the_run_bit():
    b = board(motion_s=1.0)
    play(b, 3, 10.0)
    assert b.running(10.0) == 3
    assert status_low(b, 10.0) == 0x23
    assert status_low(b, 10.999) == 0x23
    assert status_low(b, 11.0) == 0x21
    assert b.config(11.0) == 0x8721
    assert b.running(11.0) is None
    ended = [e for e in b.journal if e.kind == "motion"]
    assert len(ended) == 1 and ended[0].at == 11.0 and "motion 3 ended" in ended[0].note


def test_status_reply_is_what_the_protocol_parses_as_executing():
    b = board(motion_s=0.5)
    play(b, 0, 0.0)
    verdict = p.parse_reply(p.status_frame(), reply(b, STATUS, 0.1))
    assert verdict.kind is p.ReplyKind.STATUS and verdict.executing and verdict.status == 0x8723
    verdict = p.parse_reply(p.status_frame(), reply(b, STATUS, 0.6))
    assert verdict.kind is p.ReplyKind.STATUS and not verdict.executing and verdict.status == 0x8721


def test_durations_are_per_slot_with_a_default():
    b = board(motion_s=1.0, durations={7: 2.5})
    play(b, 7, 0.0)
    assert status_low(b, 2.4) == 0x23
    assert status_low(b, 2.5) == 0x21
    play(b, 8, 3.0)
    assert status_low(b, 3.9) == 0x23
    assert status_low(b, 4.0) == 0x21


def test_stop_frame_stops_a_running_motion_at_once():
    b = board(motion_s=5.0)
    play(b, 1, 0.0)
    assert reply(b, STOP, 1.0) == ACK_MOV
    assert b.running(1.0) is None
    assert status_low(b, 1.0) == 0x21


def test_new_play_while_running_replaces_the_motion():
    b = board(durations={1: 5.0, 2: 0.5})
    play(b, 1, 0.0)
    play(b, 2, 1.0)
    assert b.running(1.2) == 2
    assert status_low(b, 1.5) == 0x21


def test_restore_with_nothing_armed_runs_nothing_and_clears_the_run_bit_at_once():
    b = board()
    assert reply(b, STOP, 0.0) == ACK_MOV
    assert reply(b, RESTORE, 0.0) == ACK_MOV
    assert b.running(0.0) is None
    assert status_low(b, 0.0) == 0x21
    assert "nothing armed" in b.journal[-2].note


def test_call_of_a_non_slot_address_is_acked_and_arms_nothing():
    b = board()
    reply(b, STOP, 0.0)
    assert reply(b, p.call(0x0BB9), 0.0) == ACK_CALL
    assert b.armed is None
    reply(b, RESTORE, 0.0)
    assert b.running(0.0) is None


def test_call_arms_and_the_stop_frame_disarms_by_rewriting_the_program_counter():
    b = board()
    assert reply(b, p.play_frame(119).data, 0.0) == ACK_CALL
    assert b.armed == 119
    reply(b, STOP, 0.0)
    assert b.armed is None


def test_mov_write_and_read_any_ram():
    b = board()
    assert reply(b, p.mov_write(0x0100, b"\x01\x02\x03"), 0.0) == ACK_MOV
    assert reply(b, p.mov_read(0x0100, 3), 0.0) == p.ram_reply(b"\x01\x02\x03")
    assert reply(b, p.mov_write(RAM_SIZE - 1, b"\x01\x02"), 0.0) == p.nak(p.CMD_MOV)
    assert reply(b, p.mov_read(RAM_SIZE - 1, 2), 0.0) == p.nak(p.CMD_MOV)


@pytest.mark.parametrize("frame", [STOP, RESTORE, STATUS, p.play_frame(5).data])
def test_bad_checksum_gets_a_four_byte_nak_for_its_command(frame):
    b = board()
    bad = frame[:-1] + bytes(((frame[-1] + 1) & 0xFF,))
    assert reply(b, bad, 0.0) == p.nak(frame[1])
    assert p.parse_reply(p.status_frame(), p.nak(0)).kind is p.ReplyKind.NAK
    assert b.config(0.0) == 0x0002  # nothing executed


@pytest.mark.parametrize(
    "frame,command",
    [
        (p.build_frame(p.CMD_CALL, b"\xb8\x0b"), p.CMD_CALL),  # CALL with too few arguments
        (p.build_frame(p.CMD_MOV, b"\x02\x00"), p.CMD_MOV),  # MOV write without an address
        (p.build_frame(p.CMD_MOV, b"\x12\x00\x00\x00"), p.CMD_MOV),  # move type not modelled
        (p.build_frame(0x33, b"\x01"), 0x33),  # unknown command
    ],
)
def test_malformed_or_unknown_frames_get_a_nak(frame, command):
    assert reply(board(), frame, 0.0) == p.nak(command)


def test_noise_that_cannot_be_a_frame_gets_a_nak_with_the_byte_it_saw():
    assert reply(board(), b"\xff\x0c\x01", 0.0) == p.nak(0x0C)
    assert reply(board(), b"\x01", 0.0) == p.nak(0x00)


def test_ack_check_is_answered():
    assert reply(board(), bytes.fromhex("04fe0608"), 0.0) == bytes.fromhex("04fe0608")


def test_reply_times_follow_the_reply_delay_and_eleven_bits_a_byte():
    b = SimBoard(baud=115200, reply_delay_s=0.0002)
    sent = b.receive(STATUS, 1.0)
    bt = 11 / 115200
    assert sent.data == p.ram_reply(b"\x02\x00")
    assert sent.times == pytest.approx([1.0002 + (i + 1) * bt for i in range(5)], abs=1e-12)


def test_reply_times_at_1250000_baud():
    b = SimBoard(baud=1250000, reply_delay_s=0.0)
    sent = b.receive(STOP, 0.0)
    assert sent.end == pytest.approx(4 * 11 / 1250000)


def test_a_frame_that_arrives_while_the_board_is_still_replying_is_not_answered():
    b = SimBoard(reply_delay_s=0.0)
    first = b.receive(STATUS, 0.0)
    assert b.receive(STATUS, 0.0001) is None  # written without reading the reply
    assert b.frames_received == 1 and b.ignored == 1
    entry = b.journal[-1]
    assert entry.kind == "ignored" and "arrived while the board was still replying" in entry.note
    assert "ignored: MOV RAM->COM 0x0000 x2: status query arrived while the board was still replying" \
        in entry.line()
    bt = 11 / 115200
    # Its first byte must not arrive before the reply's last: 9 more bytes make the frame's end.
    assert b.receive(STATUS, first.end + (len(STATUS) - 1) * bt - 1e-9) is None
    assert b.receive(STATUS, first.end + (len(STATUS) - 1) * bt + 1e-9) is not None
    assert b.frames_received == 2 and b.ignored == 2


def test_without_wire_time_bytes_arrive_with_the_reply_delay_only():
    sent = SimBoard(wire=False, reply_delay_s=0.001).receive(STOP, 2.0)
    assert sent.times == (2.001,) * 4


def test_journal_records_frames_replies_and_counts():
    seen = []
    b = board(on_entry=seen.append)
    play(b, 4, 0.0)
    assert b.frames_received == 3
    frames = [e for e in b.journal if e.kind == "frame"]
    assert [e.number for e in frames] == [1, 2, 3]
    assert [e.data for e in frames] == [STOP, p.play_frame(4).data, RESTORE]
    assert [e.reply for e in frames] == [ACK_MOV, ACK_CALL, ACK_MOV]
    assert "motion 4 started" in frames[2].note
    assert seen == list(b.journal)
    assert "#2 07 0c b8 2b 00 00 f6" in str(frames[1])


def test_journal_is_bounded():
    b = board(journal_size=5)
    for i in range(20):
        reply(b, STATUS, float(i))
    assert len(b.journal) == 5 and b.frames_received == 20


def test_frames_must_come_in_order_but_queries_may_look_back():
    b = board()
    reply(b, STATUS, 5.0)
    with pytest.raises(ValueError, match="in order"):
        b.receive(STATUS, 4.0)
    assert b.config(1.0) == 0x0002


@pytest.mark.parametrize("kwargs", [{"baud": 9600}, {"motion_s": -1}, {"durations": {120: 1.0}}, {"reply_delay_s": -1}])
def test_bad_board_settings_are_refused(kwargs):
    with pytest.raises(ValueError):
        SimBoard(**kwargs)


# -- faults ------------------------------------------------------------------------------------


def faulty(kind: str, spelled: str, seed: int = 0, **kwargs) -> SimBoard:
    return board(faults=FaultPlan.parse({kind: spelled}, seed=seed), **kwargs)


def hit_frames(b: SimBoard) -> list[int]:
    return [e.number for e in b.journal if e.kind == "frame" and e.faults]


EXPECTED = {
    "drop": None,
    "nak": p.nak(p.CMD_MOV),
    "badsum": p.ram_reply(b"\x02\x00")[:-1] + bytes((p.ram_reply(b"\x02\x00")[-1] ^ 0xFF,)),
    "short": p.ram_reply(b"\x02\x00")[:2],
    "junk": JUNK + p.ram_reply(b"\x02\x00"),
    "late": p.ram_reply(b"\x02\x00"),
}


@pytest.mark.parametrize("kind", sorted(EXPECTED))
def test_every_kth_frame_fault_hits_frames_k_2k_3k(kind):
    b = faulty(kind, "3")
    replies = [reply(b, STATUS, float(i)) for i in range(1, 10)]
    assert hit_frames(b) == [3, 6, 9]
    for number, data in enumerate(replies, start=1):
        assert data == (EXPECTED[kind] if number % 3 == 0 else p.ram_reply(b"\x02\x00"))


def test_every_frame_with_k_1():
    b = faulty("drop", "1")
    assert [reply(b, STATUS, float(i)) for i in range(3)] == [None, None, None]


def test_late_reply_comes_late_ms_after_it_was_due_and_a_frame_meanwhile_is_not_answered():
    b = board(faults=FaultPlan.parse({"late": "1"}, late_s=0.25), wire=True, reply_delay_s=0.0002)
    sent = b.receive(STATUS, 1.0)
    assert sent.start == pytest.approx(1.0 + 0.0002 + 0.25 + 11 / 115200)
    b2 = board(faults=FaultPlan.parse({"late": "2"}, late_s=0.5))
    b2.receive(STATUS, 0.0)
    late = b2.receive(STATUS, 0.1)
    assert late.start == pytest.approx(0.6)
    assert b2.receive(STATUS, 0.2) is None  # the board is still replying (late) to frame 2
    assert b2.journal[-1].kind == "ignored" and b2.frames_received == 2
    assert b2.receive(STATUS, 0.7).data == p.ram_reply(b"\x02\x00")  # frame 3: not late


@pytest.mark.parametrize("kind", ["drop", "nak"])
def test_drop_and_nak_mean_the_board_did_not_execute_the_frame(kind):
    b = faulty(kind, "2")
    reply(b, STOP, 0.0)
    reply(b, p.play_frame(3).data, 0.0)  # frame 2: hit, not executed
    assert b.armed is None


@pytest.mark.parametrize("kind", ["badsum", "short", "junk", "late"])
def test_reply_faults_still_execute_the_frame(kind):
    b = faulty(kind, "2")
    reply(b, STOP, 0.0)
    reply(b, p.play_frame(3).data, 0.0)
    assert b.armed == 3


def test_lose_happens_once_at_frame_k_and_then_the_board_refuses_everything():
    b = faulty("lose", "2")
    assert reply(b, STATUS, 0.0) is not None
    assert reply(b, STATUS, 0.1) is None
    assert b.lost and b.lost_at_frame == 2
    with pytest.raises(ValueError, match="lost at frame 2"):
        b.receive(STATUS, 0.2)


@pytest.mark.parametrize("kind", sorted(EXPECTED))
def test_probability_faults_are_deterministic_for_a_seed(kind):
    def hits(seed: int) -> list[int]:
        b = faulty(kind, "0.25", seed=seed)
        for i in range(400):
            reply(b, STATUS, float(i))
        return hit_frames(b)

    first = hits(7)
    assert first == hits(7)
    assert first != hits(8)
    assert 50 <= len(first) <= 150  # 0.25 of 400 = 100; far outside this is a broken generator
    b = faulty(kind, "0.25", seed=7)
    for i in range(400):
        data = reply(b, STATUS, float(i))
        assert data == (EXPECTED[kind] if i + 1 in first else p.ram_reply(b"\x02\x00"))


def test_probability_lose_happens_once_and_is_repeatable():
    def lost_at(seed: int) -> int:
        b = faulty("lose", "0.1", seed=seed)
        for i in range(1000):
            if reply(b, STATUS, float(i)) is None:
                break
        assert b.lost
        return b.lost_at_frame

    assert lost_at(3) == lost_at(3)
    assert {lost_at(s) for s in range(5)} != {lost_at(0)}


def test_each_kind_draws_on_its_own_so_adding_a_kind_changes_no_other():
    plans = [{"nak": "0.3"}, {"nak": "0.3", "drop": "0.3"}, {"nak": "0.3", "junk": "0.5", "late": "0.1"}]
    boards = [board(faults=FaultPlan.parse(plan, seed=1)) for plan in plans]
    for b in boards:
        for i in range(200):
            reply(b, STATUS, float(i))
    nak_hits = [[e.number for e in b.journal if "nak" in e.faults] for b in boards]
    assert nak_hits[0] and nak_hits[0] == nak_hits[1] == nak_hits[2]


def test_several_faults_on_one_frame_combine_in_the_documented_order():
    b = board(faults=FaultPlan.parse({"junk": "1", "badsum": "1", "late": "1"}, late_s=0.1))
    sent = b.receive(STATUS, 0.0)
    good = p.ram_reply(b"\x02\x00")
    assert sent.data == JUNK + good[:-1] + bytes((good[-1] ^ 0xFF,))
    assert sent.start == pytest.approx(0.1)
    b = board(faults=FaultPlan.parse({"drop": "1", "nak": "1"}))
    assert reply(b, STATUS, 0.0) is None


@pytest.mark.parametrize(
    "text,expected",
    [("5", Trigger(every=5)), ("1", Trigger(every=1)), ("0.2", Trigger(probability=0.2)),
     (".5", Trigger(probability=0.5))],
)
def test_trigger_spelling(text, expected):
    assert Trigger.parse(text) == expected


@pytest.mark.parametrize("text", ["0", "1.0", "0.0", "-1", "x", "", "1.5", "nan"])
def test_trigger_spelling_refuses(text):
    with pytest.raises(ValueError):
        Trigger.parse(text)


def test_unknown_fault_kind_is_refused():
    with pytest.raises(ValueError, match="unknown fault kind 'melt'"):
        FaultPlan({"melt": Trigger(every=1)})
    assert set(FAULT_KINDS) == {"lose", "drop", "nak", "badsum", "short", "junk", "late", "lose_start", "hold"}


@pytest.mark.parametrize("layout", ["seed", "hth4-2.2"])
def test_frame_kind_names_each_frame_of_both_play_sequences(layout):
    from choreo.wire.layouts import layout_named
    from choreo.sim.faults import frame_kind

    chosen = layout_named(layout)
    frames = chosen.play_sequence(5, 0x821B)
    assert [frame_kind(f.data) for f in frames] == [f.kind.value for f in frames]
    assert frame_kind(chosen.status.data) == frame_kind(chosen.start_read.data) == "read"
    assert frame_kind(p.sync_frame().data) == "sync"
    assert frame_kind(p.version_frame().data) == frame_kind(b"\xff\x00\xaa") == "other"


def test_faults_on_counts_and_hits_only_frames_of_those_kinds():
    b = board(faults=FaultPlan.parse({"drop": "2"}, on=frozenset({"play"})))
    frames = p.play_sequence(1) * 3  # CALLs are frames 2, 5, 8: the second CALL is dropped
    replies = [b.receive(f.data, 0.01 * i) for i, f in enumerate(frames)]
    assert [i for i, r in enumerate(replies) if r is None] == [4]
    assert [e.number for e in b.journal if e.kind == "frame" and e.faults] == [5]
    assert FaultPlan.parse({"drop": "2"}, on=frozenset({"play", "restore"})).describe() == \
        "drop every 2th play/restore frame"


@pytest.mark.parametrize("query,message", [
    ("drop=2&faults_on=calls", "option faults_on='calls': unknown frame kind 'calls' (known: stop, counter, "),
    ("drop=2&faults_on=,", "option faults_on=',': no frame kind"),
])
def test_faults_on_refuses_unknown_kinds(query, message):
    with pytest.raises(ValueError, match=message.replace("(", r"\(")):
        parse_query(query)


# -- options -----------------------------------------------------------------------------------


def test_query_options_parse():
    o = parse_query("motion_s=0.5&drop=5&durations=3:2.5,7:1.2&reply_ms=0.3&seed=4&wire=0&baud=625000&late_ms=100")
    assert o.motion_s == 0.5 and o.durations == {3: 2.5, 7: 1.2} and o.reply_s == pytest.approx(0.0003)
    assert o.wire is False and o.baud == 625000
    assert o.faults.triggers == {"drop": Trigger(every=5)} and o.faults.seed == 4 and o.faults.late_s == 0.1
    b = o.board()
    assert b.duration(3) == 2.5 and b.duration(0) == 0.5 and b.baud == 625000


@pytest.mark.parametrize(
    "query,message",
    [
        ("colour=red", "unknown option 'colour'"),
        ("drop=0", "fault drop=0"),
        ("drop=1.0", "strictly between 0 and 1"),
        ("baud=9600", "115200, 625000, 1250000"),
        ("motion_s=-1", "motion_s"),
        ("durations=3", "SLOT:SECONDS"),
        ("durations=200:1", "out of range"),
        ("wire=maybe", "wire"),
        ("seed=x", "seed"),
        ("drop=1&drop=2", "given twice"),
    ],
)
def test_bad_options_name_the_problem(query, message):
    with pytest.raises(ValueError, match=message):
        parse_query(query)


def test_durations_spelling():
    assert parse_durations("3:2.5, 7:1.2,") == {3: 2.5, 7: 1.2}
    assert parse_options({}).durations == {}


# -- the line: framing, settings, timing -------------------------------------------------------


def test_framer_splits_contiguous_frames_and_drops_a_partial_after_a_gap():
    f = Framer(gap_s=0.001)
    units = []
    for i, byte in enumerate(STATUS + STATUS[:4]):
        units += f.push(byte, i * 0.0001, 0.0001)
    assert [u.kind for u in units] == ["frame"] and units[0].data == STATUS
    assert f.expire(0.0013) is None
    partial = f.expire(0.0025)
    assert partial.kind == "partial" and partial.data == STATUS[:4]


def test_framer_a_late_byte_starts_a_new_frame():
    f = Framer(gap_s=0.001)
    for i, byte in enumerate(STATUS[:3]):
        f.push(byte, i * 0.0001, 0.0001)
    units = []
    for i, byte in enumerate(STATUS):
        units += f.push(byte, 1.0 + i * 0.0001, 0.0001)
    assert [u.kind for u in units] == ["partial", "frame"]


def test_line_delivers_the_reply_on_schedule_including_the_frames_own_wire_time():
    b = SimBoard(reply_delay_s=0.0002)
    line = Line(b)
    line.send(STATUS, 10.0)
    bt = 11 / 115200
    arrived = 10.0 + len(STATUS) * bt
    first_byte = arrived + 0.0002 + bt
    assert b.journal[-1].at == pytest.approx(arrived)
    assert line.available(first_byte - 1e-9) == 0
    assert line.next_event() == pytest.approx(first_byte)
    assert line.take(first_byte, 10) == b"\x05"
    assert line.take(first_byte + 4 * bt, 10) == p.ram_reply(b"\x02\x00")[1:]


def test_line_flush_drops_only_what_has_arrived():
    b = board()
    line = Line(b)
    line.send(STATUS, 0.0)
    assert line.discard(0.0) == 5 and line.pending() == 0


def test_line_partial_frame_and_noise():
    b = board()
    line = Line(b, gap_s=0.01)
    line.send(STATUS[:4], 0.0)
    line.poll(0.005)
    assert line.pending() == 0 and b.frames_received == 0
    line.poll(0.02)
    assert b.journal[-1].kind == "partial"
    line.send(b"\x00\x0c\x99", 1.0)
    line.poll(1.02)
    assert line.take(2.0, 10) == p.nak(0x0C)


@pytest.mark.parametrize(
    "settings",
    [LineSettings(9600), LineSettings(115200, parity="N"), LineSettings(115200, bytesize=7),
     LineSettings(115200, stopbits=2)],
)
def test_line_with_wrong_settings_gets_no_reply(settings):
    b = board()
    line = Line(b)
    line.settings = settings
    line.send(STATUS, 0.0)
    assert line.pending() == 0 and b.frames_received == 0
    assert b.journal[-1].kind == "ignored" and "cannot be read" in b.journal[-1].note


def test_right_settings_at_another_board_baud():
    b = board(baud=625000)
    line = Line(b)
    line.settings = LineSettings(625000)
    line.send(STATUS, 0.0)
    assert line.take(1.0, 5) == p.ram_reply(b"\x02\x00")


def test_transmission_helpers():
    t = Transmission(b"ab", (1.0, 2.0))
    assert (t.start, t.end) == (1.0, 2.0)


def test_looking_at_the_board_changes_nothing():
    b = board(motion_s=1.0)
    play(b, 3, 0.0)
    assert b.running(5.0) is None and b.config(5.0) == 0x8721  # as it will be by then
    assert b.running(0.5) == 3 and b.config(0.5) == 0x8723  # as it is now
    assert status_low(b, 0.5) == 0x23  # a frame at 0.5 is still in order
    b.advance(2.0)
    assert [e.kind for e in b.journal][-1] == "motion"
    with pytest.raises(ValueError, match="in order"):
        b.receive(STATUS, 1.5)


def test_noise_closed_by_a_gap_after_someone_looked_at_the_board():
    b = board()
    line = Line(b, gap_s=0.01)
    line.send(b"\x00\x0c", 1.0)
    b.config(9.0)
    line.poll(9.0)
    assert line.take(9.0, 8) == p.nak(0x0C)


# -- the 50 ms status refresh ------------------------------------------------------------------


def refreshing(**kwargs) -> SimBoard:
    """The default board's status refresh (50 ms from power-on at t=0), otherwise ideal."""
    kwargs.setdefault("refresh_s", 0.05)
    return board(**kwargs)


def test_the_status_read_shows_the_config_as_of_the_last_50_ms_tick():
    b = refreshing(motion_s=0.3)
    play(b, 3, 1.01)  # between the ticks at 1.00 and 1.05
    assert b.config(1.01) == 0x8723  # the write took effect at once
    assert status_low(b, 1.01) == 0x02  # the read still shows the tick at 1.00: power-on config
    assert status_low(b, 1.049) == 0x02
    assert status_low(b, 1.05) == 0x23  # the tick at 1.05 saw the motion
    assert b.status(1.2) == 0x8723
    # The motion ends at 1.31; the tick at 1.30 was before it, the one at 1.35 after it.
    assert status_low(b, 1.31) == 0x23 and b.running(1.31) is None
    assert status_low(b, 1.349) == 0x23
    assert status_low(b, 1.35) == 0x21
    assert "as of the refresh at 1.350000" in b.journal[-1].note


def test_polls_within_one_refresh_period_return_the_same_stale_value():
    b = refreshing(motion_s=0.1)
    play(b, 1, 0.0)  # at the tick at 0.0 itself: the tick saw the board before the frames
    lows = [status_low(b, t) for t in (0.0, 0.02, 0.049)]
    assert lows == [0x02, 0x02, 0x02]
    assert [status_low(b, t) for t in (0.05, 0.099, 0.1, 0.149, 0.15)] == [0x23, 0x23, 0x21, 0x21, 0x21]


def test_a_motion_end_shows_at_most_one_period_late_whatever_the_phase():
    for k in range(10):
        start = 2.0 + k * 0.0071
        b = refreshing(motion_s=0.2)
        play(b, 0, start)
        t = start + 0.2
        while status_low(b, t) == 0x23:
            t += 0.001
        assert start + 0.2 <= t <= start + 0.2 + 0.05 + 1e-9


def test_the_stop_frame_changes_the_config_at_once_but_the_read_waits_for_the_tick():
    b = refreshing(motion_s=5.0)
    play(b, 1, 0.0)
    assert status_low(b, 0.5) == 0x23
    assert reply(b, STOP, 0.51) == ACK_MOV
    assert b.running(0.51) is None and b.config(0.51) == 0x8721
    assert status_low(b, 0.52) == 0x23  # as of the tick at 0.50
    assert status_low(b, 0.55) == 0x21


def test_refresh_ticks_count_from_power_on():
    b = refreshing(motion_s=1.0, power_on=100.02)
    play(b, 1, 100.03)
    assert status_low(b, 100.069) == 0x02  # ticks at 100.02, 100.07, ...
    assert status_low(b, 100.07) == 0x23


def test_only_the_status_span_is_refresh_delayed():
    # The config word and the program state (RAM 0x0000-0x000B: what the two layouts' status
    # reads look at) are shown as of the last tick; RAM beyond it reads live.
    b = refreshing()
    assert reply(b, p.mov_write(0x0000, b"\x21\x87\x55\x66"), 0.01) == ACK_MOV
    assert reply(b, p.mov_read(0x0000, 4), 0.02) == p.ram_reply(b"\x02\x00\xfd\x03")
    assert reply(b, p.mov_read(0x0001, 2), 0.03) == p.ram_reply(b"\x00\xfd")
    assert reply(b, p.mov_read(0x0000, 4), 0.05) == p.ram_reply(b"\x21\x87\x55\x66")
    assert reply(b, p.mov_write(0x0010, b"\x77"), 0.06) == ACK_MOV
    assert reply(b, p.mov_read(0x0010, 1), 0.07) == p.ram_reply(b"\x77")


def test_refresh_zero_is_live_and_a_negative_period_is_refused():
    b = refreshing(refresh_s=0.0)
    play(b, 1, 0.01)
    assert status_low(b, 0.01) == 0x23
    with pytest.raises(ValueError, match="refresh"):
        SimBoard(refresh_s=-0.05)


def test_the_default_board_refreshes_every_50_ms():
    assert SimBoard().refresh_s == 0.05
    assert parse_query("").refresh_s == 0.05
    assert parse_query("refresh_ms=20").board().refresh_s == pytest.approx(0.02)
    assert parse_query("refresh_ms=0").board().refresh_s == 0.0
    with pytest.raises(ValueError, match="refresh_ms"):
        parse_query("refresh_ms=-1")
    assert "status every 50 ms" in parse_query("").describe()


# -- the return-address stack ------------------------------------------------------------------


def test_a_call_re_sent_without_a_stop_frame_pushes_a_second_return_address():
    seen = []
    b = board(on_entry=seen.append)
    assert reply(b, STOP, 0.0) == ACK_MOV
    assert reply(b, p.play_frame(3).data, 0.0) == ACK_CALL
    assert b.stack_depth == 1 and b.stack_faults == 0
    assert reply(b, p.play_frame(3).data, 0.1) == ACK_CALL  # still ACKed: the board gives no sign
    assert b.stack_depth == 2 and b.stack_faults == 1 and b.armed == 3
    stack = [e for e in b.journal if e.kind == "stack"]
    assert len(stack) == 1 and stack[0].at == 0.1 and stack[0].number == 3
    assert "second return address pushed: CALL re-sent without a stop frame" in stack[0].note
    assert [e.kind for e in seen][-2:] == ["frame", "stack"]  # after the frame that caused it
    assert "stack: second return address pushed" in stack[0].line()
    reply(b, p.play_frame(4).data, 0.2)
    assert b.stack_faults == 2


def test_the_stop_frame_empties_the_return_stack():
    b = board(motion_s=0.1)
    for i in range(5):
        play(b, i, float(i))
    assert b.stack_faults == 0 and b.stack_depth == 1  # the last play's CALL
    assert reply(b, STOP, 9.0) == ACK_MOV
    assert b.stack_depth == 0 and "return stack (1) emptied" in b.journal[-1].note
    reply(b, p.play_frame(1).data, 9.1)
    assert b.stack_depth == 1 and b.stack_faults == 0


def test_a_motion_that_ended_does_not_allow_a_call_without_a_stop():
    b = board(motion_s=0.1)
    play(b, 1, 0.0)
    assert b.running(1.0) is None
    reply(b, p.play_frame(2).data, 1.0)
    reply(b, RESTORE, 1.0)
    assert b.stack_faults == 1


@pytest.mark.parametrize("kind", ["drop", "nak"])
def test_a_call_the_board_never_executed_pushes_nothing(kind):
    b = board(faults=FaultPlan.parse({kind: "2"}))
    reply(b, STOP, 0.0)
    reply(b, p.play_frame(3).data, 0.0)  # frame 2: hit, not executed
    reply(b, p.play_frame(3).data, 0.0)
    assert b.stack_depth == 1 and b.stack_faults == 0


# -- the journal reads frames with the board's own layout (issue 21, item 7's follow-up) ----------


def _journal_note(layout, frame: bytes, how: str) -> str:
    """The note of a frame the board did not carry out: never arrived (a drop) or came while
    the board was still replying (ignored)."""
    faults = FaultPlan({"drop": Trigger(every=1)}) if how == "drop" else FaultPlan()
    board = SimBoard(layout=layout, faults=faults, power_on_config=0x821B)
    if how == "ignored":
        board.receive(p.sync_frame().data, 1.0)  # its ACK is on the wire until ~1.0006
        board.receive(frame, 1.0003, first=1.0002)
    else:
        board.receive(frame, 1.0)
    entry = next(e for e in board.journal if e.data == frame)
    return entry.note


@pytest.mark.parametrize("how", ["drop", "ignored"])
@pytest.mark.parametrize("layout", [SEED, HTH4_22], ids=lambda layout: layout.name)
def test_the_journal_names_frames_by_the_boards_own_layout(layout, how):
    sequence = layout.play_sequence(5, 0x821B)
    call, restore = sequence[-2].data, sequence[-1].data
    assert _journal_note(layout, call, how).startswith(f"CALL 0x{layout.slot_address(5):06x}: motion 5")
    resumed = "restore status" if layout is SEED else "resume: config"
    assert resumed in _journal_note(layout, restore, how)
    other = (HTH4_22 if layout is SEED else SEED).play_frame(5).data  # another layout's slot: said so
    assert f"not a motion slot of the {layout.name} layout" in _journal_note(layout, other, how)


# -- hold: the client's OS or adapter holds a written frame (issue 21, item 2) -------------------


def test_a_held_frame_reaches_the_board_hold_ms_after_the_write_and_what_follows_waits_behind_it():
    b = board(faults=FaultPlan.parse({"hold": "2"}, hold_s=0.03), wire=True, reply_delay_s=0.0002)
    line = Line(b)
    bt = b.byte_time
    line.send(STOP, 1.0)  # write 1: not held
    assert b.journal[-1].kind == "frame" and b.journal[-1].at == pytest.approx(1.0 + len(STOP) * bt)
    assert line.take(1.05, 10) == ACK_MOV
    line.send(p.play_frame(3).data, 1.1)  # write 2: held 30 ms, taken then
    assert [e.kind for e in list(b.journal)[-2:]] == ["held", "frame"]
    assert "held 30 ms" in b.journal[-2].note and b.journal[-1].at == pytest.approx(1.13 + 7 * bt)
    assert line.available(1.13) == 0 and line.available(1.14) == 4  # its answer: after the hold
    line.send(RESTORE, 1.1)  # written at once after it: on the wire behind it (and not answered,
    assert b.journal[-1].kind == "ignored"  # the board still replying: a client must wait)
    assert b.journal[-1].at == pytest.approx(1.13 + 16 * bt)


def test_hold_is_counted_over_the_writes_faults_on_names_and_its_time_is_checked():
    plan = FaultPlan.parse({"hold": "1"}, on=frozenset({"restore"}), hold_s=0.02)
    b = board(faults=plan)
    assert [b.held_s(frame) for frame in (STOP, p.play_frame(3).data, RESTORE, STATUS)] == [0, 0, 0.02, 0]
    assert parse_query("hold=1&hold_ms=25").faults.hold_s == pytest.approx(0.025)
    assert parse_query("hold=1").faults.hold_s == pytest.approx(0.04)
    with pytest.raises(ValueError, match="hold_ms"):
        parse_query("hold=1&hold_ms=-1")
    assert "hold every frame" in parse_query("hold=1").faults.describe()
