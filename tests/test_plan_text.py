"""`choreo plan`'s table lines up on a terminal whatever the names: columns are measured in the
columns a terminal gives text (a Japanese character takes two), after escaping what it would obey."""

from __future__ import annotations

import pytest

from choreo.cli import main
from choreo.textfit import display_width
from runlog import write_show

SHOW = """\
version: 1
name: 日本語のショー
motions:
  おじぎ: {number: 1, duration: 1.0}
  wave: {number: 2, duration: 1.0}
  ﾊﾝｶｸ: {number: 3, duration: 1.0}
  "ＷＩＤＥ": {number: 4, duration: 1.0}
steps:
  - play: おじぎ
    label: はじめ
  - play: wave
    label: x
  - play: ﾊﾝｶｸ
    label: 終わり
  - play: "ＷＩＤＥ"
  - wait: 1
    label: "ＥＮＤ"
"""


def columns_of(line: str, cell: str) -> int:
    """The terminal column `cell` starts at in `line`."""
    return display_width(line[:line.index(cell)])


@pytest.mark.parametrize("robots", [False, True])
def test_the_plan_table_lines_up_with_wide_names(tmp_path, capsys, monkeypatch, robots):
    monkeypatch.setenv("COLUMNS", "300")
    body = SHOW.replace("steps:", "robots:\n  a: {}\n  b: {}\nsteps:") if robots else SHOW
    assert main(["plan", str(write_show(tmp_path, body))]) == 0
    lines = capsys.readouterr().out.splitlines()
    table = [line for line in lines if " s  " in line or line.lstrip().startswith("#")]
    assert len(table) == (6 if not robots else 12)
    for column in ("0.000 s", "play", "13 00"):
        starts = {columns_of(line, column) for line in table if column in line}
        assert len(starts) == 1, (column, table)
    starts = {columns_of(line, "steps[") for line in table if "steps[" in line}
    assert len(starts) == 1
