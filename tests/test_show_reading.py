"""Show files read as the user's editor reads them (issue 9, items 12-17): YAML 1.2 numbers, a
leading zero refused, line numbers as editors count them, what is not a regular file, labels of
non-ASCII digits, invisible characters, long names, and one rule for a `sim://` port."""

from __future__ import annotations

import os
import subprocess
import sys
from datetime import datetime, timezone

import pytest

from choreo.errors import ShowError, UsageError
from choreo.log.recorder import default_log_path
from runlog import vmain, prepare
from choreo.run.settings import RunRequest
from choreo.show.load import load_show, load_show_bytes
from choreo.show.plan import compile_plan


def problems(text: str) -> list[str]:
    with pytest.raises(ShowError) as failure:
        load_show_bytes(text.encode(), "x.yaml")
    return failure.value.lines()


def show(text: str):
    return load_show_bytes(text.encode(), "x.yaml")


@pytest.mark.parametrize("value,octal,decimal", [("010", 8, 10), ("-07", -7, -7), ("007", 7, 7), ("09", None, 9)])
def test_a_whole_number_with_a_leading_zero_is_refused_saying_both_readings(value, octal, decimal):
    lines = problems(f"version: 1\nsteps:\n  - play: {value}\n")
    assert lines[0].startswith(f"x.yaml:3:11: steps[0].play: {value} is ambiguous")
    assert f"decimal ({decimal})" in lines[0]
    assert (f"octal ({octal})" if octal is not None else "octal (not octal)") in lines[0]


def test_a_leading_zero_is_refused_under_an_explicit_yaml_1_2_directive_too():
    assert "ambiguous" in problems("%YAML 1.2\n---\nversion: 1\nsteps:\n  - play: 010\n")[0]


@pytest.mark.parametrize("text,seconds", [("1e-3", 0.001), ("1.5e1", 15.0), ("2", 2.0), (".5", 0.5), ("0.25", 0.25)])
def test_numbers_read_as_yaml_1_2_reads_them(text, seconds):
    loaded = show(f"version: 1\nsteps:\n  - wait: {text}\n")
    assert loaded.steps[0].seconds == pytest.approx(seconds)


def test_yaml_1_1_spellings_are_text_as_in_yaml_1_2():
    lines = problems("version: 1\nsteps:\n  - wait: 1:30\n  - wait: yes\n  - play: 1_0\n")
    assert "not '1:30'" in lines[0] and "not 'yes'" in lines[1] and "'1_0'" in lines[2]


def test_hex_and_octal_of_yaml_1_2_are_numbers():
    loaded = show("version: 1\nsteps:\n  - play: 0x10\n  - play: 0o17\n")
    assert [s.motion for s in loaded.steps] == [16, 15]


def test_a_huge_cue_is_a_number_out_of_range_not_text():
    assert "at" in problems("version: 1\nsteps:\n  - play: 1\n    at: 1e308\n")[0]
    assert "text" not in problems("version: 1\nsteps:\n  - play: 1\n    at: 1e308\n")[0]


@pytest.mark.parametrize("char", ["\u0085", "\u2028", "\u2029"])
def test_nel_ls_ps_do_not_shift_line_numbers_nor_end_a_comment(char):
    lines = problems(f"version: 1\n# a comment {char} going on\nsteps:\n  - play: 140\n")
    assert lines == ["x.yaml:4:11: steps[0].play: motion 140 is out of range 0..119"]


def test_a_line_separator_inside_text_is_kept_and_refused_where_it_would_print():
    lines = problems('version: 1\nname: "a\u2028b"\nsteps:\n  - play: 1\n')
    assert lines == ["x.yaml:2:7: name: the show's name holds U+2028 (LINE SEPARATOR), which is "
                     "invisible or controls the terminal: remove it"]


@pytest.mark.parametrize("label", ["a\u202eb", "a\u200bb", "a\x9bb"])
def test_invisible_and_control_characters_in_labels_are_refused(label):
    escaped = label.encode("unicode_escape").decode()
    lines = problems(f'version: 1\nsteps:\n  - play: 1\n    label: "{escaped}"\n')
    assert lines[0].startswith("x.yaml:4:12: steps[0].label: the label holds U+")


def test_an_escape_in_the_show_name_is_refused():
    lines = problems('version: 1\nname: "x\\e[31mred"\nsteps:\n  - play: 1\n')
    assert "U+001B" in lines[0]


@pytest.mark.parametrize("label", ["١", "１", "٣٤"])
def test_labels_of_non_ascii_digits_are_labels_not_indexes(label):
    loaded = show(f"version: 1\nsteps:\n  - play: 1\n  - play: 2\n    label: \"{label}\"\n")
    plan = compile_plan(loaded)
    assert plan.find(label) == 1
    assert plan.find("1") == 1 and plan.find("0") == 0  # ASCII digits are indexes


@pytest.mark.skipif(not hasattr(os, "mkfifo"), reason="no named pipes here")
def test_a_named_pipe_is_refused_at_once(tmp_path):
    fifo = tmp_path / "show.yaml"
    os.mkfifo(fifo)
    for argv in (["validate", str(fifo)], ["plan", str(fifo)], ["run", str(fifo), "--no-log"]):
        done = subprocess.run([sys.executable, "-m", "choreo", *argv], capture_output=True, text=True,
                              timeout=20)
        assert done.returncode == 2
        assert done.stderr.strip() == f"{fifo}: not a regular file (a named pipe): give a show file"


def test_a_folder_is_refused(tmp_path):
    with pytest.raises(ShowError, match="not a regular file \\(a folder\\)"):
        load_show(tmp_path)


def test_a_long_show_name_makes_a_log_name_the_file_system_takes(tmp_path):
    now = datetime(2026, 11, 23, tzinfo=timezone.utc)
    for name in ("x" * 200, "歩" * 200):
        path = default_log_path(name, tmp_path, now)
        assert len(path.name.encode()) <= 255 - len("-99")
        path.with_name(path.stem + "-99" + path.suffix).write_bytes(b"")  # the file system takes it


def test_a_long_show_name_runs_and_writes_its_log(tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)  # the default log folder, runs/, is made here
    show_path = tmp_path / "long.yaml"
    show_path.write_text(f"version: 1\nname: {'歩' * 200}\nsteps:\n  - play: 1\n")
    assert vmain(["run", str(show_path), "--port", "sim://?motion_s=0.01", "-q"]) == 0
    logs = list((tmp_path / "runs").glob("*.mcap"))
    assert len(logs) == 1 and logs[0].name.startswith("歩")


def test_a_sim_port_in_the_show_gets_the_runs_baud_and_the_shows_durations(tmp_path):
    path = tmp_path / "s.yaml"
    path.write_text("version: 1\nrobot: {port: 'sim://', baud: 625000}\nmotions:\n  m: {number: 3, duration: 0.3}\n"
                    "steps:\n  - play: m\n  - wait: done\n")
    session = prepare(RunRequest(str(path), no_log=True))
    assert session.settings.links["robot"].port_source == "show"
    port = session.settings.links["robot"].port
    assert "baud=625000" in port and "durations=3:0.3" in port
    with session:
        assert session.run().outcome == "done"


@pytest.mark.parametrize("port", ["sim://?drop=abc", "sim://?bogus=1", "sim://?layout=hth4"])
def test_a_bad_sim_option_is_a_bad_argument_in_run(tmp_path, port, capsys):
    path = tmp_path / "s.yaml"
    path.write_text("version: 1\nsteps:\n  - play: 1\n")
    assert vmain(["run", str(path), "--port", port, "--no-log"]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and err[0].startswith(f"--port {port}: sim://:")
    with pytest.raises(UsageError):
        prepare(RunRequest(str(path), port=port, no_log=True))
