"""Each fact lives once: a value other modules need is written in its home module and imported
everywhere else, so changing it is one edit and no copy can drift from it.

The check reads the code (not docstrings or comments) of every module of choreo/ for the facts
below, each a constant as the code compares or builds with it: a baud, a layout's name, the
simulator's URL, the log's folder and file suffix, the show attachment's media type, the
schema's file name, package and modeline, pyserial's network URLs, an interrupt's exit code.
A copy elsewhere fails with where it stands and where its home is; the check is proved on a
made-up package.
"""

from __future__ import annotations

import ast
from collections.abc import Iterator
from pathlib import Path

PACKAGE = Path(__file__).resolve().parent.parent / "choreo"

# fact -> its home (a path under choreo/)
FACTS: dict[str | int, str] = {
    115200: "wire/protocol.py",
    625000: "wire/protocol.py",
    1250000: "wire/protocol.py",
    "seed": "wire/layouts.py",
    "hth4-2.2": "wire/layouts.py",
    "sim://": "show/model.py",
    "socket://": "board/link.py",
    "rfc2217://": "board/link.py",
    "runs": "log/__init__.py",
    ".mcap": "log/__init__.py",
    "application/yaml": "log/format.py",
    "show.yaml": "log/format.py",
    "show.schema.json": "show/schema.py",
    "# yaml-language-server: $schema=": "show/schema.py",
    "choreo.schemas": "__init__.py",
    130: "errors.py",  # Interrupted's exit code
}
# The same spelling that means something else there: (module, value) -> why it is not the fact.
OTHER_MEANINGS: dict[tuple[str, str | int], str] = {
    ("sim/options.py", "seed"): "the simulator's random seed option, not the seed layout",
    ("run/replay.py", "runs"): "the verb, in a sentence about robots",
}


def _docstrings(tree: ast.AST) -> set[int]:
    """The ids of the docstring constants (prose, not code)."""
    found = set()
    for node in ast.walk(tree):
        if isinstance(node, (ast.Module, ast.ClassDef, ast.FunctionDef, ast.AsyncFunctionDef)) and node.body:
            first = node.body[0]
            if isinstance(first, ast.Expr) and isinstance(first.value, ast.Constant):
                found.add(id(first.value))
    return found


def copies(package: Path, facts: dict[str | int, str],
           other_meanings: dict[tuple[str, str | int], str]) -> Iterator[str]:
    """`module:line: VALUE (its home is HOME)` for each fact written outside its home."""
    for path in sorted(package.rglob("*.py")):
        module = path.relative_to(package).as_posix()
        tree = ast.parse(path.read_text(encoding="utf-8"))
        prose = _docstrings(tree)
        for node in ast.walk(tree):
            if not isinstance(node, ast.Constant) or id(node) in prose or isinstance(node.value, bool):
                continue
            value = node.value
            if not isinstance(value, (str, int)) or value not in facts:
                continue
            if facts[value] != module and (module, value) not in other_meanings:
                yield f"{module}:{node.lineno}: {value!r} (its home is {facts[value]})"


def test_each_fact_is_written_only_in_its_home():
    found = list(copies(PACKAGE, FACTS, OTHER_MEANINGS))
    assert found == [], "facts written outside their home (import them instead):\n" + "\n".join(found)


def test_the_homes_hold_their_facts_and_every_exception_is_still_there():
    """A fact moved away from its home, or an exception left after its cause went, fails too."""
    for value, home in FACTS.items():
        tree = ast.parse((PACKAGE / home).read_text(encoding="utf-8"))
        assert any(isinstance(n, ast.Constant) and n.value == value for n in ast.walk(tree)), (value, home)
    for module, value in OTHER_MEANINGS:
        tree = ast.parse((PACKAGE / module).read_text(encoding="utf-8"))
        assert any(isinstance(n, ast.Constant) and n.value == value for n in ast.walk(tree)), (module, value)


def test_a_copy_is_found_in_code_and_not_in_prose(tmp_path):
    package = tmp_path / "pkg"
    (package / "wire").mkdir(parents=True)
    (package / "wire" / "protocol.py").write_text("BAUD = 115200\n")
    (package / "run.py").write_text('"""Runs at 115200 baud, says the docstring."""\n\n'
                                     "def f(port):\n"
                                     '    """115200"""\n'
                                     "    return port.open(115200)  # 115200 in a comment is prose\n")
    (package / "sim.py").write_text('SEED_OPTION = "seed"\n')
    facts: dict[str | int, str] = {115200: "wire/protocol.py", "seed": "layouts.py"}
    assert list(copies(package, facts, {})) == ["run.py:5: 115200 (its home is wire/protocol.py)",
                                                "sim.py:1: 'seed' (its home is layouts.py)"]
    assert list(copies(package, facts, {("sim.py", "seed"): "another meaning"})) == [
        "run.py:5: 115200 (its home is wire/protocol.py)"]


def test_every_refusal_of_a_baud_says_the_same_words(capsys, tmp_path):
    """The board model, the wire, `choreo frames` and a run refuse 9600 in one text (the baud list
    and its wording come from protocol.baud_refusal; replay alone used to add the unit)."""
    import pytest

    from choreo.cli import main
    from choreo.errors import UsageError
    from choreo.run.settings import RunRequest, RunSettings
    from choreo.sim.board import SimBoard
    from choreo.wire.protocol import check_baud

    said = "baud 9600: the RCB-4 runs at 115200, 625000, 1250000 baud"
    with pytest.raises(ValueError) as wire:
        check_baud(9600)
    with pytest.raises(ValueError) as board:
        SimBoard(baud=9600)
    assert str(wire.value) == str(board.value) == said
    assert main(["frames", "status", "--baud", "9600"]) == 2
    assert capsys.readouterr().err.strip() == "--" + said
    show = tmp_path / "show.yaml"
    show.write_text("version: 1\nname: hello\nmotions:\n  wave: {number: 1}\nsteps:\n  - play: wave\n")
    with pytest.raises(UsageError) as run:
        RunSettings.settle(RunRequest(str(show), baud=9600))
    assert str(run.value) == said
