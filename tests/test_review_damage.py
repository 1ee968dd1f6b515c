"""Review and replay under attack (issue 9, items 9-11, 14, 17): damaged head records, MCAP files
of other tools, named pipes, replays in the same second, clean logs that replay clean, speeds."""

from __future__ import annotations

import os
import struct
from pathlib import Path

import pytest

from choreo.cli import main
from choreo.log.reader import LogReader
from choreo.run.replay import Difference, _polls_at_motion_ends, replay
from runlog import vmain, write_show

MAGIC = b"\x89MCAP0\r\n"
COMMANDS = (["log", "summary"], ["log", "frames"], ["log", "timeline"], ["log", "export", "--csv", "-"])

SHOW = """
    version: 1
    name: damage
    motions:
      short: {number: 2, duration: 0.1}
    steps:
      - repeat: 4
        steps:
          - play: short
          - wait: done
"""


@pytest.fixture(scope="module")
def run_log(tmp_path_factory) -> Path:
    directory = tmp_path_factory.mktemp("damage")
    show = write_show(directory, SHOW)
    path = directory / "run.mcap"
    assert vmain(["run", str(show), "--log", str(path), "-q"]) == 0
    return path


def head_records(data: bytes) -> list[tuple[int, int, int]]:
    """(offset, opcode, length) of every record before the first chunk."""
    out, pos = [], len(MAGIC)
    while pos + 9 <= len(data):
        opcode, length = struct.unpack_from("<BQ", data, pos)
        if opcode == 0x06:
            break
        out.append((pos, opcode, length))
        pos += 9 + length
    return out


def review_all(path: Path, capsys) -> list[tuple[list[str], int, str]]:
    results = []
    for command in COMMANDS:
        code = main([*command[:2], str(path), *command[2:]])
        err = capsys.readouterr().err
        results.append((command, code, err))
    return results


def mutations(data: bytes):
    records = head_records(data)
    for offset, opcode, _length in records:
        for value in (0, 1, 2**40):
            mutated = bytearray(data)
            struct.pack_into("<Q", mutated, offset + 1, value)
            yield f"length {value} of record 0x{opcode:02x} at {offset}", bytes(mutated)
    end = records[-1][0] + 9 + records[-1][2]
    for index in range(len(MAGIC) + 9, end, 11):  # one flipped bit every 11 bytes of the head
        mutated = bytearray(data)
        mutated[index] ^= 0x10
        yield f"bit flipped at {index}", bytes(mutated)


def test_a_damaged_head_record_is_reviewed_as_far_as_it_goes_or_refused_in_one_line(run_log, tmp_path, capsys):
    data = run_log.read_bytes()
    path = tmp_path / "damaged.mcap"
    checked = 0
    for what, mutated in mutations(data):
        path.write_bytes(mutated)
        for command, code, err in review_all(path, capsys):
            assert code in (0, 2), (what, command, err)
            if code == 2:
                assert len(err.strip().splitlines()) == 1, (what, command, err)
        checked += 1
    assert checked > 20


def test_a_metadata_record_of_length_zero_says_damaged_and_where(run_log, tmp_path, capsys):
    data = bytearray(run_log.read_bytes())
    offset = next(o for o, opcode, _ in head_records(bytes(data)) if opcode == 0x0C)  # metadata
    struct.pack_into("<Q", data, offset + 1, 0)
    path = tmp_path / "metadata0.mcap"
    path.write_bytes(bytes(data))
    assert main(["log", "summary", str(path)]) == 0
    out = capsys.readouterr().out
    assert "damaged" in out.lower() and f"byte {offset:,}" in out


def test_a_damaged_header_record_is_exit_2_in_one_line(run_log, tmp_path, capsys):
    data = bytearray(run_log.read_bytes())
    struct.pack_into("<Q", data, len(MAGIC) + 1, 1)  # the header's length: 1 byte
    path = tmp_path / "header.mcap"
    path.write_bytes(bytes(data))
    for command, code, err in review_all(path, capsys):
        assert code == 2 and len(err.strip().splitlines()) == 1, (command, err)


def test_an_mcap_of_another_tool_is_not_a_choreo_log(tmp_path, capsys):
    from mcap.writer import Writer

    path = tmp_path / "camera.mcap"
    with open(path, "wb") as f:
        writer = Writer(f)
        writer.start(profile="ros2", library="camera-recorder")
        channel = writer.register_channel("/camera/image", "cdr",
                                          writer.register_schema("sensor_msgs/Image", "ros2msg", b"x"))
        for n in range(3):
            writer.add_message(channel, log_time=n, publish_time=n, data=b"\x00\x01")
        writer.finish()
    for command, code, err in review_all(path, capsys):
        assert code == 2, command
        assert err.strip().endswith("choreo reviews the .mcap files `choreo run` writes"), err
        assert "not a choreo log" in err and "/camera/image" in err
    assert vmain(["replay", str(path), "--log", str(tmp_path / "r.mcap")]) == 2
    assert "not a choreo log" in capsys.readouterr().err


@pytest.mark.skipif(not hasattr(os, "mkfifo"), reason="no named pipes here")
def test_a_named_pipe_given_as_a_log_is_refused_at_once(tmp_path, capsys):
    fifo = tmp_path / "run.mcap"
    os.mkfifo(fifo)
    for _command, code, err in review_all(fifo, capsys):
        assert code == 2 and "not a regular file" in err
    assert vmain(["replay", str(fifo)]) == 2


def test_two_replays_in_the_same_second_get_two_logs(run_log, tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    from datetime import datetime, timezone

    import choreo.log.recorder as record
    import choreo.run.replay as replaying

    fixed = datetime(2026, 11, 23, 6, 0, 0, tzinfo=timezone.utc)
    real = record.default_log_path
    monkeypatch.setattr(replaying, "default_log_path",  # the name replay reads (imported at module level)
                        lambda name, directory="runs", now=None: real(name, directory, fixed))
    first = replay(run_log, speed=20)
    second = replay(run_log, speed=20)
    assert first.log_path != second.log_path
    assert first.log_path.exists() and second.log_path.exists()
    assert second.log_path.name.endswith("-2.mcap")


def test_a_clean_log_replays_clean_with_strict(run_log, tmp_path, capsys):
    # Motions of 0.1 s polled every 50 ms: polls fall right on the motions' ends, where the
    # board's status refresh (its phase unknown to the log) decides the answer.
    for attempt in range(3):
        new = tmp_path / f"replay{attempt}.mcap"
        assert vmain(["replay", str(run_log), "--strict", "--log", str(new)]) == 0, capsys.readouterr()


def test_polls_next_to_a_motions_end_are_known_from_the_recording(run_log):
    with LogReader(run_log) as reader:
        edges = _polls_at_motion_ends(reader)
        statuses = []
        for _topic, _, data in reader.messages(("/rcb4/rx",)):
            message = __import__("json").loads(data)
            if isinstance(message.get("executing"), bool):
                statuses.append((message["seq"], message.get("executing")))
    changes = [i for i in range(1, len(statuses)) if statuses[i][1] != statuses[i - 1][1]]
    assert changes and edges == {statuses[i][0] for c in changes for i in (c - 1, c)}


def test_only_a_status_difference_at_a_motions_end_is_excused():
    from choreo.log.format import RxRecord

    status = lambda executing: RxRecord(7, "status", executing=executing)  # noqa: E731
    at_end = Difference(7, 1, "status", 1.0, status(False), status(True), at_end=True)
    away = Difference(9, 1, "status", 1.5, status(False), status(True), at_end=False)
    nak = Difference(11, 1, "status", 2.0, RxRecord(11, "nak"), status(True), at_end=True)
    assert at_end.excused and not away.excused and not nak.excused


@pytest.mark.parametrize("speed", ["0.001", "1e-9", "0"])
def test_a_replay_speed_too_slow_to_end_is_refused(run_log, speed, capsys, tmp_path):
    assert vmain(["replay", str(run_log), "--speed", speed, "--log", str(tmp_path / "r.mcap")]) == 2
    assert "give a speed from 0.01 to 1000" in capsys.readouterr().err
    assert not (tmp_path / "r.mcap").exists()


def test_a_replay_of_an_hth4_run_uses_an_hth4_simulator(tmp_path, capsys):
    show = write_show(tmp_path, SHOW)
    log = tmp_path / "hth4.mcap"
    assert vmain(["run", str(show), "--layout", "hth4-2.2", "--log", str(log), "-q"]) == 0
    report = replay(log, speed=5, log_path=tmp_path / "r.mcap")
    assert "layout=hth4-2.2" in report.port
    assert report.board_differences == 0


def _rewritten(source: Path, target: Path, topic: str, key: str, value, metadata: dict | None = None) -> bool:
    """The log again with the first `topic` message's `key` set to `value` (False: no such field)."""
    import json

    from mcap.reader import make_reader
    from mcap.writer import Writer

    with open(source, "rb") as stream:
        reader = make_reader(stream)
        messages = list(reader.iter_messages(log_time_order=False))
        recorded = list(reader.iter_metadata())
        attachments = list(reader.iter_attachments())
    changed = False
    with open(target, "wb") as stream:
        writer = Writer(stream)
        writer.start()
        schemas: dict[int, int] = {}
        channels: dict[int, int] = {}
        for schema, channel, message in messages:
            if channel.id not in channels:
                if schema.id not in schemas:
                    schemas[schema.id] = writer.register_schema(schema.name, schema.encoding, schema.data)
                channels[channel.id] = writer.register_channel(channel.topic, channel.message_encoding,
                                                               schemas[schema.id], channel.metadata)
            data = message.data
            if not changed and channel.topic == topic:
                fields = json.loads(data)
                if key in fields:
                    fields[key] = value
                    data, changed = json.dumps(fields).encode(), True
            writer.add_message(channels[channel.id], message.log_time, data, message.publish_time, message.sequence)
        for attachment in attachments:
            writer.add_attachment(attachment.create_time, attachment.log_time, attachment.name,
                                  attachment.media_type, attachment.data)
        for record in recorded:
            writer.add_metadata(record.name, {**record.metadata, **(metadata or {})} if record.name == "choreo"
                                else dict(record.metadata))
        writer.finish()
    return changed


@pytest.mark.parametrize("topic, key", [
    ("/rcb4/tx", "seq"), ("/rcb4/tx", "motion"), ("/rcb4/tx", "step"), ("/rcb4/rx", "latency_ms"),
    ("/rcb4/rx", "seq"), ("/choreo/step", "actual_s"), ("/choreo/step", "late_ms"), ("/choreo/step", "index"),
    ("/choreo/clock", "show_s"), ("/choreo/clock", "monotonic_ns"),
])
@pytest.mark.parametrize("value", [10**30, -10**30, 1e308, -1e308, float("inf"), float("nan"), [], {}, True, "x"],
                         ids=["huge", "-huge", "1e308", "-1e308", "inf", "nan", "list", "dict", "bool", "text"])
def test_a_field_of_the_wrong_type_or_range_is_one_line_in_every_review(run_log, tmp_path, capsys, topic, key, value):
    """Found by rewriting logs: OverflowError, 'unhashable type' and format errors were tracebacks."""
    hostile = tmp_path / "hostile.mcap"
    assert _rewritten(run_log, hostile, topic, key, value)
    for command, code, err in review_all(hostile, capsys):
        assert code in (0, 2), (command, err)
        assert "Traceback" not in err
        if code == 2:
            assert len(err.strip().splitlines()) == 1, (command, err)


@pytest.mark.parametrize("key", ["start_ns", "baud"])
@pytest.mark.parametrize("value", ["²", "1" * 5000])
def test_a_metadata_number_that_is_no_number_is_not_a_traceback(run_log, tmp_path, capsys, key, value):
    hostile = tmp_path / "hostile.mcap"
    _rewritten(run_log, hostile, "/rcb4/tx", "-", None, {key: value})
    for command, code, err in review_all(hostile, capsys):
        assert code == 0, (command, err)
    assert main(["replay", str(hostile), "--speed", "100", "--log", str(tmp_path / "replay.mcap"), "-q"]) == 0


def _record_ends(data: bytes) -> list[int]:
    """Where each top-level chunk or message record ends (the data section: what a run writes)."""
    ends, pos = [], len(MAGIC)
    while pos + 9 <= len(data):
        opcode, length = struct.unpack_from("<BQ", data, pos)
        pos += 9 + length
        if opcode in (0x05, 0x06):
            ends.append(pos)
    return ends


@pytest.mark.parametrize("into_the_next_head", [0, 1, 5, 7, 8])
def test_a_log_that_grows_while_it_is_read_is_read_as_it_was_when_opened(run_log, tmp_path, into_the_next_head):
    """A run still writing its log: `log timeline` of it said 'message N is not a choreo message
    (read length must be non-negative or -1)' (a record head past the size it was opened with)."""
    data = run_log.read_bytes()
    growing = tmp_path / "growing.mcap"
    ends = _record_ends(data)
    cut = ends[0] + into_the_next_head
    growing.write_bytes(data[:cut])
    with LogReader(growing) as reader:
        with open(growing, "ab") as writer:  # the run writes on after the review opened the log
            writer.write(data[cut:])
        messages = list(reader.messages())
        assert reader.cut is not None and reader.cut.size == cut
    with LogReader(run_log) as whole:
        assert len(messages) <= len(list(whole.messages()))
