"""Every code block in README.md and docs/ is checked, so the documentation cannot drift from the
program: a show loads, a command parses with choreo's own parser, an excerpt of a file is in
that file; every other block says what it is (```text, ```python ...), so none slips by
unchecked. Every relative link leads to a file (and a heading) that exists.

How a block is read, by its info string (the word after the opening fence):
- `yaml`: a whole show; it must load without a problem, as `choreo validate` loads it.
- `yaml excerpt=PATH`: lines of the file PATH (from the repository's root) in their order, with
  `...` or `# ...` for lines left out; the file itself must load.
- `sh`: every line is a command; `console`: lines starting with `$ ` are commands, the rest is
  what they print (what `$ cat X.yaml` prints is a show, and must load). Each `choreo` in a
  command (after `&&`, `|`, `;`, inside `$(...)`) must parse; `python X.py` must name a file
  that exists.
- `python`: compiled, not run, and every name it imports must exist; `text`: not checked, but
  it may hold neither a show nor a line that runs choreo.

Beyond the blocks: the repository paths and choreo's dotted names in the docs' inline code exist;
the code's own citations of the docs (`docs/hardware.md, "Errata: The config word"`) name a file
and headings that exist; the architecture page draws the layers tests/test_layers.py enforces and
names every module; the README fits on a page, lists every command and every doc, and gives the
test command CI runs.
"""

from __future__ import annotations

import ast
import contextlib
import importlib
import io
import re
import shlex
from collections.abc import Iterator
from dataclasses import dataclass
from pathlib import Path

import pytest

from choreo.cli import build_parser
from choreo.errors import ChoreoError
from choreo.log.format import RESULT_METADATA_NAME
from choreo.show.load import load_show_bytes
from choreo_source import source_files

ROOT = Path(__file__).resolve().parent.parent
README = ROOT / "README.md"
DOCS = (README, *sorted((ROOT / "docs").glob("*.md")))
README_MAX_LINES = 250

SHOW_KINDS = {"yaml"}
COMMAND_KINDS = {"sh", "console"}
PLAIN_KINDS = {"text", "python", "sql"}  # sql: the README's DuckDB query, run by tests/test_export_parquet.py
_FENCE = re.compile(r"^(?P<indent> *)(?P<fence>```+)(?P<info>.*)$")
_SHOW_LINE = re.compile(r"^(version|steps|tracks):", re.M)
_SUBSTITUTION = re.compile(r"\$\(([^()]*)\)")
_SKIP_LINES = {"...", "# ..."}
_INLINE_CODE = re.compile(r"`([^`]+)`")  # it may run over a line break, as Markdown allows


@dataclass(frozen=True)
class Block:
    """One fenced code block: where it is, its info string and its text (fence indent removed)."""

    doc: Path
    line: int
    info: str
    text: str

    @property
    def kind(self) -> str:
        return self.info.split()[0] if self.info.split() else ""

    @property
    def options(self) -> dict[str, str]:
        return dict(word.split("=", 1) for word in self.info.split()[1:] if "=" in word)

    def __str__(self) -> str:
        return f"{self.doc.relative_to(ROOT)}:{self.line}"


def blocks_of(path: Path) -> list[Block]:
    """The fenced blocks of a Markdown file, also those indented inside a list item."""
    found: list[Block] = []
    lines = path.read_text(encoding="utf-8").splitlines()
    index = 0
    while index < len(lines):
        opening = _FENCE.match(lines[index])
        index += 1
        if not opening:
            continue
        start = index
        indent, fence = len(opening["indent"]), opening["fence"]
        body: list[str] = []
        while index < len(lines) and lines[index].strip() != fence:
            body.append(lines[index][indent:] if lines[index][:indent].isspace() else lines[index])
            index += 1
        if index == len(lines):
            raise AssertionError(f"{path}:{start}: a code block never closed")
        index += 1
        found.append(Block(path, start, opening["info"].strip(), "\n".join(body) + "\n"))
    return found


def all_blocks() -> list[Block]:
    return [block for doc in DOCS for block in blocks_of(doc)]


def blocks_of_kind(kinds: set[str]) -> list[Block]:
    return [block for block in all_blocks() if block.kind in kinds]


def ids(block: Block) -> str:
    return str(block)


def load_problems(text: str, where: str, folder: Path) -> list[str]:
    """What loading the show finds wrong, one line each (nothing: it loads)."""
    try:
        load_show_bytes(text.encode("utf-8"), where, folder)
    except ChoreoError as exc:
        return [str(exc)]
    return []


# --- shows -------------------------------------------------------------------------------------


def test_the_documentation_has_code_blocks_of_every_kind():
    """The checks below find their blocks: a fence the reader misread would leave them nothing."""
    kinds = {block.kind for block in all_blocks()}
    assert {"yaml", "sh", "console", "text"} <= kinds


SHOWS = blocks_of_kind(SHOW_KINDS)


@pytest.mark.parametrize("block", [b for b in SHOWS if "excerpt" not in b.options], ids=ids)
def test_a_show_in_the_docs_loads(block):
    assert load_problems(block.text, str(block), block.doc.parent) == []


@pytest.mark.parametrize("block", [b for b in SHOWS if "excerpt" in b.options], ids=ids)
def test_an_excerpt_of_a_show_is_that_file_and_the_file_loads(block):
    """The excerpt's lines are the file's, in order (`...` stands for lines left out)."""
    path = ROOT / block.options["excerpt"]
    mismatch = excerpt_mismatch(block.text, path.read_text(encoding="utf-8"))
    assert mismatch is None, f"{block}: {block.options['excerpt']} has no line {mismatch!r} after the ones before it"
    assert load_problems(path.read_text(encoding="utf-8"), str(path), path.parent) == []


def excerpt_mismatch(excerpt: str, whole: str) -> str | None:
    """The first line of the excerpt that the file does not have after the lines before it."""
    lines = [line.rstrip() for line in whole.splitlines()]
    position = 0
    for line in excerpt.splitlines():
        if line.strip() in _SKIP_LINES:
            continue
        try:
            position = lines.index(line.rstrip(), position) + 1
        except ValueError:
            return line
    return None


# --- commands ----------------------------------------------------------------------------------


def command_lines(block: Block) -> Iterator[tuple[str, str]]:
    """(command line, what it printed) for each command of a sh or console block."""
    if block.kind == "sh":
        joined = re.sub(r"\\\n\s*", " ", block.text)
        for line in joined.splitlines():
            if line.strip() and not line.lstrip().startswith("#"):
                yield line, ""
        return
    command: str | None = None
    output: list[str] = []
    for line in block.text.splitlines():
        if line.startswith("$ "):
            if command is not None:
                yield command, "\n".join(output)
            command, output = line[2:], []
        else:
            output.append(line)
    if command is not None:
        yield command, "\n".join(output)


def invocations(line: str) -> Iterator[list[str]]:
    """Each program a shell line runs, as its words: split at `|`, `&&`, `;`, and `$(...)` opened."""
    for inner in _SUBSTITUTION.findall(line):
        yield from invocations(inner)
    lexer = shlex.shlex(_SUBSTITUTION.sub("SUBSTITUTED", line), posix=True, punctuation_chars=True)
    lexer.whitespace_split = True
    lexer.commenters = "#"
    words: list[str] = []
    for word in lexer:
        if word and set(word) <= set("|&;<>()"):
            if words:
                yield words
            words = []
            if word in (">", "<", ">>"):
                next(lexer, None)  # the redirection's file is no argument
        else:
            words.append(word)
    if words:
        yield words


def choreo_arguments(line: str) -> Iterator[list[str]]:
    """The arguments of every `choreo` the line runs (`.venv/bin/choreo` too)."""
    for words in invocations(line):
        while words and re.match(r"[A-Za-z_]\w*=", words[0]):
            words = words[1:]  # a variable set for the command, or by it
        if words and Path(words[0]).name == "choreo":
            yield words[1:]


def parse_error(arguments: list[str]) -> str | None:
    """What choreo's parser says against the arguments (None: they parse), as `choreo` parses
    them: known arguments first, then anything left over is an error of the command's parser."""
    parser = build_parser()
    said = io.StringIO()
    try:
        with contextlib.redirect_stderr(said), contextlib.redirect_stdout(io.StringIO()):
            args, extra = parser.parse_known_args(arguments)
            if extra:
                getattr(args, "parser", parser).unknown_arguments(extra)
    except SystemExit as exc:
        return None if exc.code == 0 else said.getvalue().strip() or f"exit {exc.code}"
    return None


COMMANDS = blocks_of_kind(COMMAND_KINDS)


@pytest.mark.parametrize("block", COMMANDS, ids=ids)
def test_every_choreo_command_in_the_docs_parses(block):
    errors = [f"{line}: {error}" for line, _ in command_lines(block)
              for arguments in choreo_arguments(line) if (error := parse_error(arguments))]
    assert errors == []


@pytest.mark.parametrize("block", COMMANDS, ids=ids)
def test_every_script_a_command_runs_exists(block):
    """`python bench/run.py` and the like: the script is in the repository."""
    missing = [words[1] for line, _ in command_lines(block) for words in invocations(line)
               if Path(words[0]).name.startswith("python") and len(words) > 1 and words[1].endswith(".py")
               and not (ROOT / words[1]).is_file()]
    assert missing == []


@pytest.mark.parametrize("block", [b for b in COMMANDS if b.kind == "console"], ids=ids)
def test_a_show_a_console_block_prints_loads(block):
    """`$ cat shows/kxr.yaml` after `choreo import`: what it prints is a show, and it loads."""
    shows = [(line, output) for line, output in command_lines(block)
             if re.match(r"cat \S+\.ya?ml$", line.strip()) and _SHOW_LINE.search(output)]
    for line, output in shows:
        assert load_problems(output + "\n", f"{block}: {line}", block.doc.parent) == []


def test_the_command_blocks_hold_commands():
    """A sh or console block with no command is an output block that should say `text`."""
    empty = [str(block) for block in COMMANDS if not list(command_lines(block))]
    assert empty == []


# --- every other block -------------------------------------------------------------------------


@pytest.mark.parametrize("doc", DOCS, ids=lambda doc: str(doc.relative_to(ROOT)))
def test_every_block_says_what_it_is(doc):
    """An unmarked block, or one of a kind this test does not know, would escape every check."""
    known = SHOW_KINDS | COMMAND_KINDS | PLAIN_KINDS
    unmarked = [f"{block}: ```{block.info}" for block in blocks_of(doc) if block.kind not in known]
    assert unmarked == []


def hidden(blocks: list[Block]) -> list[str]:
    """Blocks marked text (or python) that hold what must be checked: a show file (`version:`
    and `steps:` or `tracks:` at the left margin), or a line that runs choreo."""
    found = []
    for block in blocks:
        if block.kind not in PLAIN_KINDS:
            continue
        if re.search(r"^version: ", block.text, re.M) and _SHOW_LINE.search(block.text.replace("version:", "")):
            found.append(f"{block}: a show")
        found += [f"{block}: {line}" for line in block.text.splitlines() if re.match(r"(\$ )?choreo ", line)]
    return found


@pytest.mark.parametrize("doc", DOCS, ids=lambda doc: str(doc.relative_to(ROOT)))
def test_a_show_or_a_command_is_never_hidden_in_a_text_block(doc):
    """A show is marked yaml and a command sh or console, so that they are checked."""
    assert hidden(blocks_of(doc)) == []


@pytest.mark.parametrize("block", blocks_of_kind({"python"}), ids=ids)
def test_python_in_the_docs_compiles_and_imports_what_exists(block):
    """Compiled, not run; every name it imports from choreo is there (modules move)."""
    missing = []
    for node in ast.walk(ast.parse(block.text, str(block))):
        if isinstance(node, ast.ImportFrom) and (node.module or "").split(".")[0] == "choreo":
            module = importlib.import_module(node.module or "")
            missing += [f"{node.module}.{alias.name}" for alias in node.names if not hasattr(module, alias.name)]
        elif isinstance(node, ast.Import):
            for alias in node.names:
                importlib.import_module(alias.name)
    assert missing == []


# --- the checks catch what they are for --------------------------------------------------------


def test_a_broken_show_in_a_doc_is_caught(tmp_path):
    """The show checks are not vacuous: a doc whose show names a slot out of range, and one whose
    excerpt says a line the file does not have, both fail."""
    doc = tmp_path / "doc.md"
    doc.write_text("```yaml\nversion: 1\nsteps:\n  - play: 140\n```\n")
    (block,) = blocks_of(doc)
    assert "out of range" in " ".join(load_problems(block.text, "doc.md:1", tmp_path))
    dance = (ROOT / "shows/dance.yaml").read_text(encoding="utf-8")
    assert excerpt_mismatch("name: Dance\n...\n  - play: spin\n", dance) is None
    assert excerpt_mismatch("name: Dance\n...\n  - play: moonwalk\n", dance) == "  - play: moonwalk"
    assert excerpt_mismatch("  - play: spin\nname: Dance\n", dance) == "name: Dance"


def test_a_bad_command_in_a_doc_is_caught():
    assert parse_error(["run", "shows/dance.yaml", "--port", "sim://"]) is None
    assert "unrecognized arguments: --prot" in (parse_error(["run", "shows/dance.yaml", "--prot", "x"]) or "")
    assert parse_error(["lgo", "summary"]) is not None
    assert parse_error(["--help"]) is None
    line = 'choreo plan x.yaml && .venv/bin/choreo log frames "$(choreo log latest)" | head\n'
    block = Block(README, 1, "sh", line)
    assert [args for line, _ in command_lines(block) for args in choreo_arguments(line)] == [
        ["log", "latest"], ["plan", "x.yaml"], ["log", "frames", "SUBSTITUTED"]]


def test_an_unmarked_block_is_caught(tmp_path):
    doc = tmp_path / "doc.md"
    doc.write_text("text\n\n```\nchoreo run --what\n```\n\n  ```text\n  fine\n  ```\n")
    assert [block.info for block in blocks_of(doc)] == ["", "text"]


def test_a_show_or_a_command_in_a_text_block_is_caught(tmp_path):
    doc = tmp_path / "doc.md"
    doc.write_text("```text\nversion: 1\nsteps:\n  - play: 1\n```\n```text\n$ choreo plan x.yaml\n```\n"
                   "```text\nsteps: the word\nchoreo: the program\n```\n")
    blocks = [Block(ROOT / "doc.md", block.line, block.info, block.text) for block in blocks_of(doc)]
    assert hidden(blocks) == ["doc.md:1: a show", "doc.md:6: $ choreo plan x.yaml"]


# --- links -------------------------------------------------------------------------------------

_LINK = re.compile(r"\[[^\]]*\]\(([^)\s]+)\)")


def without_blocks(path: Path) -> str:
    return re.sub(r"^ *```.*?^ *```", "", path.read_text(encoding="utf-8"), flags=re.S | re.M)


def prose(path: Path) -> str:
    """The file without its code: fenced blocks and inline code hold no links."""
    return re.sub(_INLINE_CODE, "", without_blocks(path))


def anchors(path: Path) -> set[str]:
    """GitHub's anchors for a Markdown file's headings: lower case, punctuation dropped, spaces to -."""
    found: set[str] = set()
    for heading in re.findall(r"^#+ +(.+)$", without_blocks(path) if path.suffix == ".md" else "", re.M):
        slug = re.sub(r"[^\w\- ]", "", heading.strip().lower().replace("`", "")).replace(" ", "-")
        found.add(slug)
    return found


def broken_links(doc: Path) -> list[str]:
    broken = []
    for target in _LINK.findall(prose(doc)):
        if re.match(r"[a-z]+:", target):
            continue  # https://, mailto: and the like
        file, _, anchor = target.partition("#")
        path = (doc.parent / file).resolve() if file else doc
        if not path.exists():
            broken.append(f"{target}: no such file")
        elif anchor and anchor not in anchors(path):
            broken.append(f"{target}: no heading '{anchor}' in {path.relative_to(doc.parent.parent)}")
    return broken


@pytest.mark.parametrize("doc", DOCS, ids=lambda doc: str(doc.relative_to(ROOT)))
def test_every_relative_link_leads_somewhere(doc):
    assert broken_links(doc) == []


def test_a_broken_link_is_caught(tmp_path):
    doc = tmp_path / "doc.md"
    (tmp_path / "there.md").write_text("# There\n\n## Some `code`: here\n")
    doc.write_text("[a](there.md) [b](there.md#some-code-here) [c](gone.md) [d](there.md#nowhere) "
                   "[e](https://example.com/x) `[f](ignored.md)` `code over\n[g](gone2.md)`\n")
    assert broken_links(doc) == ["gone.md: no such file",
                                 f"there.md#nowhere: no heading 'nowhere' in {doc.parent.name}/there.md"]


# --- the README --------------------------------------------------------------------------------


def test_the_readme_fits_on_a_page():
    assert len(README.read_text(encoding="utf-8").splitlines()) <= README_MAX_LINES


def test_the_readme_links_every_doc():
    linked = {(ROOT / target.partition("#")[0]).resolve() for target in _LINK.findall(prose(README))}
    assert sorted(str(d.relative_to(ROOT)) for d in DOCS[1:] if d.resolve() not in linked) == []


def test_the_readme_lists_every_command():
    """The commands at a glance: the table names each of choreo's commands, and no other."""
    parser = build_parser()
    (subparsers,) = [a for a in parser._actions if a.__class__.__name__ == "_SubParsersAction"]
    listed = set(re.findall(r"^\| `choreo ([a-z]+)", README.read_text(encoding="utf-8"), re.M))
    assert listed == set(subparsers.choices)


def test_the_readme_gives_the_test_command_ci_runs():
    """CI (.ci/run) runs the README's test command: the README's line runs the suite as CI does."""
    ci = next(line.strip() for line in (ROOT / ".ci/run").read_text().splitlines()
              if "-m pytest" in line and not line.lstrip().startswith("#"))
    readme = [line for block in blocks_of(README) if block.kind == "sh"
              for line, _ in command_lines(block) if "-m pytest" in line]
    assert readme and [line.split("&&")[-1].strip() for line in readme] == [ci] * len(readme)


# --- the code's citations of the docs -------------------------------------------------------------

_CITED = re.compile(r"(?P<file>\bREADME(?:\.md)?|\bdocs/\w+\.md|\b[A-Z][A-Z_]+\.md)(?=(?P<rest>.{0,120}))")


def headings(path: Path) -> set[str]:
    return {heading.strip().replace("`", "") for heading in re.findall(r"^#+ +(.+)$", without_blocks(path), re.M)}


def citations(source: str) -> Iterator[tuple[str, str | None]]:
    """(file, section or None) for each Markdown file the source names: `docs/x.md, "A: B"` is
    section B under A; `docs/x.md: A)` section A; the README is always cited with its section."""
    text = re.sub(r"\s*\n\s*(#\s*)?", " ", source)  # a citation may run over a comment's lines
    for match in _CITED.finditer(text):
        rest = match["rest"]
        section = re.match(r'[,:] *"([^"]+)"', rest) or re.match(r"[,:] *([^)\"]+)\)", rest)
        yield match["file"], section[1].strip() if section else None


def citation_problems(source: str) -> list[str]:
    problems = []
    for file, section in citations(source):
        path = ROOT / ("README.md" if file.startswith("README") else file)
        if not path.is_file():
            problems.append(f"{file}: no such file in the repository")
        elif section is None and path == README:
            problems.append(f"{file}: name the section (the README is a page of links; the reference is in docs/)")
        elif section and not set(section.split(": ")) <= headings(path):
            problems.append(f"{file}, {section!r}: no such heading")
    return problems


def test_the_code_cites_docs_that_exist():
    """choreo's modules say where a fact is explained: the file and the heading they name exist."""
    problems = [f"{path.relative_to(ROOT)}: {problem}" for path in source_files()
                for problem in citation_problems(path.read_text(encoding="utf-8"))]
    assert problems == []


def test_a_citation_of_a_missing_doc_or_heading_is_caught():
    source = '''"""As ERRATA.md says; (docs/hardware.md: Board layouts); see the README.
    docs/hardware.md, "Errata: The config word"; docs/hardware.md, "Errata: The
    # config word"; docs/live.md, "Nowhere"; README, "Exit codes"; "docs/live.md") f("x")."""'''
    assert citation_problems(source) == [
        "ERRATA.md: no such file in the repository",
        "README: name the section (the README is a page of links; the reference is in docs/)",
        "docs/live.md, 'Nowhere': no such heading"]


# --- the architecture page draws the layers the contract enforces ---------------------------------


def drawn_layers(text: str) -> dict[int, set[str]]:
    """The numbered lines of docs/architecture.md's layer picture: layer -> the modules and
    packages on it (layer 0 names `choreo` and its base modules after a colon)."""
    drawn: dict[int, set[str]] = {}
    for number, names in re.findall(r"^ *(\d+) +(choreo.*)$", text, re.M):
        if ":" in names.split("  ")[0]:
            base = names.split(":", 1)[1]
            drawn[int(number)] = {"choreo"} | {f"choreo.{name.strip()}" for name in base.split(",")}
        else:
            drawn[int(number)] = set(re.findall(r"choreo\.[\w.]+", names.split("  ")[0]))
    return drawn


def test_the_architecture_page_draws_the_layers_the_contract_enforces():
    from test_layers import LAYERS

    (picture,) = [block for block in blocks_of(ROOT / "docs/architecture.md")
                  if block.kind == "text" and "choreo.wire" in block.text]
    enforced = {number: set(names) for number, names in enumerate(LAYERS)}
    assert drawn_layers(picture.text) == enforced
    assert drawn_layers(picture.text.replace(" | choreo.sim", "")) != enforced  # the reading sees a package gone


def test_the_architecture_page_names_every_module():
    """What each package holds: every module of the package is named there (a new one too)."""
    text = (ROOT / "docs/architecture.md").read_text(encoding="utf-8")
    start = text.index("## What each package holds")
    section = text[start:text.index("\n## ", start + 1)]
    named = set(re.findall(r"`([\w.]+)`", section))
    unnamed = [str(path.relative_to(ROOT)) for path in source_files()
               if path.name != "__init__.py" and path.stem not in named]
    assert unnamed == []


# --- the files and names the prose points at --------------------------------------------------------

_PATH = re.compile(r"(?<![/\w.])((?:choreo|tests|bench|shows|schemas|foxglove|docs)/[\w./-]*)")
_DOTTED = re.compile(r"(?<![/\w.])choreo(?:\.\w+)+")
_LOG_NAMES = {RESULT_METADATA_NAME}  # what a log's records are called, not modules (the schemas' are capitalised)


def pointed_at(doc: Path) -> tuple[set[str], set[str]]:
    """The repository paths and choreo's dotted names in a doc's inline code (not in its blocks,
    where a command's output may name a file it just wrote)."""
    spans = [re.sub(r"\s+", " ", span) for span in re.findall(_INLINE_CODE, without_blocks(doc))]
    paths = {path.rstrip(".") for span in spans for path in _PATH.findall(span)}
    names = {name for span in spans for name in _DOTTED.findall(span)
             if name.split(".")[1].islower() and name not in _LOG_NAMES}
    return paths, names


def missing_name(dotted: str) -> str | None:
    """The dotted name, if no module of that name exists and no attribute of its module either."""
    parts = dotted.split(".")
    for cut in range(len(parts), 0, -1):
        try:
            target: object = importlib.import_module(".".join(parts[:cut]))
        except ModuleNotFoundError:
            continue
        for attribute in parts[cut:]:
            if not hasattr(target, attribute):
                return dotted
            target = getattr(target, attribute)
        return None
    return dotted


@pytest.mark.parametrize("doc", DOCS, ids=lambda doc: str(doc.relative_to(ROOT)))
def test_the_files_and_names_a_doc_points_at_exist(doc):
    """`choreo/wire/protocol.py`, `choreo.clock.VirtualTime`: modules move; the docs follow."""
    paths, names = pointed_at(doc)
    missing = sorted(path for path in paths if not (ROOT / path).exists())
    missing += sorted(name for name in names if missing_name(name))
    assert missing == []


def test_a_path_or_name_that_moved_is_caught(tmp_path):
    doc = tmp_path / "doc.md"
    doc.write_text("`choreo/protocol.py`, `choreo/wire/protocol.py`, `/choreo/go`, `choreo.urlhandler.register()`,"
                   " `choreo.clock.VirtualTime`, `choreo.clock.Nothing`, `choreo.Tx`\n```text\nchoreo/gone.py\n```\n")
    paths, names = pointed_at(doc)
    assert paths == {"choreo/protocol.py", "choreo/wire/protocol.py"}
    gone = [name for name in sorted(names) if missing_name(name)]
    assert gone == ["choreo.clock.Nothing", "choreo.urlhandler.register"]
