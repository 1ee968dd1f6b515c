"""Every failure is one line, whatever a name from outside holds: a port or a file named with a
line break printed two (found: validate/plan/run of a show named `nl\\nbad.yaml`, probe, doctor,
run and replay of a port named `a\\nb`)."""

from __future__ import annotations

import pytest

from choreo.cli import main
from choreo.errors import InputError, LinkError, Problem, ShowError

NAME = "a\nb\r\x1b[2J\u202e"


@pytest.mark.parametrize("error", [
    LinkError(f"port {NAME}: cannot open"),
    InputError(NAME, "not a regular file"),
    ShowError([Problem(NAME, 4, 1, "", "YAML syntax error"), Problem("x.yaml", 1, 1, "name", NAME)]),
])
def test_an_errors_lines_are_one_line_each_and_escaped(error):
    for line in error.lines():
        assert "\n" not in line and "\r" not in line and "\x1b" not in line and "\u202e" not in line
        assert "\\x0a" in line or "x.yaml" in line


def _one_line_exit(capsys, argv: list[str], code: int) -> str:
    assert main(argv) == code
    err = capsys.readouterr().err
    assert len(err.strip("\n").splitlines()) == 1, err
    return err


def test_a_show_file_named_with_a_line_break(tmp_path, capsys):
    show = tmp_path / "nl\nbad.yaml"
    show.write_text("version: 1\nsteps:\n  - play: [\n")
    for command in ("validate", "plan", "run"):
        assert "nl\\x0abad.yaml:4:1: YAML syntax error" in _one_line_exit(capsys, [command, str(show)], 2)


@pytest.mark.parametrize("argv", [["probe", "--port", "a\nb", "--timeout", "0.02"]])
def test_a_port_named_with_a_line_break(capsys, argv):
    assert "port a\\x0ab: cannot open" in _one_line_exit(capsys, argv, 3)


def test_doctors_findings_are_one_line_each(capsys):
    assert main(["doctor", "--port", "a\nb"]) == 1
    out = capsys.readouterr().out
    assert all(line.startswith(("ok ", "PROBLEM ", "note ")) for line in out.strip("\n").splitlines()), out
    assert "PROBLEM board: port a\\x0ab: cannot open" in out


def test_outputs_that_name_a_file_with_a_line_break_keep_to_one_line(tmp_path, capsys, monkeypatch):
    """validate's ok line, import's summary line, log latest (found printing the break raw)."""
    from test_import import JAPANESE, project_xml

    monkeypatch.chdir(tmp_path)
    show = tmp_path / "nl\nx.yaml"
    show.write_text("version: 1\nsteps:\n  - play: 1\n  - wait: done\n")
    project = tmp_path / "robot.h4p"
    project.write_bytes(project_xml(JAPANESE))
    logs = tmp_path / "logs"
    logs.mkdir()
    (logs / "nl\nrun.mcap").write_bytes(b"x")
    for argv, expected in ([["validate", str(show)], "nl\\x0ax.yaml: ok"],
                           [["import", str(project), "-o", "nl\nout.yaml"], "nl\\x0aout.yaml: 6 motions"],
                           [["log", "latest", str(logs)], "nl\\x0arun.mcap"]):
        assert main(argv) == 0
        out = capsys.readouterr().out
        assert len(out.strip("\n").splitlines()) == 1 and expected in out, out


@pytest.mark.parametrize(("argv", "code"), [(["run", "{show}", "--host", "{big}", "--no-log"], 2),
                                            (["run", "{show}", "--port", "{big}", "--no-log"], 3),
                                            (["validate", "{big}"], 2)])
def test_a_huge_value_from_outside_is_one_bounded_line(tmp_path, capsys, argv, code):
    """R1: `--host` given 100 KB of name printed 200 KB (escaped twice over). Every error line
    is cut, saying how much was left out, whatever value an option or a file brought in."""
    show = tmp_path / "show.yaml"
    show.write_text("version: 1\nsteps: [{play: 1}]\n")
    big = "\x1b" * 100_000
    assert main([a.format(show=show, big=big) for a in argv]) == code
    lines = capsys.readouterr().err.splitlines()  # a run says what it opens first: those lines too
    assert max(len(line) for line in lines) < 1100, [len(line) for line in lines]
    assert lines[-1].endswith("more characters)"), lines[-1][-80:]
