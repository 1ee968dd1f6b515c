"""`choreo doctor SHOW` on the Link clock: the binding, the session joined for a moment (peers,
tempo, transport, the show's proposal), whether multicast leaves the host, which robots this
host drives. Link runs for real inside loopback-only network namespaces (linkns.py: none of it
reaches the machine's network); where no namespace can be made, those tests fail saying so.
What needs no session (the binding missing, a check that hangs, the options) runs in-process."""

from __future__ import annotations

import json
import sys
import threading
from pathlib import Path

import pytest

from choreo.board.doctor import NOTE, OK, PROBLEM
from choreo.clock import VirtualTime
from choreo.cli.doctor import table
from choreo.errors import UsageError
from choreo.run.preflight import LinkSeen, Machine, Multicast, OscAsk, _route_interface, _tempo, preflight
from choreo.run.settings import RunRequest
from choreo.show.model import LinkClock
from choreo.sync.session import INSTALL_HINT, LinkSnapshot
from choreo.sync.timeline import ClockPair, Timeline
from linkns import Job, choreo_argv, output_has, peer_argv, run_in_namespace
from runlog import vmain, write_show

HOSTS_SHOW = """
    version: 1
    name: two stages
    clock: link
    tempo: {bpm: 124, meter: 4}
    robots:
      left: {port: "sim://"}
      right: {port: "sim://"}
    hosts:
      stage-left: [left]
      stage-right: [right]
    motions:
      bow: {number: 1, duration: 1.0}
    steps:
      - play: bow
      - play: bow
        at: {bar: 3}
"""

ONE_HOST_SHOW = """
    version: 1
    name: one stage
    clock: link
    tempo: {bpm: 124, meter: 4}
    robot: {port: "sim://"}
    motions:
      bow: {number: 1, duration: 1.0}
    steps:
      - play: bow
      - play: bow
        at: {bar: 3}
"""

SESSION_AGE_S = 1.5  # the peer's session this much older than doctor's: Link keeps it (ties are within 0.5 s)

# In the namespace, the preflight as `choreo doctor SHOW --json` makes it, with a discovery wait
# long enough for any machine's load (it ends as soon as the peer shows): the CLI's 1.5 s is
# plenty on a LAN, and a test never leans on it.
DRIVER = """
import json, sys
from choreo.run.preflight import Machine, OscAsk, preflight
from choreo.run.settings import RunRequest
report = preflight(RunRequest(sys.argv[1], log_path=sys.argv[2]), OscAsk(), Machine(talk=False, link_wait_s=20.0))
print(json.dumps({"exit": report.exit_code, "findings": [
    {"level": f.level, "check": f.check, "text": f.text, "fix": f.fix} for f in report.findings]}), flush=True)
"""


def rows(text: str) -> dict[str, dict]:
    """doctor's JSON findings by check name (one robot's rows by their check)."""
    record = json.loads(text.strip().splitlines()[-1])
    return {f["check"]: f for f in record["findings"]} | {"exit": record["exit"]}


def test_alone_in_the_session_is_a_note_and_the_host_drives_its_robots(tmp_path: Path) -> None:
    show = write_show(tmp_path, HOSTS_SHOW)
    doctor = Job("doctor", choreo_argv("doctor", str(show), "--host", "stage-right", "--no-probe", "--json",
                                       "--log", str(tmp_path / "right.mcap")))
    ended = run_in_namespace(tmp_path, [doctor])["doctor"]
    found = rows(ended.stdout)
    assert ended.returncode == 0, ended.stderr
    assert found["exit"] == 0
    assert found["host"]["level"] == OK
    assert "host stage-right: it drives right" in found["host"]["text"]
    assert "stage-left: left" in found["host"]["text"]
    assert found["link"]["level"] == OK and "aalink" in found["link"]["text"]
    session = found["link session"]
    assert session["level"] == NOTE
    assert "no peer" in session["text"] and "stage-left" in session["text"] and "wait" in session["text"]
    assert "multicast" in session["fix"] and "20808" in session["fix"]
    assert found["link tempo"]["level"] == OK and "124.00 bpm" in found["link tempo"]["text"]
    assert found["multicast"]["level"] == NOTE  # the namespace's multicast goes out on its loopback only
    assert "loopback" in found["multicast"]["text"] and "224.76.78.75:20808" in found["multicast"]["text"]


def test_a_peer_at_another_tempo_is_seen_and_the_shows_proposal_noted(tmp_path: Path) -> None:
    show = write_show(tmp_path, ONE_HOST_SHOW)
    peer = Job("peer", peer_argv("--tempo", "97", "--timeout", "25"),
               signals=(("TERM", output_has(tmp_path, "doctor", '"findings"')),))
    # Link keeps the older of two sessions that meet, but two started within half a second of each
    # other are tied (and drawn by id): the peer's session is made older than that, as Live's is
    driver = Job("doctor", [sys.executable, "-c", DRIVER, str(show), str(tmp_path / "show.mcap")],
                 after=output_has(tmp_path, "peer", '"joined"') + f" && sleep {SESSION_AGE_S}")
    ended = run_in_namespace(tmp_path, [peer, driver])["doctor"]
    assert ended.returncode == 0, ended.stderr
    found = rows(ended.stdout)
    assert found["exit"] == 0
    assert found["link session"]["level"] == OK and ": 1 peer," in found["link session"]["text"]
    tempo = found["link tempo"]
    assert tempo["level"] == NOTE
    assert "97.00 bpm" in tempo["text"] and "transport is stopped" in tempo["text"]
    assert "proposes 124 bpm" in tempo["text"] and "moves every peer to 124 bpm" in tempo["text"]
    assert found["multicast"]["level"] == OK and "reaches 1 peer" in found["multicast"]["text"]
    assert "host" not in found  # a show for one host


def test_no_route_for_multicast_is_said_in_the_multicast_row(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    import linkns

    monkeypatch.setattr(linkns, "SETUP", "ip link set lo up")  # loopback up, no route for 224.0.0.0/4
    show = write_show(tmp_path, ONE_HOST_SHOW)
    doctor = Job("doctor", choreo_argv("doctor", str(show), "--no-probe", "--json", "--log", str(tmp_path / "x.mcap")))
    ended = run_in_namespace(tmp_path, [doctor])["doctor"]
    found = rows(ended.stdout)
    assert ended.returncode == 0, ended.stderr
    multicast = found["multicast"]
    assert multicast["level"] == NOTE
    assert "no route for Link's discovery" in multicast["text"] and "unreachable" in multicast["text"]
    assert "ip route add 224.0.0.0/4" in multicast["fix"]
    assert found["link session"]["level"] == NOTE and "alone" in found["link session"]["text"]


def in_process(tmp_path: Path, body: str = ONE_HOST_SHOW, **given: object) -> dict:
    """The preflight's findings by name, in-process (nothing here reaches a Link session)."""
    request = RunRequest(str(write_show(tmp_path, body)), log_path=str(tmp_path / "show.mcap"), **given)
    report = preflight(request, OscAsk(), Machine(time_source=VirtualTime(), talk=False, **_no_network()))
    return {f.name: f for f in report.findings} | {"exit": report.exit_code, "table": table(report.findings)}


def _no_network() -> dict:
    def multicast() -> Multicast:
        raise AssertionError("the multicast path was checked: a test reached the machine's network")
    return {"multicast": multicast}


def test_without_the_binding_the_link_row_is_a_problem_with_the_install_command(
        tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setitem(sys.modules, "aalink", None)  # `import aalink` raises ImportError
    found = in_process(tmp_path)
    assert found["exit"] == 1
    assert found["link"].level == PROBLEM and "aalink" in found["link"].text
    assert found["link"].fix == INSTALL_HINT == "pip install 'choreo[link]'"
    assert "link session" not in found and "multicast" not in found
    assert any(line.startswith("link ") and "PROBLEM" in line and INSTALL_HINT in line for line in found["table"])


def test_a_link_check_that_hangs_is_a_problem_at_its_deadline(tmp_path: Path) -> None:
    release = threading.Event()

    def binding() -> str:
        release.wait(30)
        raise ImportError("released")

    request = RunRequest(str(write_show(tmp_path, ONE_HOST_SHOW)), log_path=str(tmp_path / "show.mcap"))
    try:
        report = preflight(request, OscAsk(), Machine(time_source=VirtualTime(), talk=False, link_binding=binding,
                                                      link_deadline_s=0.2, **_no_network()))
    finally:
        release.set()
    found = {f.name: f for f in report.findings}
    assert found["link session"].level == PROBLEM and "no answer from the Link session within 0.2 s" in \
        found["link session"].text
    assert report.exit_code == 1


def test_on_the_machines_clock_there_is_no_link_check(tmp_path: Path) -> None:
    found = in_process(tmp_path, clock="machine")
    assert found["exit"] == 0
    assert not {"link", "link session", "link tempo", "multicast"} & set(found)


def test_clock_link_on_a_show_with_music_is_refused_as_the_run_refuses_it(tmp_path: Path) -> None:
    body = ONE_HOST_SHOW.replace("    clock: link\n    tempo: {bpm: 124, meter: 4}\n", "    music: {file: x.wav}\n")
    body = body.replace("at: {bar: 3}", "at: 2")
    (tmp_path / "x.wav").write_bytes(b"")
    found = in_process(tmp_path, body, clock="link")
    assert found["exit"] == 1
    assert found["show"].level == PROBLEM and "--no-music" in found["show"].text


def test_a_show_for_several_hosts_needs_host_in_doctor_too(tmp_path: Path) -> None:
    found = in_process(tmp_path, HOSTS_SHOW)
    assert found["show"].level == PROBLEM and "--host NAME" in found["show"].text
    found = in_process(tmp_path, HOSTS_SHOW, host="stage-centre")
    assert "stage-left" in found["show"].text


def test_host_and_clock_need_the_show(capsys: pytest.CaptureFixture[str]) -> None:
    for option in (["--host", "left"], ["--clock", "link"]):
        assert vmain(["doctor", *option]) == UsageError.exit_code
        assert f"{option[0]}: it says what a show needs" in capsys.readouterr().err


def test_the_multicast_route_is_read_as_the_kernel_picks_it(tmp_path: Path) -> None:
    table_text = ("Iface\tDestination\tGateway\tFlags\tRefCnt\tUse\tMetric\tMask\tMTU\tWindow\tIRTT\n"
                  "eth0\t00000000\t0102000A\t0003\t0\t0\t100\t00000000\t0\t0\t0\n"
                  "wlan0\t000000E0\t00000000\t0001\t0\t0\t0\t000000F0\t0\t0\t0\n"
                  "eth1\t000000E0\t00000000\t0001\t0\t0\t5\t000000F0\t0\t0\t0\n"
                  "down0\t4B4E4CE0\t00000000\t0000\t0\t0\t0\tFFFFFFFF\t0\t0\t0\n"
                  "junk\n")
    if sys.byteorder != "little":
        pytest.fail("this table is written as a little-endian kernel writes it")
    routes = tmp_path / "route"
    routes.write_text(table_text)
    assert _route_interface("224.76.78.75", routes) == "wlan0"  # 224/4 beats the default; metric 0 beats 5
    assert _route_interface("10.1.2.3", routes) == "eth0"
    assert _route_interface("224.76.78.75", tmp_path / "none") is None


def test_peers_found_make_the_multicast_row_ok_whatever_the_route() -> None:
    from choreo.run.preflight import _multicast

    lonely = Multicast("lo", "127.0.0.1", None, None)
    assert _multicast(lonely, 2).level == OK and "reaches 2 peers" in _multicast(lonely, 2).text
    assert _multicast(lonely, 0).level == NOTE
    assert _multicast(Multicast("eth0", "192.0.2.2", None, None), 0).level == OK
    deaf = _multicast(Multicast("eth0", "192.0.2.2", None, "nothing came back within 0.3 s"), 0)
    assert deaf.level == NOTE and "does not hear its own multicast" in deaf.text
    assert LinkSeen(None).snapshot is None


def snapshot(tempo: float, peers: int, playing: bool) -> LinkSnapshot:
    return LinkSnapshot(Timeline(1e6, 8.0, tempo), ClockPair(10**9, 1e6, 1000), peers, playing)


def test_the_tempo_row_says_what_the_show_would_do_to_the_session() -> None:
    proposes = LinkClock(124.0, 4)
    playing = _tempo(proposes, snapshot(97.0, 2, True))
    assert playing.level == NOTE and "plays" in playing.text and "keeps its tempo" in playing.text
    assert "97.00 bpm" in playing.text and "124" in playing.fix
    stopped = _tempo(proposes, snapshot(97.0, 1, False))
    assert stopped.level == NOTE and "moves every peer to 124 bpm" in stopped.text
    assert _tempo(proposes, snapshot(124.0, 1, True)).level == OK
    takes = _tempo(LinkClock(None, 4), snapshot(97.0, 1, True))
    assert takes.level == OK and "takes the session's tempo" in takes.text
    alone = _tempo(LinkClock(None, 4), snapshot(120.0, 0, False))
    assert alone.level == OK and "alone" in alone.text and "Link's default" in alone.text


def test_a_link_check_that_fails_unforeseen_is_one_problem_row(tmp_path: Path) -> None:
    def binding() -> str:
        raise ValueError("a wheel for another machine")

    request = RunRequest(str(write_show(tmp_path, ONE_HOST_SHOW)), log_path=str(tmp_path / "show.mcap"))
    report = preflight(request, OscAsk(), Machine(time_source=VirtualTime(), talk=False, link_binding=binding,
                                                  **_no_network()))
    found = {f.name: f for f in report.findings}
    assert found["link session"].level == PROBLEM
    assert "could not join: ValueError: a wheel for another machine" in found["link session"].text
    assert "link" not in found and report.exit_code == 1
