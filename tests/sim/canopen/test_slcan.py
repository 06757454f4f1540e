"""The SLCAN codec (adapter side, pure): frame round trips, stream splitting, commands, and
garbage that must never raise."""

from __future__ import annotations

import pytest
from hypothesis import given
from hypothesis import strategies as st

from sim.canopen.slcan import (
    BITRATES,
    ERROR,
    OK,
    CanFrame,
    LineSplitter,
    SlcanAdapter,
    SlcanError,
    decode_frame,
    encode_frame,
)


@st.composite
def frames(draw: st.DrawFn) -> CanFrame:
    extended = draw(st.booleans())
    can_id = draw(st.integers(0, 0x1FFFFFFF if extended else 0x7FF))
    if draw(st.booleans()):
        return CanFrame(can_id, b"", extended, remote=True, dlc=draw(st.integers(0, 8)))
    return CanFrame(can_id, draw(st.binary(max_size=8)), extended)


@given(frames())
def test_frame_round_trip(frame: CanFrame) -> None:
    line = encode_frame(frame)
    assert line.endswith(b"\r") and b"\r" not in line[:-1]
    assert decode_frame(line) == frame


def test_known_lines() -> None:
    # python-can's slcan host writes exactly this for a SYNC and an RPDO (interfaces/slcan.py)
    assert encode_frame(CanFrame(0x080, b"")) == b"t0800\r"
    assert encode_frame(CanFrame(0x201, bytes([0x0F, 0, 0x10, 0x27, 0, 0]))) == (
        b"t20160F0010270000\r"
    )
    assert decode_frame("T1FFFFFFF2ABCD") == CanFrame(0x1FFFFFFF, b"\xab\xcd", extended=True)
    assert decode_frame(b"r7FF3") == CanFrame(0x7FF, b"", remote=True, dlc=3)


@pytest.mark.parametrize(
    "line",
    ["", "x", "t08", "t0809", "t080201", "t0G01", "t08011", "T123", "r12301", "t\xe9\xe9\xe901"],
)
def test_bad_frame_lines_are_clear_errors(line: str) -> None:
    with pytest.raises(SlcanError):
        decode_frame(line)


def test_frame_limits() -> None:
    with pytest.raises(SlcanError, match="out of range"):
        CanFrame(0x800)
    with pytest.raises(SlcanError, match="at most 8"):
        CanFrame(1, bytes(9))
    with pytest.raises(SlcanError, match="no data"):
        CanFrame(1, b"\x01", remote=True)


@given(st.lists(frames(), max_size=20), st.lists(st.integers(1, 30), max_size=40))
def test_splitter_is_independent_of_chunking(fs: list[CanFrame], cuts: list[int]) -> None:
    stream = b"".join(encode_frame(f) for f in fs)
    splitter, lines, pos = LineSplitter(), [], 0
    for n in [*cuts, len(stream)]:
        lines += splitter.feed(stream[pos : pos + n])
        pos += n
    assert [decode_frame(line) for line in lines] == fs


def test_splitter_drops_overlong_lines_and_ignores_newlines() -> None:
    s = LineSplitter()
    assert s.feed(b"O\r\n" + b"x" * 100 + b"\rC\r") == [b"O", None, b"C"]


def test_adapter_session_like_python_can() -> None:
    a = SlcanAdapter()
    # python-can's slcanBus: close, bitrate, (empty data-bitrate line), open
    assert a.handle(b"C") == (OK, None)
    assert a.handle(b"S8") == (OK, None) and a.bitrate == BITRATES[8] == 1_000_000
    assert a.handle(b"") == (OK, None)
    assert a.handle(b"O") == (OK, None) and a.is_open
    reply, frame = a.handle(b"t20120F00")
    assert reply == b"z\r" and frame == CanFrame(0x201, b"\x0f\x00")
    reply, frame = a.handle(b"T0000020120F00")
    assert reply == b"Z\r" and frame is not None and frame.extended
    assert a.handle(b"S6") == (ERROR, None)  # no bitrate change while open
    assert a.handle(b"V")[0].startswith(b"V") and a.handle(b"N")[0].startswith(b"N")
    assert a.handle(b"C") == (OK, None) and not a.is_open


def test_adapter_refuses_frames_when_closed_or_listen_only() -> None:
    a = SlcanAdapter()
    assert a.handle(b"t0800") == (ERROR, None)
    assert a.handle(b"L") == (OK, None)
    assert a.handle(b"t0800") == (ERROR, None)
    assert a.handle(None) == (ERROR, None)


@given(st.binary(max_size=200))
def test_garbage_never_raises(data: bytes) -> None:
    adapter, splitter = SlcanAdapter(is_open=True), LineSplitter()
    for line in splitter.feed(data + b"\r"):
        reply, frame = adapter.handle(line)
        assert reply in (OK, ERROR, b"z\r", b"Z\r", b"F00\r") or reply[:1] in (b"V", b"N")
        if frame is not None:
            assert decode_frame(encode_frame(frame)) == frame
