"""`choreo import PROJECT.h4p`: a Heart to Heart 4 project becomes a show `choreo validate` accepts.

The tests write project files in HTH4's own format (.NET XmlSerializer output: `Rcb4` root,
120 `DictionaryEntry` slots `M001`..`M120`, unused slots with empty `MotionData`), in both
layouts, with Japanese names, full-width brackets and arrows, and names that cannot be keys.
Every bad file is exit 2 with one line on stderr and nothing on stdout.
"""

from __future__ import annotations

import os
import subprocess
import sys
from dataclasses import dataclass, field
from pathlib import Path
from xml.sax.saxutils import escape

import pytest
import yaml
from hypothesis import given, settings
from hypothesis import strategies as st

import choreo.show.hth4
from choreo.cli import main
from choreo.errors import ShowError
from choreo.show.hth4 import LAYOUT_FIRST_SLOT, parse_project, read_project
from choreo.show.load import load_show, load_show_bytes
from choreo.show.model import hidden_character
from choreo.show.starter import starter_show, yaml_key, yaml_text

SLOT_SIZE = 2048
PACKET = "0a 00 20 00 00 00 02 00 0a 36"  # one instruction packet, as HTH4 stores it (hex text)


@dataclass
class Slot:
    number: int
    name: str
    packets: list[str] = field(default_factory=lambda: [PACKET, PACKET])
    address: int | None = None  # None: where the project's layout puts it


def project_xml(
    motions: list[Slot],
    layout: str = "hth4-2.2",
    title: str | None = "KXR デモ",
    namespace: str | None = None,
    slots: int = 120,
) -> bytes:
    """A project as HTH4 saves it: every slot listed, the unused ones with empty MotionData."""
    rest = list(motions)  # slots beyond `slots` (or a second one with a number) are keyed X<number>
    entries = []
    for number in range(slots):
        slot = next((s for s in rest if s.number == number), None)
        if slot is not None:
            rest.remove(slot)
        else:
            slot = Slot(number, f"M{number + 1:03d}", packets=[])
        entries.append(_entry(slot, f"M{number + 1:03d}", LAYOUT_FIRST_SLOT[layout]))
    entries += [_entry(slot, f"X{slot.number}", LAYOUT_FIRST_SLOT[layout]) for slot in rest]
    xmlns = f' xmlns="{namespace}"' if namespace else ""
    title_xml = f"  <ProjectTitle>{escape(title)}</ProjectTitle>\n" if title is not None else ""
    return (
        '<?xml version="1.0" encoding="utf-8"?>\n'
        f'<Rcb4 xmlns:xsi="http://www.w3.org/2001/XMLSchema-instance" xmlns:xsd="http://www.w3.org/2001/XMLSchema"{xmlns}>\n'
        f"{title_xml}"
        "  <Config>\n    <unsignedByte>27</unsignedByte>\n    <unsignedByte>130</unsignedByte>\n  </Config>\n"
        "  <MotionDataCollection>\n" + "".join(entries) + "  </MotionDataCollection>\n</Rcb4>\n"
    ).encode("utf-8")


def _entry(slot: Slot, key: str, first: int) -> str:
    address = first + slot.number * SLOT_SIZE if slot.address is None else slot.address
    packets = "".join(f'<anyType xsi:type="xsd:string">{p}</anyType>' for p in slot.packets)
    data = f"<MotionData>{packets}</MotionData>" if packets else "<MotionData />"
    return (
        f'    <DictionaryEntry>\n      <Key xsi:type="xsd:string">{key}</Key>\n'
        f'      <Value xsi:type="Motion"><Number>{slot.number}</Number><Name>{escape(slot.name)}</Name>'
        f"<Date>2024/04/01 12:00:00</Date>{data}<Address>{address}</Address></Value>\n    </DictionaryEntry>\n"
    )


def write_project(tmp_path: Path, content: bytes, name: str = "robot.h4p") -> Path:
    path = tmp_path / name
    path.write_bytes(content)
    return path


def imported(capsys, path: Path) -> str:
    assert main(["import", str(path)]) == 0
    out, err = capsys.readouterr()
    assert err == ""
    return out


JAPANESE = [
    Slot(0, "ホームポジション"),
    Slot(3, "歩く（前）→"),  # full-width brackets and an arrow: not a key, kept beside it
    Slot(4, "歩く"),
    Slot(7, "wave hello"),  # a space: not a key
    Slot(12, "右手を振る2"),
    Slot(119, "最後"),
]


# ------------------------------------------------------------------ good projects


@pytest.mark.parametrize("layout", ["hth4-2.2", "seed"])
def test_a_project_becomes_a_show_that_validates_with_its_layout_names_and_numbers(tmp_path, capsys, layout):
    path = write_project(tmp_path, project_xml(JAPANESE, layout=layout))
    text = imported(capsys, path)
    show = load_show_bytes(text.encode("utf-8"), "imported.yaml")
    assert show.name == "KXR デモ"
    assert show.robot.layout == layout
    assert {name: m.number for name, m in show.motions.items()} == {
        "ホームポジション": 0,
        "motion_3": 3,
        "歩く": 4,
        "motion_7": 7,
        "右手を振る2": 12,
        "最後": 119,
    }
    assert [(s.kind.value, s.motion, s.motion_name) for s in show.steps] == [
        ("play", 0, "ホームポジション"), ("wait_done", None, None)]


def test_a_name_that_cannot_be_a_key_is_kept_beside_the_derived_key(tmp_path, capsys):
    text = imported(capsys, write_project(tmp_path, project_xml(JAPANESE)))
    motions = yaml.safe_load(text)["motions"]
    assert motions["motion_3"] == {"number": 3, "hth4_name": "歩く（前）→"}
    assert motions["motion_7"] == {"number": 7, "hth4_name": "wave hello"}
    assert motions["歩く"] == {"number": 4}
    assert "歩く（前）→" in text, "written as itself, not as escapes"


def test_empty_slots_are_skipped(tmp_path, capsys):
    text = imported(capsys, write_project(tmp_path, project_xml([Slot(5, "bow"), Slot(6, "blank", packets=["  "])])))
    assert yaml.safe_load(text)["motions"] == {"bow": {"number": 5}}


def test_a_namespaced_project_reads_like_a_plain_one(tmp_path, capsys):
    plain = imported(capsys, write_project(tmp_path, project_xml(JAPANESE), "plain.h4p"))
    spaced = imported(capsys, write_project(tmp_path, project_xml(JAPANESE, namespace="http://kondo-robot.com/rcb4"),
                                            "ns.h4p"))
    assert spaced.replace("ns.h4p", "plain.h4p") == plain


def test_names_yaml_would_read_as_something_else_survive(tmp_path, capsys):
    slots = [Slot(1, "yes"), Slot(2, "Null"), Slot(3, "on"), Slot(4, "1e3"), Slot(5, "a: b"), Slot(6, ' "q" \\ #x '),
             Slot(7, "tab\there"), Slot(8, "line\u2028break")]
    text = imported(capsys, write_project(tmp_path, project_xml(slots, title="0o17")))
    show = load_show_bytes(text.encode("utf-8"))
    assert show.name == "0o17"
    assert {n: m.number for n, m in show.motions.items()} == {
        "yes": 1, "Null": 2, "on": 3, "motion_4": 4, "motion_5": 5, "motion_6": 6, "motion_7": 7, "motion_8": 8}
    assert show.steps[0].motion_name == "yes"
    kept = {m["number"]: m.get("hth4_name") for m in yaml.safe_load(text)["motions"].values()}
    assert kept == {1: None, 2: None, 3: None, 4: "1e3", 5: "a: b", 6: '"q" \\ #x', 7: "tab here", 8: "line break"}


def test_keys_stay_unique_when_names_repeat_or_look_derived(tmp_path, capsys):
    slots = [Slot(2, "wave"), Slot(3, "歩く（前）"), Slot(9, "wave"), Slot(10, "motion_3"), Slot(11, ""),
             Slot(12, "x" * 65)]
    text = imported(capsys, write_project(tmp_path, project_xml(slots)))
    load_show_bytes(text.encode("utf-8"))
    motions = yaml.safe_load(text)["motions"]
    assert motions == {
        "wave": {"number": 2},
        "motion_3": {"number": 10},
        "motion_3_": {"number": 3, "hth4_name": "歩く（前）"},
        "motion_9": {"number": 9, "hth4_name": "wave"},
        "motion_11": {"number": 11},
        "motion_12": {"number": 12, "hth4_name": "x" * 65},
    }


def test_the_first_motion_is_the_lowest_slot_and_no_title_means_no_name(tmp_path, capsys):
    path = write_project(tmp_path, project_xml([Slot(40, "pose"), Slot(8, "bow")], title=None))
    show = load_show_bytes(imported(capsys, path).encode("utf-8"), "starter.yaml")
    assert show.name == "starter"
    assert show.steps[0].motion == 8


def test_a_title_with_line_breaks_becomes_one_line(tmp_path, capsys):
    path = write_project(tmp_path, project_xml(JAPANESE, title="KXR\n  dance\u2028show\t"))
    assert load_show_bytes(imported(capsys, path).encode("utf-8")).name == "KXR dance show"


def test_output_is_utf8_whatever_the_console_encoding(tmp_path):
    path = write_project(tmp_path, project_xml(JAPANESE))
    env = dict(os.environ, PYTHONIOENCODING="ascii")
    done = subprocess.run([sys.executable, "-m", "choreo", "import", str(path)], capture_output=True, env=env,
                          timeout=60)
    assert done.returncode == 0, done.stderr
    assert load_show_bytes(done.stdout).motions["歩く"].number == 4


# ------------------------------------------------------------------ -o


def test_output_file_is_written_and_validates_with_a_schema_line_that_points_at_the_schema(tmp_path, capsys):
    project = write_project(tmp_path, project_xml(JAPANESE))
    (tmp_path / "shows").mkdir()
    show_path = tmp_path / "shows" / "kxr.yaml"
    assert main(["import", str(project), "-o", str(show_path)]) == 0
    out, err = capsys.readouterr()
    assert out == f"{show_path}: 6 motions, layout hth4-2.2: check it with `choreo plan {show_path}`\n" and err == ""
    show = load_show(show_path)
    assert show.robot.layout == "hth4-2.2" and len(show.motions) == 6
    first = show_path.read_text(encoding="utf-8").splitlines()[0]
    assert first.startswith("# yaml-language-server: $schema=")
    schema = first.split("=", 1)[1]
    installed = Path(choreo.show.hth4.__file__).parent.parent / "schemas" / "show.schema.json"
    assert (show_path.parent / schema).resolve() == installed.resolve()
    assert main(["validate", str(show_path)]) == 0


def test_output_dash_is_standard_output_as_for_log_export(tmp_path, capsys, monkeypatch):
    monkeypatch.chdir(tmp_path)
    path = write_project(tmp_path, project_xml(JAPANESE))
    assert main(["import", str(path), "-o", "-"]) == 0
    assert capsys.readouterr().out == imported(capsys, path)
    assert not (tmp_path / "-").exists()


def test_output_never_overwrites(tmp_path, capsys):
    project = write_project(tmp_path, project_xml(JAPANESE))
    existing = tmp_path / "show.yaml"
    existing.write_text("mine\n", encoding="utf-8")
    assert main(["import", str(project), "-o", str(existing)]) == 2
    out, err = capsys.readouterr()
    assert out == ""
    assert err == f"{existing}: already exists; `choreo import` never overwrites a file: give another with -o\n"
    assert existing.read_text(encoding="utf-8") == "mine\n"


def test_output_into_a_missing_folder_is_exit_2(tmp_path, capsys):
    project = write_project(tmp_path, project_xml(JAPANESE))
    assert main(["import", str(project), "-o", str(tmp_path / "no" / "show.yaml")]) == 2
    assert capsys.readouterr().err.count("\n") == 1


# ------------------------------------------------------------------ bad projects


def _moved(first: int) -> bytes:
    return project_xml([Slot(n, f"m{n}", address=first + n * SLOT_SIZE) for n in range(3)], slots=3)


BILLION_LAUGHS = (
    '<?xml version="1.0"?>\n<!DOCTYPE Rcb4 [\n<!ENTITY a "aaaaaaaaaa">\n'
    + "".join(f'<!ENTITY {chr(98 + i)} "{("&" + chr(97 + i) + ";") * 10}">\n' for i in range(9))
    + "]>\n<Rcb4><ProjectTitle>&j;</ProjectTitle></Rcb4>\n"
).encode()

BAD = {
    "not XML": (b"Number,Name,Address\n0,home,2944\n", "not a Heart to Heart 4 project (not XML: "),
    "binary": (bytes(range(256)), "not a Heart to Heart 4 project: byte 128 (0x80) is not utf-8 text"),
    "empty": (b"", "not a Heart to Heart 4 project (not XML: "),
    "another root": (b"<?xml version='1.0'?><Project><MotionDataCollection/></Project>",
                     "the root element is <Project>, not <Rcb4>"),
    "no collection": (b"<Rcb4><ProjectTitle>x</ProjectTitle></Rcb4>", "<Rcb4> has no <MotionDataCollection>"),
    "no motions": (project_xml([]), "no motions: every slot's MotionData is empty"),
    "no slots": (b"<Rcb4><MotionDataCollection/></Rcb4>", "no motions"),
    "unknown addresses": (_moved(0x0BC0), "slot addresses fit no layout choreo knows: slot 0 is at 3008 (0x0BC0), "
                                          "expected 3000 (0x0BB8, seed) or 2944 (0x0B80, hth4-2.2)"),
    "one slot off": (project_xml([Slot(0, "home"), Slot(5, "bow", address=0x0B80 + 5 * SLOT_SIZE + 56)]),
                     "slot 0 at 2944 (0x0B80) fits hth4-2.2, but slot 5 is at 13240 (0x33B8), not 13184 (0x3380)"),
    "mixed layouts": (project_xml([Slot(0, "home"), Slot(2, "bow", address=0x0BB8 + 2 * SLOT_SIZE)]),
                      "fits hth4-2.2, but slot 2 is at 7096 (0x1BB8)"),
    "no addresses": (b"<Rcb4><MotionDataCollection><DictionaryEntry><Key>M001</Key><Value><Number>0</Number>"
                     b"<Name>a</Name><MotionData><anyType>00</anyType></MotionData></Value></DictionaryEntry>"
                     b"</MotionDataCollection></Rcb4>", "no slot gives its Address"),
    "duplicate numbers": (project_xml([Slot(3, "a"), Slot(3, "b")], slots=0),
                          "slot number 3 is given twice (X3 and X3)"),
    "duplicate with a listed slot": (project_xml([Slot(3, "b")]).replace(b"<Number>4</Number>", b"<Number>3</Number>"),
                                     "slot number 3 is given twice (M004 and M005)"),
    "number out of range": (project_xml([Slot(120, "extra")], slots=0),
                            "slot X120 has Number 120, outside the board's slots 0..119"),
    "number not whole": (project_xml([Slot(1, "a")]).replace(b"<Number>1</Number>", b"<Number>one</Number>"),
                         "slot M002 has Number 'one', not a whole number"),
    "no number": (project_xml([Slot(1, "a")]).replace(b"<Number>1</Number>", b""), "slot M002 has no <Number>"),
    "billion laughs": (BILLION_LAUGHS, "declares a DOCTYPE, which Heart to Heart 4 never writes: refused"),
    "external entity": (b'<?xml version="1.0"?><!DOCTYPE Rcb4 [<!ENTITY x SYSTEM "file:///etc/passwd">]><Rcb4>&x;</Rcb4>',
                        "declares a DOCTYPE"),
    "undeclared entity": (b"<Rcb4><ProjectTitle>&x;</ProjectTitle></Rcb4>", "not XML: undefined entity"),
}


def assert_one_line_exit_2(capsys, argv: list[str], expected: str) -> str:
    assert main(argv) == 2
    out, err = capsys.readouterr()
    assert out == ""
    assert err.endswith("\n") and err.count("\n") == 1, err
    assert expected in err, err
    assert "Traceback" not in err
    return err


@pytest.mark.parametrize("case", sorted(BAD))
def test_a_bad_project_is_exit_2_in_one_line(tmp_path, capsys, case):
    content, expected = BAD[case]
    path = write_project(tmp_path, content)
    err = assert_one_line_exit_2(capsys, ["import", str(path)], expected)
    assert err.startswith(f"{path}: ")


def test_a_missing_file_and_a_directory_are_exit_2(tmp_path, capsys):
    assert_one_line_exit_2(capsys, ["import", str(tmp_path / "nope.h4p")],
                           "cannot read the Heart to Heart 4 project: No such file or directory")
    assert_one_line_exit_2(capsys, ["import", str(tmp_path)],
                           "not a regular file (a folder): give a Heart to Heart 4 project")


def test_a_file_over_the_cap_is_refused_before_parsing(tmp_path, capsys, monkeypatch):
    monkeypatch.setattr(choreo.show.hth4, "MAX_PROJECT_BYTES", 1024 * 1024)
    path = write_project(tmp_path, project_xml(JAPANESE) + b" " * (1024 * 1024))
    assert_one_line_exit_2(capsys, ["import", str(path)], "over 1 MiB, too big for a Heart to Heart 4 project")


def test_a_valid_project_still_reads_after_the_bad_ones(tmp_path):
    project = read_project(write_project(tmp_path, project_xml(JAPANESE, layout="seed")))
    assert project.layout == "seed" and [m.number for m in project.motions] == [0, 3, 4, 7, 12, 119]


# ------------------------------------------------------------------ YAML text


@settings(max_examples=300, deadline=None, derandomize=True)
@given(st.text(st.characters(blacklist_categories=("Cs",)), max_size=40))
def test_any_text_reads_back_as_itself(text):
    assert yaml.safe_load(f"k: {yaml_text(text)}\n") == {"k": text}
    assert yaml.safe_load(f"{yaml_key(text)}: 1\n") == {text: 1}


# ------------------------------------------------------------------ encodings (issue 21, item 6)

NIHONGO = [Slot(0, "ホームポジション"), Slot(3, "歩く（前）→"), Slot(4, "歩く"), Slot(5, "①礼～")]


def encoded(slots: list[Slot], codec: str, declared: str | None) -> bytes:
    """The project as HTH4 on a Japanese Windows saves it: the text in `codec`, the XML
    declaration naming `declared` (None: no encoding in the declaration)."""
    text = project_xml(slots).decode("utf-8")
    text = text.replace(' encoding="utf-8"', f' encoding="{declared}"' if declared else "")
    return text.encode(codec)


def names_of(capsys, path: Path) -> dict[int, str]:
    text = imported(capsys, path)
    show = load_show_bytes(text.encode("utf-8"), "imported.yaml")
    assert show.name == "KXR デモ"
    return {m["number"]: m.get("hth4_name", key) for key, m in yaml.safe_load(text)["motions"].items()}


@pytest.mark.parametrize("codec, declared", [
    ("cp932", "Shift_JIS"),  # what .NET writes: code page 932 under the name Shift_JIS
    ("cp932", "shift_jis"),
    ("cp932", "CP932"),
    ("cp932", "Windows-31J"),
    ("euc_jp", "EUC-JP"),
    ("utf-8", None),
    ("utf-8-sig", "utf-8"),
    ("utf-8-sig", None),
    ("utf-16", "utf-16"),  # with its byte order mark
    ("utf-16-be", None),  # without one: read from where the `<` falls
    ("utf-16-le", None),
])
def test_japanese_names_survive_every_encoding_a_project_comes_in(tmp_path, capsys, codec, declared):
    slots = NIHONGO if codec != "euc_jp" else NIHONGO[:3]  # EUC-JP has no ① (a Windows character)
    path = write_project(tmp_path, encoded(slots, codec, declared))
    assert names_of(capsys, path) == {s.number: s.name for s in slots}


@pytest.mark.parametrize("codec", ["utf-16-le", "utf-16-be"])
@pytest.mark.parametrize("space", ["\n", "\r\n  ", "\t"])
def test_utf16_without_a_mark_or_a_declaration_may_start_with_white_space(tmp_path, capsys, codec, space):
    text = space + project_xml(NIHONGO).decode("utf-8").split("?>\n", 1)[1]  # no declaration
    path = write_project(tmp_path, text.encode(codec))
    assert names_of(capsys, path) == {s.number: s.name for s in NIHONGO}


def test_plain_shift_jis_reads_too(tmp_path, capsys):
    slots = [Slot(0, "ホームポジション"), Slot(4, "歩く")]
    path = write_project(tmp_path, encoded(slots, "shift_jis", "Shift_JIS"))
    assert names_of(capsys, path) == {0: "ホームポジション", 4: "歩く"}


@pytest.mark.parametrize("declared, says", [
    ("bogus", "declares encoding 'bogus', which choreo cannot read"),
    ("rot13", "declares encoding 'rot13', which choreo cannot read"),  # a Python codec, not a charset
    ("base64", "declares encoding 'base64', which choreo cannot read"),
    ("unicode_escape", "declares encoding 'unicode_escape', which choreo cannot read"),
    ("x" * 300, "which choreo cannot read"),
    ("Shift_JIS\x1b[2J", "declares encoding 'Shift_JIS\\x1b[2J', which choreo cannot read"),
    ("utf-16", "declares encoding 'utf-16' but has no byte order mark"),
])
def test_an_encoding_choreo_cannot_read_is_one_line(tmp_path, capsys, declared, says):
    path = write_project(tmp_path, encoded(NIHONGO, "utf-8", "ENC").replace(b"ENC", declared.encode("latin-1")))
    err = assert_one_line_exit_2(capsys, ["import", str(path)], says)
    assert "\x1b" not in err


def test_bytes_that_are_not_in_the_declared_encoding_are_one_line(tmp_path, capsys):
    data = encoded(NIHONGO, "utf-8", "EUC-JP")  # UTF-8 bytes under an EUC-JP label
    assert_one_line_exit_2(capsys, ["import", str(write_project(tmp_path, data))], "is not euc_jp text")


# ------------------------------------------------------------------ files that are not files (item 6)


def run_import(*argv: str) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, "-m", "choreo", "import", *argv], capture_output=True, text=True,
                          timeout=30, cwd=Path(__file__).resolve().parent.parent)


@pytest.mark.skipif(not hasattr(os, "mkfifo"), reason="no named pipes here")
def test_a_named_pipe_is_refused_at_once(tmp_path):
    fifo = tmp_path / "robot.h4p"
    os.mkfifo(fifo)
    done = run_import(str(fifo))  # it blocked for ever: the timeout would fail the test
    assert (done.returncode, done.stdout) == (2, "")
    assert done.stderr == f"{fifo}: not a regular file (a named pipe): give a Heart to Heart 4 project\n"


@pytest.mark.skipif(not os.path.exists("/dev/zero"), reason="no /dev/zero here")
def test_links_to_devices_to_nothing_and_in_loops_are_one_line(tmp_path, capsys):
    (tmp_path / "zero.h4p").symlink_to("/dev/zero")
    (tmp_path / "gone.h4p").symlink_to(tmp_path / "nothing.h4p")
    (tmp_path / "a.h4p").symlink_to(tmp_path / "b.h4p")
    (tmp_path / "b.h4p").symlink_to(tmp_path / "a.h4p")
    for name, says in [("zero.h4p", "not a regular file (a device)"),
                       ("gone.h4p", "it is a link to '" + str(tmp_path / "nothing.h4p") + "', which does not exist"),
                       ("a.h4p", "a loop of symbolic links"),
                       ("x" * 300 + ".h4p", "the name is too long for this system")]:
        assert_one_line_exit_2(capsys, ["import", str(tmp_path / name)], says)


def test_a_read_error_is_a_read_error(capsys):
    if not os.path.exists("/proc/self/mem"):
        pytest.skip("no /proc here")
    assert_one_line_exit_2(capsys, ["import", "/proc/self/mem"],
                           "/proc/self/mem: cannot read the Heart to Heart 4 project: ")


# ------------------------------------------------------------------ hostile names (items 4 and 7)

HIDDEN = "\x00\x07\x1b\x7f\x85\x9b\u200b\u200d\u200e\u202a\u202e\u2066\u2069\u2028\u2029\ufeff\ue000\U000e0001"


def test_a_bidi_override_in_a_name_is_cleaned_and_validate_refuses_it_raw(tmp_path, capsys):
    path = write_project(tmp_path, project_xml([Slot(2, "右\u202e手 振る"), Slot(3, "a\u200bb")],
                                               title="KXR\u202e デモ"))
    text = imported(capsys, path)
    assert "\u202e" not in text and "\u200b" not in text
    show = load_show_bytes(text.encode("utf-8"))
    assert show.name == "KXR デモ"
    kept = {m["number"]: m.get("hth4_name") for m in yaml.safe_load(text)["motions"].values()}
    assert kept == {2: "右手 振る", 3: "ab"}
    raw = text.replace("右手 振る", "右\u202e手 振る")
    hidden = r"hth4_name: the Heart to Heart 4 name holds U\+202E \(RIGHT-TO-LEFT OVERRIDE\)"
    with pytest.raises(ShowError, match=hidden):
        load_show_bytes(raw.encode("utf-8"))


def xml_text(text: str) -> str:
    """`text` as XML 1.0 can hold it: characters it cannot (most C0 controls) as `?`."""
    return "".join(ch if ch in "\t\n\r" or 0x20 <= ord(ch) <= 0xD7FF or 0xE000 <= ord(ch) <= 0xFFFD
                   or ord(ch) >= 0x10000 else "?" for ch in text)


hostile_text = st.text(st.one_of(st.sampled_from(HIDDEN + "\"'\\:#&*!|>%@`{}[],?- \t\n"),
                                 st.characters(blacklist_categories=("Cs",))),
                       max_size=300)


@settings(max_examples=150, deadline=None, derandomize=True)
@given(names=st.lists(hostile_text, min_size=1, max_size=8), title=hostile_text)
def test_any_names_import_as_a_show_that_validates(names, title):
    slots = [Slot(n, xml_text(name)) for n, name in enumerate(names)]
    project = parse_project(project_xml(slots, title=xml_text(title)), "hostile.h4p")
    text = starter_show(project)
    show = load_show_bytes(text.encode("utf-8"), "hostile.yaml")  # raises ShowError if validate would
    assert sorted(m.number for m in show.motions.values()) == list(range(len(names)))
    assert len(set(show.motions)) == len(names)
    for name, motion in yaml.safe_load(text)["motions"].items():
        for shown in (name, motion.get("hth4_name", "")):
            assert hidden_character(shown) is None and len(shown) <= 200


def test_a_slot_key_in_a_message_is_shown_escaped(tmp_path, capsys):
    data = ("<Rcb4><MotionDataCollection><DictionaryEntry><Key>M\u202e100</Key></DictionaryEntry>"
            "</MotionDataCollection></Rcb4>")
    err = assert_one_line_exit_2(capsys, ["import", str(write_project(tmp_path, data.encode()))],
                                 "slot M\\u202e100 has no <Value>")
    assert "\u202e" not in err


def test_names_that_clean_to_the_same_text_keep_distinct_keys(tmp_path, capsys):
    slots = [Slot(1, "wave"), Slot(2, "wa\u200bve"), Slot(3, "wave\u202e"), Slot(4, "\u3164"), Slot(5, "motion_2")]
    text = imported(capsys, write_project(tmp_path, project_xml(slots)))
    load_show_bytes(text.encode("utf-8"))
    assert yaml.safe_load(text)["motions"] == {
        "wave": {"number": 1},
        "motion_2": {"number": 5},
        "motion_2_": {"number": 2, "hth4_name": "wave"},
        "motion_3": {"number": 3, "hth4_name": "wave"},
        "motion_4": {"number": 4},  # a Hangul filler alone: nothing visible is left to keep
    }


def test_an_output_in_a_loop_of_links_or_named_nothing_is_one_line(tmp_path, capsys):
    """Issue 21, item 6: `-o loop/x.yaml` (a folder that is a loop of links) was a RuntimeError
    traceback from the schema line's relative path; `-o ''` spoke of '.'."""
    project = write_project(tmp_path, project_xml([Slot(0, "home")]))
    (tmp_path / "a").symlink_to(tmp_path / "b")
    (tmp_path / "b").symlink_to(tmp_path / "a")
    looped = str(tmp_path / "a" / "x.yaml")
    assert "folder" in assert_one_line_exit_2(capsys, ["import", str(project), "-o", looped], "")
    assert "give the show's file name" in assert_one_line_exit_2(capsys, ["import", str(project), "-o", ""], "")
