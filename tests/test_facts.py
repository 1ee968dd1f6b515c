"""Each fact lives once: a value other modules need is written in its home module and imported
everywhere else, so changing it is one edit and no copy can drift from it.

The check reads the code (not docstrings or comments) of every module of choreo/ for the facts
below, each a constant as the code compares or builds with it: a baud, a layout's name, the
simulator's URL, the log's folder and file suffix, the show attachment's media type, the
schema's file name, package and modeline, pyserial's network URLs, an interrupt's exit code,
and the run log's metadata keys (log/format's Info and Result; their spellings that mean other
things elsewhere too, `port`, `baud`, `show`, `error`..., are caught where a metadata mapping is
read or written with a literal key: `run_info.get("port")`, `meta["error"] = ...`).
A copy elsewhere fails with where it stands and where its home is; the check is proved on a
made-up package.
"""

from __future__ import annotations

import ast
from collections.abc import Iterator
from pathlib import Path

from choreo_source import PACKAGE, source_files, syntax_tree


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
    # the run log's metadata: its keys (the spellings that mean nothing else in choreo)
    "choreo.result": "log/format.py",
    "show_path": "log/format.py",
    "show_sha256": "log/format.py",
    "start_time": "log/format.py",
    "start_ns": "log/format.py",
    "unison": "log/format.py",
    "robot.": "log/format.py",  # robot.<name>.port etc.
    "outcome": "log/format.py",
    "steps_run": "log/format.py",
    "late_steps": "log/format.py",
    "exit_code": "log/format.py",
    "stop_reason": "log/format.py",
    "show_zero_monotonic_ns": "log/format.py",
    "show_zero_wall_ns": "log/format.py",
    "music.file": "log/format.py",
    "music.start": "log/format.py",
    "audio.backend": "log/format.py",
    "replay_of": "log/format.py",
}
# The mappings that hold the log's metadata, by the names choreo gives them where it reads or
# builds one: a literal metadata key on one of these is a key typed outside log/format.
METADATA_MAPPINGS = frozenset({"run_info", "result", "run", "meta", "metadata", "named", "finished"})
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
    for path in source_files(package):
        module = path.relative_to(package).as_posix()
        tree = syntax_tree(path)
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


def _metadata_keys() -> set[str]:
    from choreo.log.format import Info, Result

    return {value for kind in (Info, Result) for name, value in vars(kind).items()
            if name.isupper() and isinstance(value, str) and value not in (Info.YES, Info.NO)}


def _mapping_name(node: ast.expr) -> str | None:
    """`run_info` of `reader.run_info`, `run` of `run`, `result` of `(reader.result or {})`."""
    if isinstance(node, ast.BoolOp):
        return _mapping_name(node.values[0])
    if isinstance(node, ast.Attribute):
        return node.attr
    return node.id if isinstance(node, ast.Name) else None


def literal_metadata_keys(package: Path, keys: set[str]) -> Iterator[str]:
    """`module:line: KEY` for each metadata mapping read (`.get(KEY)`, `[KEY]`) or written
    (`[KEY] = `) with a literal key outside log/format."""
    for path in source_files(package):
        module = path.relative_to(package).as_posix()
        if module == "log/format.py":
            continue
        for node in ast.walk(syntax_tree(path)):
            key: ast.expr | None = None
            if isinstance(node, ast.Subscript):
                mapping, key = node.value, node.slice
            elif (isinstance(node, ast.Call) and isinstance(node.func, ast.Attribute)
                  and node.func.attr in ("get", "setdefault") and node.args):
                mapping, key = node.func.value, node.args[0]
            if key is None or _mapping_name(mapping) not in METADATA_MAPPINGS:
                continue
            if isinstance(key, ast.Constant) and key.value in keys:
                yield f"{module}:{node.lineno}: {key.value!r}"


def test_no_metadata_key_is_read_or_written_by_a_literal():
    found = list(literal_metadata_keys(PACKAGE, _metadata_keys()))
    assert found == [], "metadata keys typed outside log/format (use its Info and Result):\n" + "\n".join(found)


def test_a_literal_metadata_key_is_found(tmp_path):
    package = tmp_path / "pkg"
    (package / "log").mkdir(parents=True)
    (package / "log" / "format.py").write_text('PORT = "port"\nx = run_info.get("port")\n')
    (package / "review.py").write_text('def f(reader, run, rows):\n'
                                       '    a = reader.run_info.get("port", "?") + (reader.result or {}).get("port")\n'
                                       '    run["port"] = a\n'
                                       '    return rows.get("port"), run.get(PORT)\n')
    assert sorted(literal_metadata_keys(package, {"port"})) == [
        "review.py:2: 'port'", "review.py:2: 'port'", "review.py:3: 'port'"]


def test_the_metadata_keys_are_the_ones_logs_have_always_had():
    """The names on disk do not change with the code: old logs read, and older choreo reads new ones."""
    assert _metadata_keys() == {
        "version", "show", "show_path", "show_sha256", "port", "baud", "layout", "start_time", "start_ns", "host",
        "python", "platform", "robots", "unison", "show_host", "hosts", "shift_ns", "spread_ns", "aligned_by",
        "outcome", "steps_run", "late_steps", "show_s", "error",
        "exit_code", "stop_reason", "clock", "show_zero_monotonic_ns", "show_zero_wall_ns", "music.file",
        "music.start", "audio.backend", "replay_of", "speed", "frames", "differences"}


def test_the_homes_hold_their_facts_and_every_exception_is_still_there():
    """A fact moved away from its home, or an exception left after its cause went, fails too."""
    for value, home in FACTS.items():
        tree = syntax_tree(PACKAGE / home)
        assert any(isinstance(n, ast.Constant) and n.value == value for n in ast.walk(tree)), (value, home)
    for module, value in OTHER_MEANINGS:
        tree = syntax_tree(PACKAGE / module)
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
