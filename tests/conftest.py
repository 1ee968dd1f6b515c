"""Settings every test shares."""

from __future__ import annotations

import os

import pytest
from hypothesis import settings

# Property tests check what choreo does with every input, not how fast: a deadline (hypothesis's
# default is 200 ms an example) is a timed assertion, and a loaded CI machine that stalls one
# example reports the test "flaky". Speed is measured in bench/. The fuzz tests that bound what
# one hostile input may cost keep a deadline of their own, far above any stall (a hang fails).
# derandomize: the same examples on every run and machine, as the rest of the suite is.
settings.register_profile("choreo", deadline=None, derandomize=True, print_blob=True)
settings.load_profile("choreo")


@pytest.fixture(autouse=True)
def output_to_a_pipe(monkeypatch):
    """pytest-xdist's workers export COLUMNS=80, and readline (which pytest loads) exports COLUMNS
    and LINES into the C environment behind os.environ's back, where a subprocess inherits them;
    choreo (like pip) takes COLUMNS as the terminal's width and fits its lines to it. Tests see
    whole lines, as through a pipe, unless they set a width themselves."""
    for name in ("COLUMNS", "LINES"):
        monkeypatch.delenv(name, raising=False)
        os.unsetenv(name)  # the C environment's copy too, which os.environ may not know of


@pytest.fixture(autouse=True)
def no_run_outlives_its_test():
    """A live run a failing test left playing would hold the process's switch interval (and a
    simulator, a log) under the next test in this worker: one failure would become several."""
    yield
    from runlog import stop_leftover_runs

    stop_leftover_runs()
