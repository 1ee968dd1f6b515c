"""The linear log reader: the same messages as the mcap library reads, any cut survived, clear errors.

Logs here are written by choreo's Recorder with synthetic frames (bench/log_review.py's generator,
the same one the benchmark uses) or by hand, byte by byte, where a writer would not produce the
case (a compression choreo cannot read). Real `choreo run` logs are in test_review_commands.py.
"""

from __future__ import annotations

import json
import struct
import subprocess
import sys
from pathlib import Path

import pytest
from mcap.reader import NonSeekingReader
from mcap.writer import CompressionType, Writer

from choreo.errors import LogError
from choreo.log.format import decode
from choreo.log.reader import MAGIC, LogReader
from choreo.review.summary import Distribution, summarize

REPO = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(REPO))
from bench.log_review import generate_log  # noqa: E402


@pytest.fixture(scope="module")
def synthetic(tmp_path_factory) -> Path:
    path = tmp_path_factory.mktemp("reader") / "run.mcap"
    generate_log(path, 1500)
    return path


def mcap_messages(path: Path) -> list[tuple[str, int, bytes]]:
    """What the mcap library reads from the file, in file order."""
    with open(path, "rb") as f:
        return [(channel.topic, message.log_time, message.data)
                for _, channel, message in NonSeekingReader(f).iter_messages(log_time_order=False)]


def read_all(path: Path) -> tuple[list[tuple[str, int, bytes]], LogReader]:
    with LogReader(path) as reader:
        return list(reader.messages()), reader


def test_reads_every_message_as_the_mcap_library_does(synthetic):
    ours, reader = read_all(synthetic)
    assert ours == mcap_messages(synthetic)
    assert len(ours) >= 1500
    assert reader.complete and reader.footer and reader.cut is None
    assert reader.run_info["show"] == "bench" and reader.run_info["baud"] == "115200"
    assert reader.result["outcome"] == "done"
    assert reader.show_source().startswith(b"version: 1")
    assert {c.topic for c in reader.channels.values()} == {"/rcb4/tx", "/rcb4/rx", "/choreo/step", "/choreo/log",
                                                                   "/choreo/clock", "/choreo/command"}


def test_topic_filter_and_a_second_pass(synthetic):
    with LogReader(synthetic) as reader:
        rx = list(reader.messages(["/rcb4/rx"]))
        everything = list(reader.messages())
    assert rx and {t for t, _, _ in rx} == {"/rcb4/rx"}
    assert rx == [m for m in everything if m[0] == "/rcb4/rx"]


def test_a_log_cut_anywhere_yields_a_prefix_and_says_where(synthetic, tmp_path):
    full = mcap_messages(synthetic)
    data = synthetic.read_bytes()
    cut_file = tmp_path / "cut.mcap"
    previous = 0
    header_end = len(MAGIC) + 9 + struct.unpack_from("<Q", data, len(MAGIC) + 1)[0]
    offsets = list(range(0, len(data), 997)) + [len(data) - 1, len(data) - 30, header_end, header_end + 1]
    for offset in sorted(offsets):
        cut_file.write_bytes(data[:offset])
        if offset < header_end:  # not even a header: not a cut log, not a log at all
            with pytest.raises(LogError, match="not an MCAP file"):
                LogReader(cut_file)
            continue
        messages, reader = read_all(cut_file)
        assert messages == full[:len(messages)], offset
        assert reader.cut is not None and not reader.complete, offset
        assert reader.cut.offset <= offset and reader.cut.size == offset
        assert len(messages) >= previous  # more file, never fewer messages
        previous = len(messages)
    assert previous > 0.9 * len(full)


def test_a_cut_chunk_gives_up_its_whole_messages(tmp_path):
    """A chunk cut short by a kill still holds whole messages: they are read, not thrown away."""
    path = tmp_path / "one-chunk.mcap"
    with open(path, "wb") as f:
        writer = Writer(f, chunk_size=1 << 20, compression=CompressionType.NONE)
        writer.start()
        schema = writer.register_schema("choreo.Tx", "jsonschema", b"{}")
        channel = writer.register_channel("/rcb4/tx", "json", schema)
        for seq in range(1, 101):
            writer.add_message(channel, log_time=seq, publish_time=seq,
                               data=json.dumps({"seq": seq, "kind": "status"}).encode())
        writer.finish()
    data = path.read_bytes()
    chunk_at = data.index(bytes((0x06,)), len(MAGIC) + 9)  # after the header record
    (length,) = struct.unpack_from("<Q", data, chunk_at + 1)
    path.write_bytes(data[:chunk_at + 9 + length // 2])
    messages, reader = read_all(path)
    assert 40 <= len(messages) < 100
    assert [decode(d)["seq"] for _, _, d in messages] == list(range(1, len(messages) + 1))
    assert "inside a chunk" in reader.cut.reason and "whole messages read" in reader.cut.reason


def test_summary_of_a_cut_log_counts_what_survived(synthetic, tmp_path):
    data = synthetic.read_bytes()
    cut_file = tmp_path / "cut.mcap"
    cut_file.write_bytes(data[:len(data) // 2])
    summary = summarize(cut_file)
    whole = summarize(synthetic)
    assert not summary.complete and summary.cut is not None and summary.result is None
    assert 0 < summary.messages < whole.messages
    assert 0 < summary.frames_sent < whole.frames_sent
    assert whole.complete and whole.unanswered == 0


def test_lz4_chunks_are_read(tmp_path):
    pytest.importorskip("lz4")
    path = tmp_path / "lz4.mcap"
    with open(path, "wb") as f:
        writer = Writer(f, chunk_size=512, compression=CompressionType.LZ4)
        writer.start()
        channel = writer.register_channel("/rcb4/rx", "json", writer.register_schema("choreo.Rx", "jsonschema", b"{}"))
        for seq in range(1, 200):
            writer.add_message(channel, log_time=seq, publish_time=seq, data=b'{"seq": %d}' % seq)
        writer.finish()
    messages, reader = read_all(path)
    assert [decode(d)["seq"] for _, _, d in messages] == list(range(1, 200))
    assert reader.footer


def _record(opcode: int, body: bytes) -> bytes:
    return struct.pack("<BQ", opcode, len(body)) + body


def _string(text: str) -> bytes:
    return struct.pack("<I", len(text)) + text.encode()


def test_a_compression_it_cannot_read_is_a_clear_log_error(tmp_path):
    records = b"\x00" * 16
    chunk = struct.pack("<QQQI", 0, 0, 64, 0) + _string("brotli") + struct.pack("<Q", len(records)) + records
    path = tmp_path / "odd.mcap"
    path.write_bytes(MAGIC + _record(0x01, _string("") + _string("x")) + _record(0x06, chunk))
    with LogReader(path) as reader, pytest.raises(LogError, match=r"compression 'brotli'.*lz4 and zstd"):
        list(reader.messages())


def test_not_mcap_missing_and_empty_files(tmp_path):
    text = tmp_path / "show.yaml"
    text.write_text("version: 1\n")
    with pytest.raises(LogError, match=r"^log .*show.yaml: not an MCAP file"):
        LogReader(text)
    with pytest.raises(LogError, match=r"nope.mcap: cannot read the run log: No such file"):
        LogReader(tmp_path / "nope.mcap")
    empty = tmp_path / "empty.mcap"
    empty.write_bytes(b"")
    with pytest.raises(LogError, match=r"^log .*empty.mcap: not an MCAP file \(empty\)$"):
        LogReader(empty)
    short = tmp_path / "short.mcap"
    for data in (MAGIC[:5], MAGIC, MAGIC + b"\x01\x10"):
        short.write_bytes(data)
        with pytest.raises(LogError, match=rf"not an MCAP file \(only {len(data)} bytes: too short"):
            LogReader(short)
    short.write_bytes(MAGIC + _record(0x06, b"\x00" * 40))
    with pytest.raises(LogError, match="not followed by a header record"):
        LogReader(short)


def test_empty_and_short_files_are_exit_2_with_one_line(tmp_path, capsys):
    from choreo.cli import main

    empty = tmp_path / "empty.mcap"
    empty.write_bytes(b"")
    for command in ("summary", "frames", "timeline"):
        assert main(["log", command, str(empty)]) == 2
        captured = capsys.readouterr()
        assert captured.out == "" and captured.err == f"log {empty}: not an MCAP file (empty)\n"


def test_a_header_and_nothing_else_is_a_cut_log(synthetic, tmp_path, capsys):
    """A valid header cut right after it is a run killed early: reviewed, exit 0."""
    from choreo.cli import main

    data = synthetic.read_bytes()
    header_end = len(MAGIC) + 9 + struct.unpack_from("<Q", data, len(MAGIC) + 1)[0]
    path = tmp_path / "header.mcap"
    path.write_bytes(data[:header_end])
    assert main(["log", "summary", str(path)]) == 0
    assert "UNFINISHED" in capsys.readouterr().out


def _damage(data: bytes) -> tuple[bytes, int]:
    """The reviewer's case: an ACK's bytes changed inside a chunk (04 00 06 0a -> 04 00 06 15)."""
    at = data.index(b'"hex":"04 00 06 0a"', len(data) // 3)
    return data[:at] + b'"hex":"04 00 06 15"' + data[at + len(b'"hex":"04 00 06 0a"'):], at


def test_a_damaged_chunk_ends_the_read_there_and_says_which(synthetic, tmp_path):
    data, at = _damage(synthetic.read_bytes())
    path = tmp_path / "damaged.mcap"
    path.write_bytes(data)
    # mcap's own reader refuses it
    with open(path, "rb") as f, pytest.raises(Exception, match="(?i)crc validation failed"):
        list(NonSeekingReader(f, validate_crcs=True).iter_messages())
    full = mcap_messages(synthetic)
    messages, reader = read_all(path)
    assert 0 < len(messages) < len(full) and messages == full[:len(messages)]
    assert b'"04 00 06 15"' not in b"".join(d for _, _, d in messages)  # nothing from the bad chunk
    cut = reader.cut
    assert cut is not None and cut.damaged and cut.state == "damaged" and not reader.complete
    assert cut.offset < at < cut.offset + 64 * 1024 + 100
    assert f"the chunk at byte {cut.offset:,} is damaged (its CRC is 0x" in str(cut)
    whole, damaged = summarize(synthetic), summarize(path)
    assert damaged.replies["ack"] < whole.replies["ack"]


def test_summary_of_a_damaged_log_is_exit_0_and_says_damaged(synthetic, tmp_path, capsys):
    from choreo.cli import main

    path = tmp_path / "damaged.mcap"
    path.write_bytes(_damage(synthetic.read_bytes())[0])
    assert main(["log", "summary", str(path)]) == 0
    out = capsys.readouterr().out
    first = out.splitlines()[0]
    assert "(complete)" not in first and "(DAMAGED: the chunk at byte " in first
    assert "outcome   unknown" in out
    assert main(["log", "frames", str(path)]) == 0
    assert capsys.readouterr().out.splitlines()[-1].startswith("log damaged: the chunk at byte")


def test_a_chunk_without_a_crc_is_not_checked(tmp_path):
    """CRC 0 means the writer computed none (the spec's rule): not damage."""
    path = tmp_path / "nocrc.mcap"
    records = _record(0x03, struct.pack("<H", 1) + _string("choreo.Tx") + _string("jsonschema") + _string(""))
    records += _record(0x04, struct.pack("<HH", 1, 1) + _string("/rcb4/tx") + _string("json") + b"\0\0\0\0")
    records += _record(0x05, struct.pack("<HIQQ", 1, 0, 5, 5) + b'{"seq":1}')
    chunk = struct.pack("<QQQI", 5, 5, len(records), 0) + _string("") + struct.pack("<Q", len(records)) + records
    path.write_bytes(MAGIC + _record(0x01, _string("") + _string("x")) + _record(0x06, chunk))
    messages, reader = read_all(path)
    assert messages == [("/rcb4/tx", 5, b'{"seq":1}')] and not reader.cut.damaged


def test_decode_takes_what_json_takes():
    assert decode(b'{"seq":1,"kind":"ack","executing":null}') == {"seq": 1, "kind": "ack", "executing": None}
    assert decode(b' {"a": [1, 2.5]} ') == {"a": [1, 2.5]}
    with pytest.raises(ValueError):
        decode(b"{not json")


def test_distribution_quantiles_are_nearest_rank_to_the_microsecond():
    values = [0.4123, 1.0, 1.0, 2.5, 7.25, 0.001, 3.3333]
    dist = Distribution()
    for v in values:
        dist.add(v)
    ordered = sorted(round(v, 3) for v in values)
    assert len(dist) == 7 and dist.min == 0.001 and dist.max == 7.25
    assert dist.median == ordered[3] and dist.quantile(0.99) == ordered[-1]
    assert dist.quantile(0.01) == ordered[0] and dist.above(1.0) == 3
    assert Distribution().median is None


def test_frames_into_a_closed_pipe_ends_quietly(synthetic):
    """`choreo log frames LOG | head -3`: three lines, exit 0, nothing on stderr."""
    done = subprocess.run(
        f"'{sys.executable}' -m choreo log frames '{synthetic}' | head -3; exit ${{PIPESTATUS[0]}}",
        shell=True, executable="/bin/bash", capture_output=True, text=True, cwd=REPO)
    assert done.returncode == 0, done.stderr
    assert done.stderr == ""
    assert len(done.stdout.splitlines()) == 3


def test_a_message_choreo_did_not_write_is_one_clear_line(tmp_path, capsys):
    from choreo.cli import main

    path = tmp_path / "foreign.mcap"
    with open(path, "wb") as f:
        writer = Writer(f)
        writer.start()
        camera = writer.register_channel("/camera", "protobuf", writer.register_schema("x.Image", "protobuf", b""))
        tx = writer.register_channel("/rcb4/tx", "json", writer.register_schema("choreo.Tx", "jsonschema", b"{}"))
        writer.add_message(camera, log_time=1, publish_time=1, data=b"\x00\xff binary")
        writer.add_message(tx, log_time=2, publish_time=2, data=b'{"seq": 1}')
        writer.finish()
    assert main(["log", "summary", str(path)]) == 2
    err = capsys.readouterr().err
    assert err == (f"log {path}: message 2 on /rcb4/tx is not a choreo /rcb4/tx message "
                   "(missing field 'kind'): was this log written by choreo run?\n")
    # frames and export show what is there, field by field, and leave the other topics alone
    assert main(["log", "frames", str(path)]) == 0
    assert "not a frame" in capsys.readouterr().out


def _log_with_stale_replies(path: Path) -> None:
    """A run log, written by choreo's Recorder, whose second and fourth replies came after late
    replies to earlier frames (one, then two) that the link set aside."""
    from dataclasses import replace

    from choreo.wire import protocol
    from choreo.events import RxEvent, Tag, TxEvent
    from choreo.log.recorder import Recorder, RunInfo

    start = 1_790_000_000_000_000_000
    recorder = Recorder(path, RunInfo("s.yaml", "stale", b"version: 1\n", "sim://", 115200, start))
    ack = protocol.Reply(protocol.ReplyKind.ACK, protocol.ack(protocol.CMD_MOV))
    status = protocol.ram_reply(bytes((0x23, 0x87)))
    stale = [b"", protocol.ack(protocol.CMD_MOV), b"", protocol.ack(protocol.CMD_CALL) + status]
    for seq, late in enumerate(stale, 1):
        frame = protocol.play_sequence(3)[0]
        t = start + seq * 10_000_000
        recorder.on_tx(TxEvent(seq, frame, 1, t, Tag(0, None)))
        recorder.on_rx(RxEvent(seq, frame, replace(ack, stale=late), t + 1_000_000, 0.001, Tag(0, None)))
    recorder.close({"outcome": "done"})


def test_stale_replies_are_exported_shown_and_counted(tmp_path, capsys):
    import csv
    import io

    from choreo.cli import main

    path = tmp_path / "stale.mcap"
    _log_with_stale_replies(path)
    assert main(["log", "export", str(path), "--csv", "-", "--json", str(tmp_path / "f.json")]) == 0
    rows = list(csv.DictReader(io.StringIO(capsys.readouterr().out)))
    records = json.loads((tmp_path / "f.json").read_text())
    assert [r["stale"] for r in rows] == ["", "04 00 06 0a", "", "04 0c 06 16 05 00 23 87 af"]
    assert [r["stale"] for r in records] == [None, "04 00 06 0a", None, "04 0c 06 16 05 00 23 87 af"]
    assert main(["log", "frames", str(path)]) == 0
    rx = [line for line in capsys.readouterr().out.splitlines() if "  rx  " in line]
    assert rx[0].endswith("ACK")
    assert rx[1].endswith("ACK (set aside a late reply: 04 00 06 0a)")
    assert rx[3].endswith("ACK (set aside 2 late replies: 04 0c 06 16, 05 00 23 87 af)")
    assert main(["log", "summary", str(path)]) == 0
    replies = next(line for line in capsys.readouterr().out.splitlines() if line.startswith("replies"))
    assert replies.startswith("replies   ACK 4, NAK 0, status 0, timeout 0, invalid 0; stale 3 ")


def test_stale_bytes_that_are_not_replies_stay_together():
    from choreo.review.summary import stale_replies

    assert stale_replies(None) == [] and stale_replies("") == []
    assert stale_replies("04 00 06 0a 05 00 23 87 af") == ["04 00 06 0a", "05 00 23 87 af"]
    assert stale_replies("ff 00 01") == ["ff 00 01"]  # noise waiting on the line, as logged
    assert stale_replies("04 00 06 0a 02 99") == ["04 00 06 0a", "02 99"]


def _log_with_late_plays(path: Path) -> None:
    """Four plays as `choreo run` logs them: on time; late at its start and retried (late once);
    on time but delayed by its retries (late, as the runner counts it, with its warning line);
    on time with a slow first frame but no retry (not late); then one aborted by a second Ctrl-C."""
    from choreo.wire import protocol
    from choreo.events import RxEvent, Tag, TxEvent
    from choreo.log.format import WARNING
    from choreo.log.recorder import Recorder, RunInfo
    from choreo.events import StepEvent
    from choreo.show.model import PlannedStep, StepKind

    start = 1_790_000_000_000_000_000
    recorder = Recorder(path, RunInfo("s.yaml", "late", b"version: 1\n", "sim://", 115200, start))
    ack = protocol.Reply(protocol.ReplyKind.ACK, protocol.ack(protocol.CMD_MOV))
    nak = protocol.Reply(protocol.ReplyKind.NAK, protocol.nak(protocol.CMD_MOV), error="NAK")
    seq = 0
    # (start late_ms, tries, end late_ms, outcome)
    plays = [(0.2, 1, 0.3, "ok"), (5.0, 2, 30.0, "ok"), (0.2, 2, 25.0, "ok"), (0.2, 1, 1.5, "ok"),
             (0.1, 1, 0.0, "aborted")]
    for index, (late_start, tries, late_end, outcome) in enumerate(plays):
        step = PlannedStep(index, f"steps[{index}]", StepKind.PLAY, motion=3)
        t = start + (index + 1) * 100_000_000
        recorder.on_step(StepEvent(step, "start", index * 0.1, index * 0.1, t, late_start))
        for attempt in range(1, tries + 1):
            seq += 1
            frame = protocol.play_sequence(3)[0]
            recorder.on_tx(TxEvent(seq, frame, attempt, t + seq, Tag(index, None)))
            recorder.on_rx(RxEvent(seq, frame, ack if attempt == tries else nak, t + seq + 1, 0.001, Tag(index, None)))
        if tries > 1 and late_end > 1:
            recorder.on_log(WARNING, f"step {index}: motion 3 started {late_end:.1f} ms late ({tries} tries)", t + 50)
        recorder.on_step(StepEvent(step, "end", index * 0.1, index * 0.1 + 0.01, t + 60, late_end, outcome))
    recorder.close({"outcome": "aborted"})


def test_a_play_its_retries_made_late_is_late_once(tmp_path):
    path = tmp_path / "late.mcap"
    _log_with_late_plays(path)
    summary = summarize(path)
    assert (summary.steps_late, summary.steps_late_by_retries) == (2, 1)
    assert len(summary.lateness) == 5 and summary.lateness.above(1.0) == 1  # cue lateness: the starts
    assert (summary.steps_done, summary.steps_aborted, summary.steps_unfinished) == (4, 1, 0)
    from choreo.review.summarytext import render

    steps = next(line for line in render(summary) if line.startswith("steps"))
    assert steps == "steps     5 run: 4 done, 2 late (1 by retries), 0 failed, 1 aborted"
