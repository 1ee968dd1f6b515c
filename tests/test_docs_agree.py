"""What the README, docs/ and the example shows say about timing is what `choreo plan` (and so the run)
does: the comments are read and checked against the compiled plan."""

from __future__ import annotations

import re
from pathlib import Path

from choreo.show.load import load_show
from choreo.show.plan import compile_plans
from runlog import write_show

ROOT = Path(__file__).resolve().parent.parent


def plan_of(path: Path):  # type: ignore[no-untyped-def]
    show = load_show(str(path))
    return show, next(iter(compile_plans(show).values()))


def readme_block(containing: str) -> str:
    """The YAML block of README.md or docs/*.md that holds the text (a show, or an excerpt of one)."""
    docs = [ROOT / "README.md", *sorted((ROOT / "docs").glob("*.md"))]
    blocks = [block for doc in docs for block in re.findall(r"```yaml[^\n]*\n(.*?)```", doc.read_text(), re.S)]
    return next(block for block in blocks if containing in block)


def test_the_readme_go_example_says_when_the_timed_cue_plays(tmp_path):
    """docs/live.md: `at: 4` after a GO cue and a `wait: 2` plays N s after the GO, as the comment says.
    The show clock holds at the GO cue's show time, so the cue plays (4 - that time) s after the GO."""
    block = readme_block("at: go              # waits for the operator's GO")
    said = float(re.search(r"at: 4 .*?: ([\d.]+) s after the GO", block).group(1))
    _, plan = plan_of(write_show(tmp_path, block))
    go = next(step for step in plan.steps if step.go)
    cued = next(step for step in plan.steps if step.at == 4)
    assert cued.planned_s - go.planned_s == said


def test_the_dance_shows_comment_on_the_waves_is_true():
    text = (ROOT / "shows/dance.yaml").read_text()
    claim = re.search(r"wait: ([\d.]+) .*the left wave starts ([\d.]+) s (after|before) the right one ends", text)
    assert claim, "the comment on the wait between the waves"
    show, plan = plan_of(ROOT / "shows/dance.yaml")
    right = next(step for step in plan.steps if step.motion_name == "wave_right")
    left = next(step for step in plan.steps if step.motion_name == "wave_left")
    gap = left.planned_s - (right.planned_s + show.motions["wave_right"].duration)
    said = float(claim.group(2)) * (1 if claim.group(3) == "after" else -1)
    assert abs(gap - said) < 1e-9


def test_the_readme_shows_the_dance_as_it_is():
    """docs/shows.md's listing of shows/dance.yaml (with `...` for lines left out) is the file's."""
    block = readme_block("name: Dance")
    lines = (ROOT / "shows/dance.yaml").read_text().splitlines()
    position = 0
    for line in block.splitlines():
        if line.strip() == "...":
            continue
        position = lines.index(line, position) + 1  # ValueError: the README says what the file does not
