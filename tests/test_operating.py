"""A stage manager's evening end to end (issue 24), on the real `choreo run` process: a music
show on the null output, driven over OSC as QLab would, UDP and TCP mixed. `/choreo/pause`
during the first motion stands the music's clock still (status says so twice, apart), a resume
over TCP goes on, a GO cue reached by its label percent-escaped is released, and afterwards the
reviews (summary, export, export --cues) tell the same evening: the pause as a pause, each cue's
release by who gave it. Real time: every wait is for a state, never for a duration."""

from __future__ import annotations

import csv
import io
import json
import subprocess
import sys
import time
from pathlib import Path

from choreo.live.osclimits import LIMITS
from choreo.live.oscwire import END, decode_packet, encode_message, slip_decode
from runlog import REPO, ended_if_left, read_log, start_choreo, wait_for
from test_music import write_song
from test_osc import free_port
from test_osc_limits import Peer

EVENING = """\
version: 1
name: evening
music: {file: song.wav}
motions:
  bow: {number: 1, duration: 0.6}
  wave: {number: 2, duration: 0.4}
  clap: {number: 3, duration: 0.3}
steps:
  - play: bow
    at: 0.2
    label: intro
  - wait: done
  - play: wave
    at: go
    cue: 5
    label: act 2/intro
  - play: clap
    at: 2.0
    label: finale
"""


POLL_S = 0.5  # a status poll's wait for its reply: a poll missed is only asked again
# A command's (and an asserted status's): a poll before choreo listens is refused at once (ICMP),
# so only a loaded machine's slow reply waits this long (with 0.5 s, one was lost).
ANSWER_S = 5.0


def answer(peer: Peer, address: str, *args: object, wait_s: float = ANSWER_S) -> dict | None:
    """The reply to one message (None: none came within `wait_s`, e.g. before choreo listens);
    a reply to another address, which came after its own wait, is passed over."""
    try:
        peer.send(encode_message(address, list(args)))
        deadline = time.monotonic() + wait_s
        while True:
            peer.sock.settimeout(max(deadline - time.monotonic(), 0.001))
            message = decode_packet(_packet(peer), LIMITS).messages[0]
            if message.address == "/reply" + address:
                return json.loads(message.args[0])
    except (ConnectionRefusedError, TimeoutError, OSError):
        return None


def _packet(peer: Peer) -> bytes:
    """The next packet from choreo: a datagram, or one SLIP frame over TCP."""
    if peer.transport == "udp":
        return peer.sock.recv(65536)
    buffer = b""  # SLIP: a frame ends at its END byte
    while END not in buffer.lstrip(END):
        buffer += peer.sock.recv(65536)
    packet = slip_decode(buffer.lstrip(END).split(END)[0])
    assert packet is not None, buffer
    return packet


def status(peer: Peer, wait_s: float = ANSWER_S) -> dict | None:
    reply = answer(peer, "/choreo/status", wait_s=wait_s)
    return reply["data"] if reply is not None else None


def review(*args: str) -> str:
    done = subprocess.run([sys.executable, "-m", "choreo", "log", *args], capture_output=True, text=True,
                          cwd=REPO, timeout=60)
    assert done.returncode == 0, done.stderr
    return done.stdout


def test_an_evening_driven_over_osc_is_paused_released_and_reviewed_as_it_went(tmp_path: Path) -> None:
    write_song(tmp_path / "song.wav", 3.0)
    (tmp_path / "show.yaml").write_text(EVENING)
    log_path = tmp_path / "run.mcap"
    port = free_port()
    process = start_choreo("run", str(tmp_path / "show.yaml"), "--port", "sim://", "--osc", str(port),
                           "--log", str(log_path), "--audio-device", "null")
    with ended_if_left(process):
        # the polls from a peer of their own: a reply that came after its poll's wait is never
        # taken for the answer to a command or to an asserted status
        udp, poller, tcp = Peer("udp", port), Peer("udp", port), None
        try:
            seen: list[dict] = []

            def in_first_motion() -> bool:  # step 0 plays, step 1 waits for its end: the motion runs
                now = status(poller, POLL_S)
                seen.append(now or {})
                return now is not None and now["robots"]["robot"]["step"] in (0, 1)

            assert wait_for(in_first_motion, 30, every=0.01), seen[-1:]
            paused = answer(udp, "/choreo/pause")
            assert paused is not None and paused["status"] == "ok", paused
            first = status(udp)
            time.sleep(0.3)
            second = status(udp)
            assert first is not None and second is not None
            assert first["state"] == second["state"] == "paused" and first["clock"] == "music"
            assert first["show_s"] == second["show_s"] == paused["data"]["show_s"]  # the song's clock stands
            tcp = Peer("tcp", port)
            resumed = answer(tcp, "/choreo/resume")
            assert resumed is not None and resumed["status"] == "ok", resumed
            assert wait_for(lambda: (status(poller, POLL_S) or {}).get("waiting"), 30, every=0.02)
            go = answer(tcp, "/choreo/cue/act%202%2Fintro/go")
            assert go is not None and go["status"] == "ok" and go["message"] == "GO: cue 5 'act 2/intro'", go
            assert go["data"]["cue"] == "5"
        finally:
            udp.close()
            poller.close()
            if tcp is not None:
                tcp.close()
        _, err = process.communicate(timeout=60)
    assert process.returncode == 0, err

    log = read_log(log_path)
    commands = [(m["command"], m["source"].split()[1], m["status"]) for m in log.topic("/choreo/command")]
    assert commands == [("pause", "udp", "ok"), ("resume", "tcp", "ok"), ("cue_go", "tcp", "ok")]
    pause_at, resume_at = (m["_log_time"] for m in log.topic("/choreo/command")[:2])
    starts = [m for m in log.topic("/choreo/step") if m["event"] == "start"]
    assert len(starts) == 4 and not [m for m in starts if pause_at < m["_log_time"] < resume_at]
    assert "paused" in [m.get("state") for m in log.topic("/choreo/clock")]

    summary = json.loads(review("summary", "--json", str(log_path)))
    lengths = summary["lengths"]
    assert lengths["pauses"] == 1 and lengths["paused_s"] >= 0.3 and lengths["held_s"] == 0
    assert abs(lengths["wall_s"] - lengths["show_s"] - lengths["paused_s"]) < 0.002
    cues = list(csv.DictReader(io.StringIO(review("export", "--cues", "--csv", "-", str(log_path)))))
    assert [(c["number"], c["label"], c["released"].split(" ")[:3]) for c in cues] == [
        ("1", "intro", ["time"]), ("5", "act 2/intro", ["go", "osc", "tcp"]), ("6", "finale", ["time"])]
    by_label = {m["label"]: m["actual_s"] for m in starts if m.get("label")}
    for cue in cues:  # the export's times are the log's, to the millisecond
        assert abs(float(cue["actual_s"]) - by_label[cue["label"]]) < 0.001
    timeline = review("timeline", str(log_path))
    assert f"{lengths['show_s']:.3f} s on the show clock" in timeline and "paused" in timeline
