"""Run every choreo benchmark and print one table; the full run also writes bench/RESULTS.md.

    python bench/run.py            # full: a few minutes, writes bench/RESULTS.md
    python bench/run.py --quick    # under 2 minutes (the Link benchmark plays a 30 s show), prints only
    python bench/run.py cues wire  # only some benchmarks (prints only)

Each benchmark module exposes `run(quick: bool = False) -> list[dict]` with rows
`{name, value, unit, goal, ok}` (ok None: a figure without a goal). A benchmark that cannot run
(a missing module, an error) becomes a failed row saying why, so the table is always complete.
Exit status 1 if any goal is missed (with --quick, only if a benchmark could not run: its few
samples show the figures, the full run judges the goals).
"""

from __future__ import annotations

import argparse
import datetime
import importlib
import os
import platform
import sys
import time
import traceback
from pathlib import Path

BENCH = Path(__file__).resolve().parent
if str(BENCH) not in sys.path:
    sys.path.insert(0, str(BENCH))

# (module, what it measures), in the order of issue 6, then issue 23's and issue 25's.
BENCHMARKS = (
    ("cues", "1. cue accuracy"),
    ("drift", "2. drift"),
    ("polls", "3. poll spacing"),
    ("wire", "4. play latency against the wire"),
    ("recording", "5. recording cost"),
    ("log_review", "6. log review"),
    ("startup", "7. start-up"),
    ("skew", "8. unison skew (several robots)"),
    ("motion_start", "9. motion start against the cue"),
    ("music_clock", "10. the music's clock (5-minute song)"),
    ("go", "11. GO over OSC to the wire"),
    ("go_key", "12. GO by a key on the console to the wire"),
    ("beats", "13. beat finding on songs with known beats (issue 23)"),
    ("heldout", "14. beat finding on a held-out set, never tuned on"),
    ("link", "15. two hosts on one Ableton Link session (issue 25)"),
    ("go_tracks", "16. a GO in one track against another track's timed cues (issue 21)"),
    ("go_siege", "17. GO over OSC while 300 idle TCP connections are held (issue 21)"),
)
RESULTS = BENCH / "RESULTS.md"


def run_one(module_name: str, quick: bool) -> tuple[list[dict], float]:
    """The rows of one benchmark and its wall time; failures become a row that says why."""
    began = time.perf_counter()
    try:
        module = importlib.import_module(module_name)
    except ModuleNotFoundError as exc:
        if exc.name != module_name:
            raise
        return [_failed(module_name, f"not available (bench/{module_name}.py is missing)")], 0.0
    try:
        rows = module.run(quick=quick)
    except Exception as exc:  # one broken benchmark must not hide the others' figures
        traceback.print_exc(file=sys.stderr)
        rows = [_failed(module_name, f"error: {type(exc).__name__}: {exc}")]
    return rows, time.perf_counter() - began


def _failed(module_name: str, why: str) -> dict:
    return {"name": f"{module_name}: {why}", "value": None, "unit": "", "goal": "runs", "ok": False}


def _mark(ok: bool | None) -> str:
    return "-" if ok is None else "pass" if ok else "FAIL"


def _value(value: object) -> str:
    return "n/a" if value is None else f"{value:g}" if isinstance(value, float) else str(value)


def table_lines(sections: list[tuple[str, list[dict]]], markdown: bool = False) -> list[str]:
    """The table as plain aligned text, or as Markdown."""
    rows = [(title, r) for title, section in sections for r in section]
    cells = [(r["name"], _value(r["value"]), r["unit"], r["goal"] or "", _mark(r["ok"])) for _, r in rows]
    header = ("benchmark", "value", "unit", "goal", "result")
    if markdown:
        lines = ["| " + " | ".join(header) + " |", "|---|---:|---|---|---|"]
        return lines + ["| " + " | ".join(c.replace("|", "\\|") for c in cell) + " |" for cell in cells]
    widths = [max(len(c[i]) for c in [header, *cells]) for i in range(5)]
    fmt = lambda c: "  ".join(  # noqa: E731
        [c[0].ljust(widths[0]), c[1].rjust(widths[1]), c[2].ljust(widths[2]), c[3].ljust(widths[3]), c[4]])
    lines = [fmt(header), "  ".join("-" * w for w in widths)]
    previous = None
    for (title, _), cell in zip(rows, cells, strict=True):
        if title != previous and title:
            lines.append(f"[{title}]")
            previous = title
        lines.append(fmt(cell))
    return lines


def print_table(rows: list[dict]) -> int:
    """Print one benchmark's rows (for `python bench/<name>.py`); exit status 1 on a miss."""
    print("\n".join(table_lines([("", rows)])))
    return 0 if all(r["ok"] is not False for r in rows) else 1


def machine() -> dict[str, str]:
    """What the figures were measured on: they mean little without it."""
    cpu = platform.processor() or platform.machine()
    try:
        for line in Path("/proc/cpuinfo").read_text().splitlines():
            if line.startswith("model name"):
                cpu = line.split(":", 1)[1].strip()
                break
    except OSError:
        pass
    cores = len(os.sched_getaffinity(0)) if hasattr(os, "sched_getaffinity") else os.cpu_count()
    try:
        load = "{:.2f} {:.2f} {:.2f}".format(*os.getloadavg())
    except OSError:
        load = "?"
    return {
        "CPU": cpu,
        "cores available": str(cores),
        "OS": f"{platform.system()} {platform.release()}",
        "Python": f"{platform.python_implementation()} {platform.python_version()}",
        "load average at the start": load,
        "date": datetime.datetime.now(datetime.timezone.utc).strftime("%Y-%m-%d %H:%M UTC"),
    }


def write_results(sections: list[tuple[str, list[dict]]], info: dict[str, str], command: str,
                  took_s: float) -> None:
    lines = [
        "# choreo benchmark results",
        "",
        f"Measured with `{command}` (from the repository root, in the project's virtual environment)",
        f"in {took_s:.0f} s. Regenerate with the same command; `--quick` runs a smaller version and",
        "writes nothing. What each figure means and how it is measured: the docstring of each",
        "module in `bench/`, and `docs/performance.md`.",
        "",
        *(f"- {key}: {value}" for key, value in info.items()),
        "",
        *table_lines(sections, markdown=True),
        "",
    ]
    RESULTS.write_text("\n".join(lines))


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description="Run choreo's benchmarks and print one table.")
    parser.add_argument("--quick", action="store_true", help="smaller sizes, under 2 minutes; writes nothing")
    parser.add_argument("only", nargs="*", metavar="NAME",
                        help=f"run only these ({', '.join(name for name, _ in BENCHMARKS)})")
    args = parser.parse_args(argv)
    known = {name for name, _ in BENCHMARKS}
    unknown = [name for name in args.only if name not in known]
    if unknown:
        parser.error(f"unknown benchmark {unknown[0]!r}")
    info = machine()
    began = time.perf_counter()
    sections = []
    for name, title in BENCHMARKS:
        if args.only and name not in args.only:
            continue
        print(f"running {title} ({name})...", file=sys.stderr, flush=True)
        rows, took = run_one(name, args.quick)
        print(f"  {took:.1f} s", file=sys.stderr, flush=True)
        sections.append((title, rows))
    took_s = time.perf_counter() - began
    print(", ".join(f"{k}: {v}" for k, v in info.items()))
    print("\n".join(table_lines(sections)))
    print(f"({took_s:.0f} s)")
    if not args.quick and not args.only:
        write_results(sections, info, "python bench/run.py", took_s)
        print(f"wrote {RESULTS.relative_to(BENCH.parent)}")
    return 1 if any(_fails(r, args.quick) for _, rows in sections for r in rows) else 0


def _fails(row: dict, quick: bool) -> bool:
    """A missed goal fails the full run; --quick's few samples put p99 near the worst one, so
    there only a benchmark that could not run fails (its rows still say pass/FAIL)."""
    return row["ok"] is False and (not quick or row["goal"] == "runs")


if __name__ == "__main__":
    sys.exit(main())
