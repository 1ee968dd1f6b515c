"""A show file's problems are bounded: a hostile file of 256 KiB can hold 60,000 wrong list
entries, and saying each took 5 s and 60,000 lines. The first `MAX_SHOWN` are said in file
order, then one line counts the rest; past `MAX_FOUND` the schema stops looking (and the checks
after it, which would read values it never reached, do not run)."""

from __future__ import annotations

import pytest

from choreo.errors import ShowError
from choreo.show.load import load_show_bytes
from choreo.show.report import MAX_FOUND, MAX_SHOWN


def said(source: str) -> list[tuple[int, str, str]]:
    with pytest.raises(ShowError) as info:
        load_show_bytes(source.encode(), "s.yaml")
    return [(p.line, p.path, p.message) for p in info.value.problems]


@pytest.mark.parametrize("body", [
    "tempo: {{bars: [{entries}]}}\nsteps: [{{play: 1, at: {{bar: 2}}}}]\n",  # the cue reads the map
    "steps: [{entries}]\n",
])
def test_sixty_thousand_wrong_entries_are_fifty_lines_and_a_count(body):
    source = "version: 1\n" + body.format(entries=", ".join(["x"] * 60_000))
    assert len(source) < 256 * 1024
    found = said(source)
    assert len(found) == MAX_SHOWN + 1
    assert found[0][1].endswith("[0]") and found[MAX_SHOWN - 1][1].endswith(f"[{MAX_SHOWN - 1}]")  # file order
    assert found[-1] == (0, "", f"and at least {MAX_FOUND - MAX_SHOWN:,} more problems (fix these first)")


def test_a_few_more_than_are_shown_are_counted_exactly():
    found = said("version: 1\ntempo: {bars: [" + ", ".join(["x"] * (MAX_SHOWN + 7)) + "]}\nsteps: [{play: 1}]\n")
    assert len(found) == MAX_SHOWN + 1 and found[-1] == (0, "", "and 7 more problems (fix these first)")


def test_as_many_as_are_shown_are_all_said():
    found = said("version: 1\ntempo: {bars: [" + ", ".join(["x"] * MAX_SHOWN) + "]}\nsteps: [{play: 1}]\n")
    assert len(found) == MAX_SHOWN and all(path.startswith("tempo.bars[") for _, path, _ in found)
