"""Print a pip constraints file that pins every dependency pyproject.toml declares to its lower bound.

Why: CI installs the newest releases on every run, which proves the upper end of what choreo
promises; the lower end (`>=X` in pyproject) is only a promise until something installs exactly
X. Generated from pyproject.toml at each run, so the bounds live in one place and cannot drift.
Every runtime dependency and every extra's dependency must carry a `>=` bound, or an exact `==`
pin (the `lint` extra's linters: their one version is their lowest): one without is an error here,
since "any version" cannot be tested.
"""

from __future__ import annotations

import re
import sys
from pathlib import Path

try:
    import tomllib  # Python 3.11+
except ModuleNotFoundError:  # Python 3.10, which pyproject also promises: pip carries a TOML reader
    try:
        import tomli as tomllib  # type: ignore[no-redef]
    except ModuleNotFoundError:
        from pip._vendor import tomli as tomllib  # type: ignore[no-redef]

_REQUIREMENT = re.compile(r"^\s*([A-Za-z0-9][A-Za-z0-9._-]*)\s*(?:\[[^\]]*\])?\s*(.*?)\s*(?:;.*)?$")
_LOWER = re.compile(r"(?:>=|==)\s*([0-9][A-Za-z0-9.]*)")


def lower_bounds(pyproject: Path) -> list[str]:
    project = tomllib.loads(pyproject.read_text(encoding="utf-8"))["project"]
    declared = list(project.get("dependencies", []))
    for extra in project.get("optional-dependencies", {}).values():
        declared.extend(extra)
    pins: dict[str, str] = {}
    for requirement in declared:
        match = _REQUIREMENT.match(requirement)
        if match is None:
            raise SystemExit(f"pyproject.toml: cannot read the requirement {requirement!r}")
        name, spec = match.group(1), match.group(2)
        lower = _LOWER.search(spec)
        if lower is None:
            raise SystemExit(f"pyproject.toml: {name} has no lower bound (>=) nor exact pin (==): give it one")
        pins.setdefault(name.lower(), f"{name}=={lower.group(1)}")
    return sorted(pins.values(), key=str.lower)


if __name__ == "__main__":
    root = Path(__file__).resolve().parent.parent
    sys.stdout.write("".join(pin + "\n" for pin in lower_bounds(root / "pyproject.toml")))
