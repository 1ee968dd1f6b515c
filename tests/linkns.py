"""Test helpers for Ableton Link: processes run together in a fresh loopback-only network namespace.

Link finds its peers by multicast on every network the machine has; a test that joined the
machine's own session could start a musician's transport or take a lab's tempo. So every Link
test runs its processes (choreo hosts, scripted peers: linkpeer.py) inside a namespace of
their own (`unshare -rn`: a user namespace maps us to root inside, with a new network stack),
whose only network is loopback brought up with a multicast route on it. Processes in one
namespace share one Link session; two namespaces never meet, so tests run in parallel.

Where namespaces are unavailable (no unshare, no ip, user namespaces turned off), the test
FAILS saying so: the issue asks that CI fail rather than skip Link silently.
"""

from __future__ import annotations

import os
import shlex
import shutil
import signal
import subprocess
import sys
from dataclasses import dataclass, field
from pathlib import Path

import pytest

REPO = Path(__file__).resolve().parent.parent
PEER = Path(__file__).resolve().parent / "linkpeer.py"
SETUP = "ip link set lo up && ip route add 224.0.0.0/4 dev lo"
READY = "namespace.ok"  # written once the namespace's network is set up
NEVER = -1  # the exit code file of a job never started
RESTORE_SIGINT = ("import os, signal, sys; signal.signal(signal.SIGINT, signal.SIG_DFL); "
                  "os.execv(sys.argv[1], sys.argv[1:])")


@dataclass
class Job:
    """One process of a namespace run: `argv`, started `after` (a shell condition waited for,
    e.g. another job's line in its output: `output_has`), and sent each of `signals` (a signal's
    name, as kill takes it, and the shell condition it waits for)."""

    name: str
    argv: list[str]
    after: str | None = None
    signals: tuple[tuple[str, str], ...] = ()


@dataclass
class Ended:
    """How a job ended: its exit code (None: it never ran) and its output."""

    returncode: int | None
    stdout: str
    stderr: str


@dataclass
class NamespaceRun:
    directory: Path
    jobs: dict[str, Ended] = field(default_factory=dict)

    def __getitem__(self, name: str) -> Ended:
        return self.jobs[name]


def choreo_argv(*args: str) -> list[str]:
    return [sys.executable, "-m", "choreo", *args]


def peer_argv(*args: str) -> list[str]:
    return [sys.executable, str(PEER), *args]


def output_has(directory: Path, job: str, text: str) -> str:
    """A shell condition: `job`'s stderr or stdout holds `text` (for Job.after and signal_when)."""
    files = " ".join(shlex.quote(str(directory / f"{job}.{kind}")) for kind in ("out", "err"))
    return f"grep -qsF -- {shlex.quote(text)} {files}"


def ended(directory: Path, *jobs: str) -> str:
    """A shell condition: every one of `jobs` has ended."""
    return " && ".join(f"[ -e {shlex.quote(str(directory / f'{job}.rc'))} ]" for job in jobs)


def _waited(condition: str, limit_s: float, give_up: str) -> str:
    """Shell that waits (at most `limit_s`, and no longer once `give_up` holds) for `condition`."""
    tries = int(limit_s / 0.02)
    return f"i=0; until {condition} || {give_up} || [ $i -ge {tries} ]; do sleep 0.02; i=$((i+1)); done"


def _job(directory: Path, job: Job, limit_s: float) -> list[str]:
    """Shell for one job: started once its condition holds (or not at all, if another job ended
    first, saying why), its pid and exit code in files; each signal sent once its condition holds."""
    def path(kind: str) -> str:
        return shlex.quote(str(directory / f"{job.name}.{kind}"))
    argv = job.argv
    if any(name == "INT" for name, _ in job.signals):
        # sh starts a job in the background with SIGINT ignored (no job control), and a process
        # keeps that through exec: the job gets the default back, as from a terminal
        argv = [sys.executable, "-c", RESTORE_SIGINT, *argv]
    run = f"{shlex.join(argv)} >{path('out')} 2>{path('err')} & echo $! >{path('pid')}; wait $!; echo $? >{path('rc')}"
    if job.after:
        never = f"echo never started: {shlex.quote(job.after)} >{path('err')}; echo {NEVER} >{path('rc')}"
        anyone_ended = f"ls {shlex.quote(str(directory))}/*.rc >/dev/null 2>&1"
        run = f"{_waited(job.after, limit_s, anyone_ended)}; if {job.after}; then {run}; else {never}; fi"
    lines = [f"( {run} ) &"]
    for name, when in job.signals:
        condition = f"[ -s {path('pid')} ] && {when}"
        waited = _waited(condition, limit_s, f"[ -e {path('rc')} ]")
        lines.append(f"( {waited}; if {condition}; then kill -{name} $(cat {path('pid')}); fi ) &")
    return lines


def _script(directory: Path, jobs: list[Job], limit_s: float, setup: str) -> str:
    lines = [f"{{ {setup}; }} && touch {shlex.quote(str(directory / READY))} || exit 1"]  # no network: no jobs
    for job in jobs:
        lines += _job(directory, job, limit_s)
    return "\n".join([*lines, "wait"]) + "\n"


def run_in_namespace(directory: Path, jobs: list[Job], timeout: float = 30.0, *,
                     setup: str | None = None) -> NamespaceRun:
    """Run `jobs` together in a fresh loopback-only network namespace; each one's exit code and
    output once all ended. The test fails if namespaces are unavailable, or at `timeout`.
    `setup`: the namespace's network set up another way (SETUP: loopback with a multicast route)."""
    for tool in ("unshare", "ip"):
        if shutil.which(tool) is None:
            pytest.fail(f"the Link tests need network namespaces: {tool} is not installed (util-linux, iproute2)")
    script = _script(directory, jobs, timeout, setup if setup is not None else SETUP)
    env = dict(os.environ)
    env["PYTHONPATH"] = str(REPO) + os.pathsep + env.get("PYTHONPATH", "")
    # a session of its own: on a timeout every process of the namespace is killed, none left behind
    setup = subprocess.Popen(["unshare", "-rn", "sh", "-c", script], stdout=subprocess.PIPE,
                             stderr=subprocess.PIPE, text=True, cwd=directory, env=env, start_new_session=True)
    try:
        _, stderr = setup.communicate(timeout=timeout)
    except subprocess.TimeoutExpired:
        os.killpg(setup.pid, signal.SIGKILL)
        setup.communicate()
        pytest.fail(f"the namespace's processes ran past {timeout:g} s: {_outputs(directory, jobs)}")
    if not (directory / READY).exists():
        pytest.fail("the Link tests need a network namespace (unshare -rn, then ip on its loopback), and "
                    f"none could be made here (exit {setup.returncode}): {stderr.strip()[-400:]}")
    run = NamespaceRun(directory)
    for job in jobs:
        rc = directory / f"{job.name}.rc"
        code = int(rc.read_text()) if rc.exists() else NEVER
        run.jobs[job.name] = Ended(None if code == NEVER else code,
                                   _read(directory / f"{job.name}.out"), _read(directory / f"{job.name}.err"))
    return run


def _read(path: Path) -> str:
    return path.read_text(errors="replace") if path.exists() else ""


def _outputs(directory: Path, jobs: list[Job]) -> str:
    """Each job's state and the end of its output, for a run that never ended."""
    def one(job: Job) -> str:
        rc = directory / f"{job.name}.rc"
        state = f"exit {_read(rc).strip()}" if rc.exists() else "running"
        return (f"\n--- {job.name} ({state}) stderr: {_read(directory / f'{job.name}.err')[-1500:]}"
                f"\n--- {job.name} stdout: {_read(directory / f'{job.name}.out')[-600:]}")
    return "".join(one(job) for job in jobs)
