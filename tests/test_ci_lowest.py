"""CI's lowest-versions pass reads its pins from pyproject.toml (.ci/lowest.py): a `>=` bound is
its lowest version, an exact `==` pin (the linters of the `lint` extra) is its only one, and a
dependency with neither is refused, since "any version" cannot be tested."""

from __future__ import annotations

import importlib.util
from pathlib import Path
from types import ModuleType

import pytest

ROOT = Path(__file__).resolve().parent.parent


def _lowest() -> ModuleType:
    spec = importlib.util.spec_from_file_location("ci_lowest", ROOT / ".ci" / "lowest.py")
    assert spec is not None and spec.loader is not None
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


def _pyproject(tmp_path: Path, dependencies: list[str], extras: dict[str, list[str]]) -> Path:
    lines = ["[project]", 'name = "x"', f"dependencies = {dependencies!r}".replace("'", '"'),
             "[project.optional-dependencies]"]
    lines += [f"{name} = {pins!r}".replace("'", '"') for name, pins in extras.items()]
    path = tmp_path / "pyproject.toml"
    path.write_text("\n".join(lines) + "\n", encoding="utf-8")
    return path


def test_a_lower_bound_and_an_exact_pin_are_each_their_lowest_version(tmp_path):
    path = _pyproject(tmp_path, ["PyYAML>=6.0", "mcap>=1.5,<2"], {"lint": ["ruff==0.17.6", "mypy==2.4.1"]})
    assert _lowest().lower_bounds(path) == ["mcap==1.5", "mypy==2.4.1", "PyYAML==6.0", "ruff==0.17.6"]


@pytest.mark.parametrize("requirement", ["rich", "rich<14", "rich~=13.0"])
def test_a_dependency_with_no_lower_bound_is_refused(tmp_path, requirement):
    path = _pyproject(tmp_path, [requirement], {})
    with pytest.raises(SystemExit, match="rich has no lower bound"):
        _lowest().lower_bounds(path)


def test_the_projects_own_pins_all_have_a_lowest_version():
    pins = _lowest().lower_bounds(ROOT / "pyproject.toml")
    assert "ruff==0.17.6" in pins and any(pin.startswith("mypy==") for pin in pins)
