"""The limits on what commands may cost a show (`choreo.live.limits`), and the commands a stopping
show refuses (`choreo.live.controls`): on the virtual clock, no network.

A flood of commands must not fill the log or the terminal (what is refused is logged one by one
only within a budget; the rest is counted and summed up in `unlogged` records whose counts the
review adds up), one sender must not take every command's share, and a GO while the show is
stopping must not be answered "ok".
"""

from __future__ import annotations

import json
import threading
from pathlib import Path

import jsonschema
import pytest

from choreo.clock import VirtualTime
from choreo.live.limits import LIMITS, Budgets, Limits, Rate, ReportGate, SenderLimits
from choreo.log.format import UNLOGGED, CommandRecord
from choreo.live.controls import Live
from choreo.events import PANIC, Command, StopRequest
from choreo.log.recorder import Recorder, RunInfo
from choreo.review.summary import summarize
from choreo.review.summarytext import render
from choreo.show.model import PlannedStep, StepKind

SCHEMA = json.loads((Path(__file__).resolve().parent.parent / "schemas" / "log.command.schema.json").read_text())


class Heard:
    """A command listener keeping every event (what the log and the terminal would get)."""

    def __init__(self) -> None:
        self.events: list = []

    def on_command(self, event) -> None:  # type: ignore[no-untyped-def]
        self.events.append(event)

    def commands(self) -> int:
        """How many commands the events stand for (a summary by its count)."""
        return sum(e.answer.data["count"] if e.command.name == UNLOGGED else 1 for e in self.events)


def live_on(time: VirtualTime, **options) -> tuple[Live, Heard]:  # type: ignore[no-untyped-def]
    live = Live(StopRequest(), now=time.now, **options)
    heard = Heard()
    live.subscribe(heard)
    return live, heard


# -- the token buckets ---------------------------------------------------------------------------


def test_a_sender_gets_its_burst_then_its_rate_and_cannot_take_the_others_share():
    time = VirtualTime()
    limits = SenderLimits(Limits(commands_per_sender=Rate(10, 5.0), commands_total=Rate(20, 10.0)), time.now)
    assert sum(limits.admit("127.0.0.1") for _ in range(408)) == 10  # one bundle of 408 GOs: 10 carried out
    assert sum(limits.admit("127.0.0.2") for _ in range(5)) == 5  # another sender still has its own
    time.advance(1.0)
    assert sum(limits.admit("127.0.0.1") for _ in range(100)) == 5  # then 5 a second
    # many senders at once: the total bounds them together
    assert sum(limits.admit(f"10.0.0.{n}") for n in range(100)) <= 20


def test_replies_to_one_sender_are_bounded_and_refusals_share_one_budget():
    time = VirtualTime()
    limits = SenderLimits(LIMITS, time.now)
    assert sum(limits.may_reply("127.0.0.1") for _ in range(408)) == LIMITS.replies_per_sender.burst
    assert limits.may_reply("127.0.0.9")  # another sender's own budget
    forged = sum(limits.may_answer_refusal() for _ in range(1000))  # forged senders, every address different
    assert forged == LIMITS.refusals.burst


def test_the_table_of_senders_stays_bounded_under_forged_addresses():
    time = VirtualTime()
    budgets = Budgets(Rate(2, 1.0), keys=16, now=time.now)
    assert budgets.take("10.0.0.1") and budgets.take("10.0.0.1") and not budgets.take("10.0.0.1")
    for n in range(10_000):
        budgets.take(f"10.1.{n // 256}.{n % 256}")
    assert len(budgets._budgets) <= 16 + 1  # noqa: SLF001 - the table's size is the point
    assert not budgets.take("10.0.0.1")  # a known sender's spent budget was not reset by the flood


# -- what the listeners hear ---------------------------------------------------------------------


def test_a_flood_of_refused_commands_is_summed_up_not_logged_one_by_one():
    time = VirtualTime()
    live, heard = live_on(time, lockout_s=0.5)
    for n in range(20_000):  # 80,000 GOs in 5 s, a quarter of it: each refused (nothing waits)
        live.command(Command("go", "osc udp 127.0.0.1:9000"))
        if n % 4000 == 3999:
            time.advance(1.0)
            live.flush_reports()
    live.close()
    summaries = [e for e in heard.events if e.command.name == UNLOGGED]
    assert len(heard.events) <= LIMITS.reported.burst + 5 * LIMITS.reported.per_s + 6
    assert 1 <= len(summaries) <= 6
    assert heard.commands() == 20_000  # every one accounted for
    first = summaries[0]
    assert first.answer.status == "error" and first.command.source == "osc udp 127.0.0.1:9000"
    assert first.answer.data["counts"] == {"go": first.answer.data["count"]}
    assert first.answer.message.startswith(f"refused or ignored: {first.answer.data['count']} commands not logged")


def test_commands_taken_are_always_told_and_a_summary_comes_before_the_next_one():
    time = VirtualTime()
    live, heard = live_on(time, wait_start=True, lockout_s=0.0)
    for _ in range(50):
        live.command(Command("go", "key"))  # refused: the show waits for its start
    time.advance(LIMITS.summary_every_s)
    assert live.command(Command("start", "key")).ok
    names = [e.command.name for e in heard.events]
    assert names[-2:] == [UNLOGGED, "start"]  # the held ones summed up first, in order
    assert heard.commands() == 51


def test_the_summary_waits_for_its_interval_unless_forced():
    time = VirtualTime()
    gate = ReportGate(Limits(reported=Rate(1, 1.0), summary_every_s=1.0), time.now)
    assert gate.passes("go", "a", ok=False)
    assert not gate.passes("go", "a", ok=False) and not gate.passes("unknown", "b", ok=False)
    assert gate.due() is None  # not yet a second since the start
    time.advance(1.0)
    held = gate.due()
    assert held is not None and held.counts == {"go": 1, "unknown": 1} and held.source == "2 sources"
    assert gate.due(force=True) is None  # nothing held since
    assert gate.passes("go", "a", ok=True)  # taken commands pass whatever the budget


# -- a stopping show takes no command ------------------------------------------------------------


def waiting_live(time: VirtualTime) -> Live:
    live = Live(StopRequest(), now=time.now, lockout_s=0.0)
    step = PlannedStep(index=1, path="steps[1]", kind=StepKind.PLAY, planned_s=1.0, label="bow", go=True)
    waiter = threading.Thread(target=live.await_go, args=(step, "solo", 1.0, lambda: False), daemon=True)
    waiter.start()
    for _ in range(1000):
        if live.waiting:
            break
        waiter.join(0.005)
    assert live.waiting
    return live


@pytest.mark.parametrize("how", ["stop", "panic", "signal"])
def test_a_go_while_the_show_is_stopping_is_refused(how):
    time = VirtualTime()
    live = waiting_live(time)
    if how == "signal":
        live.stop.request("interrupted (Ctrl-C)")
    else:
        assert live.command(Command(how, "key")).ok
    reason = {"stop": "stopped", "panic": PANIC, "signal": "interrupted (Ctrl-C)"}[how]
    for name, label in (("go", None), ("cue_go", "bow"), ("start", None), ("stop", None), ("panic", None)):
        answer = live.command(Command(name, "osc udp 127.0.0.1:9000", label))
        assert (answer.status, answer.message) == ("error", f"refused: the show is stopping ({reason})"), name
    assert [cue.name for cue in live.waiting] == ["bow"]  # nothing was released
    assert live.stop.reason == reason  # nor the stop under way changed
    live.stop.request(reason)


def test_a_command_after_the_show_is_over_is_refused():
    live, heard = live_on(VirtualTime(), wait_start=True)
    live.close()
    for name in ("go", "start", "stop", "panic"):
        answer = live.command(Command(name, "key"))
        assert (answer.status, answer.message) == ("error", "refused: the show is over"), name
    assert not live.stop()


# -- the log and its review ----------------------------------------------------------------------


def test_the_log_carries_the_counts_and_the_review_adds_them_up(tmp_path):
    """`choreo log summary` once said "38201 commands, 19 refused" where 38,188 were: it counted
    refusals among the 20 commands it lists. The summary records carry their counts."""
    time = VirtualTime()
    path = tmp_path / "flood.mcap"
    recorder = Recorder(path, RunInfo("show.yaml", "flood", b"version: 1\n", "sim://", 115200, time.wall_ns()))
    live = Live(StopRequest(), wait_start=True, now=time.now, lockout_s=0.5)
    live.subscribe(recorder)
    sent = 0
    for _second in range(5):
        for _ in range(2000):
            live.command(Command("go", "osc udp 127.0.0.1:9000"))
            sent += 1
        live.command(Command("unknown", "osc tcp 127.0.0.1:9001", "/choreo/gp"))
        sent += 1
        time.advance(1.0)
        live.flush_reports()
    assert live.command(Command("start", "key")).ok
    sent += 1
    live.close()
    recorder.close()
    assert path.stat().st_size < 64 * 1024  # 10,006 commands; without the limits, about 1.7 MB

    summary = summarize(path)
    assert summary.commands_total == sent
    assert summary.commands_refused == sent - 1  # every one but the start
    assert summary.commands_by["go"] == 10_000 and summary.commands_by["start"] == 1
    text = "\n".join(render(summary))
    assert f"commands  {sent} received ({sent - 1} refused; " in text
    assert "choreo log export" not in text  # it has no commands: the line pointed nowhere

    from mcap.reader import make_reader

    with open(path, "rb") as f:
        records = [json.loads(m.data) for _, channel, m in make_reader(f).iter_messages()
                   if channel.topic == "/choreo/command"]
    for record in records:
        jsonschema.validate(record, SCHEMA)
    unlogged = [r for r in records if r["command"] == UNLOGGED]
    assert unlogged and all(r["count"] == sum(r["counts"].values()) for r in unlogged)
    assert summary.command_records == len(records) < 40
    assert summary.commands_unlogged == sum(r["count"] for r in unlogged) == sent - (len(records) - len(unlogged))


def test_a_summary_record_without_counts_is_counted_by_its_count(tmp_path):
    from choreo.events import Answer, CommandEvent

    time = VirtualTime()
    path = tmp_path / "short.mcap"
    recorder = Recorder(path, RunInfo("show.yaml", "short", b"version: 1\n", "sim://", 115200, time.wall_ns()))
    unlogged = Command(UNLOGGED, "osc")
    recorder.on_command(CommandEvent(unlogged, Answer("error", "x", {"count": 7}), time.wall_ns(), None))
    recorder.close()
    summary = summarize(path)
    assert (summary.commands_total, summary.commands_refused, summary.commands_by) == (7, 7, {UNLOGGED: 7})


@pytest.mark.parametrize("count", ["12", -3, 0, 1.5, True])
def test_a_summary_record_whose_count_is_no_count_is_refused(count):
    with pytest.raises(ValueError):
        _ = CommandRecord(UNLOGGED, "osc", "error", "", count=count, counts={"go": 1}).commands


@pytest.mark.parametrize("data", [{"count": "12", "counts": {"go": 12}}, {"count": 5, "counts": {"go": 4}},
                                  {"count": 3, "counts": ["go"]}, {"count": 2, "counts": {"go": -1, "stop": 3}}])
def test_a_log_whose_summary_record_does_not_add_up_is_refused_in_one_line(tmp_path, data):
    """A log written by another program (or edited) must not make the review count wrong or
    raise a traceback."""
    from choreo.errors import ChoreoError
    from choreo.events import Answer, CommandEvent

    time = VirtualTime()
    path = tmp_path / "forged.mcap"
    recorder = Recorder(path, RunInfo("show.yaml", "forged", b"version: 1\n", "sim://", 115200, time.wall_ns()))
    recorder.on_command(CommandEvent(Command(UNLOGGED, "osc"), Answer("error", "forged", data), time.wall_ns(), None))
    recorder.close()
    with pytest.raises(ChoreoError) as refused:
        summarize(path)
    assert "\n" not in str(refused.value)


def test_a_flood_of_new_senders_on_a_full_table_does_not_sweep_it_for_each_packet():
    """With the table full, each new address made a pass over every bucket to find idle ones:
    a flood of new addresses cost a pass a packet. The table is swept at most once in the time
    a bucket takes to refill."""
    time = VirtualTime()
    reads = [0]

    def now() -> float:
        reads[0] += 1
        return time.now()

    budgets = Budgets(Rate(2, 1.0), keys=256, now=now)
    for n in range(256):
        budgets.take(f"10.0.{n // 256}.{n % 256}")
    reads[0] = 0
    for n in range(1000):
        budgets.take(f"10.1.{n // 256}.{n % 256}")
    assert reads[0] < 1000 * 3  # a take reads the clock once or twice; a sweep 256 times
