"""Load a show file into a checked `Show`, or fail with every problem in it, each one located.

Three passes, each reporting everything it finds before the next runs on what survived:

1. Read and parse (`read`, with `yamlwalk` and `scalars`): the bytes become plain JSON-like
   data with the line and column of every value and key; nothing unsafe is ever built.
2. The JSON Schema (`schema`), the same file editors use, its findings reworded for a show
   author and mapped back to their node.
3. What a schema cannot say (`checks`): motion names exist, `wait: done` follows a play, cues
   do not go back in time, labels are unique, the show does not expand to an absurd size.

Then `build` turns the document into the `Show` records. The passes share a `report.Report`;
messages are `FILE:LINE:COL: PATH: WHAT` (`choreo.errors.Problem`).
"""

from __future__ import annotations

from pathlib import Path

from choreo.errors import ShowError
from choreo.show.build import build_show
from choreo.show.checks import check_meaning
from choreo.show.model import Show
from choreo.show.read import read_document, read_file
from choreo.show.report import Report
from choreo.show.schema import check_schema, load_schema, schema_path

__all__ = ["load_schema", "load_show", "load_show_bytes", "schema_path"]


def load_show(path: str | Path) -> Show:
    """The checked show at `path`; `ShowError` listing every problem if it cannot be run."""
    report = Report(str(path))
    source = read_file(Path(path), report)
    if source is None:
        raise ShowError(report.problems())
    return load_show_bytes(source, str(path), folder=Path(path).parent)


def load_show_bytes(source: bytes, path: str = "<show>", folder: Path | None = None) -> Show:
    """A show from its bytes (e.g. attached to a log); `path` names it in messages and records.

    `folder`: where the show file is, so that its music is looked for there (None: a show with
    no folder, as one attached to a log: its music is not looked for)."""
    report = Report(path)
    doc = read_document(source, report)
    if doc is None:
        raise ShowError(report.problems())
    check_schema(doc, report)
    check_meaning(doc, report, folder)
    if report.any():
        raise ShowError(report.problems())
    return build_show(path, source, doc, folder)
