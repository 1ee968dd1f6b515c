"""The README and docs/live.md say what each limit on OSC is (connections, timeouts, sizes, the
commands' and the log's rates), and the numbers they say are the code's (issue 21, item 3's
"Done when"): each phrase is built from `choreo.live.limits.LIMITS` and
`choreo.live.osclimits.LIMITS`, so a limit changed in the code and not in the docs fails here."""

from __future__ import annotations

import re

import pytest

from choreo.live.limits import LIMITS, Rate
from choreo.live.osclimits import LIMITS as NET
from runlog import REPO


def rate(r: Rate) -> str:
    return f"{r.burst}, then {r.per_s:g} a second"


def _flat(path: str) -> str:
    """A document's text with its line breaks as spaces (a phrase may wrap)."""
    return re.sub(r"\s+", " ", (REPO / path).read_text(encoding="utf-8"))


README = [
    f"{NET.max_connections} TCP connections at once, {NET.max_per_sender} from one address",
    f"command or question within {NET.message_timeout_s:g} s of connecting",
    f"after {NET.idle_timeout_s:g} s without a message",
    f"one packet at most {NET.max_datagram // 1024} KB",
    f"commands carried out: {rate(LIMITS.commands_per_sender)} from one sender, {rate(LIMITS.commands_total)} from all "
    "over UDP and as many over TCP",
    f"replies: {rate(LIMITS.replies_per_sender)} to one sender",
    f"printed one by one: {rate(LIMITS.reported)}, the rest counted and summed up every {LIMITS.summary_every_s:g} s",
    f"Link session changes logged one by one: {rate(LIMITS.link_events)}",
]

LIVE_MD = [
    f"| TCP connections | {NET.max_connections} open at once, {NET.max_per_sender} from one address",
    f"| TCP: the first message | a command or question within {NET.message_timeout_s:g} s of connecting",
    f"every message begun whole within {NET.message_timeout_s:g} s of its first byte",
    f"is closed after {NET.idle_timeout_s:g} s without a message (",
    f"| TCP: replies not read | {NET.max_unsent // 1024} KB queued",
    f"| one OSC packet (a datagram, a TCP message) | {NET.max_message:,} bytes",
    f"| one UDP datagram | any, up to {NET.max_datagram // 1024} KB",
    f"nested {NET.max_bundle_depth} deep at most, and {NET.max_bundle_elements} elements",
    f"and {NET.max_arguments} arguments",
    f"| commands carried out, one sender | {rate(LIMITS.commands_per_sender)};",
    f"| commands carried out, all senders together | {rate(LIMITS.commands_total)} over UDP, and as many "
    "over TCP apart",
    f"| replies to one sender | {rate(LIMITS.replies_per_sender)} (",
    f"| replies to senders not allowed, all together | {rate(LIMITS.refusals)} |",
    f"logged (and printed, and notified) one by one | {rate(LIMITS.reported)};",
    f"per {'second' if LIMITS.summary_every_s == 1 else f'{LIMITS.summary_every_s:g} s'} at most",
    "| packets read, one allowed sender (",
    f"| {rate(LIMITS.packets_per_sender)} (a desk's fader moves fit)",
    f"| senders with budgets of their own | {LIMITS.senders_tracked} (",
    f"one sender | {rate(LIMITS.queries_per_sender)}, apart from",
    f"all senders together | {rate(LIMITS.queries_total)} (",
    f"| a `/choreo/status` reply over UDP | {LIMITS.status_datagram:,} bytes",
    f"| `--osc-notify` targets | {LIMITS.notify_targets} |",
    f"a `link:` line | {rate(LIMITS.link_events)};",
    f"| {LIMITS.update_subscribers} at once;",
    f"| {LIMITS.update_bytes.burst // 1024} KB, then {LIMITS.update_bytes.per_s / 1024:g} KB a second;",
    f"| ends after {LIMITS.update_expire_s:g} s",
    f"| {LIMITS.address_shown} characters, then cut",
    f"one more per {NET.packet_bytes_per_token // 1024} KB past its first",
]


@pytest.mark.parametrize("phrase", README)
def test_the_readme_says_each_limit_as_the_code_sets_it(phrase):
    assert phrase in _flat("README.md")


@pytest.mark.parametrize("phrase", LIVE_MD)
def test_docs_live_limits_table_says_each_limit_as_the_code_sets_it(phrase):
    assert phrase in _flat("docs/live.md")
