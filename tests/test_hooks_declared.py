"""Optional hooks and capabilities are declared, not probed (issue 22): choreo asks
`isinstance(x, SomeProtocol)` of its own objects, never `hasattr(x, "on_result")` or
`getattr(x, "stage", None)`. What is still probed by name is the platform (a signal or a
flag this OS may lack), an exception's optional fields, argparse's namespace, and third-party
objects with no declared interface; each is listed here with its reason.
"""

from __future__ import annotations

import ast
from pathlib import Path

from choreo_source import PACKAGE, source_files, syntax_tree


# `receiver.name` as written (`*`: a name computed at run time), with why probing it is right.
PROBED = {
    "sys.*": "the process entry: which standard streams Python found closed at start-up",
    "sys.stdout.buffer": "a replaced stdout (a test's, an embedding program's) may have no binary buffer",
    "exc.strerror": "an OSError's text, absent from other exceptions",
    "exc.errno": "an OSError's number, absent from other exceptions",
    "exc.start": "a UnicodeDecodeError's position, absent from other decoding errors",
    "exc.character": "a YAML reader error's character, absent from other YAML errors",
    "exc.position": "a YAML reader error's position, absent from other YAML errors",
    "port.port": "pyserial's port name: a URL handler's port may not carry one",
    "args.*": "argparse's namespace: the options a subcommand defines",
    "args.parser": "argparse's namespace: the subparser, set only when a subcommand was given",
    "args.json": "argparse's namespace: only some commands have --json",
    "args.own_json_failure": "argparse's namespace: set by the commands that print their own failure record",
    "termios.*": "the platform: not every OS has every terminal constant",
    "signal.*": "the platform: not every OS has every signal",
    "os.O_BINARY": "the platform: an open flag only some OSes have",
    "os.O_NOCTTY": "the platform: an open flag only some OSes have",
    "os.O_NONBLOCK": "the platform: an open flag only some OSes have",
    "socket.CMSG_SPACE": "the platform: not every OS has ancillary data",
    "libc.fallocate64": "the C library: glibc names it so, others only fallocate",
    "yaml.CSafeLoader": "PyYAML built without libyaml has no C loader",
    "out.encoding": "a text stream given by the caller may not say its encoding",
    "self.wrapped.*": "a stream wrapper's __getattr__: whatever the wrapped stream has",
    "self._stream.*": "a stream wrapper's __getattr__: whatever the wrapped stream has",
    "self.stream.*": "a stream wrapper's __getattr__: whatever the wrapped stream has",
    "self.*": "a record's own dataclass fields, read by their names",
    "report.*": "replay sums its own ReplayReport's counter fields by their names",
    "part.*": "replay sums its own ReplayReport's counter fields by their names",
    "self._rich._live_render": "rich keeps no public way to forget the drawn shape after a resize",
    "live_render._shape": "rich keeps no public way to forget the drawn shape after a resize",
    "self._rich._lock": "rich keeps no public way to forget the drawn shape after a resize",
}


def probes(path: Path, root: Path = PACKAGE.parent) -> list[str]:
    """Each `hasattr(x, name)` / `getattr(x, name, ...)` in a module: `path:line: x.name`."""
    found = []
    for node in ast.walk(syntax_tree(path)):
        if isinstance(node, ast.Call) and isinstance(node.func, ast.Name) and \
                node.func.id in ("hasattr", "getattr") and len(node.args) >= 2:
            name = node.args[1]
            attr = name.value if isinstance(name, ast.Constant) and isinstance(name.value, str) else "*"
            found.append(f"{path.relative_to(root)}:{node.lineno}: {ast.unparse(node.args[0])}.{attr}")
    return found


def _all_probes() -> list[str]:
    return sorted(line for path in source_files() for line in probes(path))


def test_nothing_of_choreos_own_is_probed_by_name():
    """The console looked for a session's stage with getattr (a Session always has one, None
    until it opens); listener hooks were found with hasattr before they became Protocols."""
    found = [line for line in _all_probes() if line.split(": ", 1)[1] not in PROBED]
    assert found == [], "\n".join(found)


def test_every_listed_probe_is_still_made():
    """The list shrinks with the code: a probe no longer made is taken out."""
    made = {line.split(": ", 1)[1] for line in _all_probes()}
    assert sorted(set(PROBED) - made) == []


def test_the_probe_check_sees_a_hook_looked_for_by_name(tmp_path):
    sample = tmp_path / "choreo" / "sample.py"
    sample.parent.mkdir()
    sample.write_text("def tell(listener, result, name):\n"
                      "    if hasattr(listener, 'on_result'):\n        listener.on_result(result)\n"
                      "    hook = getattr(listener, name, None)\n")
    assert probes(sample, tmp_path) == ["choreo/sample.py:2: listener.on_result", "choreo/sample.py:4: listener.*"]
