"""choreo's own OSC decoding and TCP framing (`choreo.live.oscwire`) and the connections' caps and
timeouts as decisions (`choreo.live.oscnet.ConnectionTable`): pure, no sockets. The packets choreo
must read are built with python-osc's builders (another implementation than the one tested);
hostile ones by hand, and by the thousand in the fuzz tests at the end."""

from __future__ import annotations

import random
import struct
import sys

import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st
from pythonosc.osc_bundle_builder import IMMEDIATELY, OscBundleBuilder
from pythonosc.osc_message_builder import OscMessageBuilder, build_msg

from choreo.live.oscnet import ConnectionTable
from choreo.live.osclimits import LIMITS, OscLimits
from choreo.live.oscwire import (BUNDLE, END, Decoded, FrameReader, Message, decode_packet, encode_bundle,
                                 encode_message, slip_decode, slip_encode)
from runlog import HANG_S

GO = build_msg("/choreo/go", []).dgram
TAG = BUNDLE + struct.pack(">Q", 1)


def element(packet: bytes, size: int | None = None) -> bytes:
    """A bundle element: its size (the true one unless told) and the packet."""
    return struct.pack(">i", len(packet) if size is None else size) + packet


def bundle(*parts: bytes) -> bytes:
    return TAG + b"".join(parts)


# -- what choreo reads --------------------------------------------------------------------------


def test_every_argument_type_python_osc_sends_is_read():
    builder = OscMessageBuilder("/choreo/cue/ä/go")
    values = [("i", -5), ("f", 1.5), ("s", "héllo"), ("b", b"abcde"), ("T", True), ("F", False), ("N", None),
              ("h", 2**40), ("d", 2.25), ("m", (1, 2, 3, 4)), ("r", 0x11223344)]
    for tag, value in values:
        builder.add_arg(value, tag)
    decoded = decode_packet(builder.build().dgram)
    assert decoded == Decoded((Message("/choreo/cue/ä/go", (-5, 1.5, "héllo", b"abcde", True, False, None, 2**40,
                                                            2.25, b"\x01\x02\x03\x04", 0x11223344)),))
    char_time_impulse = b"/c\x00\x00,ctI\x00\x00\x00\x00" + b"\x00\x00\x00x" + b"\x00" * 7 + b"\x01"
    assert decode_packet(char_time_impulse).messages == (Message("/c", (ord("x"), 1, None)),)


def test_nested_bundles_give_their_messages_in_order():
    outer, inner = OscBundleBuilder(IMMEDIATELY), OscBundleBuilder(IMMEDIATELY)
    inner.add_content(build_msg("/b", ["x"]))
    outer.add_content(build_msg("/a", [1]))
    outer.add_content(inner.build())
    outer.add_content(build_msg("/c", []))
    assert decode_packet(outer.build().dgram).messages == (Message("/a", (1,)), Message("/b", ("x",)), Message("/c"))
    assert decode_packet(bundle()) == Decoded()  # an empty bundle: nothing to do, nothing wrong


def test_an_old_senders_message_without_type_tags_has_no_arguments():
    assert decode_packet(b"/choreo/go\x00\x00").messages == (Message("/choreo/go"),)


def test_what_choreo_sends_reads_back():
    args = ("a reply", 3, -2**31, 2**40, 0.5, True, False, None, b"\x00\xff")
    assert decode_packet(encode_message("/reply/choreo/go", args)).messages == (Message("/reply/choreo/go", args),)
    nested = encode_bundle([encode_message("/a"), encode_bundle([encode_message("/b", [1])])])
    assert decode_packet(nested).messages == (Message("/a"), Message("/b", (1,)))
    assert decode_packet(encode_message("/a\x00b", ["c\x00"])).messages == (Message("/a\ufffdb", ("c\ufffd",)),)
    with pytest.raises(TypeError):
        encode_message("/a", [object()])  # type: ignore[list-item]


# -- what choreo refuses ------------------------------------------------------------------------


@pytest.mark.parametrize("size", [0, -4, -8, -2**31, 20, 2**31 - 1, 4, 12])
def test_a_bundle_elements_size_out_of_bounds_is_refused(size):
    """Size 0 or negative sent python-osc's parser round for ever; past the end, it read what was
    not there (4 and 12: within the packet, but not the element's true size of 16)."""
    for packet in (bundle(element(GO, size)), bundle(element(GO), element(GO, size))):
        decoded = decode_packet(packet)
        assert decoded.messages == ()
        if size not in (4, 12):
            assert "a bundle element's size" in decoded.error
        else:
            assert decoded.error


@pytest.mark.parametrize("tag", ["x", "Q", "[", "]", "\x01", "é"])
def test_an_unknown_type_tag_refuses_the_message(tag):
    """`/choreo/panic ,Q` was carried out (python-osc skipped the tag it did not know)."""
    tags = (f",{tag}".encode() + b"\x00\x00\x00\x00")[:4 if len(tag.encode()) < 3 else 8]
    packet = b"/choreo/panic\x00\x00\x00" + tags
    decoded = decode_packet(packet)
    assert decoded.messages == () and decoded.address == "/choreo/panic"
    assert "which choreo does not take" in decoded.error
    assert decode_packet(bundle(element(GO), element(packet))).messages == ()  # one bad message refuses its packet


def test_bundles_nest_only_so_deep_and_hold_only_so_many():
    limits = OscLimits(max_bundle_depth=3, max_bundle_elements=10)
    nested = GO
    for _ in range(3):
        nested = bundle(element(nested))
    assert decode_packet(nested, limits).messages == (Message("/choreo/go"),)
    assert "nested more than 3 deep" in decode_packet(bundle(element(nested)), limits).error
    assert len(decode_packet(bundle(*[element(GO)] * 9), limits).messages) == 9  # the bundle itself counts
    assert "more than 10 elements" in decode_packet(bundle(*[element(GO)] * 10), limits).error
    deep = GO
    for _ in range(10_000):  # deeper than Python's recursion: refused at the limit, not by a crash
        deep = bundle(element(deep))
    assert "nested more than" in decode_packet(deep, OscLimits(max_message=10**7)).error


@pytest.mark.parametrize("packet, why", [
    (b"", "an empty packet"),
    (b"/abc", "address without the zero"),
    (b"/choreo/go\x00", "(OSC comes in 4-byte units)"),  # not padded
    (b"choreo/go\x00\x00\x00", "does not start with /"),
    (b"/a\x00\x00i\x00\x00\x00", "do not start with ','"),
    (b"/a\x00\x00,i\x00\x00", "argument 'i' past the end"),
    (b"/a\x00\x00,ii\x00\x00\x00\x00\x01", "argument 'i' past the end"),
    (b"/a\x00\x00,s\x00\x00abcd", "without the zero"),
    (b"/a\x00\x00,b\x00\x00\x00\x00\x00\x08abcd", "a blob past the end"),
    (b"/a\x00\x00,b\x00\x00\xff\xff\xff\xfc", "a blob past the end"),  # negative size
    (b"/a\x00\x00,\x00\x00\x00\x00\x00\x00\x01", "bytes after the arguments"),
    (b"/\xff\x00\x00", "not UTF-8"),
    (b"#bundle\x00\x00\x00", "(OSC comes in 4-byte units)"),
    (b"#bundle\x00\x00\x00\x00\x00", "without its time tag"),
    (TAG + element(b"/a\x00"), "4-byte units"),
])
def test_malformed_packets_are_refused_with_the_reason(packet, why):
    decoded = decode_packet(packet)
    assert decoded.messages == () and why in decoded.error


def test_a_packet_over_the_size_limit_is_refused_unread():
    packet = encode_message("/choreo/go", ["x" * 100])
    assert decode_packet(packet, OscLimits(max_message=len(packet))).messages
    assert "the limit is 100" in decode_packet(packet, OscLimits(max_message=100)).error


# -- TCP framing --------------------------------------------------------------------------------


def test_slip_frames_as_any_sender_frames_them():
    reader = FrameReader()
    assert reader.feed(b"\xc0one\xc0\xc0tw").packets == [b"one"]  # double END, a frame cut in two
    assert reader.pending
    assert reader.feed(b"o\xc0three\xc0").packets == [b"two", b"three"]  # END-terminated only
    assert not reader.pending
    assert reader.feed(b"\xdb\xdc\xdb\xdd\xc0").packets == [b"\xc0\xdb"]  # escaped END and ESC
    fed = reader.feed(b"bad\xdbx\xc0ok\xc0")
    assert fed.packets == [b"ok"] and fed.bad == ["a SLIP frame with a bad escape"]  # dropped, not the stream
    assert reader.frame(b"\xc0") == b"\xc0\xdb\xdc\xc0"  # a reply, framed as the peer frames
    assert slip_decode(slip_encode(bytes(range(256)))[1:-1]) == bytes(range(256))


def test_a_slip_frame_without_an_end_is_fatal_past_the_limit():
    reader = FrameReader(max_message=100)
    assert reader.feed(b"/" + b"x" * 199).fatal is None  # every byte could be escaped: twice the limit
    assert "without its end" in reader.feed(b"x").fatal


def test_a_length_prefix_frames_as_liblo_sends():
    """OSC 1.0 over TCP (liblo: Pure Data, SuperCollider, Max): a big-endian int32 length, then
    the packet; told from SLIP by its first byte (a length within the limit starts with 0)."""
    reader = FrameReader()
    stream = struct.pack(">I", len(GO)) + GO + struct.pack(">I", 0) + struct.pack(">I", len(GO)) + GO
    assert reader.feed(stream[:3]).packets == [] and reader.framing == "length"
    assert reader.feed(stream[3:30]).packets == [GO] and reader.pending
    assert reader.feed(stream[30:]).packets == [GO] and not reader.pending  # the empty packet between: nothing
    assert reader.frame(GO) == struct.pack(">I", len(GO)) + GO
    assert "a length prefix of 65537" in FrameReader().feed(struct.pack(">I", 65537)).fatal
    assert "a length prefix of -1" in FrameReader().feed(struct.pack(">I", len(GO)) + GO + b"\xff" * 4).fatal
    assert FrameReader().feed(b"/" + GO[1:] + b"\xc0").packets == [GO]  # END-terminated SLIP: not a length


# -- connections: caps and timeouts -------------------------------------------------------------


LIMITED = OscLimits(max_connections=4, max_per_sender=2, message_timeout_s=5.0, idle_timeout_s=600.0)


def test_a_new_connection_takes_the_place_of_the_oldest_silent_one():
    table = ConnectionTable(LIMITED)
    assert table.admit("a1", "10.0.0.1", 0.0) == (True, [])
    assert table.admit("a2", "10.0.0.1", 1.0) == (True, [])
    assert table.admit("a3", "10.0.0.1", 2.0) == (True, ["a1"])  # per sender: the oldest silent goes
    table.heard("a2", 2.5, messages=1, pending=False)
    table.heard("a3", 2.5, messages=1, pending=False)
    assert table.admit("a4", "10.0.0.1", 3.0) == (False, [])  # both speak: the new one is refused
    assert table.admit("b1", "10.0.0.2", 3.0) == (True, [])
    assert table.admit("c1", "10.0.0.3", 4.0) == (True, [])
    assert len(table) == 4
    assert table.admit("d1", "10.0.0.4", 5.0) == (True, ["b1"])  # in total: the oldest silent goes
    for key in ("c1", "d1"):
        table.heard(key, 5.0, messages=1, pending=False)
    table.heard("a3", 5.5, messages=1, pending=False)
    # every place taken by connections that speak: the address holding the most gives up the one
    # heard least lately (a new address is never locked out)
    assert table.admit("e1", "10.0.0.5", 6.0) == (True, ["a2"])


def test_connections_that_speak_from_a_few_addresses_cannot_lock_a_new_address_out():
    """Four allowed addresses, each with its share of connections, each sending a junk frame
    now and then, held every place: the operator's QLab, connecting from a fifth, was refused
    ("too many connections") for as long as they went on."""
    limits = OscLimits(max_connections=32, max_per_sender=8)
    table = ConnectionTable(limits)
    for n in range(32):
        key = f"junk{n}"
        assert table.admit(key, f"127.0.1.{n % 4}", float(n))[0]
        table.heard(key, 100.0 + n, messages=1, pending=False)
    taken, evicted = table.admit("qlab", "127.0.0.9", 200.0)
    assert taken and evicted == ["junk0"]  # of an address with 8, the one heard least lately
    table.heard("qlab", 200.0, messages=1, pending=False)
    for n in range(40):  # the junk senders reconnect: they push out their own, never QLab
        key = f"again{n}"
        assert table.admit(key, f"127.0.1.{n % 4}", 300.0 + n)[0]
        table.heard(key, 300.0 + n, messages=1, pending=False)
    assert len(table) == 32 and "qlab" in table._slots  # noqa: SLF001 - who holds a place is the point


def test_out_of_descriptors_the_oldest_silent_connection_makes_room():
    table = ConnectionTable(LIMITED)
    for key, at in (("old", 0.0), ("speaks", 1.0), ("new", 2.0)):
        table.admit(key, key, at)
    table.heard("speaks", 1.5, messages=1, pending=False)
    assert table.make_room() == "old"
    assert table.make_room() == "new"
    assert table.make_room() is None and len(table) == 1


def test_a_connection_must_speak_in_time_and_a_trickle_does_not_keep_it():
    table = ConnectionTable(LIMITED)
    table.admit("silent", "h", 0.0)
    table.admit("trickle", "h", 0.0)
    table.admit("q", "h2", 0.0)
    table.admit("lab", "h2", 0.0)
    table.heard("trickle", 1.0, messages=0, pending=True)
    table.heard("trickle", 4.0, messages=0, pending=True)  # more bytes of the same message: no more time
    table.heard("q", 1.0, messages=1, pending=False)
    table.heard("lab", 1.0, messages=1, pending=True)  # a message, then the start of the next one
    assert table.next_due() == 5.0
    assert table.expired(4.99) == []
    assert sorted(table.expired(5.0)) == [("silent", "closed: no command within 5 s of connecting"),
                                          ("trickle", "closed: a message unfinished after 5 s")]
    assert table.expired(6.0) == [("lab", "closed: a message unfinished after 5 s")]
    assert table.expired(600.99) == []
    assert table.expired(601.0) == [("q", "closed: idle for 600 s")]
    assert len(table) == 0 and table.next_due() is None


# -- fuzzing: never an exception, never unbounded work -----------------------------------------

ARG = st.one_of(st.text(max_size=12), st.integers(-2**63, 2**63 - 1), st.floats(width=32, allow_nan=False),
                st.booleans(), st.none(), st.binary(max_size=12))
ADDRESS = st.text(max_size=16).map(lambda text: "/" + text.replace("\x00", ""))
MESSAGE = st.builds(encode_message, ADDRESS, st.lists(ARG, max_size=4))
PACKET = st.recursive(MESSAGE, lambda inner: st.lists(inner, max_size=4).map(encode_bundle), max_leaves=12)
FUZZ = settings(max_examples=150, deadline=HANG_S * 1000, suppress_health_check=[HealthCheck.too_slow])


def check(packet: bytes, limits: OscLimits = LIMITS) -> Decoded:
    """decode_packet's promises, whatever the packet: no exception, a result or a reason, never both."""
    decoded = decode_packet(packet, limits)
    assert isinstance(decoded, Decoded)
    assert (decoded.error is None) or decoded.messages == ()
    assert len(decoded.messages) <= limits.max_bundle_elements
    assert all(message.address.startswith("/") for message in decoded.messages)
    return decoded


@settings(FUZZ, max_examples=1000)
@given(st.binary(max_size=256))
def test_fuzz_random_bytes(packet):
    check(packet)
    check(b"#bundle\x00" + packet)  # random bytes where a bundle's header promises more


@FUZZ
@given(PACKET, st.data())
def test_fuzz_truncated_and_mutated_packets(packet, data):
    """A valid packet reads back; cut or changed anywhere (a size field above all), and ten
    variants of it each, it is read or refused, never more."""
    assert check(packet).error is None
    for _ in range(10):
        mutant = bytearray(packet)
        how = data.draw(st.sampled_from(["cut", "flip", "size", "splice"]))
        at = data.draw(st.integers(0, max(0, len(packet) - 1)))
        if how == "cut":
            mutant = mutant[:at]
        elif how == "flip":
            mutant[at] ^= data.draw(st.integers(1, 255))
        elif how == "size":
            mutant[at:at + 4] = struct.pack(">i", data.draw(st.sampled_from([0, -4, -1, 4, 2**31 - 1, -2**31,
                                                                            len(packet)])))
        else:
            mutant[at:at] = data.draw(st.binary(min_size=1, max_size=8))
        check(bytes(mutant))


def test_fuzz_ten_thousand_mutated_bundles_quickly():
    """Deterministic besides hypothesis: 10,000 mutated bundles (sizes overwritten, cut, bytes
    flipped), each decoded or refused; the work is linear in a packet's length, so this is fast
    (a packet that looped, as python-osc's did, would hang the test)."""
    rng = random.Random(21)
    base = encode_bundle([GO, encode_bundle([encode_message("/choreo/cue/x/go", [1, "a", 2.0])]),
                          encode_message("/choreo/stop", [b"blob", None])])
    refused = 0
    for _ in range(10_000):
        mutant = bytearray(base)
        for _ in range(rng.randint(1, 3)):
            at = rng.randrange(len(mutant)) if mutant else 0
            kind = rng.random()
            if kind < 0.4:
                mutant[at:at + 4] = struct.pack(">i", rng.choice([0, -4, rng.randint(-2**31, 2**31 - 1), 4, 8]))
            elif kind < 0.7:
                del mutant[at:]
            else:
                mutant[at:at + 1] = bytes([rng.randrange(256)])
        refused += check(bytes(mutant)).error is not None
    assert 5_000 < refused < 10_000  # most mutants are refused; some (a flipped letter) still read


@FUZZ
@given(st.lists(st.binary(max_size=64), max_size=20), st.sampled_from([b"", b"\xc0", b"\x00"]))
def test_fuzz_tcp_framing_is_bounded(chunks, first):
    reader = FrameReader(max_message=64)
    for chunk in [first, *chunks]:
        fed = reader.feed(chunk)
        assert all(len(packet) <= 128 for packet in fed.packets)
        if fed.fatal is not None:
            return
        assert len(reader._buffer) <= 2 * 64 + 64


def _steps(feed) -> int:  # type: ignore[no-untyped-def]
    """How many calls (Python functions and builtins) `feed()` makes: the work it does, counted
    rather than timed."""
    calls = [0]

    def count(frame, event, arg):  # type: ignore[no-untyped-def]
        if event in ("call", "c_call"):
            calls[0] += 1

    sys.setprofile(count)
    try:
        feed()
    finally:
        sys.setprofile(None)
    return calls[0]


@pytest.mark.parametrize("filler", [END, b"\x00\x00\x00\x00"], ids=["SLIP ENDs", "zero lengths"])
def test_bytes_that_frame_nothing_cost_no_step_each(filler):
    """A stream of ENDs (SLIP) or of zero lengths (length-prefixed) frames nothing; each cost a
    Python step (8 connections sending them used a whole core and held a GO 211 ms). Now the
    work is the same for 400 KB of them as for 4 KB, and the packet after them still comes."""
    head = slip_encode(GO) if filler == END else struct.pack(">I", len(GO)) + GO
    tail = slip_encode(GO) if filler == END else struct.pack(">I", len(GO)) + GO

    def work(size: int) -> int:
        reader = FrameReader()
        reader.feed(head)
        fed: list = []
        steps = _steps(lambda: fed.append(reader.feed(filler * (size // len(filler)) + tail)))
        assert fed[0].packets == [GO] and fed[0].fatal is None and not reader.pending
        return steps

    assert work(400_000) <= work(4_000) + 5


def test_a_packets_arguments_are_bounded_before_they_are_read():
    """A 64 KB packet of 13,000 arguments took 10 ms to read (no command takes more than one);
    a packet has at most `max_arguments`, all its messages' together, counted from the type
    tags before any argument is read."""
    most = LIMITS.max_arguments
    assert decode_packet(encode_message("/x", [True] * most)).error is None
    assert decode_packet(encode_message("/x", [True] * (most + 1))).error == f"more than {most} arguments in one packet"
    spread = encode_bundle([encode_message("/x", [1] * (most // 4))] * 4 + [encode_message("/y", [1])])
    assert decode_packet(spread).error == f"more than {most} arguments in one packet"
    tags_only = b"/x\x00\x00" + encode_message("", [None] * 60_000)[4:]  # 60,000 tags and no data
    assert _steps(lambda: decode_packet(tags_only)) < 100
