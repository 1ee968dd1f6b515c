"""`choreo log export LOG... --parquet DIR` (issue 25, "Many runs, one query"): four typed tables a
run, every row with its run's id; the README's DuckDB query, read out of the README and run over
two real runs' tables; pyarrow missing, a missing folder, hostile logs: one line, exit 2, and no
half-written table left (nor an earlier export spoilt)."""

from __future__ import annotations

import json
import shlex
import sys

import duckdb  # the test extra installs both, as CI does: missing, this file fails rather than skips
import pyarrow as pa
import pyarrow.parquet as pq
import pytest

from choreo.events import Answer, Command, CommandEvent
from choreo.log.format import UNLOGGED, StepRecord
from choreo.log.reader import LogReader
from choreo.log.recorder import Recorder, RunInfo
from choreo.review.export import cue_rows, rows
from choreo.review.parquet import KINDS, RUN_COLUMNS, TABLES
from runlog import REPO, vmain, write_show


# The motion runs 0.5 s on the first night and 1.5 s on the second (the simulator's motion_s): the
# cue after each `wait: done` starts later, and the last cue later still: late more and more.
NIGHTLY = """\
version: 1
motions:
  bow: {number: 2, duration: 0.5}
steps:
  - play: bow
    label: first
  - wait: done
  - play: bow
    at: 1.0
    label: second
  - wait: done
  - play: bow
    at: 2.0
    label: third
"""
S, T0 = 10**9, 10**18


def two_nights(tmp_path) -> list:  # type: ignore[no-untyped-def]
    show = write_show(tmp_path, NIGHTLY)
    (tmp_path / "runs").mkdir()
    logs = []
    for night, motion_s in ((1, 0.5), (2, 1.5)):
        log = tmp_path / "runs" / f"night{night}.mcap"
        assert vmain(["run", str(show), "--port", f"sim://?motion_s={motion_s}", "--log", str(log), "-q"]) == 0
        logs.append(log)
    return logs


def readme_block(kind: str, holding: str) -> str:
    """The README's one code block of `kind` that holds `holding`."""
    blocks = [body for body in doc_blocks("README.md", kind) if holding in body]
    assert len(blocks) == 1, f"README: {len(blocks)} ```{kind} blocks hold {holding!r}"
    return blocks[0]


def doc_blocks(doc: str, kind: str) -> list[str]:
    return [body for info, body in _fenced((REPO / doc).read_text(encoding="utf-8")) if info == kind]


def _fenced(text: str) -> list[tuple[str, str]]:
    parts = text.split("```")
    return [(part.split("\n", 1)[0].strip(), part.split("\n", 1)[1]) for part in parts[1::2]]


def test_the_readmes_query_over_two_exported_runs_finds_the_cue_late_more_and_more(tmp_path, monkeypatch, capsys):
    logs = two_nights(tmp_path)
    (tmp_path / "exports").mkdir()
    monkeypatch.chdir(tmp_path)
    command = next(line for line in readme_block("sh", "--parquet").splitlines() if "--parquet" in line)
    assert vmain(shlex.split(command)[1:]) == 0
    assert capsys.readouterr().err.count("exported ") == 2
    found = duckdb.connect().execute(readme_block("sql", "read_parquet")).fetchall()
    lateness: dict[str, list[float]] = {}
    for log in logs:
        with LogReader(log) as reader:
            for cue in cue_rows(reader):
                lateness.setdefault(cue["number"], []).append(cue["late_ms"])
    assert [row[:3] for row in found] == [("2", "third", 2), ("1", "second", 2)]  # the later, the worse
    for number, _label, _runs, avg_ms, max_ms, more_each_run_ms in found:
        late = lateness[number]
        assert (avg_ms, max_ms) == (pytest.approx(sum(late) / 2, abs=0.1), pytest.approx(max(late), abs=0.1))
        assert more_each_run_ms == pytest.approx(late[1] - late[0], abs=0.1) and more_each_run_ms > 400
    for query in doc_blocks("docs/logs.md", "sql"):  # the other queries the docs give run too
        assert duckdb.connect().execute(query).fetchall()


def test_each_table_is_typed_and_holds_the_rows_of_the_other_exports_with_the_runs_columns(tmp_path, capsys):
    logs = two_nights(tmp_path)
    out = tmp_path / "out"
    out.mkdir()
    assert vmain(["log", "export", str(logs[0]), str(logs[1]), "--parquet", str(out)]) == 0
    assert sorted(p.name for p in out.iterdir()) == sorted(f"night{n}.{k}.parquet" for n in (1, 2) for k in KINDS)
    assert f"exported {logs[0]}: " in capsys.readouterr().err
    with LogReader(logs[1]) as reader:
        frames, cues, start_ns = list(rows(reader)), cue_rows(reader), reader.info.start_ns
        steps = [StepRecord.from_json(json.loads(data)) for _, _, data in reader.messages(("/choreo/step",))]
    tables = {kind: pq.read_table(out / f"night2.{kind}.parquet") for kind in KINDS}
    types = {"int": pa.int64(), "float": pa.float64(), "str": pa.string(), "json": pa.string(), "bool": pa.bool_(),
             "time": pa.timestamp("us", tz="UTC")}
    for kind, table in tables.items():
        assert [(f.name, f.type) for f in table.schema] == [(n, types[t]) for n, t in RUN_COLUMNS + TABLES[kind]]
        run = {name: table.column(name).to_pylist() for name, _ in RUN_COLUMNS}
        assert set(run["run_id"]) <= {f"show@{_iso(start_ns)}"} and set(run["show_name"]) <= {"show"}
        assert set(run["host"]) <= {None}
    run_columns = [name for name, _ in RUN_COLUMNS]
    assert tables["frames"].drop(run_columns).to_pylist() == frames and len(frames) > 20
    assert tables["cues"].drop(run_columns).to_pylist() == cues
    assert tables["steps"].column("index").to_pylist() == [step.index for step in steps]
    assert tables["steps"].column("late_ms").to_pylist() == [step.late_ms for step in steps]
    assert tables["commands"].num_rows == 0  # no commands: the table is there all the same, with its columns
    # the run's start to the microsecond (truncated, as Parquet's timestamp[us] keeps it): compared as an integer,
    # not as float seconds, which round either way of it
    assert tables["frames"].column("run_start").cast(pa.int64()).to_pylist()[0] == start_ns // 1000


def _iso(ns: int) -> str:
    import time
    return time.strftime("%Y-%m-%dT%H:%M:%S", time.gmtime(ns // S)) + f".{ns % S:09d}Z"


def commanded(path, step_index: int = 0, label: str = "\udcffcue") -> None:  # type: ignore[no-untyped-def]
    """A log of a step, a GO with a label no UTF-8 holds (as an OSC sender's bytes decode), and the
    limiter's summary of commands it did not log one by one."""
    recorder = Recorder(path, RunInfo("show.yaml", "nightly", b"version: 1\nsteps:\n  - play: 1\n",
                                      "sim://", 115200, T0, show_host="left"))
    recorder.on_step_record(StepRecord(step_index, "play", "start", 0.0), T0)
    recorder.on_command(CommandEvent(Command("go", "osc udp 127.0.0.1:53001", label), Answer("error", "no cue"),
                                     T0 + S, 1.0))
    recorder.on_command(CommandEvent(Command(UNLOGGED, "osc udp 127.0.0.1:53001"),
                                     Answer("ok", "", {"count": 40, "counts": {"go": 30, "unknown": 10}}),
                                     T0 + 2 * S, 2.0))
    recorder.close({"outcome": "done"})


def test_commands_keep_the_limiters_summaries_and_text_no_utf8_holds_goes_as_its_escape(tmp_path):
    commanded(tmp_path / "live.mcap")
    assert vmain(["log", "export", str(tmp_path / "live.mcap"), "--parquet", str(tmp_path)]) == 0
    table = pq.read_table(tmp_path / "live.commands.parquet").to_pylist()
    assert [(r["command"], r["label"], r["count"], r["counts"], r["time_ns"], r["show_s"]) for r in table] == [
        ("go", "\\udcffcue", None, None, T0 + S, 1.0),
        (UNLOGGED, None, 40, '{"go": 30, "unknown": 10}', T0 + 2 * S, 2.0)]
    assert {r["run_id"] for r in table} == {"nightly@2001-09-09T01:46:40.000000000Z@left"}
    assert {r["host"] for r in table} == {"left"}


def test_without_pyarrow_it_says_how_to_install_it(tmp_path, monkeypatch, capsys):
    commanded(tmp_path / "live.mcap")
    monkeypatch.setitem(sys.modules, "pyarrow", None)  # `import pyarrow` now fails, as where it is not installed
    monkeypatch.setitem(sys.modules, "pyarrow.parquet", None)
    assert vmain(["log", "export", str(tmp_path / "live.mcap"), "--parquet", str(tmp_path)]) == 2
    err = capsys.readouterr().err.splitlines()
    assert len(err) == 1 and "pip install 'choreo[parquet]'" in err[0]
    assert not list(tmp_path.glob("*.parquet*"))


def test_a_missing_folder_or_two_logs_of_one_name_are_refused_before_anything_is_written(tmp_path, capsys,
                                                                                          monkeypatch):
    monkeypatch.chdir(tmp_path)  # where '' would write
    commanded(tmp_path / "live.mcap")
    (tmp_path / "b").mkdir()
    commanded(tmp_path / "b" / "live.mcap")
    for argv, says in (([str(tmp_path / "live.mcap"), "--parquet", str(tmp_path / "nosuch" / "x")], "does not exist"),
                       ([str(tmp_path / "live.mcap"), str(tmp_path / "b"), "--parquet", str(tmp_path)], "same tables"),
                       ([str(tmp_path / "live.mcap"), "--parquet", str(tmp_path), "--cues"], "leave out"),
                       ([str(tmp_path / "live.mcap"), str(tmp_path / "live.mcap"), "--csv", "-"], "one log at a time"),
                       # issue 21, item 6: '' (an unset shell variable) wrote the tables into the current folder,
                       # and a file was 'folder is not a folder'
                       ([str(tmp_path / "live.mcap"), "--parquet", ""], "give the folder the tables go in"),
                       ([str(tmp_path / "live.mcap"), "--format", "parquet", "-o", ""], "give the folder"),
                       ([str(tmp_path / "live.mcap"), "--parquet", "live.mcap"], "is not a folder (a file)")):
        assert vmain(["log", "export", *argv]) == 2
        err = capsys.readouterr().err.splitlines()
        assert len(err) == 1 and says in err[0], err
    assert not (tmp_path / "nosuch").exists() and not list(tmp_path.rglob("*.parquet*"))
    (tmp_path / "live.cues.parquet").mkdir()  # a folder where a table goes: refused before any table is written
    assert vmain(["log", "export", str(tmp_path / "live.mcap"), "--parquet", str(tmp_path)]) == 2
    err = capsys.readouterr().err.splitlines()
    assert len(err) == 1 and "live.cues.parquet: cannot write: it is a folder" in err[0], err
    assert [p.name for p in tmp_path.rglob("*.parquet*")] == ["live.cues.parquet"]


def test_a_hostile_log_is_one_line_its_tables_are_gone_and_the_others_still_export(tmp_path, capsys):
    good, bad, folder = tmp_path / "good.mcap", tmp_path / "bad.mcap", tmp_path / "out"
    folder.mkdir()
    commanded(good)
    commanded(bad)
    assert vmain(["log", "export", str(bad), "--parquet", str(folder)]) == 0
    before = {p.name: p.read_bytes() for p in folder.iterdir()}
    capsys.readouterr()
    bad.unlink()
    commanded(bad, step_index=2**63)  # a step number no int64 holds: the log's fault
    (tmp_path / "junk.mcap").write_bytes(b"\x89MCAP0\r\n" + b"\xff" * 100)
    assert vmain(["log", "export", str(tmp_path), "--parquet", str(folder)]) == 2
    err = capsys.readouterr().err.splitlines()
    assert len([line for line in err if line.startswith("exported ")]) == 1
    failures = [line for line in err if not line.startswith("exported ")]
    assert len(failures) == 2 and any("bad.mcap" in line and "index" in line for line in failures), failures
    assert {p.name: p.read_bytes() for p in folder.iterdir() if p.name.startswith("bad.")} == before
    assert sorted(p.name for p in folder.iterdir() if not p.name.startswith("bad.")) == [
        f"good.{kind}.parquet" for kind in sorted(KINDS)]
    assert not list(folder.glob("*.part"))


def test_a_step_record_that_is_not_choreos_is_the_reviews_one_line(tmp_path, capsys):
    path = tmp_path / "odd.mcap"
    recorder = Recorder(path, RunInfo("show.yaml", "x", b"", "sim://", 115200, T0))
    recorder.on_step_record(StepRecord(0, "play", "start", "soon"), T0)  # type: ignore[arg-type]  # what another program wrote
    recorder.close({"outcome": "done"})
    assert vmain(["log", "export", str(path), "--parquet", str(tmp_path)]) == 2
    err = capsys.readouterr().err.splitlines()
    assert len(err) == 1 and "not a choreo /choreo/step message" in err[0], err
    assert not list(tmp_path.glob("*.parquet*"))


def test_the_logs_of_two_hosts_and_their_merge_are_three_runs_the_merge_holding_both_hosts_rows(tmp_path):
    from hostlogs import merged_hosts

    made = merged_hosts(tmp_path)
    out = tmp_path / "out"
    out.mkdir()
    assert vmain(["log", "export", *map(str, made.logs.values()), str(made.merged), "--parquet", str(out)]) == 0
    found = duckdb.connect().execute(
        f"SELECT run_id, host, robot, number, late_ms FROM read_parquet('{out}/*.cues.parquet', union_by_name = true)"
        " ORDER BY host, robot, number").fetchall()
    hosts = {host: {row[0] for row in found if row[1] == host} for host in {row[1] for row in found}}
    assert sorted(hosts) == ["stageleft", "stageleft,stageright", "stageright"]
    assert all(len(ids) == 1 for ids in hosts.values()) and len(set.union(*hosts.values())) == 3
    assert next(iter(hosts["stageleft"])).startswith("duo@") and next(iter(hosts["stageleft"])).endswith("@stageleft")
    by_host = {host: [row[2:] for row in found if row[1] == host] for host in hosts}
    assert {row[0] for row in by_host["stageleft,stageright"]} == {"lead", "follow"}
    assert sorted(by_host["stageleft,stageright"]) == sorted(by_host["stageleft"] + by_host["stageright"])
    frames = {path.name: pq.read_table(path).num_rows for path in out.glob("*.frames.parquet")}
    assert frames["show.frames.parquet"] == frames["stageleft.frames.parquet"] + frames["stageright.frames.parquet"] > 0


def test_format_and_output_say_the_same_as_the_format_options(tmp_path, capsys):
    """`log export --format F -o PATH` (the issue's spelling) is `--F PATH`; the two together,
    -o alone, or parquet with nowhere to go are one-line errors (exit 2)."""
    log = tmp_path / "one.mcap"
    commanded(log)
    out = tmp_path / "tables"
    out.mkdir()
    assert vmain(["log", "export", str(log), "--format", "parquet", "-o", str(out)]) == 0
    assert sorted(p.name for p in out.iterdir()) == [f"one.{kind}.parquet" for kind in ("commands", "cues", "frames",
                                                                                         "steps")]
    assert vmain(["log", "export", str(log), "--format", "csv", "-o", str(tmp_path / "f.csv")]) == 0
    assert (tmp_path / "f.csv").read_text().startswith("seq,")
    capsys.readouterr()
    for argv, said in ((["--format", "parquet"], "-o DIR"), (["--format", "csv", "--csv", "x.csv"], "not both"),
                       (["-o", "x.csv"], "goes with --format")):
        assert vmain(["log", "export", str(log), *argv]) == 2
        err = capsys.readouterr().err.strip()
        assert len(err.splitlines()) == 1 and said in err, err
