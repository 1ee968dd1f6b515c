"""`choreo import PROJECT.h4p [-o SHOW.yaml]`: a starter show from a Heart to Heart 4 project.

The module is `importer` because `import` is a Python keyword; the command is `import`. A bad
project is `ProjectError` (exit 2, one line), mapped by the CLI's `main` like every other error.
"""

from __future__ import annotations

import argparse
import os
import sys
from pathlib import Path

from choreo.cli.terminal import print_fitted
from choreo.errors import UsageError, one_line


def register(subparsers: argparse._SubParsersAction) -> None:
    command = subparsers.add_parser(
        "import",
        help="write a starter show from a Heart to Heart 4 project",
        description="Read a Heart to Heart 4 project (.h4p) and write a starter show: `name` from "
        "the project title, `robot.layout` from where the project's slots start in ROM (slot 0 at "
        "0x0B80: hth4-2.2; 0x0BB8: seed), one `motions:` entry for every slot that holds a motion "
        "(keyed by its HTH4 name where that is a valid show name, else `motion_N` with the HTH4 "
        "name as `hth4_name`), and steps that play the first motion and wait until it is done. "
        "Projects in Shift_JIS (CP932), EUC-JP, UTF-8 or UTF-16 are read; control, bidi-override and "
        "invisible characters are left out of the names, so the show always validates. "
        "A file that is not such a project, holds no motions or has slot addresses that fit no "
        "layout is exit status 2 with one line saying why.",
    )
    command.add_argument("project", metavar="PROJECT.h4p", help="a Heart to Heart 4 project file")
    command.add_argument(
        "-o",
        "--output",
        metavar="SHOW.yaml",
        help="write the show to this file (never overwrites one: exit 2 if it exists); default (or -): "
        "standard output, as `log export` takes - for it",
    )
    command.set_defaults(handler=run_import)


def run_import(args: argparse.Namespace) -> int:
    # the project reader (XML, codecs) when the command runs: `choreo --help` does not pay for it
    from choreo.show.hth4 import read_project
    from choreo.show.starter import schema_reference, starter_show

    project = read_project(args.project)
    if args.output in (None, "-"):  # a file named "-" is ./-
        _write_stdout(starter_show(project))
        return 0
    output = _new_output(args.output)
    try:
        schema = schema_reference(output)
    except (OSError, RuntimeError):  # a link loop met on the way (Path.resolve's RuntimeError)
        schema = None
    _write_new(output, starter_show(project, schema))
    count = len(project.motions)
    print_fitted(one_line(f"{output}: {count} motion{'s' if count != 1 else ''}, layout {project.layout}: "
                          f"check it with `choreo plan {output}`"))
    return 0


def _write_stdout(text: str) -> None:
    """UTF-8 whatever the console's encoding: the show is a file, and show files are UTF-8."""
    buffer = getattr(sys.stdout, "buffer", None)
    if buffer is None:
        sys.stdout.write(text)
        return
    sys.stdout.flush()
    buffer.write(text.encode("utf-8"))
    buffer.flush()


def _new_output(name: str) -> Path:
    """`-o`'s file, checked before anything is made of its name: a link loop in its folder was a
    RuntimeError traceback (the schema's relative path resolves the folder), `-o ''` wrote of '.'."""
    from choreo.run.settings import check_output_folder

    if not name:
        raise UsageError("-o '': give the show's file name (or - for standard output)")
    path = Path(name)
    check_output_folder(path, "-o")
    if os.path.lexists(path):
        raise UsageError(f"{path}: already exists; `choreo import` never overwrites a file: give another with -o")
    return path


def _write_new(path: Path, text: str) -> None:
    try:
        with open(path, "x", encoding="utf-8", newline="\n") as stream:
            stream.write(text)
    except FileExistsError:
        raise UsageError(f"{path}: already exists; `choreo import` never overwrites a file: "
                         "give another with -o") from None
    except OSError as exc:
        raise UsageError(f"{path}: cannot write the show: {exc.strerror or exc}") from None
