"""A port that fails to open is logged at its time on the run's clock (issue 21 follow-up): the
error line was stamped with the machine's wall clock, so on virtual time (or the music's clock)
`log summary` placed it near -1000 s on the show clock."""

from __future__ import annotations

import pytest

from choreo.review.summary import summarize
from runlog import read_log, vmain, write_show

SHOW = "version: 1\nsteps:\n  - play: 1\n"
TWO = "version: 1\nrobots:\n  left: {}\n  right: {}\nsteps:\n  - play: 1\n"


@pytest.mark.parametrize("body,ports", [(SHOW, ["--port", "{missing}"]),
                                        (TWO, ["--port", "left=sim://", "--port", "right={missing}"])],
                         ids=["one robot", "two robots"])
def test_the_open_error_is_logged_on_the_run_clock(tmp_path, body, ports):
    log = tmp_path / "run.mcap"
    missing = str(tmp_path / "no-such-adapter")
    argv = ["run", str(write_show(tmp_path, body)), *[a.format(missing=missing) for a in ports],
            "--log", str(log), "-q"]
    assert vmain(argv) == 3
    (error,) = [m for m in read_log(log).logs if m["level"] == 4]
    assert "no-such-adapter" in error["message"]
    start_ns = int(read_log(log).metadata["choreo"]["start_ns"])
    stamp = error["timestamp"]
    assert abs(stamp["sec"] * 1_000_000_000 + stamp["nsec"] - start_ns) < 1_000_000_000  # was ~1000 s off
    (line,) = summarize(log).log_lines
    assert -1.0 < line.show_s < 1.0
