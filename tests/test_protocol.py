"""Every byte of the document's frames, and every verdict on a reply."""

from __future__ import annotations

from pathlib import Path

import pytest

from choreo.wire import protocol as p
from choreo.errors import MotionRangeError
from choreo.wire.framewords import describe_frame, describe_reply
from choreo.wire.layouts import SEED

DATA = Path(__file__).parent / "data"


def spec_table() -> dict[int, str]:
    rows = {}
    for line in (DATA / "spec_play_frames.txt").read_text().splitlines():
        if line.strip() and not line.startswith("#"):
            motion, frame = line.split(None, 1)
            rows[int(motion)] = frame.strip()
    return rows


def test_table_has_all_101_rows_of_the_document():
    assert sorted(spec_table()) == list(range(101))


@pytest.mark.parametrize("motion,expected", sorted(spec_table().items()))
def test_play_frame_matches_every_row_of_the_document(motion, expected):
    assert p.play_frame(motion).hex == expected


@pytest.mark.parametrize("motion", range(101, 120))
def test_slots_101_to_119_follow_the_formula(motion):
    address = 0x0BB8 + motion * 0x800
    body = bytes([0x07, 0x0C, address & 0xFF, address >> 8 & 0xFF, address >> 16 & 0xFF, 0x00])
    assert p.play_frame(motion).data == body + bytes([sum(body) & 0xFF])
    assert SEED.slot_of(address) == motion


def test_document_checksums_hold_for_every_row():
    for frame in spec_table().values():
        data = bytes.fromhex(frame)
        assert data[0] == len(data)
        assert p.checksum(data[:-1]) == data[-1]


def test_stop_restore_status_frames_byte_for_byte():
    assert p.stop_frame().hex == "13 00 02 00 00 00 21 87 fd 03 00 00 00 00 00 00 00 00 bd"
    assert p.restore_frame().hex == "09 00 02 00 00 00 23 87 b5"
    assert p.status_frame().hex == "0a 00 20 00 00 00 00 00 02 2c"


def test_play_sequence_is_stop_call_restore():
    kinds = [f.kind for f in p.play_sequence(7)]
    assert kinds == [p.FrameKind.STOP, p.FrameKind.PLAY, p.FrameKind.RESTORE]
    assert p.play_sequence(7)[1].motion == 7


def test_play_sequence_at_every_baud_is_the_seed_layouts_and_carries_the_bauds_code():
    for baud, code in p.BAUD_CODES.items():
        stop, play, restore = p.play_sequence(4, baud)
        assert (stop, play, restore) == SEED.play_sequence(4, baud=baud)
        assert stop.data[6] >> 6 == restore.data[6] >> 6 == code and play == p.play_frame(4)
        assert {stop.motion, restore.motion} == {4}
    with pytest.raises(ValueError, match="baud 9600: the RCB-4 runs at 115200, 625000, 1250000"):
        p.play_sequence(4, 9600)


def test_the_protocol_does_not_import_the_layouts_that_build_on_it():
    import subprocess
    import sys

    code = "import sys, choreo.wire.protocol; print('choreo.wire.layouts' in sys.modules)"
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    assert out.stdout.strip() == "False"


def test_the_bauds_are_spelt_from_the_one_list():
    assert p.BAUDS == (115200, 625000, 1250000) and p.DEFAULT_BAUD in p.BAUDS
    assert p.spell_bauds() == "115200, 625000, 1250000"
    assert p.spell_bauds("or") == "115200, 625000 or 1250000"
    assert p.spell_bauds("and") == "115200, 625000 and 1250000"
    assert p.spell_bauds("or", mark_default=True) == "115200 (default), 625000 or 1250000"
    assert p.spell_bauds(mark_default=True) == "115200 (default), 625000, 1250000"


def test_the_show_schema_offers_the_protocols_bauds():
    """The schema is data for editors, so it spells the list itself: this keeps it the same fact."""
    import json
    from importlib.resources import files

    schema = json.loads(files("choreo").joinpath("schemas/show.schema.json").read_text(encoding="utf-8"))
    baud = schema["$defs"]["robot"]["properties"]["baud"]
    assert tuple(baud["enum"]) == p.BAUDS and baud["default"] == p.DEFAULT_BAUD
    assert p.spell_bauds("or").replace(f"{p.DEFAULT_BAUD}", f"{p.DEFAULT_BAUD} (the RCB-4's default)") \
        in baud["description"]


def test_a_baud_code_names_its_baud_and_a_config_word_takes_one():
    assert [p.baud_of_code(code) for code in range(4)] == [115200, 625000, 1250000, None]
    assert p.with_baud(0x8721, 625000) == 0x8761 and p.with_baud(0x87E1, 115200) == 0x8721
    assert p.check_baud(1250000) == 1250000


def test_kondos_running_rule_wants_a_counter_in_the_slots_and_something_pushed():
    pushed = p.little_endian(0x0B80, 3) + p.little_endian(0x00044B, 3) + bytes((1, 0, 0, 0))
    assert p.in_called_motion(pushed)
    assert not p.in_called_motion(p.little_endian(0x0B7F, 3) + pushed[3:])  # below every slot
    assert not p.in_called_motion(pushed[:3] + bytes(7))  # nothing pushed
    assert p.in_called_motion(pushed[:3] + bytes(4) + b"\x01" + bytes(2))  # the byte after the depth counts


@pytest.mark.parametrize("bad", [-1, 120, 140, 1.5, "3", True, None])
def test_out_of_range_or_non_integer_motion_is_refused(bad):
    with pytest.raises(MotionRangeError, match="0..119"):
        p.play_frame(bad)


def test_acks_are_the_documented_bytes():
    assert p.ack(p.CMD_MOV).hex() == "0400060a"
    assert p.ack(p.CMD_CALL).hex() == "040c0616"


@pytest.mark.parametrize(
    "frame,reply,kind",
    [
        (p.stop_frame(), "04 00 06 0a", p.ReplyKind.ACK),
        (p.play_frame(0), "04 0c 06 16", p.ReplyKind.ACK),
        (p.restore_frame(), "04 00 06 0a", p.ReplyKind.ACK),
        (p.stop_frame(), "04 00 15 19", p.ReplyKind.NAK),
        (p.play_frame(0), "04 0c 15 25", p.ReplyKind.NAK),
        (p.status_frame(), "04 00 15 19", p.ReplyKind.NAK),
        (p.status_frame(), "05 00 23 87 af", p.ReplyKind.STATUS),
        (p.status_frame(), "05 00 21 87 ad", p.ReplyKind.STATUS),
    ],
)
def test_valid_replies(frame, reply, kind):
    assert p.parse_reply(frame, bytes.fromhex(reply)).kind is kind


def test_status_reply_says_executing_only_for_0x23():
    running = p.parse_reply(p.status_frame(), bytes.fromhex("05 00 23 87 af"))
    idle = p.parse_reply(p.status_frame(), bytes.fromhex("05 00 21 87 ad"))
    assert running.executing is True and running.status == 0x8723
    assert idle.executing is False and idle.status == 0x8721


@pytest.mark.parametrize(
    "frame,reply,reason",
    [
        (p.stop_frame(), "", "short reply"),
        (p.stop_frame(), "04 00 06", "short reply"),
        (p.stop_frame(), "04 00 06 0b", "bad checksum"),
        (p.stop_frame(), "05 00 06 0a 15", "5-byte reply"),
        (p.stop_frame(), "04 0c 06 16", "command 0c"),
        (p.play_frame(1), "04 00 06 0a", "command 00"),
        (p.stop_frame(), "04 00 07 0b", "neither ACK"),
        (p.stop_frame(), "05 00 21 87 ad", "5-byte reply to a stop"),
        (p.status_frame(), "05 0c 23 87 bb", "command 0c"),
        (p.status_frame(), "06 00 23 87 00 b0", "6-byte reply"),
        (p.status_frame(), "ff 04 00 06 0a", "size byte"),
        (p.status_frame(), "04 00 06 0a", "an ACK where the status was expected"),
    ],
)
def test_invalid_replies_carry_a_reason(frame, reply, reason):
    verdict = p.parse_reply(frame, bytes.fromhex(reply))
    assert verdict.kind is p.ReplyKind.INVALID
    assert reason in verdict.error


def test_parse_command_reads_what_the_board_reads():
    stop = p.parse_command(p.stop_frame().data)
    assert (stop.move_type, stop.address) == (p.MOV_COM_TO_RAM, 0)
    assert stop.payload[:2] == bytes.fromhex("2187")
    status = p.parse_command(p.status_frame().data)
    assert (status.move_type, status.address, status.count) == (p.MOV_RAM_TO_COM, 0, 2)
    play = p.parse_command(p.play_frame(5).data)
    assert (play.command, play.address, play.condition) == (p.CMD_CALL, 0x0BB8 + 5 * 0x800, 0)
    with pytest.raises(ValueError, match="checksum"):
        p.parse_command(bytes.fromhex("07 0c b8 0b 00 00 d7"))


def test_describe_frames_and_replies_of_the_seed_layout():
    assert describe_frame(p.play_frame(0).data, SEED) == "CALL 0x000bb8: motion 0"
    assert describe_frame(p.stop_frame().data, SEED).endswith("stop and save status")
    assert describe_frame(p.status_frame().data, SEED).endswith("status query")
    assert describe_reply(bytes.fromhex("04 0c 06 16"), p.play_frame(0).data, SEED) == "ACK"
    assert describe_reply(bytes.fromhex("04 00 15 19"), p.stop_frame().data, SEED) == "NAK"
    assert describe_reply(bytes.fromhex("05 00 23 87 af"), p.status_frame().data, SEED) == "status 0x23: executing"


@pytest.mark.parametrize(
    "frame,reply,stale",
    [
        (p.play_frame(1), "04 00 06 0a", True),  # a MOV's ACK while a CALL waits
        (p.stop_frame(), "04 0c 06 16", True),  # a CALL's ACK while a MOV waits
        (p.stop_frame(), "05 00 23 87 af", True),  # a status while a write waits
        (p.status_frame(), "04 00 06 0a", True),  # a write's ACK while a status waits
        (p.status_frame(), "04 00 15 19", False),  # a NAK answers a status query
        (p.stop_frame(), "04 00 06 0a", False),
        (p.play_frame(1), "04 00 06 0b", False),  # not well-formed: invalid, not stale
    ],
)
def test_stale_replies_are_well_formed_answers_to_another_frame(frame, reply, stale):
    assert p.is_stale(frame, bytes.fromhex(reply)) is stale


def test_probe_frames_and_their_answers():
    version = p.version_frame()
    assert version.hex == "03 fd 00"
    answer = p.build_frame(p.CMD_VERSION, b"CB-4 V1.0")
    assert p.parse_reply(version, answer).kind is p.ReplyKind.STATUS
    read = p.read_frame(0x0002, 10)
    assert read.hex == "0a 00 20 00 00 00 02 00 0a 36"  # LAYOUTS.md's 10-byte read at 0x0002
    assert read.reply_sizes == (4, 13)
    data = p.ram_reply(bytes.fromhex("4b0400") + bytes(7))
    assert p.parse_reply(read, data).kind is p.ReplyKind.STATUS
    assert p.parse_reply(read, p.ack(p.CMD_MOV)).kind is p.ReplyKind.INVALID
    assert p.is_stale(read, p.ack(p.CMD_MOV))  # an ACK to a read is a late answer to a write
    assert p.parse_reply(read, p.nak(p.CMD_MOV)).kind is p.ReplyKind.NAK
