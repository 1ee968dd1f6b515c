"""The layers contract: choreo's packages import only downward, nothing imports in a circle, and
no function grows past a screen.

A small AST check of our own rather than import-linter: it reads function-level and
TYPE_CHECKING imports too (a lazy import up the layers is still a dependency that runs up), needs
no extra tool on a fresh machine, and says each violation in one line a reviewer can act on.
docs/architecture.md draws the same picture; `LAYERS` here is the one place it is spelled.
"""

from __future__ import annotations

import ast
import functools
from collections.abc import Iterator
from dataclasses import dataclass
from pathlib import Path

import pytest

from choreo_source import PACKAGE, source_files, syntax_tree


# Lowest first. A module may import its own package (the longest prefix below that names it)
# or any lower layer; names in one layer are independent of each other, except the base
# modules, which are small enough to lean on one another (without a cycle).
BASE = ("choreo", "choreo.errors", "choreo.textfit", "choreo.numtext", "choreo.clock",
        "choreo.userfile", "choreo.signals")
LAYERS: tuple[tuple[str, ...], ...] = (
    BASE,
    ("choreo.wire",),  # frames and replies as bytes and values; layouts as data
    ("choreo.show",),  # the show model, reading and checking a show file, the plan, HTH4 import
    ("choreo.events",),  # every event and listener a run has; the stop request
    ("choreo.music", "choreo.board", "choreo.sim", "choreo.sync"),  # music clock; boards; simulator; Link
    ("choreo.log",),  # the log's format, its recorder and its reader
    ("choreo.live",),  # the operator's controls and OSC
    ("choreo.review",),  # reviews: read a log, never run
    ("choreo.run",),  # runner, ensemble, session, settings, stage, replay
    ("choreo.cli",),  # the commands: parse, call one layer below, print
    ("choreo.__main__",),  # the entry point: signals, then the CLI
)
# Not Python: the JSON Schemas, linked into the package so an installed choreo finds them.
DATA_FOLDERS = {"schemas", "__pycache__"}
MAX_FUNCTION_LINES = 60


@dataclass(frozen=True)
class Import:
    importer: str
    imported: str
    line: int

    def __str__(self) -> str:
        return f"{self.importer}:{self.line} imports {self.imported}"


def module_name(path: Path, root: Path) -> str:
    parts = list(path.relative_to(root.parent).with_suffix("").parts)
    return ".".join(parts[:-1] if parts[-1] == "__init__" else parts)


def modules(root: Path) -> dict[str, Path]:
    return {module_name(path, root): path for path in source_files(root)}


@functools.cache
def _trees(root: Path) -> dict[str, tuple[Path, ast.Module]]:
    """Each module's syntax tree, parsed once for all the checks (the package does not change
    while the tests run; a made-up package is a new root)."""
    return {name: (path, syntax_tree(path))
            for name, path in modules(root).items()}


def _targets(node: ast.AST, importer: str, is_package: bool) -> Iterator[str]:
    if isinstance(node, ast.Import):
        yield from (alias.name for alias in node.names)
    elif isinstance(node, ast.ImportFrom):
        if node.level:
            base = importer.split(".") if is_package else importer.split(".")[:-1]
            base = base[: len(base) - node.level + 1]
            module = ".".join(base + ([node.module] if node.module else []))
        else:
            module = node.module or ""
        yield module
        yield from (f"{module}.{alias.name}" for alias in node.names)


def imports(root: Path) -> list[Import]:
    """Every import of one of the package's own modules, wherever it sits in the file."""
    known = _trees(root)
    found: list[Import] = []
    for name, (path, tree) in known.items():
        for node in ast.walk(tree):
            targets = {t for t in _targets(node, name, path.name == "__init__.py") if t in known and t != name}
            # `from choreo.sim import board` names the module, not the package that holds it
            for target in targets - {t.rsplit(".", 1)[0] for t in targets}:
                found.append(Import(name, target, node.lineno))  # type: ignore[attr-defined]  # import nodes have one
    return sorted(set(found), key=lambda i: (i.importer, i.line, i.imported))


def place(module: str, layers: tuple[tuple[str, ...], ...] = LAYERS) -> tuple[int, str] | None:
    """The layer a module sits in and the name (package or base module) that puts it there."""
    best: tuple[int, str] | None = None
    for number, names in enumerate(layers):
        for name in names:
            if (module == name or module.startswith(name + ".")) and (best is None or len(name) > len(best[1])):
                best = (number, name)
    return best


def violations(found: list[Import], layers: tuple[tuple[str, ...], ...] = LAYERS) -> list[str]:
    said = []
    for edge in found:
        (low, owner), (high, other) = place(edge.importer, layers), place(edge.imported, layers)  # type: ignore[misc]  # every module has a place (test_every_module_has_a_layer)
        if high > low:
            said.append(f"{edge}: layer {high} ({other}) is above layer {low} ({owner})")
        elif high == low and owner != other and low != 0:
            said.append(f"{edge}: {owner} and {other} share layer {low} and must stay independent")
    return said


def _reach(graph: dict[str, set[str]], start: str) -> set[str]:
    seen: set[str] = set()
    todo = list(graph.get(start, ()))
    while todo:
        node = todo.pop()
        if node not in seen:
            seen.add(node)
            todo.extend(graph.get(node, ()))
    return seen


def cycles(found: list[Import]) -> list[list[str]]:
    """Groups of two or more modules that reach each other through imports: each a circle.
    (Reachability from every module: the package has a hundred, so no cleverer walk is needed.)"""
    graph: dict[str, set[str]] = {}
    for edge in found:
        graph.setdefault(edge.importer, set()).add(edge.imported)
    reach = {node: _reach(graph, node) for node in graph}
    groups = {tuple(sorted({node} | {other for other in reach[node] if node in reach.get(other, ())}))
              for node in graph}
    return sorted(list(group) for group in groups if len(group) > 1)


def long_functions(root: Path, limit: int = MAX_FUNCTION_LINES) -> list[str]:
    said = []
    for name, (_, tree) in _trees(root).items():
        for node in ast.walk(tree):
            if isinstance(node, (ast.FunctionDef, ast.AsyncFunctionDef)):
                length = (node.end_lineno or node.lineno) - node.lineno + 1
                if length > limit:
                    said.append(f"{name}:{node.lineno} {node.name} is {length} lines (at most {limit})")
    return said


# --------------------------------------------------------------------------- the contract


def test_the_top_level_holds_only_the_layers_packages_and_the_base_modules():
    declared = {name for names in LAYERS for name in names}
    strays = [entry.name for entry in sorted(PACKAGE.iterdir())
              if entry.name not in DATA_FOLDERS and entry.name != "__init__.py"
              and f"choreo.{entry.name.removesuffix('.py')}" not in declared]
    assert strays == [], f"choreo/ holds rooms outside the layers: {strays} (add each to LAYERS or move it in)"


def test_every_module_has_a_layer():
    assert [name for name in modules(PACKAGE) if place(name) is None] == []


def test_imports_run_only_down_the_layers():
    assert violations(imports(PACKAGE)) == []


def test_no_modules_import_each_other_in_a_circle():
    assert cycles(imports(PACKAGE)) == []


def test_no_function_is_longer_than_a_screen():
    assert long_functions(PACKAGE) == []


# --------------------------------------------------------------------------- the check checks


def _tree(root: Path, files: dict[str, str]) -> Path:
    package = root / "choreo"
    for relative, text in files.items():
        path = package / relative
        path.parent.mkdir(parents=True, exist_ok=True)
        path.write_text(text)
    for folder in [package, *(p for p in package.rglob("*") if p.is_dir())]:
        (folder / "__init__.py").touch()
    return package


@pytest.mark.parametrize("statement", [
    "from choreo.run.runner import Runner\n",  # at the top
    "def send():\n    from choreo.run import runner\n    return runner\n",  # inside a function
    "from typing import TYPE_CHECKING\nif TYPE_CHECKING:\n    import choreo.run.runner\n",  # for types only
])
def test_an_import_up_the_layers_is_caught_wherever_it_is_written(tmp_path, statement):
    package = _tree(tmp_path, {"board/link.py": statement, "run/runner.py": "Runner = 1\n"})
    said = violations(imports(package))
    assert len(said) == 1 and said[0].startswith("choreo.board.link:") and "layer 8 (choreo.run)" in said[0]


def test_siblings_in_one_layer_stay_apart_and_a_package_may_use_itself(tmp_path):
    package = _tree(tmp_path, {"board/link.py": "from choreo.sim import board\nfrom . import usb\n",
                               "board/usb.py": "", "sim/board.py": ""})
    said = violations(imports(package))
    assert said == ["choreo.board.link:1 imports choreo.sim.board: choreo.board and choreo.sim share layer 4 "
                    "and must stay independent"]


def test_a_circle_of_imports_is_found(tmp_path):
    package = _tree(tmp_path, {"wire/protocol.py": "from choreo.wire import layouts\n",
                               "wire/layouts.py": "def f():\n    from choreo.wire.protocol import X\n"})
    assert cycles(imports(package)) == [["choreo.wire.layouts", "choreo.wire.protocol"]]


def test_a_long_function_is_found(tmp_path):
    body = "".join(f"    x{i} = {i}\n" for i in range(MAX_FUNCTION_LINES))
    package = _tree(tmp_path, {"errors.py": f"def short():\n    pass\n\n\ndef long():\n{body}"})
    assert long_functions(package) == [f"choreo.errors:5 long is {MAX_FUNCTION_LINES + 1} lines (at most 60)"]
