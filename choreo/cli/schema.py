"""`choreo schema`: where the installed show schema is, for an editor's modeline."""

from __future__ import annotations

import argparse


def register(subparsers: argparse._SubParsersAction) -> None:
    parser = subparsers.add_parser(
        "schema",
        help="print the path of the installed show schema (for editors)",
        description="Print the path of the show format's JSON Schema as installed with choreo, "
        "so that a show file can start with `# yaml-language-server: $schema=PATH` and editors "
        "with the YAML language server complete and check it, wherever the show lives. "
        "--modeline prints that whole first line.",
    )
    parser.add_argument("--modeline", action="store_true", help="print the line to put at the top of a show")
    parser.set_defaults(handler=run)


def run(args: argparse.Namespace) -> int:
    from choreo.show.schema import modeline, schema_path

    path = schema_path()
    print(modeline(path.as_uri()) if args.modeline else path)
    return 0
