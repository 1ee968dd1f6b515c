"""Wiring with an owner: whoever attaches a listener or a stop check detaches it, a stop request
keeps the first reason but never loses a panic, and no module sets another object's attributes.

Issue 22: `--loop` built new runners on the same link and each appended a retry reporter that
was never removed (pass N logged each failed try N times); `StopRequest.reason` was written from
four threads, last writer winning, so a link fault right after a panic turned the panic into a
plain stop and the other robots never got their stop frames.
"""

from __future__ import annotations

import ast
import threading
from pathlib import Path

import pytest

from choreo.board.link import Link
from choreo.clock import RunClock, VirtualTime
from choreo.errors import LinkError
from choreo.events import PANIC, STOPPED, StepEvent, StopRequest, never
from choreo.log.format import WARNING
from choreo.run.runner import Runner
from choreo.show.load import load_show
from choreo.show.plan import compile_plan
from choreo_source import PACKAGE, source_files, syntax_tree
from runlog import prepare, read_log, write_show

FAULT = "stopped: robot right's link failed"


# -- the stop request ------------------------------------------------------------------------------


def test_the_first_reason_wins_and_says_whether_it_took():
    stop = StopRequest()
    assert not stop() and stop.reason == STOPPED  # nothing asked yet
    assert stop.request("interrupted (Ctrl-C)")
    assert not stop.request(FAULT)  # a later reason does not replace the first
    assert stop() and stop.reason == "interrupted (Ctrl-C)" and not stop.panicked


@pytest.mark.parametrize("first", ["interrupted (Ctrl-C)", FAULT, STOPPED])
def test_a_panic_replaces_any_reason_and_nothing_replaces_a_panic(first):
    stop = StopRequest()
    stop.request(first)
    assert stop.request(PANIC)  # the panic after a fault (or a Ctrl-C) is still a panic
    assert not stop.request(FAULT)  # the fault the panic's stop frames cause comes after it
    assert not stop.request("interrupted (Ctrl-C)")
    assert stop.reason == PANIC and stop.panicked


def test_the_reason_is_read_only():
    stop = StopRequest()
    with pytest.raises(AttributeError):
        stop.reason = PANIC  # type: ignore[misc]  # the point: nobody sets it from outside


def test_a_fault_racing_a_panic_on_other_threads_still_ends_as_a_panic():
    """Every thread released at once by a barrier: the runner threads' faults, the log's full
    disk and a Ctrl-C against the operator's panic. Whatever the interleaving, a panic."""
    reasons = [PANIC, FAULT, "stopped: robot left's link failed", "stopped: the log's disk is full (x)",
               "interrupted (Ctrl-C)"]
    for round_ in range(200):
        stop = StopRequest()
        order = reasons[round_ % len(reasons):] + reasons[:round_ % len(reasons)]  # who starts first varies
        barrier = threading.Barrier(len(order))

        def ask(reason: str, stop: StopRequest = stop, barrier: threading.Barrier = barrier) -> None:
            barrier.wait()
            stop.request(reason)

        threads = [threading.Thread(target=ask, args=(reason,)) for reason in order]
        for thread in threads:
            thread.start()
        for thread in threads:
            thread.join()
        assert stop.reason == PANIC, (round_, stop.reason)


# -- a run's listeners and stop check --------------------------------------------------------------

SHOW = """
    version: 1
    motions:
      home: {number: 0, duration: 0.05}
    on_abort: home
    steps:
      - play: 3
      - wait: 0.2
      - play: 4
"""


class Frames:
    """A link listener for the whole life of the link (as the log is): given at its opening."""

    def __init__(self, stop: StopRequest | None = None, stop_at: int | None = None) -> None:
        self.stop = stop
        self.stop_at = stop_at
        self.sent = 0

    def on_tx(self, event: object) -> None:
        self.sent += 1
        if self.stop is not None and self.sent == self.stop_at:
            self.stop.request("interrupted (test)")

    def on_rx(self, event: object) -> None:
        pass


def _runner(tmp_path: Path, url: str, stop: StopRequest, frames: Frames) -> Runner:
    show = load_show(write_show(tmp_path, SHOW))
    clock = RunClock(VirtualTime())
    link = Link.open(url, listeners=[frames], clock=clock)
    return Runner(compile_plan(show), link, clock=clock, on_abort=show.on_abort, stop=stop)


@pytest.mark.parametrize("url, stop_at, outcome", [
    ("sim://", None, "done"),
    ("sim://", 2, "aborted"),  # interrupted mid-show: the abort motion under its own `never` check
    ("sim://?nak=1&faults_on=play", None, LinkError),  # every CALL refused: the run fails
])
def test_after_a_run_only_the_links_own_listeners_remain(tmp_path, url, stop_at, outcome):
    stop = StopRequest()
    frames = Frames(stop, stop_at)
    runner = _runner(tmp_path, url, stop, frames)
    link = runner.link
    assert list(link.listeners) == [frames]
    if isinstance(outcome, type):
        with pytest.raises(outcome):
            runner.run()
    else:
        assert runner.run().outcome == outcome
    assert list(link.listeners) == [frames]  # the run's retry reporter went with the run
    assert link._should_stop is never  # and so did its stop check: the next user of the link starts clean


def test_a_subscription_detaches_once_and_leaves_the_others(tmp_path):
    frames, other = Frames(), Frames()
    link = _runner(tmp_path, "sim://", StopRequest(), frames).link
    with link.subscribe(other) as subscription:
        assert list(link.listeners) == [frames, other]
        link.query_status()
        subscription.close()
        subscription.close()  # once only: a second close removes nothing else
    assert list(link.listeners) == [frames]
    link.query_status()
    assert (frames.sent, other.sent) == (2, 1)


# -- whole runs on virtual time --------------------------------------------------------------------

LOOP_SHOW = """
    version: 1
    steps:
      - play: 1
        label: intro
      - play: 2
        label: a
      - wait: 0.1
      - play: 3
        label: b
      - play: 4
"""


class StopAtPass:
    """Stops the run as `--loop`'s pass `last + 1` begins (the operator's Ctrl-C, on virtual
    time: the same passes on any machine)."""

    def __init__(self, stop: StopRequest, last: int) -> None:
        self.stop = stop
        self.last = last

    def on_step(self, event: StepEvent) -> None:
        pass

    def on_log(self, level: int, message: str, time_ns: int | None = None) -> None:
        if message.startswith(f"loop: pass {self.last + 1} "):
            self.stop.request("interrupted (test)")


def test_loop_over_three_passes_logs_each_failed_try_once(tmp_path):
    """Every 5th frame NAKed over three passes of a section: one warning line per NAK. Before,
    pass N's link carried N retry reporters (23 lines for 11 NAKs)."""
    from choreo.run.settings import RunRequest

    show = write_show(tmp_path, LOOP_SHOW)
    log_path = tmp_path / "run.mcap"
    session = prepare(RunRequest(str(show), port="sim://?nak=5", log_path=str(log_path), loop="a..b"))
    stop = StopRequest()
    with session:
        result = session.run([StopAtPass(stop, 3)], stop)
    assert result.outcome == "aborted"
    log = read_log(log_path)
    passes = [m for m in log.logs if m["message"].startswith("loop: pass")]
    assert [m["message"] for m in passes] == ["loop: pass 2 from 'a' to 'b'", "loop: pass 3 from 'a' to 'b'",
                                              "loop: pass 4 from 'a' to 'b'"]
    naks = [m for m in log.rx if m["kind"] == "nak"]
    in_pass_3 = [m for m in naks if passes[1]["_log_time"] <= m["_log_time"] < passes[2]["_log_time"]]
    assert len(naks) >= 4 and in_pass_3  # pass 3 met some: it would have logged each three times
    warned = [m["message"] for m in log.logs if m["level"] == WARNING and "NAK" in m["message"]]
    assert len(warned) == len(naks), warned
    assert len(set(warned)) == len(warned)  # no line twice


TWO_ROBOTS = """
    version: 1
    robots:
      left: {}
      right: {}
    steps:
      - play: 1
      - wait: 5
        label: hold
      - play: 2
"""


class PanicAt:
    """The operator's panic as robot `robot` starts step `label` (from that robot's thread, as a
    panic from the console lands between two of its frames)."""

    def __init__(self, stop: StopRequest, robot: str, label: str) -> None:
        self.stop = stop
        self.robot = robot
        self.label = label

    def on_step(self, event: StepEvent) -> None:
        if event.event == "start" and event.robot == self.robot and event.step.label == self.label:
            self.stop.request(PANIC)

    def on_log(self, level: int, message: str, time_ns: int | None = None) -> None:
        pass


def test_a_link_fault_right_after_a_panic_still_ends_the_show_as_a_panic(tmp_path):
    """Right panics, and its panic stop frame is lost with its port: its fault asks the show to
    stop just after the panic. Left, woken later, still reads a panic and sends its stop frame
    (it has no abort motion); before, the fault's reason replaced the panic and left sent nothing."""
    from choreo.run.settings import RunRequest

    show = write_show(tmp_path, TWO_ROBOTS)
    log_path = tmp_path / "run.mcap"
    ports = {"left": "sim://", "right": "sim://?lose=2&faults_on=stop"}  # right's 2nd stop frame: the panic's
    session = prepare(RunRequest(str(show), robot_ports=ports, log_path=str(log_path)))
    stop = StopRequest()
    with session, pytest.raises(LinkError, match="robot right"):
        session.run([PanicAt(stop, "right", "hold")], stop)
    assert stop.reason == PANIC
    log = read_log(log_path)
    lines = [m["message"] for m in log.logs]
    assert any(line.startswith("robot left: show panic at") for line in lines), lines
    assert "robot left: panic: stop frame" in lines
    assert not any("link failed at" in line and line.startswith("robot left") for line in lines)
    left_stops = [m for m in log.topic("/rcb4/left/tx") if m["kind"] == "stop"]
    assert len(left_stops) == 2  # the play's, then the panic's


class Heard:
    """A command listener, with the optional GO-cue hook or without it."""

    def __init__(self) -> None:
        self.commands: list[str] = []

    def on_command(self, event) -> None:  # type: ignore[no-untyped-def]
        self.commands.append(event.command.name)


class HeardWithCues(Heard):
    def __init__(self) -> None:
        super().__init__()
        self.cues: list[str] = []

    def on_waiting(self, cue) -> None:  # type: ignore[no-untyped-def]
        self.cues.append(cue.name)


def test_live_tells_the_go_cue_hook_only_to_those_declaring_it_and_subscriptions_end(tmp_path):
    from choreo.events import Command, WaitingListener
    from choreo.live.controls import Live
    from choreo.show.model import SOLO

    show = load_show(write_show(tmp_path, "version: 1\nsteps:\n  - play: 1\n    at: go\n    label: bow\n"))
    step = compile_plan(show).steps[0]
    time = VirtualTime()
    live = Live(StopRequest(), now=time.now, lockout_s=0.0)
    plain, cued = Heard(), HeardWithCues()
    assert isinstance(cued, WaitingListener) and not isinstance(plain, WaitingListener)
    with live.subscribe(plain), live.subscribe(cued):
        waiter = threading.Thread(target=live.await_go, args=(step, SOLO, 0.0, never))
        waiter.start()
        while not live.waiting:
            time.advance(0.01)
        assert live.command(Command("go", "test")).ok
        waiter.join(5)
    assert live.command(Command("stop", "test")).ok  # after the subscriptions: nobody hears it
    assert cued.cues == ["bow"] and plain.commands == cued.commands == ["go"]
    assert len(live.listeners) == 0


def test_the_log_hears_the_live_controls_for_the_run_only(tmp_path):
    """The session subscribes its log to the live controls for the run, and sums up what the
    limits held back into it before it unsubscribes: nothing of it is left on the controls."""
    from choreo.events import Command
    from choreo.live.controls import Live
    from choreo.run.settings import RunRequest

    show = write_show(tmp_path, "version: 1\nsteps:\n  - play: 1\n  - wait: 0.5\n")
    log_path = tmp_path / "run.mcap"
    session = prepare(RunRequest(str(show), log_path=str(log_path)))
    live = Live(StopRequest(), now=session.clock.mono, wall_ns=session.clock.wall_ns)
    with session:
        result = session.run([], live=live)
        assert result.outcome == "done"
        assert len(live.listeners) == 0  # the log no longer hears the controls
        live.command(Command("go", "test"))  # after the run: not the log's any more
    commands = read_log(log_path).topic("/choreo/command")
    assert commands == []


def test_the_console_watches_the_links_from_its_start_to_its_close(tmp_path):
    import io

    from choreo.cli.console import Console
    from choreo.live.controls import Live
    from choreo.run.settings import RunRequest

    session = prepare(RunRequest(str(write_show(tmp_path, "version: 1\nsteps:\n  - play: 1\n")), no_log=True))
    with session:
        link = next(iter(session.stage.links.values()))
        assert len(link.listeners) == 0  # no log: nobody listens to the link of its own
        console = Console(session, Live(StopRequest()), out=io.StringIO(), keys=io.StringIO(), width=80)
        console.start()
        try:
            assert len(link.listeners) == 1
        finally:
            console.close()
        assert len(link.listeners) == 0


def test_a_port_that_keeps_time_is_given_the_runs_clock_whatever_its_class(monkeypatch):
    """The board layer asks for a capability (KeepsTime), not for the simulator: any port with a
    time source gets the run's; one without is refused on virtual time."""
    import serial

    from choreo.board.link import KeepsTime, open_port

    class Timed:
        port = "test://"

        def __init__(self) -> None:
            self.time_source = None
            self.opened = False

        def open(self) -> None:
            self.opened = True

    class Plain:
        port = "test://"

        def open(self) -> None:
            raise AssertionError("a port that keeps no time is not opened on virtual time")

    clock = RunClock(VirtualTime())
    monkeypatch.setattr(serial, "serial_for_url", lambda url, **settings: Timed())
    port = open_port("test://", clock=clock)
    assert isinstance(port, KeepsTime) and port.time_source is clock.source and port.opened
    monkeypatch.setattr(serial, "serial_for_url", lambda url, **settings: Plain())
    with pytest.raises(LinkError, match="only the in-process simulator"):
        open_port("test://", clock=clock)


def test_nothing_imports_the_process_entry():
    """`choreo.__main__` imports the CLI; the CLI and everything else read the signals from
    `choreo.signals`: the dependency runs one way."""
    importers = []
    for path in source_files():
        for node in ast.walk(syntax_tree(path)):
            if isinstance(node, ast.ImportFrom) and node.module == "choreo.__main__" or \
                    isinstance(node, ast.Import) and any(a.name == "choreo.__main__" for a in node.names):
                importers.append(str(path.relative_to(PACKAGE.parent)))
    assert importers == []


# -- nobody sets another object's attributes -------------------------------------------------------

# Assignments `x.attr = ...` with x not `self`/`cls`, which are genuinely the assigner's to make.
# Keyed by the target as written; each with its reason. Anything else is wiring from outside.
ALLOWED = {
    "port.time_source": "a pyserial port's setting, given by open_port before it opens the port it made",
    "sys.stdout": "the process's standard streams, swapped by the CLI entry that owns the process",
    "sys.stderr": "the process's standard streams, swapped by the CLI entry and the console it starts",
    "sys.excepthook": "the process entry installs how a crash is printed",
    "threading.excepthook": "the process entry installs how a crash in a thread is printed",
    "subparsers.required": "argparse's documented way to require a subcommand, on a parser built here",
    "commands.required": "argparse's documented way to require a subcommand, on a parser built here",
    "function.argtypes": "ctypes: the prototype of a C function this module looked up",
    "function.restype": "ctypes: the prototype of a C function this module looked up",
    "library.snd_lib_error_set_handler.argtypes": "ctypes: the prototype of the C function it calls",
    "library.snd_lib_error_set_handler.restype": "ctypes: the prototype of the C function it calls",
    "live_render._shape": "rich keeps no public way to forget the drawn shape after a terminal resize",
    "self._screen.size": "rich's Console.size setter, on the console this object made",
    "self.line.settings": "the simulator's own line, held by the port that made it",
    "setattr(sys)": "the process entry gives Python a stream on a standard descriptor found closed at start-up",
    "link.quantum": "aalink's Link is set up by its properties (the binding's only way), on the peer the session made",
    "link.start_stop_sync_enabled": "aalink's Link is set up by its properties, on the peer the session made",
    "link.enabled": "aalink's Link joins and leaves by its `enabled` property, on the peer the session made",
    "link.tempo": "aalink's Link proposes a tempo to the session by its `tempo` property, on the session's peer",
    "serial.protocol_handler_packages.append": "pyserial's documented way to find URL handlers by package name "
                                               "(register_url_handlers adds choreo.sim once)",
}


def _class_names(node: ast.AST | None) -> set[str]:
    """The class names an annotation or an expression mentions (`_Gate | None`, `_Gate()`)."""
    if node is None:
        return set()
    if isinstance(node, ast.Constant) and isinstance(node.value, str):
        try:
            node = ast.parse(node.value, mode="eval")
        except SyntaxError:
            return set()
    return {n.id for n in ast.walk(node) if isinstance(n, ast.Name)}


def _own_records(function: ast.FunctionDef | ast.AsyncFunctionDef, classes: set[str]) -> set[str]:
    """Names in `function` that hold an instance of a class of the function's own module: a
    parameter annotated with one, or a name bound to what such a class made. Filling in the
    module's own record is its own business; an object of another module's class is not."""
    args = function.args
    own = {a.arg for a in (*args.posonlyargs, *args.args, *args.kwonlyargs)
           if _class_names(a.annotation) & classes}
    for node in ast.walk(function):
        if isinstance(node, ast.Assign) and _called_classes(node.value) & classes:
            own |= {n.id for target in node.targets for n in ast.walk(target) if isinstance(n, ast.Name)}
        elif isinstance(node, ast.AnnAssign) and isinstance(node.target, ast.Name) and \
                _class_names(node.annotation) & classes:
            own.add(node.target.id)
    return own


def _called_classes(node: ast.AST) -> set[str]:
    return {n.func.id for n in ast.walk(node) if isinstance(n, ast.Call) and isinstance(n.func, ast.Name)}


def _outside_assignments(path: Path, root: Path = PACKAGE.parent) -> list[str]:
    tree = syntax_tree(path)
    classes = {n.name for n in ast.walk(tree) if isinstance(n, ast.ClassDef)}
    found = []
    # what the module does as it is imported (`Other.attr = ...` at its top level) is read too
    top = [s for s in tree.body if not isinstance(s, (ast.FunctionDef, ast.AsyncFunctionDef, ast.ClassDef))]
    on_import = ast.FunctionDef(name="<module>", args=ast.arguments(posonlyargs=[], args=[], kwonlyargs=[],
                                kw_defaults=[], defaults=[]), body=top or [ast.Pass()], decorator_list=[])
    for function in [*ast.walk(tree), on_import]:
        if not isinstance(function, (ast.FunctionDef, ast.AsyncFunctionDef)):
            continue
        own = _own_records(function, classes) | {"self", "cls"}
        for node in ast.walk(function):
            targets = node.targets if isinstance(node, ast.Assign) else \
                [node.target] if isinstance(node, (ast.AugAssign, ast.AnnAssign)) else []
            for attribute in (a for t in targets for a in ast.walk(t)):
                if not isinstance(attribute, ast.Attribute) or not isinstance(attribute.ctx, ast.Store):
                    continue
                if isinstance(attribute.value, ast.Name) and attribute.value.id in own:
                    continue
                found.append(f"{path.relative_to(root)}:{node.lineno}: {ast.unparse(attribute)}")
        found += [f"{path.relative_to(root)}:{line}: {what}" for line, what in _outside_mutations(function, own)]
    return found


# What changes an object as surely as `x.attr = ...` does: a container attribute edited in
# place, an attribute deleted, or set and read by name.
_MUTATORS = {"append", "extend", "insert", "remove", "pop", "popitem", "clear", "update", "setdefault",
             "add", "discard", "sort", "reverse", "__setitem__", "__delitem__", "__setattr__", "__delattr__"}


def _foreign(node: ast.AST, own: set[str]) -> bool:
    """An attribute of something other than the function's own names (`link.listeners`,
    `self.runner.cues`, `make().x`): not `self.x`, not `record.x` of its own record."""
    return isinstance(node, ast.Attribute) and not (isinstance(node.value, ast.Name) and node.value.id in own)


def _outside_mutations(function: ast.FunctionDef | ast.AsyncFunctionDef, own: set[str]) -> list[tuple[int, str]]:
    """`setattr(x, ...)`, `vars(x)`, `x.__dict__`, `x.items.append(...)`, `x.table[k] = v`,
    `x.total[k] += 1`, `del x.attr`, `del x.table[k]`, `for x.attr in ...`, `with ... as x.attr`."""
    found: list[tuple[int, str]] = []
    for node in ast.walk(function):
        call = _outside_call(node, own) if isinstance(node, ast.Call) else None
        if call is not None:
            found.append((node.lineno, call))
        elif isinstance(node, ast.Attribute) and node.attr == "__dict__":
            found.append((node.lineno, ast.unparse(node)))
        targets = node.targets if isinstance(node, (ast.Assign, ast.Delete)) else \
            [node.target] if isinstance(node, (ast.AugAssign, ast.AnnAssign, ast.For, ast.AsyncFor)) else \
            [item.optional_vars for item in node.items if item.optional_vars is not None] \
            if isinstance(node, (ast.With, ast.AsyncWith)) else []
        for target in targets:
            if isinstance(target, ast.Subscript) and _foreign(target.value, own):
                found.append((node.lineno, f"{ast.unparse(target.value)}[]"))
            elif isinstance(node, ast.Delete) and _foreign(target, own):
                found.append((node.lineno, f"del {ast.unparse(target)}"))
            elif isinstance(node, (ast.For, ast.AsyncFor, ast.With, ast.AsyncWith)) and _foreign(target, own):
                found.append((node.lineno, ast.unparse(target)))
    return found


def _outside_call(node: ast.Call, own: set[str]) -> str | None:
    """A call that changes another object: `setattr(x, ...)`, `vars(x)`, `x.items.append(...)`,
    `x.__setattr__(...)`, `object.__setattr__(x, ...)`; None for anything else."""
    func = node.func
    if isinstance(func, ast.Name) and node.args and func.id in ("setattr", "delattr", "vars"):
        receiver: ast.expr = node.args[0]
    elif isinstance(func, ast.Attribute) and func.attr in _MUTATORS and _foreign(func.value, own):
        return ast.unparse(func)
    elif isinstance(func, ast.Attribute) and func.attr in ("__setattr__", "__delattr__") and \
            isinstance(func.value, ast.Name):
        receiver = node.args[0] if func.value.id in ("object", "type") and node.args else func.value
    else:
        return None
    if isinstance(receiver, ast.Name) and receiver.id in own:
        return None
    name = func.id if isinstance(func, ast.Name) else func.attr
    return f"{name}({ast.unparse(receiver)})"


def _all_outside_assignments() -> list[str]:
    return sorted({line for path in source_files() for line in _outside_assignments(path)})


def test_no_module_sets_another_objects_attributes():
    """`link.should_stop = ...`, `runner.cues = ...`, `recorder.on_stop = ...`, `live.show = ...`
    were wiring from outside; each is now a constructor argument, a per-run argument, or a
    scoped context of the object's own."""
    found = [line for line in _all_outside_assignments() if line.split(": ", 1)[1] not in ALLOWED]
    assert found == [], "\n".join(found)


def test_every_allowed_assignment_is_still_needed():
    """The allow-list shrinks with the code: an entry the check would no longer flag is taken out."""
    needed = {line.split(": ", 1)[1] for line in _all_outside_assignments()}
    assert sorted(set(ALLOWED) - needed) == []


def test_the_attribute_check_sees_wiring_from_outside(tmp_path):
    """The check itself: an object's attribute set by another, a parameter's, is found; a
    record the function built, and `self`, are not."""
    sample = tmp_path / "choreo" / "sample.py"
    sample.parent.mkdir()
    sample.write_text("from choreo.run.runner import Runner\n"
                      "class Record:\n    total = 0\n"
                      "def wire(runner, gates):\n    runner.cues = gates\n    self.x = 1\n"
                      "def build(old: Record):\n    record = Record()\n    record.total = 3\n    old.total = 4\n"
                      "def start(plan):\n    runner = Runner(plan)\n    runner.on_idle = print\n")
    assert _outside_assignments(sample, tmp_path) == ["choreo/sample.py:5: runner.cues",
                                                      "choreo/sample.py:13: runner.on_idle"]
    assert "port.time_source" in ALLOWED  # the allow-list is applied by the test, not by the check


def test_the_attribute_check_sees_edits_that_are_not_plain_assignments(tmp_path):
    """The holes a plain `x.attr = ...` check leaves: a list or dict attribute edited in place,
    set by name or through `__dict__`/`vars`, deleted, or bound by a loop or a `with`. The
    function's own names (`self`, its own records) stay its own to change."""
    sample = tmp_path / "choreo" / "sample.py"
    sample.parent.mkdir()
    sample.write_text("class Record:\n    total = 0\n"
                      "def wire(link, runner, live, name, make):\n"
                      "    link.listeners.append(print)\n"        # 4
                      "    runner.gates[name] = None\n"           # 5
                      "    runner.counts[name] += 1\n"            # 6
                      "    setattr(runner, name, None)\n"         # 7
                      "    runner.__dict__['cues'] = None\n"      # 8
                      "    vars(live)['show'] = None\n"           # 9
                      "    del link.should_stop\n"                # 10
                      "    del runner.gates[name]\n"              # 11
                      "    make().extras.update(a=1)\n"           # 12
                      "    for live.show in (1, 2):\n        pass\n"  # 13
                      "    self.link.listeners.remove(print)\n"   # 15
                      "def own(self, name):\n"
                      "    record = Record()\n"
                      "    self.items.append(name)\n    self.table[name] = 1\n    del self.table[name]\n"
                      "    setattr(self, name, 1)\n    setattr(record, name, 2)\n    record.parts.append(3)\n"
                      "Runner.on_idle = print\n"                 # 24: on import, another module's class
                      "serial.protocol_handler_packages.append('x')\n"  # 25
                      "HANDLERS = []\nHANDLERS.append(print)\n"  # the module's own list
                      "def dunder(runner, self):\n"
                      "    runner.__setattr__('cues', None)\n"      # 29
                      "    object.__setattr__(runner, 'cues', None)\n"  # 30
                      "    object.__setattr__(self, 'frozen', 1)\n")  # a frozen dataclass's own field
    assert sorted(_outside_assignments(sample, tmp_path)) == sorted(
        f"choreo/sample.py:{line}: {what}" for line, what in [
            (4, "link.listeners.append"), (5, "runner.gates[]"), (6, "runner.counts[]"), (7, "setattr(runner)"),
            (8, "runner.__dict__[]"), (8, "runner.__dict__"), (9, "vars(live)"),
            (10, "del link.should_stop"), (11, "runner.gates[]"), (12, "make().extras.update"),
            (13, "live.show"), (15, "self.link.listeners.remove"), (24, "Runner.on_idle"),
            (25, "serial.protocol_handler_packages.append"), (29, "__setattr__(runner)"),
            (30, "__setattr__(runner)")])
