"""The show format's JSON Schema, and its findings said in a show author's words.

`schemas/show.schema.json` (draft 2020-12) is the same file editors use, so the file and the
editor agree on what a show may hold. A jsonschema error is written for schema authors
(`'plya' does not match any of the regexes`); each one is reworded here for the person writing
the show and mapped back to the node it is about, through the marks of the parsed `Doc`.
"""

from __future__ import annotations

import functools
import json
from collections.abc import Callable, Mapping
from dataclasses import dataclass
from importlib.resources import files
from itertools import islice
from pathlib import Path
from typing import TYPE_CHECKING, Any

from choreo import SCHEMAS
from choreo.show.cues import MAX_NUMBER_CHARS
from choreo.show.model import MOTION_NAME_FORMAT, is_motion_name
from choreo.show.report import MAX_FOUND, Doc, JsonPath, Report, closest, kind_text, value_text
from choreo.wire.protocol import MOTION_SLOTS, spell_bauds

if TYPE_CHECKING:
    from jsonschema import Draft202012Validator, ValidationError

SCHEMA_FILE = "show.schema.json"
_SLOTS = f"0..{MOTION_SLOTS - 1}"  # the motion numbers a board has, as messages write them


def load_schema() -> dict[str, Any]:
    """The show format's JSON Schema, as shipped inside the package."""
    schema: dict[str, Any] = json.loads(schema_path().read_text(encoding="utf-8"))
    return schema


def modeline(schema: str) -> str:
    """A show's first line that points editors with the YAML language server at `schema`
    (`choreo schema --modeline` prints it, `choreo import` writes it)."""
    return f"# yaml-language-server: $schema={schema}"


def schema_path() -> Path:
    """Where the installed show schema is: what an editor's `$schema=` modeline points at."""
    return Path(str(files(SCHEMAS) / SCHEMA_FILE)).resolve()


@functools.lru_cache(maxsize=1)
def _validator() -> Draft202012Validator:
    """The schema's validator, built once. jsonschema takes about 60 ms to import: it is
    imported here, when a show is checked, not by `choreo schema` or `choreo import`."""
    from jsonschema import Draft202012Validator, FormatChecker

    # Only our own format: a name's letters are Unicode categories, which the schema's
    # pattern cannot say portably (editors run it as an ECMAScript regex).
    formats = FormatChecker(formats=())
    formats.checks(MOTION_NAME_FORMAT)(_is_motion_name)
    return Draft202012Validator(load_schema(), format_checker=formats)


def _is_motion_name(value: object) -> bool:
    """The schema's `motion-name` format: only motion names (mapping keys, so text) have it."""
    return isinstance(value, str) and is_motion_name(value)


def check_schema(doc: Doc, report: Report) -> None:
    """Report every way the document breaks the schema, at the node (or key) concerned, up to
    `MAX_FOUND` of them (a hostile file's 60,000 wrong entries would take seconds)."""
    errors = list(islice(_validator().iter_errors(doc.data), MAX_FOUND))
    if len(errors) == MAX_FOUND:
        report.stop_looking()
    # A wrong type explains everything else wrong at the same node: report it first.
    errors.sort(key=lambda e: (e.validator != "type", len(e.absolute_path)))
    for error in errors:
        for path, message, on_key in _explain(_Error.of(error), doc.data):
            if not on_key and report.silenced(path):
                continue
            mark = doc.key_mark(path) if on_key else doc.mark(path)
            report.add(mark, path, message)


@dataclass(frozen=True)
class _Error:
    """The parts of a jsonschema error the messages read."""

    path: JsonPath  # of the value, from the document's root
    schema_path: tuple[str | int, ...]  # of the keyword, from the schema's root
    validator: str  # the keyword that failed: `type`, `required`, ...
    instance: Any  # the value
    expected: Any  # the keyword's value in the schema
    properties: tuple[str, ...]  # the schema's `properties` where the keyword is
    context: tuple[_Error, ...]  # the errors of each branch of an `anyOf`

    @classmethod
    def of(cls, error: ValidationError) -> _Error:
        schema = error.schema
        properties = schema.get("properties", {}) if isinstance(schema, Mapping) else {}
        return cls(tuple(error.absolute_path), tuple(error.absolute_schema_path), str(error.validator),
                   error.instance, error.validator_value, tuple(sorted(properties)),
                   tuple(cls.of(e) for e in error.context))

    @property
    def leaf(self) -> str | int:
        return self.path[-1] if self.path else ""


_Said = tuple[JsonPath, str, bool]  # where, what, and whether to point at the key


def _explain(error: _Error, data: Any) -> list[_Said]:
    """One jsonschema error as (path, message, point at the key?) in a show author's words:
    the first rule that knows the error says it, else the error's keyword alone does."""
    for rule in _RULES:
        said = rule(error, data)
        if said is not None:
            return said
    return [(error.path, _simple_problem(error.path, error.validator, error.instance, error.expected), False)]


def _dependent_schema(error: _Error, data: Any) -> list[_Said] | None:
    """A step's keys that go together: `timeout` with `wait: done`, one kind a step."""
    if "dependentSchemas" not in error.schema_path:
        return None
    trigger = error.schema_path[error.schema_path.index("dependentSchemas") + 1]
    path = error.path
    step = path[:-1] if path and not isinstance(path[-1], int) else path
    if trigger == "timeout":
        return [(step + ("timeout",), "`timeout` goes with `wait: done` only", True)]
    here = _value_at(data, step)
    return [(step, _step_kind_problem(here if isinstance(here, dict) else {}), False)]


def _tempo_form(error: _Error, data: Any) -> list[_Said] | None:
    """`tempo:` is one tempo (`bpm:`) or a tempo map (`bars:`): not both, not neither."""
    if error.validator != "oneOf" or error.path != ("tempo",) or not isinstance(error.instance, dict):
        return None
    extra = [key for key in ("bpm", "offset") if key in error.instance]
    if "bars" in error.instance and extra:
        return [(error.path + (key,), f"a tempo map (`bars:`) places bar 1 and every bar itself: leave out `{key}:`",
                 True) for key in extra]
    return [(error.path, "needs `bpm:` (one tempo, e.g. `{bpm: 120, offset: 0.5}`) or `bars:` (a tempo "
                         "map: each bar's start in seconds, as `choreo beats` prints it)", False)]


def _whole_show(error: _Error, data: Any) -> list[_Said] | None:
    if error.path or error.validator not in ("oneOf", "not", "dependentRequired"):
        return None
    return [_whole_show_problem(error.validator, error.instance)]


def _robot_settings(error: _Error, data: Any) -> list[_Said] | None:
    path, instance = error.path, error.instance
    if error.validator != "type" or len(path) != 2 or path[0] != "robots" or isinstance(instance, dict):
        return None
    return [(path, f"robot {path[1]!r}: expected its settings as a mapping (`port: ...`, or `{{}}` for "
                   f"none), not {kind_text(instance)}; a show for one robot says `robot:`", False)]


def _property_name(error: _Error, data: Any) -> list[_Said] | None:
    """A key the schema's `propertyNames` refuses: a robot's name or a motion's."""
    if "propertyNames" not in error.schema_path:
        return None
    name = error.instance
    if error.schema_path[1:2] == ("hosts",):
        return [(error.path + (str(name),), f"host name {name!r} must hold only letters, digits, `_` and `-` "
                                            "(1 to 32 characters)", True)]
    if error.schema_path[1:2] in (("robots",), ("tracks",)):
        return [(error.path + (str(name),), _robot_name_problem(name), True)]
    if error.validator == "maxLength":
        return [(error.path + (name,), f"motion name is longer than {error.expected} characters", True)]
    return [(error.path + (str(name),), f"motion name {name!r} must start with a letter or `_` and hold only "
                                        "letters, digits, `_` and `-`", True)]


def _unknown_keys(error: _Error, data: Any) -> list[_Said] | None:
    if error.validator != "additionalProperties" or error.expected is not False or not isinstance(error.instance, dict):
        return None
    allowed = list(error.properties)
    return [(error.path + (key,), _unknown_key(key, allowed), True) for key in error.instance if key not in allowed]


def _missing_keys(error: _Error, data: Any) -> list[_Said] | None:
    if error.validator != "required" or not isinstance(error.instance, dict):
        return None
    return [(error.path + (key,), _REQUIRED.get(key, f"missing: `{key}` is required"), False)
            for key in error.expected if key not in error.instance]


def _step_kind(error: _Error, data: Any) -> list[_Said] | None:
    """A list entry that is no kind of step, or more than one."""
    step = error.instance
    if error.validator != "anyOf" or not isinstance(step, dict) or not isinstance(error.leaf, int):
        return None
    if not any(k in step for k in _STEP_KINDS) and ("steps" in step or any(k not in _STEP_KEYS for k in step)):
        return []  # `plya: 3`, or `steps:` alone: the unknown-key or `repeat` report says it better
    return [(error.path, _step_kind_problem(step), False)]


def _repeat_parts(error: _Error, data: Any) -> list[_Said] | None:
    """`repeat:` and its `steps:` come together."""
    if error.validator != "dependentRequired" or not isinstance(error.instance, dict):
        return None
    if "steps" in error.instance and "repeat" not in error.instance:
        return [(error.path + ("steps",), "nested `steps:` need `repeat: N` beside them", True)]
    return [(error.path + ("repeat",), "`repeat` needs the `steps:` to repeat", True)]


def _one_of_forms(error: _Error, data: Any) -> list[_Said] | None:
    """A value that may be written in two forms (`at:`, `play:`, `wait:`) and is neither."""
    if error.validator != "anyOf":
        return None
    if error.leaf == "at":
        return [_cue_problem(error)]
    if error.leaf == "cue":
        return [(error.path, _cue_number_problem(error), False)]
    if error.path == ("tempo", "bpm"):
        return [(error.path, _bpm_problem(error), False)]
    return [(error.path, _either_problem(error), False)]


# In this order: the first that knows the error says it.
_RULES: tuple[Callable[[_Error, Any], list[_Said] | None], ...] = (
    _tempo_form, _dependent_schema, _whole_show, _robot_settings, _property_name, _unknown_keys, _missing_keys,
    _step_kind, _repeat_parts, _one_of_forms,
)


def _cue_problem(error: _Error) -> _Said:
    """`at:` is seconds or `{bar: N, beat: B}`: say what is wrong with the form it was given in."""
    path, instance = error.path, error.instance
    if isinstance(instance, dict):
        for e in error.context:
            said = _beat_cue_problem(path, instance, e)
            if said is not None:
                return said
    for e in error.context:
        if e.validator not in ("type", "$ref") and not e.path[len(path):]:
            return path, _simple_problem(path, e.validator, e.instance, e.expected), False
    return path, (f"expected seconds (a number) or a bar and beat (`{{bar: 12, beat: 3}}`), "
                  f"not {kind_text(instance)}"), False


def _bpm_problem(error: _Error) -> str:
    """`bpm:` is beats a minute (its range is checked on its own, as before `link` was one) or `link`."""
    return (f"the tempo is beats a minute (more than 0, at most 400) or `link` (with `clock: link`: the "
            f"session's), not {value_text(error.instance)}")


def _cue_number_problem(error: _Error) -> str:
    """`cue:` is a number as written or short text: say which rule the value breaks."""
    instance = error.instance
    kinds = {e.validator for e in error.context}
    if isinstance(instance, str):
        shown = repr(instance) if len(instance) <= 24 else repr(instance[:24]) + "…"
        if "maxLength" in kinds:
            return f"cue number {shown} is longer than {MAX_NUMBER_CHARS} characters: name the cue with `label:`"
        if "minLength" in kinds:
            return "the cue number is empty: give one (`12.5`, `A3`) or leave `cue:` out"
        return (f"cue number {shown} may hold only letters, digits, `.`, `-` and `_`, starting with a letter "
                "or digit: name the cue with `label:`")
    if isinstance(instance, (int, float)) and not isinstance(instance, bool):
        return f"a cue number is 0 or more, not {value_text(instance)}"
    hint = _quote_hint(instance) if isinstance(instance, bool) else ""
    return f"expected a cue number (`12.5`) or short text (`A3`), not {kind_text(instance)}{hint}"


def _beat_cue_problem(path: JsonPath, cue: dict[str, Any], e: _Error) -> _Said | None:
    """What one branch's error says of a cue written as a mapping (a bar and beat)."""
    inner = e.path[len(path):]
    if e.validator == "additionalProperties":
        extra = next(key for key in cue if key not in ("bar", "beat"))
        return path + (extra,), _unknown_key(extra, ["bar", "beat"]), True
    if e.validator == "required":
        return path, "a cue in bars and beats needs its `bar:` (from 1), e.g. `{bar: 12, beat: 3}`", False
    if inner and e.validator != "type":
        return path + inner, _simple_problem(path + inner, e.validator, e.instance, e.expected), False
    if inner:
        return path + inner, f"expected a number, not {kind_text(e.instance)}", False
    return None


def _whole_show_problem(validator: str, show: Any) -> _Said:
    """What the show as a whole lacks or has twice: its steps, its robots."""
    if validator == "not":
        return (("robots",), "a show has `robot:` (one robot) or `robots:` (several, by name), not both", True)
    if validator == "dependentRequired":
        return (("tracks",), "`tracks:` are per robot: name the robots in `robots:` first", True)
    if isinstance(show, dict) and "steps" in show and "tracks" in show:
        return (("tracks",), "a show has `steps:` (every robot together) or `tracks:` (one list per robot), "
                             "not both", True)
    return (("steps",), _REQUIRED["steps"], False)


def _value_at(data: Any, path: JsonPath) -> Any:
    for part in path:
        data = data[part]
    return data


def _unknown_key(key: str, allowed: list[str]) -> str:
    close = closest(key, allowed)
    hint = f"did you mean `{close}`? " if close else ""
    return f"unknown key {key!r}: {hint}expected one of {', '.join(allowed)}"


def _robot_name_problem(name: Any) -> str:
    return (f"robot name {name!r} must start with a letter and hold only letters, digits, `_` and `-` "
            "(at most 32 characters)")


def _step_kind_problem(step: dict[str, Any]) -> str:
    kinds = [key for key in _STEP_KINDS if key in step]
    if not kinds:
        return "a step needs one of `play`, `wait` or `repeat`"
    named = [f"`{k}`" for k in kinds]
    listed = named[0] if len(named) == 1 else ", ".join(named[:-1]) + " and " + named[-1]
    return f"a step does one thing, this one has {listed}: make them separate steps"


def _either_problem(error: _Error) -> str:
    """`play`/`on_abort` (number or name) and `wait` (seconds or `done`)."""
    instance = error.instance
    near = [e for e in error.context if e.validator != "type"]
    if error.leaf == "wait":
        for e in near:
            if e.validator in ("exclusiveMinimum", "minimum"):
                return f"wait takes more than 0 seconds, not {value_text(instance)}"
            if e.validator in ("maximum", "exclusiveMaximum"):
                return f"wait takes at most {value_text(e.expected)} seconds (a day), not {value_text(instance)}"
        return f"wait takes seconds (a number > 0) or `done`, not {value_text(instance)}"
    for e in near:
        if e.validator in ("minimum", "maximum"):
            return _slot_problem(instance)
        if e.validator == "minLength":
            return "the motion name is empty"
    return (f"expected a motion number {_SLOTS} or a name from `motions:`, not {kind_text(instance)}"
            f"{_quote_hint(instance)}")


def _simple_problem(path: JsonPath, validator: str, instance: Any, expected: Any) -> str:
    """One keyword's finding: a robot list's, else the keyword's on this field, else its own."""
    robots = _robot_list_problem(path, validator, instance, expected)
    if robots is not None:
        return robots
    leaf = path[-1] if path else ""
    say = _ON_FIELD.get((validator, leaf)) or _BY_KEYWORD.get(validator)
    if say is None:
        return f"{validator}: not allowed here ({kind_text(instance)})"
    return say(instance, expected)


def _robot_list_problem(path: JsonPath, validator: str, instance: Any, expected: Any) -> str | None:
    """`robots:`/`tracks:` at the top, or a step's `robots:`: what is wrong with the list."""
    hosts = _host_list_problem(path, validator, instance, expected)
    if hosts is not None:
        return hosts
    if validator in _ROBOT_LISTS:
        said = _ROBOT_LISTS[validator].format(expected=expected)
        if len(path) == 1 and path[0] in ("robots", "tracks"):
            return f"`{path[0]}:` {said}"
        if "robots" in path[-2:]:
            return f"a step's `robots:` {said}"
    if validator == "pattern" and len(path) >= 2 and path[-2] == "robots" and isinstance(path[-1], int):
        return _robot_name_problem(instance)
    return None


def _host_list_problem(path: JsonPath, validator: str, instance: Any, expected: Any) -> str | None:
    """`hosts:` (empty, too many), one host's list of robots (empty, a robot twice), a name in it."""
    if path == ("hosts",) and validator in ("minProperties", "maxProperties"):
        return ("`hosts:` is empty: name each host and its robots, or leave it out (one host)"
                if validator == "minProperties" else f"`hosts:` names more than {expected} hosts")
    if len(path) == 3 and path[0] == "hosts" and validator == "pattern":
        return _robot_name_problem(instance)
    if len(path) != 2 or path[0] != "hosts":
        return None
    if validator == "minItems":
        return f"host {path[1]!r} drives no robot: list its robots, or leave the host out"
    if validator == "uniqueItems":
        return f"host {path[1]!r} names a robot twice: list each once"
    return None


def _type_problem(instance: Any, expected: Any) -> str:
    want: list[str] = expected if isinstance(expected, list) else [expected]
    words = " or ".join(_TYPE_WORDS.get(t, t) for t in want)
    return f"expected {words}, not {kind_text(instance)}{_quote_hint(instance) if 'string' in want else ''}"


def _layout_problem(instance: Any, expected: Any) -> str:
    known = " or ".join(f"`{name}`" for name in expected)
    return (f"unknown layout {value_text(instance)}: choreo knows {known} "
            "(`choreo import` reads a board's layout from its Heart to Heart 4 project)")


def _slot_problem(instance: Any, expected: Any = None) -> str:
    """A motion number past the board's slots (`expected`: the schema's bound, implied)."""
    return f"motion {value_text(instance)} is out of range {_SLOTS}"


_Say = Callable[[Any, Any], str]  # (the value, the keyword's value in the schema) -> message

# A keyword's message on one field, before the keyword's own.
_ON_FIELD: dict[tuple[str, str | int], _Say] = {
    ("const", "version"): lambda instance, expected:
        f"unsupported format version {value_text(instance)}: this choreo reads `version: 1`",
    ("enum", "baud"): lambda instance, expected:
        f"baud {value_text(instance)} is not one the RCB-4 speaks: {spell_bauds('or')}",
    ("enum", "layout"): _layout_problem,
    ("minimum", "number"): _slot_problem,
    ("maximum", "number"): _slot_problem,
    ("minItems", "bars"): lambda instance, expected: f"a tempo map needs at least {expected} bars (where each "
        "starts, in seconds); for one tempo give `bpm:` and `offset:`",
    ("maxItems", "bars"): lambda instance, expected:
        f"a tempo map of {len(instance):,} bars is more than the {expected:,} a show may hold",
    ("pattern", "label"): lambda instance, expected:
        f"label {instance!r} must not be only digits (those name steps by index) nor hold `#` or control characters",
}

# A keyword's own message, wherever it is.
_BY_KEYWORD: dict[str, _Say] = {
    "type": _type_problem,
    "minimum": lambda instance, expected: f"must be at least {value_text(expected)}, not {value_text(instance)}",
    "exclusiveMinimum": lambda instance, expected:
        f"must be more than {value_text(expected)}, not {value_text(instance)}",
    "maximum": lambda instance, expected: f"must be at most {value_text(expected)}, not {value_text(instance)}",
    "exclusiveMaximum": lambda instance, expected:
        f"must be at most {value_text(expected)}, not {value_text(instance)}",
    "minItems": lambda instance, expected: "must not be empty: list at least one step",
    "minLength": lambda instance, expected: "must not be empty",
    "maxLength": lambda instance, expected: f"is longer than {expected} characters",
    "const": lambda instance, expected: f"must be {value_text(expected)}, not {value_text(instance)}",
    "enum": lambda instance, expected:
        f"must be one of {', '.join(value_text(v) for v in expected)}, not {value_text(instance)}",
}


def _quote_hint(value: Any) -> str:
    """YAML reads `yes`, `off`, `null` as true/false/nothing: say how to mean the word."""
    if value is None or isinstance(value, bool):
        return " (put the word in quotes to mean text)"
    return ""


_TYPE_WORDS = {
    "object": "a mapping (`key: value` lines)",
    "array": "a list (`- item` lines)",
    "string": "text",
    "integer": "a whole number",
    "number": "a number",
    "boolean": "true or false",
}

_STEP_KINDS = ("play", "wait", "repeat")
_STEP_KEYS = frozenset(("play", "wait", "timeout", "repeat", "steps", "at", "cue", "label", "robots"))

_REQUIRED = {
    "version": "missing: add `version: 1` (the show format's version)",
    "steps": "missing: a show needs `steps:`, the list of what it does (or, with `robots:`, `tracks:`)",
    "number": "missing: give the motion's slot, e.g. `number: 3`",
}

_ROBOT_LISTS = {
    "minProperties": "is empty: name at least one robot",
    "maxProperties": "names more than {expected} robots: at most {expected} in one show",
    "uniqueItems": "names a robot twice: list each once",
    "minItems": "is empty: name at least one robot (or leave it out: every robot)",
}
