"""Both board layouts (issue 10): the frames byte for byte, the simulator in each layout, runs in
each, a mismatched layout seen as stray calls, the config word's baud bits, and lost start replies
that never start a motion twice."""

from __future__ import annotations

from pathlib import Path

import pytest

from choreo.wire import protocol as p
from choreo.cli import main
from choreo.wire.layouts import HTH4_22, SEED, layout_named
from choreo.board.probe import probe
from choreo.run.settings import RunRequest
from choreo.sim.board import SimBoard
from choreo.sim.faults import FaultPlan
from runlog import prepare, read_log, write_show

SPEC_ROWS = "tests/data/spec_play_frames.txt"


def hexs(frames) -> list[str]:
    return [f.hex for f in frames]


# -- frames ------------------------------------------------------------------------------------

def test_hth4_frames_are_kondos_example_byte_for_byte():
    assert hexs(HTH4_22.play_sequence(0, 0x821B)) == [
        "09 00 02 00 00 00 10 82 9d",
        "11 00 02 02 00 00 4b 04 00 00 00 00 00 00 00 00 64",
        "07 0c 80 0b 00 00 9e",
        "09 00 02 00 00 00 1b 82 a8",
    ]
    assert [f.kind.value for f in HTH4_22.play_sequence(0, 0x821B)] == ["stop", "counter", "play", "restore"]
    assert HTH4_22.status.hex == "0a 00 20 00 00 00 02 00 0a 36"


@pytest.mark.parametrize("config", [0x821B, 0x0002, 0x0000, 0xFFFF, 0x87A3])
def test_hth4_frames_for_every_slot_and_config_word(config):
    suspend = config & ~0x000F
    resume = (config | 0x000B) & ~0x0004
    for motion in range(120):
        frames = [f.data for f in HTH4_22.play_sequence(motion, config)]
        assert frames[0] == p.mov_write(0x0000, suspend.to_bytes(2, "little"))
        assert frames[1] == p.mov_write(0x0002, bytes.fromhex("4b0400") + bytes(7))
        address = 0x0B80 + motion * 0x800
        assert frames[2][:6] == bytes([7, 0x0C, address & 0xFF, address >> 8 & 0xFF, address >> 16, 0])
        assert frames[3] == p.mov_write(0x0000, resume.to_bytes(2, "little"))
        assert all(f[-1] == p.checksum(f[:-1]) for f in frames)


def test_seed_frames_stay_the_documents_at_115200():
    rows = {}
    for line in Path(SPEC_ROWS).read_text().splitlines():
        if line.strip() and not line.startswith("#"):
            number, hex_text = line.split(None, 1)
            rows[int(number)] = hex_text.strip()
    for motion, expected in rows.items():
        stop, play, restore = SEED.play_sequence(motion)
        assert play.hex == expected
        assert stop.hex == "13 00 02 00 00 00 21 87 fd 03 00 00 00 00 00 00 00 00 bd"
        assert restore.hex == "09 00 02 00 00 00 23 87 b5"


@pytest.mark.parametrize("baud,stop_word,restore_word", [
    (115200, "21 87", "23 87"), (625000, "61 87", "63 87"), (1250000, "a1 87", "a3 87")])
def test_seed_stop_and_restore_carry_the_runs_baud(baud, stop_word, restore_word):
    stop, play, restore = SEED.play_sequence(5, baud=baud)
    assert stop.hex[18:23] == stop_word and restore.hex[18:23] == restore_word
    assert stop.data[-1] == p.checksum(stop.data[:-1]) and restore.data[-1] == p.checksum(restore.data[:-1])
    assert play.hex == SEED.play_sequence(5)[1].hex  # the CALL does not depend on the baud


def test_layout_names_and_an_unknown_one():
    assert layout_named("hth4-2.2") is HTH4_22 and layout_named("seed") is SEED
    with pytest.raises(ValueError, match="choose seed or hth4-2.2"):
        layout_named("hth4-2.1")


@pytest.mark.parametrize("argv,out", [
    (["play", "0", "--layout", "hth4-2.2"], "07 0c 80 0b 00 00 9e"),
    (["stop", "--layout", "hth4-2.2", "--config", "0x821b"], "09 00 02 00 00 00 10 82 9d"),
    (["counter", "--layout", "hth4-2.2"], "11 00 02 02 00 00 4b 04 00 00 00 00 00 00 00 00 64"),
    (["restore", "--layout", "hth4-2.2"], "09 00 02 00 00 00 1b 82 a8"),
    (["status", "--layout", "hth4-2.2"], "0a 00 20 00 00 00 02 00 0a 36"),
    (["stop", "--baud", "625000"], "13 00 02 00 00 00 61 87 fd 03 00 00 00 00 00 00 00 00 fd"),
    (["restore", "--baud", "1250000"], "09 00 02 00 00 00 a3 87 35"),
])
def test_frames_command_in_each_layout_and_baud(argv, out, capsys):
    assert main(["frames", *argv]) == 0
    assert capsys.readouterr().out == out + "\n"


@pytest.mark.parametrize("argv", [["counter"], ["stop", "--config", "0x821b"], ["stop", "--baud", "9600"],
                                  ["stop", "--layout", "hth4-2.2", "--config", "0x10000"]])
def test_frames_command_refuses_what_a_layout_does_not_have(argv, capsys):
    assert main(["frames", *argv]) == 2
    assert len(capsys.readouterr().err.strip().splitlines()) == 1


# -- the simulator in each layout ---------------------------------------------------------------

def ideal(**kwargs) -> SimBoard:
    return SimBoard(wire=False, reply_delay_s=0.0, refresh_s=0.0, **kwargs)


def send(board: SimBoard, frames, now: float) -> list[bytes | None]:
    out = []
    for frame in frames:
        sent = board.receive(frame.data, now)
        out.append(None if sent is None else sent.data)
    return out


def running(board: SimBoard, layout, now: float) -> bool:
    data = board.receive(layout.status.data, now).data
    return bool(p.parse_reply(layout.status, data).executing)


def test_an_hth4_board_runs_kondos_sequence_and_reports_by_program_counter():
    board = ideal(layout=HTH4_22, power_on_config=0x821B, motion_s=1.0)
    assert not running(board, HTH4_22, 0.0)
    assert send(board, HTH4_22.play_sequence(3, 0x821B), 0.0) == [p.ack(0)] * 2 + [p.ack(0x0C), p.ack(0)]
    assert board.running(0.5) == 3 and running(board, HTH4_22, 0.5)
    counter = board.receive(HTH4_22.status.data, 0.5).data
    assert int.from_bytes(counter[2:5], "little") == 0x0B80 + 3 * 0x800  # in the slot
    assert counter[5:8] == bytes.fromhex("4b0400")  # the return address: the main loop
    assert not running(board, HTH4_22, 1.5)  # back in the main loop, nothing pushed
    assert board.stray_calls == 0 and board.stack_faults == 0


@pytest.mark.parametrize("board_layout,client_layout", [(SEED, HTH4_22), (HTH4_22, SEED)])
def test_a_call_with_the_other_layout_is_a_stray_call_that_plays_nothing(board_layout, client_layout):
    board = ideal(layout=board_layout, power_on_config=0x821B)
    send(board, client_layout.play_sequence(4, 0x821B), 0.0)
    assert board.running(0.1) is None and board.stray_calls == 1
    stray = [e for e in board.journal if e.kind == "stray"]
    assert len(stray) == 1 and "not the first byte of a" in stray[0].note


def test_baud_switch_a_config_write_with_other_baud_bits_switches_the_board():
    board = ideal(baud=625000, baud_switch=True)
    documents = [p.stop_frame(), p.play_frame(1), p.restore_frame()]  # baud bits 00: 115200
    replies = send(board, documents[:1], 0.0)
    assert replies == [None] and board.baud == 115200  # its ACK went out at the new baud
    assert "switched from 625000 baud" in board.journal[-1].note


def test_baud_switch_keeps_the_baud_the_frames_carry():
    board = ideal(baud=625000, baud_switch=True)
    assert None not in send(board, SEED.play_sequence(1, baud=625000), 0.0)
    assert board.baud == 625000 and board.running(0.1) == 1


def test_lose_start_loses_only_the_reply_to_a_start():
    board = ideal(faults=FaultPlan.parse({"lose_start": "1"}))
    replies = send(board, SEED.play_sequence(2), 0.0)
    assert replies[:2] == [p.ack(0), p.ack(0x0C)] and replies[2] is None
    assert board.running(0.1) == 2 and board.starts == 1


# -- runs ----------------------------------------------------------------------------------------

SHOW = """
    version: 1
    name: layouts
    motions:
      home: {number: 0, duration: 0.2}
      wave: {number: 3, duration: 0.2}
    on_abort: home
    steps:
      - play: wave
      - wait: done
      - repeat: 2
        steps:
          - play: 7
          - wait: done
"""


def run_show(tmp_path, port: str | None = None, **request):
    show = write_show(tmp_path, SHOW)
    session = prepare(RunRequest(str(show), port=port, log_path=str(tmp_path / "run.mcap"),
                                         **request))
    with session:
        result = session.run()
        board = session.stage.links["robot"].port.board
    return session, result, board, read_log(tmp_path / "run.mcap")


def calls(board: SimBoard) -> list[int]:
    return [p.parse_command(e.data).address for e in board.journal
            if e.kind == "frame" and e.data[1:2] == b"\x0c"]


def test_a_run_in_the_hth4_layout_drives_an_hth4_board(tmp_path):
    session, result, board, log = run_show(tmp_path, layout="hth4-2.2")
    assert result.outcome == "done"
    assert board.layout is HTH4_22  # the built-in simulator gets the run's layout
    assert calls(board) == [0x0B80 + 3 * 0x800, 0x0B80 + 7 * 0x800, 0x0B80 + 7 * 0x800]
    assert board.stray_calls == 0 and board.stack_faults == 0
    kinds = [m["kind"] for m in log.tx]
    assert kinds[:2] == ["sync", "read"]  # the config word, read once when the port opened
    assert kinds[2:6] == ["stop", "counter", "play", "restore"]
    assert log.metadata["choreo"]["layout"] == "hth4-2.2"
    statuses = [m for m in log.tx if m["kind"] == "status"]
    assert statuses and all(m["hex"] == HTH4_22.status.hex for m in statuses)


def test_a_run_in_the_seed_layout_names_it_in_the_log(tmp_path):
    session, result, board, log = run_show(tmp_path)
    assert result.outcome == "done" and board.stray_calls == 0
    assert calls(board) == [0x0BB8 + 3 * 0x800, 0x0BB8 + 7 * 0x800, 0x0BB8 + 7 * 0x800]
    assert log.metadata["choreo"]["layout"] == "seed"
    assert log.tx[0]["kind"] == "stop"  # nothing is read first: the document's bytes only


@pytest.mark.parametrize("board_layout,run_layout", [("seed", "hth4-2.2"), ("hth4-2.2", "seed")])
def test_a_run_with_a_mismatched_layout_shows_as_stray_calls(tmp_path, board_layout, run_layout):
    session, result, board, log = run_show(tmp_path, port=f"sim://?layout={board_layout}&config=0x821b",
                                           layout=run_layout)
    assert board.stray_calls == 3 and board.running(0) is None
    assert all(e.kind != "motion" for e in board.journal)  # no motion ever ran


def test_the_show_names_the_layout(tmp_path):
    show = write_show(tmp_path, SHOW.replace("name: layouts", "name: layouts\n    robot: {layout: hth4-2.2}"))
    session = prepare(RunRequest(str(show), no_log=True))
    assert session.settings.links["robot"].layout is HTH4_22 and session.settings.links["robot"].layout_source == "show"
    assert "layout=hth4-2.2" in session.settings.links["robot"].port
    assert not session.settings.links["robot"].assumes_layout  # a simulator, and the show said it anyway


def test_a_real_port_without_a_layout_says_which_it_assumes(tmp_path, capsys):
    show = write_show(tmp_path, SHOW)
    assert main(["run", str(show), "--port", "/dev/nonexistent-choreo", "--no-log"]) == 3
    err = capsys.readouterr().err
    assert "layout: seed (motion 0 at 0x0bb8), assumed: the show names no robot.layout" in err
    assert "--layout hth4-2.2" in err


def test_a_run_at_625000_with_a_baud_switching_board_keeps_talking(tmp_path):
    # The board switches to whatever the config word's baud bits say. choreo writes the run's
    # baud there, so the board stays at 625000; the document's bytes (bits 00) would have
    # switched it to 115200 mid-show (see test_baud_switch_... above).
    session, result, board, log = run_show(tmp_path, port="sim://?baud_switch=1", baud=625000)
    assert result.outcome == "done" and board.baud == 625000


@pytest.mark.parametrize("layout", ["seed", "hth4-2.2"])
@pytest.mark.parametrize("every", [1, 2])
def test_a_lost_start_reply_never_starts_a_motion_twice(tmp_path, layout, every):
    session, result, board, log = run_show(tmp_path, port=f"sim://?lose_start={every}", layout=layout)
    assert result.outcome == "done"
    assert board.starts == 3  # three plays, three motion starts: none twice
    assert len(calls(board)) == 3
    recovered = [m for m in log.logs if "was not sent again" in m["message"]]
    assert len(recovered) == (3 if every == 1 else 1)


def test_a_start_frame_the_board_never_got_is_played_again(tmp_path):
    # hth4-2.2: frames 1-2 read the config at open, 3-6 are the first play; frame 6, the resume,
    # is dropped on the way and never reaches the board (seed 96 drops the first resume only). Two
    # status reads show the motion did not start, so the sequence goes again from its first frame.
    session, result, board, log = run_show(tmp_path, port="sim://?drop=0.5&faults_on=restore&seed=96",
                                           layout="hth4-2.2")
    assert result.outcome == "done"
    assert board.starts == 3  # every play started its motion once
    assert calls(board)[:2] == [0x0B80 + 3 * 0x800] * 2  # motion 3 was called again: it never started
    assert [m["kind"] for m in log.tx[5:12]] == ["restore", "read", "read", "stop", "counter", "play", "restore"]


# -- probe in both layouts ---------------------------------------------------------------------

@pytest.mark.parametrize("layout,pc,hint", [("seed", 0x0003FD, "HTH4 1.x"), ("hth4-2.2", 0x00044B, "hth4-2.2")])
def test_probe_reads_each_layouts_board(layout, pc, hint):
    info = probe(f"sim://?layout={layout}&config=0x821b", timeout=0.05)
    assert info.config is not None and info.config.word == 0x821B
    assert info.counter is not None and info.counter.program_counter == pc
    assert any(hint in line for line in info.hints())
