"""`choreo validate` and `choreo plan`: one line a file or a step, located problems, exit 2, no traceback."""

from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

import pytest

from choreo.cli import main

ROOT = Path(__file__).resolve().parent.parent
SHOWS = sorted((ROOT / "shows").glob("*.yaml"))


def choreo(*args: str, cwd: Path = ROOT) -> subprocess.CompletedProcess:
    env = {**os.environ, "PYTHONPATH": str(ROOT)}
    return subprocess.run([sys.executable, "-m", "choreo", *args], capture_output=True, text=True, cwd=cwd, env=env,
                          timeout=60)


def test_validate_prints_one_line_a_valid_file(capsys):
    assert main(["validate", *map(str, SHOWS)]) == 0
    out, err = capsys.readouterr()
    assert err == ""
    lines = out.splitlines()
    assert len(lines) == len(SHOWS)
    dance = next(line for line in lines if "dance.yaml" in line)
    assert dance == (
        f"{ROOT / 'shows' / 'dance.yaml'}: ok, 26 steps, 2 cues (1-2), motions 0 home, 1 bow, 4 wave_right, "
        "5 wave_left, 10 step_left, 11 step_right, 20 clap, 30 spin, 40 pose, estimated 22.0 s"
    )


def test_validate_names_a_planned_late_cue(tmp_path, capsys):
    show = tmp_path / "late.yaml"
    show.write_text("version: 1\nsteps:\n  - wait: 3\n  - play: 1\n    at: 2\n    label: drop\n")
    assert main(["validate", str(show)]) == 0
    assert capsys.readouterr().out == (f"{show}: ok, 2 steps, 1 cue (1), motions 1, estimated 3.0 s; "
                                       "1 cue planned late (drop)\n")


def test_validate_reports_every_problem_of_every_file_and_exits_2(tmp_path, capsys):
    bad = tmp_path / "bad.yaml"
    bad.write_text("version: 1\nsteps:\n  - play: 140\n  - wait: done\n    timeout: 0\n")
    worse = tmp_path / "worse.yaml"
    worse.write_text("- not a show\n")
    good = ROOT / "shows" / "minimal.yaml"
    assert main(["validate", str(bad), str(good), str(worse)]) == 2
    out, err = capsys.readouterr()
    assert out == f"{good}: ok, 2 steps, motions 1, estimated 1.0 s\n"
    assert err.splitlines() == [
        f"{bad}:3:11: steps[0].play: motion 140 is out of range 0..119",
        f"{bad}:5:14: steps[1].timeout: must be more than 0, not 0",
        f"{worse}:1:1: the top level must be a mapping (`version: 1`, `steps:` ...), not a list",
    ]


def test_plan_prints_a_line_a_step_and_the_total(capsys):
    assert main(["plan", str(ROOT / "shows" / "dance.yaml")]) == 0
    lines = capsys.readouterr().out.splitlines()
    assert lines[0] == f"Dance ({ROOT / 'shows' / 'dance.yaml'}), layout seed"
    assert lines[1].split() == ["#", "cue", "label", "start", "step", "path", "frames"]
    assert len(lines) == 2 + 26 + 1
    first = lines[2]
    assert first.split()[:5] == ["0", "-", "start", "0.000", "s"]
    assert "steps[0]" in first
    assert "play 0 (home)" in first
    assert first.endswith("13 00 02 00 00 00 21 87 fd 03 00 00 00 00 00 00 00 00 bd | 07 0c b8 0b 00 00 d6 | "
                          "09 00 02 00 00 00 23 87 b5")
    groove = lines[2 + 8]
    assert groove.split()[:4] == ["8", "-", "groove", "6.200"] and "steps[8]#1.steps[0]" in groove
    wait_done = lines[3]
    assert "wait until motion 0 is done (timeout 60 s)" in wait_done
    assert wait_done.endswith("0a 00 20 00 00 00 00 00 02 2c")
    spin = next(line for line in lines if " spin " in line)
    assert "14.000 s (at 14)" in spin
    wait = next(line for line in lines if "wait 1.5 s" in line)
    assert wait.rstrip().endswith("-")  # sends nothing
    assert lines[-1] == "estimated total 22.0 s (26 steps)"


def test_plan_of_a_bad_show_exits_2(tmp_path, capsys):
    bad = tmp_path / "bad.yaml"
    bad.write_text("version: 1\nsteps:\n  - play: wave\n")
    assert main(["plan", str(bad)]) == 2
    out, err = capsys.readouterr()
    assert out == ""
    assert err == (f"{bad}:3:11: steps[0].play: unknown motion 'wave': name it in `motions:` with its slot number, "
                   "or play the number\n")


@pytest.mark.parametrize(
    "content,first",
    [
        (b"version: 1\nsteps:\n  - play: 140\n", "bad.yaml:3:11: steps[0].play: motion 140 is out of range 0..119"),
        (b"version: 1\nsteps: [\n",
         "bad.yaml:3:1: YAML syntax error: did not find expected node content (while parsing a flow node)"),
        (b"version: 1\nname: \xff\n", "bad.yaml:2:7: not UTF-8 (byte 0xff): save the file as UTF-8"),
        (b"a: &a [1, 2]\nb: [*a, *a]\n", "bad.yaml:1:1: a: unknown key 'a'"),
        (b"[" * 10000, "bad.yaml:1:40: "),
    ],
    ids=["range", "syntax", "utf8", "alias", "deep"],
)
def test_bad_files_exit_2_without_a_traceback(tmp_path, content, first):
    (tmp_path / "bad.yaml").write_bytes(content)
    for command in ("validate", "plan"):
        done = choreo(command, "bad.yaml", cwd=tmp_path)
        assert done.returncode == 2, done.stderr
        assert "Traceback" not in done.stderr
        assert done.stdout == ""
        assert done.stderr.splitlines()[0].startswith(first)


def test_a_missing_file_exits_2(tmp_path):
    done = choreo("validate", "nope.yaml", cwd=tmp_path)
    assert (done.returncode, done.stdout, done.stderr) == (
        2, "", "nope.yaml: cannot read the show file: No such file or directory\n")


def test_validate_needs_a_file():
    done = choreo("validate")
    assert done.returncode == 2 and "Traceback" not in done.stderr and "SHOW" in done.stderr


def test_validate_imports_no_serial_or_mcap():
    """`choreo validate` must stay fast: it never loads the link, the log or plotting."""
    code = (
        "import sys; from choreo.cli import main; rc = main(['validate', 'shows/dance.yaml']); "
        "print(rc, sorted(m for m in sys.modules if m.split('.')[0] in ('serial', 'mcap', 'matplotlib', 'numpy')))"
    )
    done = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, cwd=ROOT, timeout=60)
    assert done.stdout.splitlines()[-1] == "0 []"


def test_validate_says_when_a_show_plays_no_motion(tmp_path, capsys):
    from choreo.cli import main

    path = tmp_path / "quiet.yaml"
    path.write_text("version: 1\nsteps:\n  - wait: 1\n")
    assert main(["validate", str(path)]) == 0
    assert capsys.readouterr().out == f"{path}: ok, 1 step, no motions, estimated 1.0 s\n"
