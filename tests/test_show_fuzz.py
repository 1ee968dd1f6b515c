"""Property tests: whatever a show file holds, loading it ends in a `Show` or a `ShowError`, fast.

Random bytes, random text, random YAML data, show-shaped data with wrong values, and the example
shows mutated character by character. Never a traceback, never a hang: each example is bounded
in time, and a file that loads must also compile to a plan.
"""

from __future__ import annotations

import tempfile
import time
from pathlib import Path

import yaml
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from choreo.errors import ShowError
from choreo.show.load import load_show
from choreo.show.plan import compile_plan
from runlog import HANG_S

ROOT = Path(__file__).resolve().parent.parent
EXAMPLES = [p.read_text() for p in sorted((ROOT / "shows").glob("*.yaml"))]
FUZZ = settings(max_examples=200, suppress_health_check=[HealthCheck.too_slow])  # conftest: derandomized

_dir = tempfile.TemporaryDirectory(prefix="choreo-fuzz-")
_file = Path(_dir.name) / "show.yaml"


def check(content: bytes | str) -> None:
    """Load `content` from a file: a Show that compiles, or located one-line problems."""
    if isinstance(content, str):
        _file.write_text(content, encoding="utf-8", errors="surrogatepass")
    else:
        _file.write_bytes(content)
    started = time.perf_counter()
    try:
        show = load_show(_file)
    except ShowError as exc:
        assert exc.problems and exc.exit_code == 2
        for problem in exc.problems:
            line = str(problem)
            assert "\n" not in line and line.startswith(str(_file))
            assert problem.line >= 0 and problem.column >= 0
    else:
        plan = compile_plan(show)
        assert plan.steps and plan.estimated_s >= 0
    assert time.perf_counter() - started < HANG_S


@FUZZ
@given(st.binary(max_size=400))
def test_random_bytes(data):
    check(data)


@FUZZ
@given(st.text(alphabet=st.characters(codec="utf-8"), max_size=300))
def test_random_text(text):
    check(text)


YAML_BITS = st.sampled_from(
    [":", " ", "  ", "\n", "- ", "[", "]", "{", "}", ",", "&a ", "*a", "!!", "!x ", "#", "'", '"', "?", "|", ">",
     "---", "...", "\t", "%YAML 1.1\n", "<<: ", "0x1", ".inf", ".nan", "~", "null", "yes", "1e3", "-", "0", "119",
     "play", "wait", "done", "repeat", "steps", "at", "label", "version: 1", "motions", "on_abort", "é", "\\"]
)


@FUZZ
@given(st.lists(YAML_BITS, max_size=60))
def test_yaml_like_noise(bits):
    check("".join(bits))


@FUZZ
@given(st.sampled_from(EXAMPLES),
       st.lists(st.tuples(st.integers(0, 10_000), st.integers(0, 3), YAML_BITS), min_size=1, max_size=6))
def test_mutated_examples(text, edits):
    for position, how, bit in edits:
        at = position % (len(text) + 1)
        if how == 0:
            text = text[:at] + bit + text[at:]  # insert
        elif how == 1:
            text = text[:at] + text[at + len(bit):]  # delete
        elif how == 2:
            text = text[:at] + bit + text[at + len(bit):]  # replace
        else:
            end = text.find("\n", at)
            text = text[:at] + text[end:] if end >= 0 else text[:at]  # cut the rest of a line
    check(text)


SCALARS = st.one_of(
    st.none(),
    st.booleans(),
    st.integers(-200, 200),
    st.integers(),
    st.floats(allow_nan=True, allow_infinity=True),
    st.sampled_from(["done", "wave", "bow", "", "3", "x#1", "12"]),
    st.text(max_size=8),
)
DATA = st.recursive(
    SCALARS,
    lambda inner: st.one_of(st.lists(inner, max_size=4), st.dictionaries(st.text(max_size=6), inner, max_size=4)),
    max_leaves=20)


@FUZZ
@given(DATA)
def test_random_yaml_data(data):
    check(yaml.safe_dump(data, allow_unicode=True))


STEP_VALUES = {
    "play": st.one_of(st.integers(-5, 125), st.sampled_from(["wave", "bow", "nope", ""]), SCALARS),
    "wait": st.one_of(st.sampled_from(["done", "soon"]), st.floats(-1, 5), SCALARS),
    "timeout": st.one_of(st.floats(-1, 100), SCALARS),
    "at": st.one_of(st.floats(-1, 30), st.integers(0, 30), SCALARS),
    "label": st.one_of(st.sampled_from(["a", "b", "a#2", "7"]), SCALARS),
    "repeat": st.one_of(st.integers(-1, 4), SCALARS),
}


def steps_strategy(depth: int) -> st.SearchStrategy:
    keys = st.lists(st.sampled_from(sorted(STEP_VALUES) + ["steps", "bogus"]), min_size=1, max_size=4, unique=True)

    @st.composite
    def step(draw):
        out = {}
        for key in draw(keys):
            if key == "steps":
                out[key] = draw(steps_strategy(depth - 1)) if depth > 0 else []
            elif key == "bogus":
                out[key] = draw(SCALARS)
            else:
                out[key] = draw(STEP_VALUES[key])
        return out

    return st.lists(step(), max_size=6)


SHOWS = st.fixed_dictionaries(
    {"version": st.one_of(st.just(1), SCALARS), "steps": steps_strategy(2)},
    optional={
        "name": SCALARS,
        "motions": st.dictionaries(
            st.sampled_from(["wave", "bow", "bad name", "1x"]),
            st.fixed_dictionaries({"number": st.integers(-2, 122)}, optional={"duration": st.floats(-1, 5)}),
            max_size=3,
        ),
        "on_abort": STEP_VALUES["play"],
        "robot": st.fixed_dictionaries({}, optional={"baud": st.sampled_from([115200, 9600]),
                                                      "retries": st.integers(-1, 12)}),
    },
)


@FUZZ
@given(SHOWS, st.booleans())
def test_show_shaped_data(show, flow):
    check(yaml.safe_dump(show, default_flow_style=flow, allow_unicode=True))


# Valid by construction: such a show must load, and its plan must expand and time it right.
PLAIN_STEP = st.one_of(
    st.builds(lambda m: {"play": m}, st.one_of(st.integers(0, 119), st.sampled_from(["wave", "bow"]))),
    st.builds(lambda s: {"wait": s}, st.floats(0.001, 5, allow_nan=False)),
    st.builds(lambda t: {"wait": "done", **({"timeout": t} if t else {})}, st.one_of(st.none(), st.floats(0.5, 60))),
)
BODY = st.recursive(
    st.lists(PLAIN_STEP, min_size=1, max_size=4),
    lambda inner: st.lists(
        st.one_of(PLAIN_STEP, st.builds(lambda n, s: {"repeat": n, "steps": s}, st.integers(1, 3), inner)),
        min_size=1, max_size=4),
    max_leaves=12,
)


def _expanded(steps: list[dict]) -> int:
    return sum(s["repeat"] * _expanded(s["steps"]) if "repeat" in s else 1 for s in steps)


@FUZZ
@given(BODY, st.lists(st.floats(0, 100), max_size=3), st.booleans())
def test_valid_shows_load_and_plan(body, cues, flow):
    steps = [{"play": "wave"}, *body]
    for n, at in enumerate(sorted(cues)):  # top-level cues, in order
        steps.insert(min(len(steps), 1 + 2 * n), {"play": "bow", "at": at, "label": f"cue{n}"})
    show = {"version": 1, "motions": {"wave": {"number": 4, "duration": 1.5}, "bow": {"number": 1}}, "steps": steps}
    _file.write_text(yaml.safe_dump(show, default_flow_style=flow))
    plan = compile_plan(load_show(_file))
    assert len(plan.steps) == _expanded(steps)
    times = [s.planned_s for s in plan.steps]
    assert times == sorted(times)
    assert all(s.planned_s >= s.at for s in plan.steps if s.at is not None)
    last = plan.steps[-1]
    assert plan.estimated_s >= last.planned_s
    assert abs(plan.estimated_s - (last.planned_s + last.expected_s)) < 1e-6
