"""Mistyped commands, options and values (issue 11, item 3): the error names the subcommand,
prints its usage, and suggests what was probably meant."""

from __future__ import annotations

import pytest

from choreo.cli import main
from runlog import vmain


def error_of(capsys, *argv: str) -> list[str]:
    with pytest.raises(SystemExit) as done:
        main(list(argv))
    assert done.value.code == 2
    return capsys.readouterr().err.strip().splitlines()


@pytest.mark.parametrize("argv,prog,suggestion", [
    (["runn", "x"], "choreo", "did you mean 'run'?"),
    (["log", "sumary", "x"], "choreo log", "did you mean 'summary'?"),
    (["log", "frames", "x", "--kind", "stopp"], "choreo log frames", "did you mean 'stop'?"),
    (["run", "shows/minimal.yaml", "--prot", "sim://"], "choreo run", "did you mean '--port'?"),
    (["log", "frames", "x", "--stpe", "3"], "choreo log frames", "did you mean '--step'?"),
])
def test_a_mistake_names_its_command_and_suggests(capsys, argv, prog, suggestion):
    lines = error_of(capsys, *argv)
    assert lines[0].startswith(f"usage: {prog} ")
    assert lines[-1].startswith(f"{prog}: error:") and suggestion in lines[-1]


def test_an_unknown_option_of_a_subcommand_prints_that_subcommands_usage(capsys):
    lines = error_of(capsys, "run", "--bad", "x")
    assert lines[0].startswith("usage: choreo run ") and "unrecognized arguments: --bad" in lines[-1]


def test_from_a_mistyped_label_suggests_the_label(capsys):
    assert vmain(["run", "shows/dance.yaml", "--from", "grove", "--no-log"]) == 2
    assert "did you mean 'groove'?" in capsys.readouterr().err


# -- several logs, the newest log ---------------------------------------------------------------

@pytest.fixture(scope="module")
def two_logs(tmp_path_factory):
    import os
    import time

    directory = tmp_path_factory.mktemp("runs")
    for name in ("older", "newer"):
        assert vmain(["run", "shows/minimal.yaml", "--port", "sim://?motion_s=0.05",
                     "--log", str(directory / f"{name}.mcap"), "-q"]) == 0
    stamp = time.time()
    os.utime(directory / "older.mcap", (stamp - 60, stamp - 60))
    return directory


def test_summary_of_several_logs_and_of_a_folder(two_logs, capsys):
    assert main(["log", "summary", str(two_logs / "older.mcap"), str(two_logs / "newer.mcap")]) == 0
    out = capsys.readouterr().out
    heads = [line for line in out.splitlines() if line.startswith("log       ")]
    assert len(heads) == 2 and "\n\nlog       " in out
    assert main(["log", "summary", str(two_logs)]) == 0
    first, second = [line for line in capsys.readouterr().out.splitlines() if line.startswith("log       ")]
    assert "older.mcap" in first and "newer.mcap" in second


def test_summary_goes_on_past_a_bad_log_and_exits_2(two_logs, tmp_path, capsys):
    bad = tmp_path / "bad.mcap"
    bad.write_text("not a log")
    assert main(["log", "summary", str(bad), str(two_logs / "newer.mcap")]) == 2
    out, err = capsys.readouterr()
    assert "newer.mcap" in out and err.strip().splitlines()[0].startswith(f"log {bad}: not an MCAP file")


def test_latest_prints_the_newest_log(two_logs, tmp_path, capsys):
    assert main(["log", "latest", str(two_logs)]) == 0
    assert capsys.readouterr().out.strip() == str(two_logs / "newer.mcap")
    assert main(["log", "latest", str(tmp_path / "nowhere")]) == 2
    assert main(["log", "latest", str(tmp_path)]) == 2
    assert "no .mcap logs" in capsys.readouterr().err


# -- the live line fits the terminal ------------------------------------------------------------

@pytest.mark.parametrize("columns", [200, 80, 60, 40, 30, 20, 12, 8, 2])
def test_the_live_line_never_fills_the_last_column(columns):
    from choreo.cli.progress import live_line

    step = "step 12 'chorus' (13/26): play 30 (spin_around_twice_and_bow)"
    line = live_line(step, 12.34, 22.0, columns)
    assert 0 < len(line) <= max(columns - 1, 1)
    if columns >= 40:
        assert "12.3/22.0 s" in line and line.startswith("step 1")
    if columns >= 80:
        assert "[" in line  # the bar is there where there is room


def test_the_live_line_keeps_its_step_whole_when_it_fits():
    from choreo.cli.progress import live_line

    assert live_line("step 0: play 1", 0.5, 1.0, 80) == "step 0: play 1  0.5/1.0 s [##########----------]"


HUGE = "x" * 100_000


@pytest.mark.parametrize("argv", [
    ["log", "frames", "x.mcap", "--kind", HUGE],  # a choice: argparse quotes it whole, then the choices
    ["frames", "play", "--baud", "9" * 5000],  # a number argparse could not read
    ["run", "shows/minimal.yaml", "--layout", "\x1b]0;owned\x07" + HUGE],
    ["log", "summary", "--bogus" + HUGE],
    [HUGE],
])
def test_a_huge_or_hostile_value_is_cut_in_the_error_line(capsys, argv):
    """Issue 21, item 6: a 100 KB value argparse could not take was printed whole (100 KB a line,
    the choices lost after it); the error line is cut, the choices kept, controls escaped."""
    lines = error_of(capsys, *argv)
    assert len(lines[-1]) < 1200 and "\x1b" not in lines[-1] and "\x07" not in lines[-1]
    if "--kind" in argv:
        assert "more characters)" in lines[-1] and lines[-1].endswith("'invalid')")


def test_a_huge_value_is_cut_in_the_json_error_too(capsys):
    with pytest.raises(SystemExit):
        main(["log", "frames", "--json", "x.mcap", "--kind", HUGE])
    import json

    error = json.loads(capsys.readouterr().out)["error"]
    assert len(error) < 1200 and "(choose from 'stop'" in error
