"""A Link session's changes cost the log and the terminal a bounded amount: a peer changing its
tempo every 10 ms (R1's flood) gets 20 lines, then 5 a second, and the rest summed up."""

from __future__ import annotations

from choreo.live.limits import LIMITS
from choreo.run.session import _LinkEventGate
from choreo.sync.session import LinkSnapshot
from choreo.sync.timeline import ClockPair, Timeline


def test_a_flood_of_session_changes_is_logged_within_the_budget_and_summed_up():
    snapshot = LinkSnapshot(Timeline(0.0, 0.0, 231.4), ClockPair(0, 0.0, 0), 2, True)
    gate = _LinkEventGate(LIMITS.link_events, every_s=3600.0)
    passed = sum(gate.passes() for _ in range(1000))  # 1000 changes at once
    assert LIMITS.link_events.burst <= passed <= LIMITS.link_events.burst + 1
    assert gate.due(snapshot) is None  # within the summary's period: nothing yet
    summary = gate.due(snapshot, force=True)  # the pass's end
    assert summary == f"{1000 - passed} more session changes not logged one by one (now 231.40 bpm, 2 peers, playing)"
    assert gate.due(snapshot, force=True) is None  # summed up once
