"""The OSC decoder fuzzed with hypothesis, as issue 21's "Done when" asks: random bytes, random
bundles (element sizes anything an int32 holds, bodies valid or not, nested), and every
truncation of them, well over 10,000 packets in all. Each is decoded or refused with a reason,
never an exception, and within the example's deadline (python-osc's parser looped for ever on
a bundle element of size 0 or less; a hang here fails the deadline).

test_osc_wire.py holds the decoder's own tests and smaller fuzzers; this file only counts."""

from __future__ import annotations

import random
import struct

from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from choreo.live.oscwire import BUNDLE, FrameReader, decode_packet, encode_message
from runlog import HANG_S
from test_osc_wire import PACKET, check

EXAMPLES = 101
PACKETS_EACH = 100  # decoded per example: 10,100 in all
SIZE = st.one_of(st.sampled_from([0, -1, -4, -8, 1, 3, 4, 8, 16, 2**31 - 1, -2**31]), st.integers(-2**31, 2**31 - 1))


@st.composite
def raw_bundle(draw, depth: int = 0) -> bytes:  # type: ignore[no-untyped-def]
    """A bundle as a hostile sender writes one: each element's size field says anything (its
    true size, or not), its body a valid packet, random bytes or another such bundle."""
    elements = []
    for _ in range(draw(st.integers(0, 5))):
        body = draw(st.one_of(PACKET, st.binary(max_size=40),
                              raw_bundle(depth + 1) if depth < 3 else st.binary(max_size=8)))
        size = len(body) if draw(st.booleans()) else draw(SIZE)
        elements.append(struct.pack(">i", size) + body)
    time_tag = draw(st.sampled_from([struct.pack(">Q", 1), b"", b"\x00" * 4, draw(st.binary(min_size=8, max_size=8))]))
    return BUNDLE + time_tag + b"".join(elements)


def _variants(packet: bytes, rnd: random.Random) -> list[bytes]:
    """PACKETS_EACH packets from one: its truncation at each 4-byte boundary and at random
    points, then bytes flipped and size fields overwritten in it (hypothesis draws `rnd`, so a
    failure shrinks and replays)."""
    out = [packet[:at] for at in range(0, len(packet), 4)][:PACKETS_EACH // 2]
    out += [packet[:rnd.randrange(len(packet) + 1)] for _ in range(10)]
    while len(out) < PACKETS_EACH:
        mutant = bytearray(packet)
        at = rnd.randrange(len(mutant)) if mutant else 0
        if rnd.random() < 0.5:
            mutant[at:at + 4] = struct.pack(">i", rnd.choice([0, -4, 4, 2**31 - 1, rnd.randint(-2**31, 2**31 - 1)]))
        elif mutant:
            mutant[at] ^= rnd.randrange(1, 256)
        out.append(bytes(mutant))
    return out


FUZZ = settings(max_examples=EXAMPLES, deadline=HANG_S * 1000, suppress_health_check=[HealthCheck.too_slow,
                                                                             HealthCheck.data_too_large])


@FUZZ
@given(packet=st.one_of(raw_bundle(), st.binary(max_size=512), PACKET), rnd=st.randoms(use_true_random=False))
def test_random_bytes_random_and_truncated_bundles_never_raise_nor_hang(packet, rnd):
    packets = _variants(packet, rnd)
    assert len(packets) == PACKETS_EACH
    for each in packets:
        check(each)


@settings(FUZZ, max_examples=50)
@given(packet=st.one_of(raw_bundle(), PACKET), chunks=st.lists(st.integers(1, 64), min_size=1, max_size=8))
def test_random_bundles_through_both_tcp_framings_never_raise(packet, chunks):
    """The same packets length-prefixed (liblo) and in SLIP (QLab), fed in random pieces, then
    decoded: every frame comes out whole or the stream is refused, and nothing raises."""
    for framed in (struct.pack(">I", len(packet)) + packet, FrameReader().frame(packet)):
        reader = FrameReader()
        got, at = [], 0
        for size in [*chunks, len(framed)]:
            fed = reader.feed(framed[at:at + size])
            at += size
            got += fed.packets
            if fed.fatal:
                break
        for each in got:
            decode_packet(each)
        assert got in ([packet], [])  # whole, or refused (a frame past the limit)


def test_a_message_choreo_takes_still_reads_after_the_fuzz():
    assert check(encode_message("/choreo/go")).messages[0].address == "/choreo/go"
