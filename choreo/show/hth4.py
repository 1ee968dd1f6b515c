"""Heart to Heart 4 project files (`.h4p`): which motions a board holds, and where it keeps them.

A project is what the owner of a real board has at hand, and it answers the question a show
cannot: at which ROM address each motion slot starts, i.e. which layout the board's motions
were written with. HTH4 2.2 and later put slot 0 at 0x0B80; the source document's frames (the
`seed` layout) CALL 0x0BB8. Each slot is `SLOT_SIZE` bytes after the one before.

The file is .NET `XmlSerializer` output: root `Rcb4`; `ProjectTitle`; and
`MotionDataCollection`, one `DictionaryEntry` a slot with `Key` (`M001`..`M120`) and a `Value`
(`xsi:type="Motion"`) holding `Number` (0-based slot), `Name`, `MotionData` (hex strings, none
for an unused slot) and `Address` (decimal). Tags are matched by local name, so a namespaced
file reads the same as a plain one. Its text is UTF-8 (with or without a byte order mark),
UTF-16, or what its XML declaration says: Japanese projects are often `Shift_JIS`, which the
XML parser cannot decode itself, so the bytes are decoded here (`decode_project`).

The file comes from elsewhere, so it is read defensively: its size is capped, and a DOCTYPE is
refused before anything in it is expanded (HTH4 never writes one; a DTD is how entity bombs
and external entities get in).
"""

from __future__ import annotations

import codecs
import re
import xml.etree.ElementTree as ET
from dataclasses import dataclass
from pathlib import Path

from choreo.errors import UsageError
from choreo.wire.layouts import LAYOUTS
from choreo.numtext import whole_number
from choreo.wire.protocol import MOTION_SLOTS, SLOT_SIZE
from choreo.textfit import visible
from choreo.userfile import read_input

# Where each layout puts slot 0 (choreo.wire.layouts is the one place the layouts are defined; the
# show schema's `robot.layout` enum lists their names too, and a test holds them equal).
LAYOUT_FIRST_SLOT: dict[str, int] = {layout.name: layout.first_slot for layout in LAYOUTS.values()}

# Real projects are a few hundred KiB to a few MiB; the cap bounds memory and time on a bad file.
MAX_PROJECT_BYTES = 16 * 1024 * 1024


class ProjectError(UsageError):
    """A file that cannot be imported as a Heart to Heart 4 project (exit 2, one line)."""


@dataclass(frozen=True)
class ProjectSlot:
    """One `DictionaryEntry` of the project's `MotionDataCollection`."""

    key: str  # HTH4's own label for the slot, `M001`..`M120`
    number: int  # the slot, 0..119: what a show plays
    name: str  # as the author typed it in HTH4 (often Japanese); may be empty
    address: int | None  # the slot's first ROM byte, if the file gives it
    has_data: bool  # False for an unused slot (empty `MotionData`)


@dataclass(frozen=True)
class Project:
    """What a show needs from a project: its title, its layout and its motions."""

    path: str
    title: str | None
    layout: str  # one of LAYOUT_NAMES, read from the slots' addresses
    motions: tuple[ProjectSlot, ...]  # the slots that hold motion data, by number


def read_project(path: str | Path) -> Project:
    """The project at `path`; `ProjectError` (or `InputError`) with one line if it cannot be imported."""
    data = read_input(path, "Heart to Heart 4 project", MAX_PROJECT_BYTES)
    return parse_project(data, visible(str(path)))


def parse_project(data: bytes, path: str = "<project>") -> Project:
    """A project from the file's bytes; `path` names it in messages."""
    root = _parse_xml(decode_project(data, path), path)
    if _local(root.tag) != "Rcb4":
        raise ProjectError(f"{path}: not a Heart to Heart 4 project: the root element is <{_local(root.tag)}>, "
                           "not <Rcb4>")
    collection = _child(root, "MotionDataCollection")
    if collection is None:
        raise ProjectError(f"{path}: not a Heart to Heart 4 project: <Rcb4> has no <MotionDataCollection>")
    slots = _slots(collection, path)
    motions = tuple(sorted((s for s in slots if s.has_data), key=lambda s: s.number))
    if not motions:
        raise ProjectError(f"{path}: no motions: every slot's MotionData is empty (write motions in Heart to Heart 4 "
                           "and save the project)")
    title = _text(_child(root, "ProjectTitle")).strip() or None
    return Project(path, title, layout_of(slots, path), motions)


def layout_of(slots: list[ProjectSlot], path: str = "<project>") -> str:
    """The layout every slot's address fits; `ProjectError` naming the addresses found if none does."""
    placed = sorted((s for s in slots if s.address is not None), key=lambda s: s.number)
    if not placed:
        raise ProjectError(f"{path}: no slot gives its Address, so the board's layout is unknown: set `robot.layout` "
                           "in the show by hand")
    first = placed[0]
    for layout, base in LAYOUT_FIRST_SLOT.items():
        if first.address != base + first.number * SLOT_SIZE:
            continue
        odd = next((s for s in placed if s.address != base + s.number * SLOT_SIZE), None)
        if odd is None:
            return layout
        expected = base + odd.number * SLOT_SIZE
        raise ProjectError(
            f"{path}: slot addresses fit no layout choreo knows: slot {first.number} at {_address(first.address)} "
            f"fits {layout}, but slot {odd.number} is at {_address(odd.address)}, not {_address(expected)}"
        )
    known = " or ".join(_address(base + first.number * SLOT_SIZE, layout) for layout, base in LAYOUT_FIRST_SLOT.items())
    raise ProjectError(
        f"{path}: slot addresses fit no layout choreo knows: slot {first.number} is at {_address(first.address)}, "
        f"expected {known}, each slot {SLOT_SIZE} bytes after the last"
    )


# --------------------------------------------------------------------------- XML


class _Refused(Exception):
    """A DOCTYPE: stop before the parser reads its declarations."""


class _TreeBuilder(ET.TreeBuilder):
    def doctype(self, name: str, pubid: str | None, system: str | None) -> None:
        raise _Refused


def _parse_xml(text: str, path: str) -> ET.Element:
    parser = ET.XMLParser(target=_TreeBuilder())
    try:
        parser.feed(text)  # text, not bytes: the parser ignores the declared encoding
        return parser.close()
    except _Refused:
        raise ProjectError(f"{path}: the file declares a DOCTYPE, which Heart to Heart 4 never writes: refused "
                           "(entities could expand without bound)") from None
    except ET.ParseError as exc:
        raise ProjectError(f"{path}: not a Heart to Heart 4 project (not XML: {exc})") from None


# Byte order marks, longest first (UTF-32's begin with UTF-16's).
# Each codec named here reads its mark and drops it.
_BOMS = ((codecs.BOM_UTF32_LE, "utf-32"), (codecs.BOM_UTF32_BE, "utf-32"), (codecs.BOM_UTF8, "utf-8-sig"),
         (codecs.BOM_UTF16_LE, "utf-16"), (codecs.BOM_UTF16_BE, "utf-16"))
_DECLARED = re.compile(rb"""\A<\?xml[^>]*?\sencoding\s*=\s*(["'])([^"'<>]*)\1""")
_DECLARATION_MAX = 4096  # bytes the XML declaration is sought in (it is the first thing in the file)
# What Windows means by these names: code page 932, Shift_JIS with Microsoft's extensions
# (NEC and IBM characters, a different tilde), which .NET writes under the name Shift_JIS.
_WINDOWS_NAMES = {"shift_jis": "cp932", "shift-jis": "cp932", "sjis": "cp932", "x-sjis": "cp932",
                  "windows-31j": "cp932", "ms_kanji": "cp932", "csshiftjis": "cp932"}
# Python codecs that are not a file's character set (they unescape or transform text).
_NOT_CHARSETS = frozenset(("unicode-escape", "raw-unicode-escape", "idna", "punycode", "undefined", "charmap"))


def decode_project(data: bytes, path: str = "<project>") -> str:
    """The project's text: by its byte order mark, else by the encoding its XML declaration
    names, else UTF-8 (XML's default); `ProjectError` for an encoding choreo does not know or
    bytes that are not in it."""
    encoding = _encoding_of(data, path)
    try:
        return data.decode(encoding)
    except UnicodeError as exc:
        start = getattr(exc, "start", None)
        where = f"byte {start} (0x{data[start]:02x})" if isinstance(start, int) and start < len(data) else "a byte"
        raise ProjectError(f"{path}: not a Heart to Heart 4 project: {where} is not {encoding} text "
                           "(the encoding it declares or implies)") from None


def _encoding_of(data: bytes, path: str) -> str:
    for bom, encoding in _BOMS:
        if data.startswith(bom):
            return encoding
    unmarked = _utf16_without_mark(data)
    if unmarked:
        return unmarked
    declared = _DECLARED.match(data[:_DECLARATION_MAX])
    if declared is None:
        return "utf-8"
    name = declared.group(2).decode("latin-1")[:100]
    try:
        info = codecs.lookup(_WINDOWS_NAMES.get(name.lower(), name)) if name.isascii() and name.isprintable() else None
    except LookupError:
        info = None
    if info is None or not info._is_text_encoding or info.name in _NOT_CHARSETS:
        raise ProjectError(f"{path}: the file declares encoding {visible(repr(name))}, which choreo cannot read: "
                           "save the project again in Heart to Heart 4, or as UTF-8")
    if info.name.startswith(("utf-16", "utf-32")):
        raise ProjectError(f"{path}: the file declares encoding {visible(repr(name))} but has no byte order mark and "
                           "does not start with '<' in it: save the project again in Heart to Heart 4, or as UTF-8")
    return info.name


_XML_SPACE = b" \t\r\n"


def _utf16_without_mark(data: bytes) -> str | None:
    """`utf-16-le`/`-be` for UTF-16 text without a byte order mark: its first character that is
    not XML white space (which may come before the root when there is no declaration) is `<`."""
    for index in range(0, min(len(data), _DECLARATION_MAX) - 1, 2):
        pair = data[index:index + 2]
        if pair[0] in _XML_SPACE and pair[1] == 0 or pair[1] in _XML_SPACE and pair[0] == 0:
            continue
        return {b"<\0": "utf-16-le", b"\0<": "utf-16-be"}.get(pair)
    return None


def _local(tag: str) -> str:
    """`{namespace}Name` and `Name` alike as `Name`."""
    return tag.rsplit("}", 1)[-1]


def _child(element: ET.Element, name: str) -> ET.Element | None:
    return next((c for c in element if _local(c.tag) == name), None)


def _text(element: ET.Element | None) -> str:
    return (element.text or "") if element is not None else ""


# --------------------------------------------------------------------------- slots


def _slots(collection: ET.Element, path: str) -> list[ProjectSlot]:
    """Every slot of the collection, checked: numbers whole, in range and given once."""
    slots: list[ProjectSlot] = []
    seen: dict[int, str] = {}
    for index, entry in enumerate(c for c in collection if _local(c.tag) == "DictionaryEntry"):
        slot = _slot(entry, index, path)
        if slot.number in seen:
            raise ProjectError(f"{path}: slot number {slot.number} is given twice ({seen[slot.number]} and {slot.key})")
        seen[slot.number] = slot.key
        slots.append(slot)
    return slots


def _slot(entry: ET.Element, index: int, path: str) -> ProjectSlot:
    key = visible(_text(_child(entry, "Key")).strip()[:40]) or f"entry {index + 1}"  # only messages show it
    value = _child(entry, "Value")
    if value is None:
        raise ProjectError(f"{path}: slot {key} has no <Value>")
    number = _whole(value, "Number", key, path)
    if number is None:
        raise ProjectError(f"{path}: slot {key} has no <Number>")
    if not 0 <= number < MOTION_SLOTS:
        raise ProjectError(f"{path}: slot {key} has Number {number}, outside the board's slots 0..{MOTION_SLOTS - 1}")
    data = _child(value, "MotionData")
    has_data = data is not None and any(_text(packet).strip() for packet in data)
    return ProjectSlot(key, number, _text(_child(value, "Name")), _whole(value, "Address", key, path), has_data)


def _whole(value: ET.Element, field: str, key: str, path: str) -> int | None:
    text = _text(_child(value, field)).strip()
    if not text:
        return None
    number = whole_number(text, max_digits=9)
    if number is None:
        raise ProjectError(f"{path}: slot {key} has {field} {text[:20]!r}, not a whole number (up to 9 digits)")
    return number


def _address(address: int | None, layout: str = "") -> str:
    """`2944 (0x0B80)`: HTH4 writes decimal, addresses are read in hex."""
    return f"{address} (0x{address:04X}{', ' + layout if layout else ''})" if address is not None else "no address"
