"""Fuzzing the Dynamixel Protocol 2.0 streaming decoder with hypothesis (``pytest
--hypothesis-profile fuzz`` runs them for long, tests/conftest.py): any bytes, in any chunks,
never raise, never grow the buffer beyond one maximal frame, and decode the same however they
are cut."""

from __future__ import annotations

import itertools

from hypothesis import given, settings
from hypothesis import strategies as st

from robot.dynamixel import protocol as proto


def examples(n: int) -> settings:
    """``n`` examples in the suite; the ``fuzz`` profile's count under ``--hypothesis-profile
    fuzz`` (tests/conftest.py)."""
    fuzzing = settings.get_current_profile_name() == "fuzz"
    return settings(deadline=None) if fuzzing else settings(max_examples=n, deadline=None)


# Streams biased towards headers, stuffing and plausible lengths, so the fuzzer reaches the
# decoder's deeper branches rather than only skipping garbage.
fragments = st.one_of(
    st.binary(max_size=40),
    st.just(proto.HEADER),
    st.just(b"\xff\xff\xfd\xfd"),
    st.builds(
        lambda i, n: proto.HEADER + bytes([i, n & 0xFF, n >> 8]),
        st.integers(0, 255),
        st.integers(0, 3000),
    ),
    st.builds(
        lambda sid, err, params: proto.StatusPacket(sid, err, params).encode(),
        st.integers(0, 252),
        st.integers(0, 255),
        st.binary(max_size=30),
    ),
)
streams = st.lists(fragments, max_size=30).map(b"".join)


def _cut(data: bytes, cuts: list[int]) -> list[bytes]:
    points = sorted({c % (len(data) + 1) for c in cuts})
    edges = [0, *points, len(data)]
    return [data[a:b] for a, b in itertools.pairwise(edges)]


def _key(item) -> tuple:
    return (type(item).__name__, *vars(item).values())


@examples(400)
@given(streams, st.lists(st.integers(0, 10_000), max_size=12))
def test_any_bytes_in_any_chunks_decode_the_same_and_never_raise(data, cuts):
    whole = proto.Decoder()
    items = whole.feed(data)
    chunked = proto.Decoder()
    items_chunked = []
    for piece in _cut(data, cuts):
        items_chunked += chunked.feed(piece)
        assert chunked.pending <= proto.PREFIX_SIZE + chunked.max_length
    assert [_key(i) for i in items] == [_key(i) for i in items_chunked]
    for item in items:
        assert isinstance(item, proto.StatusPacket | proto.InstructionPacket | proto.CorruptFrame)


@examples(300)
@given(streams)
def test_every_decoded_packet_re_encodes_to_itself(data):
    for item in proto.Decoder().feed(data):
        if isinstance(item, proto.StatusPacket | proto.InstructionPacket):
            assert [_key(p) for p in proto.decode_all(item.encode())] == [_key(item)]


@examples(300)
@given(st.integers(0, 252), st.integers(0, 255), st.binary(max_size=64), streams, streams)
def test_a_valid_status_packet_between_garbage_is_found(sid, err, params, before, after):
    packet = proto.StatusPacket(sid, err, params)
    wire = packet.encode()
    # the zeros complete or break any partial header the garbage ends with
    items = proto.Decoder().feed(before + b"\x00" * 8 + wire + after)
    found = [i for i in items if isinstance(i, proto.StatusPacket) and _key(i) == _key(packet)]
    assert found, (before, wire, after)
