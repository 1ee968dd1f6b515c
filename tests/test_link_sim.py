"""The link against the simulator, in-process (`sim://`) and over `choreo sim`'s pseudo-terminal.

For every fault kind, in both spellings (every K-th frame, probability with a seed): either the
right LinkError (naming the frame, what came back and what to check) or a retry that succeeds,
and every frame and every reply reported to a listener, one reply event per frame written.
"""

from __future__ import annotations

import contextlib
import re
import signal
import subprocess
import sys
import threading

import pytest

from choreo.errors import LinkError
from choreo.clock import RunClock, VirtualTime
from choreo.board.link import Link
from choreo.events import RxEvent, TxEvent
from choreo.wire.protocol import FrameKind, ReplyKind
from choreo.sim.faults import FaultPlan
from choreo.sim.board import SimBoard
from choreo.sim.pty import PtyServer
from runlog import REPLY_S

SIM_TIMEOUT = 0.05  # in-process replies take ~2 ms of simulated wire time
PTY_TIMEOUT = 0.15  # a pty puts a scheduler between the link and the board: replies take ~1-5 ms
# The link's timeout over a pty where every reply comes (nak, badsum, junk, lose) is REPLY_S: no
# loaded machine's delay (a reply over 0.15 s in CI) passes for a silent board there, which added
# an ACK check or a retry the counts did not expect.


def pty_timeout(kind: str) -> float:
    """The link's timeout for a fault: the short one where the link waits it out (no reply, a
    late one, a short one)."""
    return PTY_TIMEOUT if kind in ("drop", "late", "short") else REPLY_S


class Recorder:
    """A link listener that keeps every event."""

    def __init__(self) -> None:
        self.tx: list[TxEvent] = []
        self.rx: list[RxEvent] = []

    def on_tx(self, event: TxEvent) -> None:
        self.tx.append(event)

    def on_rx(self, event: RxEvent) -> None:
        self.rx.append(event)

    def check_paired(self) -> None:
        """One reply event for every frame written, in order, for the same frame."""
        assert [e.seq for e in self.tx] == [e.seq for e in self.rx] == list(range(1, len(self.tx) + 1))
        assert all(t.frame == r.frame for t, r in zip(self.tx, self.rx, strict=True))

    def failed(self) -> list[int]:
        return [e.seq for e in self.rx if not e.reply.ok]


def workload(link: Link) -> None:
    """A play and four status polls: frames 1-3 the play sequence, then polls (and retries)."""
    link.play(3)
    for _ in range(4):
        assert link.query_status().kind is ReplyKind.STATUS


# What the link makes of a reply each fault damaged, and what its error must say when the fault
# hits every frame.
REPLY_KIND = {
    "drop": ReplyKind.TIMEOUT,
    "late": ReplyKind.TIMEOUT,
    "nak": ReplyKind.NAK,
    "badsum": ReplyKind.INVALID,
    "short": ReplyKind.INVALID,
    "junk": ReplyKind.INVALID,
}
ERROR_WORDS = {
    # no reply, and no answer to the ACK checks after it either: a dead line, given up at once
    "drop": ["no reply to 'play 3' (stop frame) after 1 try and 3 unanswered ACK checks",
             "check baud (115200), even parity", "adapter"],
    "late": ["no reply to 'play 3' (stop frame) after 1 try and 3 unanswered ACK checks",
             "check baud (115200), even parity"],
    "nak": ["NAK (04 00 15 19) to 'play 3' (stop frame) after 3 tries", "refused", "check baud"],
    "badsum": ["invalid reply (04 00 06 f5", "bad checksum", "to 'play 3' (stop frame)", "check baud"],
    "short": ["invalid reply (04 00", "short reply", "to 'play 3' (stop frame)", "check baud"],
    "junk": ["invalid reply (ff 00 aa 04 00 06 0a", "junk", "to 'play 3' (stop frame)", "check baud"],
}


def late_ms(timeout: float) -> int:
    """Later than the link's timeout, but inside its settle wait before the retry."""
    return int(timeout * 1.5 * 1000)


# -- sim:// ------------------------------------------------------------------------------------


def sim_link(url: str, **kwargs) -> Link:
    """The in-process simulator on virtual time: timeouts and late replies play out exactly,
    at no cost in real time."""
    return Link.open(url, clock=RunClock(VirtualTime()), **kwargs)


def open_sim(query: str, recorder: Recorder) -> Link:
    return sim_link(f"sim://?motion_s=0.1&{query}", timeout=SIM_TIMEOUT, listeners=[recorder])


def retry_after(rec: Recorder, seq: int) -> TxEvent:
    """The next frame after `seq` that is not an ACK check (the link's sync after a timeout)."""
    return next(e for e in rec.tx[seq:] if e.frame.kind is not FrameKind.SYNC)


def hit_frames(link: Link) -> list[int]:
    return hit_seqs(link.port.board)


def hit_seqs(board: SimBoard) -> list[int]:
    """The link's seq numbers of the frames a fault hit: the board numbers only the frames it
    took, so frames it ignored (sent while it was still replying) are counted back in."""
    hits, seq = [], 0
    for entry in board.journal:
        if entry.kind in ("frame", "ignored"):
            seq += 1
            if entry.kind == "frame" and entry.faults:
                hits.append(seq)
    return hits


def test_no_faults_every_frame_acked_and_reported():
    rec = Recorder()
    with open_sim("", rec) as link:
        workload(link)
        assert link.port.board.frames_received == 7
    rec.check_paired()
    assert [e.reply.kind for e in rec.rx] == [ReplyKind.ACK] * 3 + [ReplyKind.STATUS] * 4
    assert all(e.attempt == 1 for e in rec.tx)


@pytest.mark.parametrize("kind", sorted(REPLY_KIND))
def test_sim_fault_on_every_frame_is_the_right_link_error(kind):
    rec = Recorder()
    query = f"{kind}=1" + (f"&late_ms={late_ms(SIM_TIMEOUT) * 4}" if kind == "late" else "")
    with open_sim(query, rec) as link:
        with pytest.raises(LinkError) as caught:
            link.play(3)
        # A late reply outlasts the link's timeout and quiet wait: the board is still replying
        # when the ACK checks come, so it does not answer (or count) them.
        board = link.port.board
        expected = {"late": (1, 3), "drop": (4, 0)}.get(kind, (3, 0))
        assert (board.frames_received, board.ignored) == expected
    message = str(caught.value)
    for words in ERROR_WORDS[kind]:
        assert words in message, message
    assert caught.value.exit_code == 3
    rec.check_paired()
    if kind in ("drop", "late"):  # a timeout: ACK checks, unanswered, so the line is dead
        assert [e.frame.kind.value for e in rec.tx] == ["stop", "sync", "sync", "sync"]
    else:
        assert [e.attempt for e in rec.tx] == [1, 2, 3]
    assert all(e.reply.kind is REPLY_KIND[kind] for e in rec.rx)


@pytest.mark.parametrize("kind", sorted(REPLY_KIND))
def test_sim_fault_every_4th_frame_is_retried_and_succeeds(kind):
    rec = Recorder()
    query = "4" + (f"&late_ms={late_ms(SIM_TIMEOUT)}" if kind == "late" else "")
    with open_sim(f"{kind}={query}", rec) as link:
        workload(link)
        hits = hit_frames(link)
        assert link.port.board.frames_received == len(rec.tx)
    rec.check_paired()
    assert hits == [4, 8] and rec.failed() == hits
    assert all(rec.rx[n - 1].reply.kind is REPLY_KIND[kind] for n in hits)
    assert [retry_after(rec, n).attempt for n in hits] == [2, 2]  # the retry of each


@pytest.mark.parametrize("kind", sorted(REPLY_KIND))
@pytest.mark.parametrize("seed", [1, 2])
def test_sim_fault_at_random_is_retried_or_the_right_error(kind, seed):
    rec = Recorder()
    query = f"{kind}=0.3&seed={seed}" + (f"&late_ms={late_ms(SIM_TIMEOUT)}" if kind == "late" else "")
    with open_sim(query, rec) as link:
        try:
            for _ in range(2):
                workload(link)
        except LinkError as exc:
            assert "after 3 tries" in str(exc)
            assert rec.tx[-1].attempt == 3 and not rec.rx[-1].reply.ok
        hits = hit_frames(link)
        board = link.port.board
        assert board.frames_received + board.ignored == len(rec.tx)
    rec.check_paired()
    assert hits and set(rec.failed()) >= set(hits)
    assert all(rec.rx[n - 1].reply.kind is REPLY_KIND[kind] for n in hits)


@pytest.mark.parametrize("spelled", ["5", "0.1"])
def test_sim_port_lost_is_a_link_error_and_the_last_frame_is_reported(spelled):
    rec = Recorder()
    with open_sim(f"lose={spelled}&seed=3", rec) as link:
        with pytest.raises(LinkError) as caught:
            for _ in range(20):
                workload(link)
        lost_at = link.port.board.lost_at_frame
    message = str(caught.value)
    assert "lost" in message and "check the cable and the adapter" in message
    assert re.search(r"while sending '(stop|play 3|restore|status)'", message)
    rec.check_paired()
    assert len(rec.tx) == lost_at and (spelled != "5" or lost_at == 5)
    assert rec.failed() == [lost_at] and "port lost" in (rec.rx[-1].reply.error or "")


def test_sim_late_reply_within_the_timeout_is_no_fault():
    rec = Recorder()
    with open_sim(f"late=1&late_ms={int(SIM_TIMEOUT * 400)}", rec) as link:
        link.timeout = link.port.timeout = SIM_TIMEOUT * 2
        workload(link)
    rec.check_paired()
    assert rec.failed() == []


# -- choreo sim on a pseudo-terminal -----------------------------------------------------------


@contextlib.contextmanager
def choreo_sim(*args: str):
    """`choreo sim -v ARGS`: yields (process, path); the -v journal is read back at the end."""
    proc = subprocess.Popen(
        [sys.executable, "-m", "choreo", "sim", "-v", "--motion-s", "0.1", *args],
        stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
    )
    try:
        path = proc.stdout.readline().strip()
        assert path.startswith("/"), proc.stderr.read()
        yield proc, path
    finally:
        if proc.poll() is None:
            proc.kill()
        proc.communicate(timeout=10)


def journal_of(proc: subprocess.Popen, stop: bool = True) -> tuple[int, list[int], str]:
    """Stop the server (or let it end by itself); return (frames received, frames hit, stderr)."""
    if stop:
        proc.send_signal(signal.SIGTERM)
    _, err = proc.communicate(timeout=10)
    numbers = [int(n) for n in re.findall(r"^\s*[\d.]+ #(\d+) ", err, re.M)]
    hits = [int(n) for n in re.findall(r"^\s*[\d.]+ #(\d+) .*\[fault: ", err, re.M)]
    return len(numbers), hits, err


def pty_options(kind: str, late: int) -> list[str]:
    """`choreo sim`'s options beside the fault: a late reply `late` ms late; junk and the reply
    after it written at once (no wire time). With wire time the server writes each byte when it
    is due, and a server put off between two (a loaded machine) for longer than the link's
    quiet spell (`QUIET_S`, 10 ms, a UART's line is never so slow) split the junk in two: the
    link took the rest for the next try's reply (the error then quoted another try's bytes)."""
    return ["--late-ms", str(late)] if kind == "late" else ["--no-wire"] if kind == "junk" else []


def hit_seqs_of(journal: str) -> list[int]:
    """`hit_seqs` read from `choreo sim -v`'s journal: frames taken and ignored, in order."""
    hits, seq = [], 0
    for line in journal.splitlines():
        if re.match(r"\s*[\d.]+ (#\d+ |ignored: )", line):
            seq += 1
            if "[fault: " in line:
                hits.append(seq)
    return hits


def open_pty(path: str, recorder: Recorder, timeout: float = PTY_TIMEOUT) -> Link:
    return Link.open(path, timeout=timeout, listeners=[recorder])


@pytest.mark.parametrize("kind", sorted(REPLY_KIND))
def test_pty_fault_on_every_frame_is_the_right_link_error(kind):
    rec = Recorder()
    # late past the link's giving up (0.6 s on an idle machine, later on a loaded one), however
    # late: the reply never has to come (the server is stopped first), so a long wait costs nothing
    with choreo_sim(f"--{kind}", "1", *pty_options(kind, late_ms(PTY_TIMEOUT) * 20)) as (proc, path):
        with open_pty(path, rec, pty_timeout(kind)) as link, pytest.raises(LinkError) as caught:
            link.play(3)
        received, hits, err = journal_of(proc)
    assert proc.returncode == 0
    message = str(caught.value)
    assert message.startswith(f"port {path}:")
    for words in ERROR_WORDS[kind]:
        assert words in message, message
    rec.check_paired()
    if kind == "late":  # the ACK checks come while the board is still (late) replying: not answered
        assert len(rec.tx) == 4 and received == 1 and hits == [1] and err.count("still replying") == 3
    elif kind == "drop":  # no reply, and the ACK checks after it unanswered too
        assert len(rec.tx) == received == 4 and hits == [1, 2, 3, 4]
    else:
        assert len(rec.tx) == received == 3 and hits == [1, 2, 3]
    assert all(e.reply.kind is REPLY_KIND[kind] for e in rec.rx)


@pytest.mark.parametrize("kind", sorted(REPLY_KIND))
def test_pty_fault_every_4th_frame_is_retried_and_succeeds(kind):
    rec = Recorder()
    with choreo_sim(f"--{kind}", "4", *pty_options(kind, late_ms(PTY_TIMEOUT))) as (proc, path):
        with open_pty(path, rec, pty_timeout(kind)) as link:
            workload(link)
        received, hits, err = journal_of(proc)
    rec.check_paired()
    # a late reply a loaded machine put off past the link's settle wait overlaps the ACK check
    # after it, which the board ignores (not one of its frames): counted back in, as `hit_seqs` does
    assert received + err.count(" ignored: ") == len(rec.tx)
    assert hits == [n for n in range(1, received + 1) if n % 4 == 0]
    seqs = hit_seqs_of(err)
    assert len(seqs) == len(hits) and all(rec.rx[n - 1].reply.kind is REPLY_KIND[kind] for n in seqs)
    assert set(rec.failed()) >= set(seqs)  # a loaded machine may add a timeout, never hide a fault


def test_pty_port_lost_is_a_link_error_and_the_server_exits_3():
    rec = Recorder()
    with choreo_sim("--lose", "5") as (proc, path):
        with open_pty(path, rec, REPLY_S) as link, pytest.raises(LinkError) as caught:
            workload(link)
        received, hits, err = journal_of(proc, stop=False)
    assert proc.returncode == 3 and "fault 'lose' at frame 5" in err
    assert "lost" in str(caught.value) and "check the cable and the adapter" in str(caught.value)
    rec.check_paired()
    assert received == len(rec.tx) == 5 and hits == [5]


@contextlib.contextmanager
def pty_in_process(kind: str, spelled: str, seed: int):
    """The same server as `choreo sim`, in a thread, so its board's journal can be read."""
    late_s = late_ms(PTY_TIMEOUT) / 1000
    board = SimBoard(motion_s=0.1, faults=FaultPlan.parse({kind: spelled}, seed=seed, late_s=late_s))
    server = PtyServer(board)
    path = server.open()
    thread = threading.Thread(target=server.serve, daemon=True)
    thread.start()
    try:
        yield board, path
    finally:
        server.stop()
        thread.join(5)
        server.close()


# Every kind at random runs on sim:// (virtual time) above; over a real pty, the kinds that
# garble or refuse a reply (the silent ones, drop and late, are covered every frame and every 4th).
@pytest.mark.parametrize("kind", ["badsum", "junk", "nak", "short"])
def test_pty_fault_at_random_is_retried_or_the_right_error(kind):
    rec = Recorder()
    with pty_in_process(kind, "0.25", seed=3) as (board, path):
        with open_pty(path, rec, pty_timeout(kind)) as link:
            try:
                workload(link)
                workload(link)
            except LinkError as exc:
                assert "after 3 tries" in str(exc)
                assert rec.tx[-1].attempt == 3 and not rec.rx[-1].reply.ok
        hits = hit_seqs(board)
        assert board.frames_received + board.ignored == len(rec.tx)
    rec.check_paired()
    assert hits and set(rec.failed()) >= set(hits)
    assert all(rec.rx[n - 1].reply.kind is REPLY_KIND[kind] for n in hits)


def test_pty_port_lost_at_random():
    rec = Recorder()
    with (pty_in_process("lose", "0.2", seed=6) as (board, path), open_pty(path, rec, REPLY_S) as link,
          pytest.raises(LinkError, match="lost")):
        for _ in range(10):
            workload(link)
    rec.check_paired()
    assert board.lost and len(rec.tx) == board.lost_at_frame == board.frames_received


# -- the board's return-address stack ----------------------------------------------------------


@pytest.mark.parametrize("kind", sorted(REPLY_KIND) + ["lose"])
@pytest.mark.parametrize("every", [2, 3, 4])
def test_play_retries_never_push_a_second_return_address(kind, every):
    """Whatever fault hits the stop frame, the CALL or the restore, the link retries from the stop
    frame (which resets the board's program): never a CALL re-sent alone."""
    rec = Recorder()
    query = f"{kind}={every}" + (f"&late_ms={late_ms(SIM_TIMEOUT)}" if kind == "late" else "")
    with open_sim(query, rec) as link:
        with contextlib.suppress(LinkError):  # every=3 hits every restore: the play gives up
            for motion in range(4):
                link.play(motion)
        board = link.port.board
        stack = [e for e in board.journal if e.kind == "stack"]
        assert board.stack_faults == 0 and stack == [], [e.line() for e in stack]
        calls = [e for e in board.journal if e.kind == "frame" and e.data[1:2] == b"\x0c"]
    rec.check_paired()
    assert calls and hit_frames(link)
    if kind != "lose":
        assert any(e.attempt > 1 for e in rec.tx)  # the faults made the link retry


def test_a_late_restore_ack_is_never_taken_for_the_answer_to_a_later_frame():
    rec = Recorder()
    timeout = 0.1
    # The second play's restore (frame 6) is answered 250 ms late: the link gives up at 100 ms
    # and waits for the line to go quiet until 200 ms; its first ACK check reaches a board still
    # replying (ignored), the restore's late ACK arrives and is set aside, the next ACK check is
    # answered, and only then does the sequence start again from its stop frame.
    with sim_link(f"sim://?motion_s=0.1&late=6&late_ms={int(timeout * 2500)}", timeout=timeout,
                   listeners=[rec]) as link:
        link.play(2)
        played = link.play(3)
        board = link.port.board
        assert board.ignored == 1
        assert board.stack_faults == 0
    # The restore's reply is missing, so the board is asked whether motion 3 started: that read
    # of its program state reaches a board still replying (ignored) and times out; the ACK check
    # after it reads the late ACK (set aside); the read again finds the 0.1 s motion over (back
    # at the return address): it started, so the play is done and nothing is sent again.
    assert played.tries == 1 and "motion 3 started and already over" in played.recovered
    assert board.starts == 2  # each play's motion once
    kinds = [e.frame.kind.value for e in rec.tx[3:]]
    assert kinds == ["stop", "play", "restore", "read", "sync", "read"]
    assert rec.rx[7].reply.stale == bytes.fromhex("04 00 06 0a")  # the late restore ACK, set aside


def test_a_late_restore_ack_of_a_running_motion_is_a_play_done():
    rec = Recorder()
    timeout = 0.1
    with sim_link(f"sim://?motion_s=2&late=3&late_ms={int(timeout * 2500)}", timeout=timeout,
                   listeners=[rec]) as link:
        played = link.play(3)
        board = link.port.board
        assert board.stack_faults == 0
    assert played.tries == 1 and played.recovered
    calls = [e for e in board.journal if e.kind == "frame" and e.data[1:2] == b"\x0c"]
    assert len(calls) == 1  # motion 3 was called once