"""Every review names a command's cue as the cue list names it, whatever the operator typed
(issue 24): the summary (text and JSON), the timeline's marks and the cue export's `released`
say `cue 1 'applause'`, with what was typed too where it differs, or alone when it found no cue.
The log keeps both (`label`: as given; `cue`, `cue_label`: the cue acted on)."""

from __future__ import annotations

import json
import threading

import pytest

from choreo.clock import VirtualTime
from choreo.events import Answer, Command, CommandEvent, StopRequest
from choreo.live.controls import Live
from choreo.log.format import CommandRecord, StepRecord
from choreo.log.reader import LogReader
from choreo.log.recorder import Recorder, RobotInfo, RunInfo
from choreo.review.export import cue_rows
from choreo.review.summary import summarize, summary_record
from choreo.review.summarytext import render
from choreo.review.timeline import build
from choreo.run.session import Session
from choreo.run.settings import RunRequest
from choreo.show.cues import cue_list
from runlog import read_log, wait_for, write_show

SHOW = """\
version: 1
motions:
  wave: {number: 1, duration: 0.4}
steps:
  - play: wave
    at: go
    label: applause
  - wait: done
  - play: wave
    at: 1.0
    label: encore
  - wait: done
  - play: wave
    at: go
    label: finale
  - wait: done
  - play: wave
    at: 9.0
    label: never
"""


@pytest.fixture(scope="module")
def named(tmp_path_factory):
    """GO by label, a plain GO, a GO by a number written otherwise, a refused cue GO naming a
    timed cue, one naming no cue, the playhead moved by label and by a key, a skip by number."""
    tmp = tmp_path_factory.mktemp("named")
    log = tmp / "run.mcap"
    source = VirtualTime()
    session = Session.prepare(RunRequest(str(write_show(tmp, SHOW)), log_path=str(log)), source)
    live = Live(StopRequest(), cues=cue_list(session.settings.plans), now=source.now, wall_ns=source.wall_ns)
    thread = threading.Thread(target=lambda: _run(session, live), daemon=True)
    thread.start()

    def say(name: str, label: str | None = None, source_: str = "key") -> Answer:
        return live.command(Command(name, source_, label))

    assert wait_for(lambda: bool(live.waiting), 20, 0.002)
    source.advance(0.5)
    assert say("cue_go", "applause", "osc udp 127.0.0.1:53001").ok
    assert wait_for(lambda: bool(live.waiting), 20, 0.002)  # finale
    assert not say("cue_go", "02").ok  # cue 2 'encore': a timed cue, nothing to GO
    assert not say("cue_go", "nosuch").ok
    assert say("playhead", "never").ok  # the playhead may stand on a timed cue
    assert say("playhead_previous").ok  # back on the waiting finale
    assert say("skip", "4").ok  # cue 4 'never', ahead: will not run
    source.advance(0.7)
    assert say("go").ok  # finale, under the auto playhead
    thread.join(20)
    return log


def _run(session: Session, live: Live) -> None:
    with session:
        session.run([], live=live)


def test_the_log_keeps_the_cue_as_given_and_the_cue_acted_on(named):
    records = [(m["command"], m.get("label"), m.get("cue"), m.get("cue_label"))
               for m in read_log(named).topic("/choreo/command")]
    assert records[:3] == [("cue_go", "applause", "1", "applause"), ("cue_go", "02", "2", "encore"),
                           ("cue_go", "nosuch", None, None)]
    assert records[-1] == ("go", None, "3", "finale")


def test_the_summary_names_each_commands_cue_one_way(named):
    text = "\n".join(render(summarize(named)))
    assert "cue_go cue 1 'applause' osc udp 127.0.0.1:53001: GO: cue 1 'applause'" in text
    assert "cue_go cue 2 'encore' (given as '02') key ERROR:" in text
    assert "cue_go 'nosuch' key ERROR:" in text
    assert "skip cue 4 'never' key: skipped: cue 4 'never'" in text  # typed "4": the number, not repeated
    assert "playhead cue 4 'never' key: playhead: cue 4 'never'" in text
    assert "playhead_previous cue 3 'finale' key: playhead: cue 3 'finale'" in text
    assert "go cue 3 'finale' key: GO: cue 3 'finale'" in text
    assert " go 3 " not in text and "cue_go applause" not in text


def test_the_summarys_json_and_the_timeline_name_them_the_same(named):
    listed = summary_record(summarize(named))["commands"]
    with LogReader(named) as reader:
        marks = [m.text for m in build(reader).commands if m.kind == "command"]
    assert [c["what"] for c in listed] == [m.split(" from ")[0] for m in marks]
    assert listed[0]["what"] == "cue_go cue 1 'applause'" and listed[0]["cue"] == "1"
    json.dumps(listed)  # JSON-ready


def test_the_cue_export_says_which_go_released_each_cue(named):
    with LogReader(named) as reader:
        rows = {r["number"]: r["released"] for r in cue_rows(reader)}
    assert rows == {"1": "go osc udp 127.0.0.1:53001", "2": "time", "3": "go key", "4": "skipped"}


@pytest.mark.parametrize("record, shown", [
    (CommandRecord("go", "key", "ok", cue="1", cue_label="applause"), "go cue 1 'applause'"),
    (CommandRecord("go", "key", "error"), "go"),
    (CommandRecord("cue_go", "key", "ok", label="1", cue="1", cue_label="x"), "cue_go cue 1 'x'"),
    (CommandRecord("cue_go", "key", "ok", label="1.0", cue="1"), "cue_go cue 1 (given as '1.0')"),
    (CommandRecord("cue_go", "key", "error", label="a\x1b[2Jb"), "cue_go 'a\x1b[2Jb'"),
    (CommandRecord("cue_go", "key", "error", label="x" * 10_000), "cue_go '" + "x" * 40 + "…'"),
    (CommandRecord("unknown", "osc udp 1.2.3.4:5", "error", label="/choreo/nope"), "unknown /choreo/nope"),
    (CommandRecord("go", "key", "ok", label="applause"), "go applause"),  # an older log's plain GO
    (CommandRecord("skip", "key", "ok", cue="9" * 5000, cue_label="\n"), "skip cue " + "9" * 40 + "… '\n'"),
])
def test_a_commands_name_from_any_record(record, shown):
    assert record.what == shown


def test_a_go_is_matched_to_its_own_cue_not_to_the_last_go_logged(tmp_path):
    """Two tracks' GO cues released close together, their commands logged in the other order
    than their steps' starts: each row names the GO of its own cue."""
    show = (b"version: 1\nrobots: {a: {}, b: {}}\ntracks:\n  a:\n    - play: 1\n      at: go\n"
            b"  b:\n    - play: 2\n      at: go\n")
    path = tmp_path / "two.mcap"
    robots = (RobotInfo("a", "sim://", 115200), RobotInfo("b", "sim://", 115200))
    recorder = Recorder(path, RunInfo("show.yaml", "two", show, "sim://", 115200, 10**18, robots=robots))
    t = 10**18

    def command(at: int, number: str, source: str) -> None:
        answer = Answer("ok", f"GO: cue {number}", {"cue": number, "label": None})
        recorder.on_command(CommandEvent(Command("go", source), answer, at, 0.0))

    def start(at: int, robot: str, number: str) -> None:
        recorder.on_step_record(StepRecord(0, "play", "start", 0.0, robot=robot, go=True, cue_number=number), at)

    command(t + 1000, "2", "osc udp 10.0.0.2:9")
    command(t + 2000, "1", "key")
    start(t + 2500, "a", "1")
    start(t + 3000, "b", "2")
    recorder.close({"outcome": "done"})
    with LogReader(path) as reader:
        rows = {(r["number"], r["robot"]): r["released"] for r in cue_rows(reader)}
    assert rows == {("1", "a"): "go key", ("2", "b"): "go osc udp 10.0.0.2:9"}
