"""Reviews print no negative zero (issue 21, hostile logs): a frame, a step or a merged host's
shift a few ns before show zero printed `-0.000000` in log frames, `-0.000 s` in log timeline and
summary, and `-0.0` in an export: a time before the show that was none. One helper formats every
figure a review prints (showtime.fixed), one rounds what an export writes (showtime.rounded)."""

from __future__ import annotations

import re

import pytest

from choreo.log.format import ERROR, ClockRecord, StepRecord
from choreo.log.recorder import Recorder, RunInfo
from choreo.review.showtime import fixed, rounded
from runlog import vmain
from test_review_layouts import _TxEvent

T0, S = 10**18, 10**9
NEGATIVE_ZERO = re.compile(r"(?<![\w.])-0\.0*(?![0-9])")


@pytest.mark.parametrize("value", [-0.0, -1e-12, -4e-7, -4.9e-7])
def test_a_figure_that_rounds_to_zero_has_no_minus(value):
    assert fixed(value) == "0.000" and fixed(value, 6, 10) == "  0.000000" and fixed(value, 1, sign=True) == "+0.0"
    assert str(rounded(value, 3)) == "0.0"
    assert fixed(-0.0006) == "-0.001" and fixed(float("-inf")) == "-inf"


def _before_zero(r: Recorder) -> None:
    r.on_step_record(StepRecord(0, "play", "start", -1e-7, planned_s=0.0), T0 - 100)
    r.on_tx(_TxEvent(1, T0 - 100))  # type: ignore[arg-type]
    r.on_log(ERROR, "a fault a breath before the show", T0 - 100)
    r.on_clock(ClockRecord(0.0, 0, state="running"), T0)
    r.on_step_record(StepRecord(0, "play", "end", -1e-7), T0 + 50)
    r.on_clock(ClockRecord(1.0, S, state="running"), T0 + S)


def test_no_review_prints_minus_zero(tmp_path, capsys):
    log = tmp_path / "zero.mcap"
    recorder = Recorder(log, RunInfo("show.yaml", "x", b"version: 1\nsteps:\n  - play: 1\n", "sim://", 115200, T0))
    _before_zero(recorder)
    recorder.close({"outcome": "done"})
    for review in (["summary"], ["summary", "--json"], ["frames"], ["timeline"], ["export", "--csv", "-"],
                   ["export", "--json", "-"], ["export", "--cues", "--csv", "-"]):
        capsys.readouterr()
        assert vmain(["log", review[0], str(log), *review[1:]]) == 0, review
        out = capsys.readouterr().out
        assert not NEGATIVE_ZERO.search(out), (review, NEGATIVE_ZERO.search(out))
