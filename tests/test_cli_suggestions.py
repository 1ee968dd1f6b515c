"""Mistyped commands, options and values (issue 11, item 3): the error names the subcommand,
prints its usage, and suggests what was probably meant."""

from __future__ import annotations

import pytest

from choreo.cli import main


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
    assert main(["run", "shows/dance.yaml", "--from", "grove", "--no-log"]) == 2
    assert "did you mean 'groove'?" in capsys.readouterr().err
