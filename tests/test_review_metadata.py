"""A hostile log's `choreo` metadata against the reviews and `log merge` (issue 21, hostile logs):
50 KB names, 100,000 robots or keys, controls in any value. The reader keeps the metadata
bounded in one place (format.kept_metadata): every review and a merge print or copy only that,
with a note of what was left out, and what choreo itself writes is kept whole."""

from __future__ import annotations

from pathlib import Path

import pytest

from choreo.log.format import (NAME_KEPT, ROBOTS_KEPT, SHOW_NAME_KEPT, VALUE_KEPT, ClockRecord, Info, StepRecord,
                               kept_metadata, robot_key)
from choreo.log.reader import LogReader
from choreo.log.recorder import Recorder, RobotInfo, RunInfo
from runlog import vmain
from test_review_damage import _rewritten
from test_review_hostile import T0, S, logged

BIG = "\x1b[2J\u202e" + "N" * 50_000
REVIEWS = (["summary"], ["summary", "--json"], ["frames"], ["timeline"], ["export", "--csv", "-"],
           ["export", "--cues", "--json", "-"])
HOSTILE = {
    "a 50 KB robot name": {"robots": f"left,{BIG},right", robot_key(BIG, "port"): BIG,
                           robot_key(BIG, "layout"): "seed"},
    "100,000 robots": {"robots": ",".join(f"r{i}" for i in range(100_000))},
    "20,000 keys": {f"k{i}": "v" for i in range(20_000)},
    "every value 50 KB": {key: BIG for key in ("show", "show_path", "host", "port", "version", "start_time",
                                               "python", "platform", "show_host", "layout", "baud")},
}
NOTES = {"a 50 KB robot name": "robot names longer than", "100,000 robots": "the log names 100,000 robots",
         "20,000 keys": "keys choreo does not write", "every value 50 KB": "metadata texts longer than"}


def _clocked(recorder: Recorder) -> None:
    for n in range(3):  # clock samples a merge lines the hosts up by
        recorder.on_clock(ClockRecord(n * 0.5, n * S // 2, state="running"), T0 + n * S // 2)
    recorder.on_step_record(StepRecord(0, "play", "start", 0.0), T0)


@pytest.fixture(scope="module")
def plain(tmp_path_factory) -> Path:
    return logged(tmp_path_factory.mktemp("metadata") / "plain.mcap", _clocked)


@pytest.mark.parametrize("kind", list(HOSTILE))
def test_hostile_metadata_is_bounded_escaped_and_noted_in_every_review(plain, tmp_path, capsys, kind):
    # Before: log summary printed a 50 KB name or a 790 KB robot list in one line, --json 1.3 MB
    # of keys, and log frames a layout note for each of 100,000 robots (13 MB).
    log = tmp_path / "hostile.mcap"
    _rewritten(plain, log, "/rcb4/tx", "-", None, HOSTILE[kind])
    for review in REVIEWS:
        capsys.readouterr()
        assert vmain(["log", review[0], str(log), *review[1:]]) == 0, review
        out = capsys.readouterr().out
        assert len(out) < 40_000 and "N" * (VALUE_KEPT + 1) not in out, review
        assert "\x1b" not in out and "\u202e" not in out, review
    assert vmain(["log", "summary", str(log)]) == 0
    assert NOTES[kind] in capsys.readouterr().out


def test_what_choreo_writes_is_kept_whole():
    robots = tuple(RobotInfo(f"r{i:02d}" + "x" * (NAME_KEPT - 3), "/dev/" + "p" * 4000, 115200)
                   for i in range(ROBOTS_KEPT))
    info = RunInfo("/" + "d" * (VALUE_KEPT - 1), "s" * SHOW_NAME_KEPT, b"", "/dev/ttyUSB0", 115200, 10**18,
                   robots=robots, unison=True, show_host="h" * NAME_KEPT)
    written = info.metadata()
    assert kept_metadata("choreo", written) == (written, [])
    merged = {**written, Info.HOSTS: ",".join(f"h{i:02d}" + "y" * 29 for i in range(16)),
              **{f"host.h{i:02d}{'y' * 29}.shift_ns": str(-10**18) for i in range(16)}}
    assert kept_metadata("choreo", merged) == (merged, [])


def test_a_cut_robot_keeps_its_own_keys_and_names_collapse_to_one():
    kept, notes = kept_metadata("choreo", {"robots": f"{'a' * 40},{'a' * 50},b", robot_key("a" * 40, "port"): "p"})
    assert kept["robots"] == f"{'a' * (NAME_KEPT - 1)}\u2026,b"
    assert kept[robot_key("a" * (NAME_KEPT - 1) + "\u2026", "port")] == "p" and len(notes) == 1
    assert kept_metadata("another", {"robot.x.y": "1", "k": "v"}) == ({"robot.x.y": "1", "k": "v"}, [])


def _host(plain: Path, path: Path, host: str, extra: dict) -> Path:
    _rewritten(plain, path, "/rcb4/tx", "-", None, {"show_host": host, **extra})
    return path


def test_a_merge_of_hostile_logs_does_not_amplify(plain, tmp_path, capsys):
    # Before: a 1.2 MB log of 200 keys of 5 KB merged into 2.4 MB (its metadata copied twice).
    junk = {"host": BIG, "port": BIG, **{f"k{i}": "v" * 5000 for i in range(200)}}
    a, b = _host(plain, tmp_path / "a.mcap", "a", junk), _host(plain, tmp_path / "b.mcap", "b", {})
    merged = tmp_path / "m.mcap"
    assert vmain(["log", "merge", str(a), str(b), "-o", str(merged)]) == 0
    assert merged.stat().st_size < (a.stat().st_size + b.stat().st_size) // 2
    with LogReader(merged) as reader:
        assert all(len(record) < 100 for record in reader.metadata.values())
        assert len(reader.run_info[Info.HOST]) <= 64
    capsys.readouterr()
    assert vmain(["log", "summary", str(merged)]) == 0
    assert len(capsys.readouterr().out) < 20_000


def _forged(path: Path, info: dict[str, str], robots: list[str]) -> Path:
    """A log written with the mcap library: `info` as its metadata, then one play sequence's
    frames and replies for each of `robots` (in its messages only)."""
    import json

    from mcap.writer import Writer

    with open(path, "wb") as stream:
        writer = Writer(stream)
        writer.start()
        writer.add_metadata("choreo", info)
        tx, rx = (writer.register_channel(topic, "json", 0) for topic in ("/rcb4/tx", "/rcb4/rx"))
        for n, robot in enumerate(robots):
            for seq, kind in enumerate(("stop", "play", "restore"), 1):
                t = T0 + n * S + seq * 1000
                writer.add_message(tx, t, json.dumps({"seq": seq, "kind": kind, "hex": "04fe0608", "step": 0,
                                                      "motion": 1, "robot": robot}).encode(), t)
                writer.add_message(rx, t + 500, json.dumps({"seq": seq, "kind": "ack", "hex": "04fe0608",
                                                            "robot": robot}).encode(), t + 500)
        writer.finish()
    return path


def test_robot_names_in_messages_are_cut_and_their_count_bounded(tmp_path, capsys):
    # Before: a 50 KB robot name in the frames printed it on every line of log frames (1.2 MB from
    # a 20 KB log), and 20,000 robots named in messages made 20,000 sections of log summary.
    big = _forged(tmp_path / "big.mcap", {"show": "x", "robots": BIG}, [BIG, BIG])
    many = _forged(tmp_path / "many.mcap", {"show": "x"}, [f"r{i}" for i in range(2000)])
    for review in REVIEWS:
        capsys.readouterr()
        assert vmain(["log", review[0], str(big), *review[1:]]) == 0, review
        out = capsys.readouterr().out
        assert "N" * NAME_KEPT not in out and "\x1b" not in out, review
    capsys.readouterr()
    assert vmain(["log", "summary", str(many)]) == 0
    out = capsys.readouterr().out
    assert len(out.splitlines()) < 100 and f"robots past the first {ROBOTS_KEPT}" in out


def test_text_in_a_logs_messages_is_cut_where_it_is_read(plain, tmp_path, capsys):
    # Before: a 50 KB reply error, label or log line (a few bytes compressed) was printed on every
    # line of log frames and every row of an export: 1.2 MB of CSV from a 19 KB log.
    import json

    from mcap.writer import Writer

    from choreo.errors import MESSAGE_CHARS
    from choreo.log.format import RxRecord, TxRecord

    cut = TxRecord.from_json({"seq": 1, "kind": "play", "hex": "07", "label": BIG})
    assert cut.label == BIG[:MESSAGE_CHARS - 1] + "…"
    log = tmp_path / "text.mcap"
    with open(log, "wb") as stream:
        writer = Writer(stream)
        writer.start()
        writer.add_metadata("choreo", {"show": "x"})
        tx, rx, lines = (writer.register_channel(t, "json", 0) for t in ("/rcb4/tx", "/rcb4/rx", "/choreo/log"))
        for seq in range(1, 21):
            writer.add_message(tx, T0 + seq, json.dumps(TxRecord(seq, "play", "070c", label=BIG).to_json()).encode(), 0)
            writer.add_message(rx, T0 + seq, json.dumps(RxRecord(seq, "timeout", error=BIG).to_json()).encode(), 0)
            writer.add_message(lines, T0 + seq, json.dumps({"timestamp": {"sec": 0, "nsec": 0}, "level": 4,
                                                             "message": BIG}).encode(), 0)
        writer.finish()
    for review in REVIEWS:
        capsys.readouterr()
        assert vmain(["log", review[0], str(log), *review[1:]]) == 0, review
        out = capsys.readouterr().out
        assert len(out) < 20 * 3 * 2 * MESSAGE_CHARS and "\x1b" not in out, (review, len(out))


def test_an_attached_show_over_a_shows_size_is_not_read_and_its_name_is_cut(plain, tmp_path, capsys, monkeypatch):
    # Before: the attachment was read whole whatever its size (a gigabyte: memory), and a 50 KB
    # attachment name was printed whole in the timeline's "does not load" line.
    from mcap.writer import Writer

    from choreo.show.read import MAX_BYTES

    def forged(name: str, data: bytes) -> Path:
        path = tmp_path / f"attached{len(data)}.mcap"
        with open(path, "wb") as stream:
            writer = Writer(stream)
            writer.start()
            writer.add_metadata("choreo", {"show": "x"})
            writer.add_attachment(0, 0, name, "application/yaml", data)
            writer.finish()
        return path

    huge, named = forged("show.yaml", b"#" * (MAX_BYTES + 1)), forged("N" * 50_000 + ".yaml", b"version: [")
    monkeypatch.setattr(LogReader, "attachment_data", lambda *a: pytest.fail("an oversized show was read"))
    capsys.readouterr()
    assert vmain(["log", "timeline", str(huge)]) == 0
    assert "over the 256 KiB a show file may be" in capsys.readouterr().out
    monkeypatch.undo()
    from choreo.review.attached import attached_show

    with LogReader(named) as reader:
        problem = attached_show(reader).problem  # the timeline's line, whole as a pipe gets it
    assert problem is not None and "does not load" in problem and len(problem) < 1000, problem


def test_a_log_of_thousands_of_attachments_keeps_a_few_and_finds_its_show(tmp_path):
    # Before: each attachment was looked for in the list of those kept: 20,000 empty attachments
    # (2.6 MB) cost log summary 111 s, 100,000 would cost hours; now 0.2 s.
    from mcap.writer import Writer

    from choreo.log.reader import ATTACHMENTS_KEPT

    path = tmp_path / "attachments.mcap"
    with open(path, "wb") as stream:
        writer = Writer(stream)
        writer.start()
        writer.add_metadata("choreo", {"show": "x"})
        for n in range(2000):
            writer.add_attachment(0, 0, f"a{n}", "text/plain", b"")
        writer.add_attachment(0, 0, "show.yaml", "application/yaml", b"version: 1\nsteps: []\n")
        writer.finish()
    with LogReader(path) as reader:
        list(reader.messages())
        assert len(reader.attachments) == ATTACHMENTS_KEPT + 1
        show = reader.show_attachment()
        assert show is not None and reader.attachment_data(show).startswith(b"version: 1")


def test_a_replay_reads_no_oversized_attached_show_and_attaches_none(tmp_path, capsys, monkeypatch):
    # Before: replay read the attachment whole again (whatever size the log said) to attach it to
    # its own log; the review's read, bounded by a show file's size, is the one it attaches now.
    from choreo.show.read import MAX_BYTES

    log = tmp_path / "big.mcap"
    recorder = Recorder(log, RunInfo("show.yaml", "x", b"#" * (MAX_BYTES + 1), "sim://", 115200, T0))
    _clocked(recorder)
    recorder.close({"outcome": "done"})
    monkeypatch.setattr(LogReader, "attachment_data", lambda *a: pytest.fail("an oversized show was read"))
    replayed = tmp_path / "replayed.mcap"
    assert vmain(["replay", str(log), "--log", str(replayed), "--speed", "100"]) == 0, capsys.readouterr().err
    monkeypatch.undo()
    with LogReader(replayed) as reader:
        attachment = reader.show_attachment()
        assert attachment is None or attachment.size == 0
