"""A starter show written from a Heart to Heart 4 project: the text `choreo import` prints.

The show is written by hand rather than by a YAML dumper, so that it reads like the examples
(comments, one line a motion) and so that every scalar is written the one way every YAML reader
takes as text: names that are plain words stay plain, anything else is double-quoted with
escapes (YAML 1.1 reads `yes` as true, YAML 1.2 reads `1e3` as a number, a raw U+2028 is a line
break to both). The result always loads with `load_show`: tests hold it to that.
"""

from __future__ import annotations

import os
import unicodedata
from dataclasses import dataclass
from importlib.resources import files
from pathlib import Path

from choreo import SCHEMAS
from choreo.show.hth4 import LAYOUT_FIRST_SLOT, Project, ProjectSlot
from choreo.show.model import MOTION_NAME_MAX, hidden_character, is_motion_name
from choreo.show.schema import SCHEMA_FILE, modeline

NAME_MAX = 200  # characters of a show's `name` and of an `hth4_name` (the schema's maxLength)

# Words some YAML reader takes for true, false or nothing when written plain.
_YAML_WORDS = frozenset(("y", "n", "yes", "no", "true", "false", "on", "off", "null"))


@dataclass(frozen=True)
class StarterMotion:
    """A `motions:` entry: its key, its slot and the HTH4 name when that could not be the key."""

    key: str
    number: int
    hth4_name: str | None = None


def starter_motions(slots: tuple[ProjectSlot, ...]) -> list[StarterMotion]:
    """A key for every slot: its HTH4 name where that is a valid, unused name; else `motion_N`.

    Valid names are taken first so that a derived key never takes a name the project uses.
    """
    keys: set[str] = set()
    named: dict[int, str] = {}
    for slot in slots:
        if is_motion_name(slot.name) and len(slot.name) <= MOTION_NAME_MAX and slot.name not in keys:
            keys.add(slot.name)
            named[slot.number] = slot.name
    motions = []
    for slot in slots:
        if slot.number in named:
            motions.append(StarterMotion(named[slot.number], slot.number))
            continue
        key = f"motion_{slot.number}"
        while key in keys:
            key += "_"
        keys.add(key)
        motions.append(StarterMotion(key, slot.number, _one_line(slot.name)[:NAME_MAX].strip() or None))
    return motions


def starter_show(project: Project, schema: str | None = None) -> str:
    """The show's text: a header, `version`, `name`, `robot.layout`, `motions:`, one play.

    `schema` is the path or URL of the show schema as seen from where the show will be saved,
    for editors; None leaves that line out (stdout: nobody knows where it will be saved).
    """
    motions = starter_motions(project.motions)
    source = _one_line(Path(project.path).name)
    lines = [modeline(schema), "#"] if schema else []
    lines += [
        f"# A starter show written by `choreo import` from the Heart to Heart 4 project {source}.",
        f"# The project puts slot 0 at ROM 0x{LAYOUT_FIRST_SLOT[project.layout]:04X}, "
        f"so the board's layout is {project.layout};"
        f" {len(motions)} slot{'s' if len(motions) != 1 else ''} hold{'' if len(motions) != 1 else 's'} a motion.",
        "# Add each motion's `duration:`, then the steps; `choreo plan` prints the timeline.",
        "version: 1",
    ]
    title = _show_name(project.title)
    if title:
        lines.append(f"name: {yaml_text(title)}")
    lines += ["robot:", f"  layout: {project.layout}", "motions:"]
    for motion in motions:
        beside = f", hth4_name: {yaml_text(motion.hth4_name)}" if motion.hth4_name else ""
        lines.append(f"  {yaml_key(motion.key)}: {{number: {motion.number}{beside}}}")
    lines += ["steps:", f"  - play: {yaml_key(motions[0].key)}", "  - wait: done", ""]
    return "\n".join(lines)


def schema_reference(show: Path) -> str | None:
    """The installed show schema as a path relative to where `show` will be, if there is one."""
    schema = files(SCHEMAS) / SCHEMA_FILE
    if not isinstance(schema, Path) or not schema.is_file():
        return None  # inside a zip: no file an editor could open
    try:
        relative = os.path.relpath(schema.resolve(), show.resolve().parent)
    except ValueError:  # another drive (Windows)
        return schema.resolve().as_uri()
    return Path(relative).as_posix()


# --------------------------------------------------------------------------- YAML scalars


def yaml_key(name: str) -> str:
    """A motion name as a key or a `play:` value: plain if it can only be read as that text."""
    if is_motion_name(name) and name.lower() not in _YAML_WORDS:
        return name
    return yaml_text(name)


def yaml_text(text: str) -> str:
    """`text` as a double-quoted YAML scalar that any YAML reader reads back as exactly `text`."""
    out = ['"']
    for ch in text:
        if ch in '"\\':
            out.append("\\" + ch)
        elif _quotable(ch):
            out.append(ch)
        else:
            code = ord(ch)
            out.append(f"\\x{code:02x}" if code <= 0xFF else f"\\u{code:04x}" if code <= 0xFFFF else f"\\U{code:08x}")
    out.append('"')
    return "".join(out)


def _quotable(ch: str) -> bool:
    """Printable in YAML and not a line break: may stand as itself inside double quotes."""
    code = ord(ch)
    if 0x20 <= code <= 0x7E:
        return True
    if code in (0x2028, 0x2029, 0xFEFF):  # line and paragraph separators, byte order mark
        return False
    return 0xA0 <= code <= 0xD7FF or 0xE000 <= code <= 0xFFFD or 0x10000 <= code <= 0x10FFFF


def _show_name(title: str | None) -> str | None:
    """The project title as a show name: one line, within the schema's length."""
    if not title:
        return None
    return _one_line(title)[:NAME_MAX].strip() or None


def _one_line(text: str) -> str:
    """`text` as `choreo validate` takes a name (`hidden_character`): control characters and
    line breaks as spaces, runs of spaces as one, and what cannot be seen or would reorder the
    letters around it (bidi overrides, zero-width characters) left out."""
    kept = "".join(" " if unicodedata.category(ch) in ("Cc", "Zl", "Zp") else "" if hidden_character(ch) else ch
                   for ch in text)
    return " ".join(kept.split())
