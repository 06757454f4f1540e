"""Fuzzing the SLCAN codec and adapter state machine with hypothesis (``pytest
--hypothesis-profile fuzz`` runs them for long, tests/conftest.py)."""

from __future__ import annotations

import itertools

from hypothesis import given, settings
from hypothesis import strategies as st

from sim.canopen import slcan


def examples(n: int) -> settings:
    """``n`` examples in the suite; the ``fuzz`` profile's count under ``--hypothesis-profile
    fuzz`` (tests/conftest.py)."""
    fuzzing = settings.get_current_profile_name() == "fuzz"
    return settings(deadline=None) if fuzzing else settings(max_examples=n, deadline=None)


lines = st.one_of(
    st.binary(max_size=80),
    st.text(alphabet="tTrRSsOLCVNF0123456789abcdefABCDEFxyz\r\n", max_size=40).map(str.encode),
)
frames = st.builds(
    lambda ext, can_id, data, remote, dlc: slcan.CanFrame(
        can_id & (slcan.MAX_EXT_ID if ext else slcan.MAX_STD_ID),
        b"" if remote else data, ext, remote, dlc if remote else -1,
    ),
    st.booleans(), st.integers(0, slcan.MAX_EXT_ID), st.binary(max_size=8), st.booleans(),
    st.integers(0, 8),
)  # fmt: skip


@examples(500)
@given(lines)
def test_decode_frame_returns_a_frame_or_raises_slcan_error_only(line):
    try:
        frame = slcan.decode_frame(line)
    except slcan.SlcanError as exc:
        assert "\n" not in str(exc)
        return
    # whatever parses re-encodes to a line that parses to the same frame
    assert slcan.decode_frame(slcan.encode_frame(frame)) == frame


@examples(300)
@given(frames)
def test_frames_round_trip(frame):
    line = slcan.encode_frame(frame)
    assert line.endswith(b"\r") and len(line) <= slcan.MAX_LINE
    assert slcan.decode_frame(line) == frame


@examples(300)
@given(st.lists(lines, max_size=20).map(b"".join), st.lists(st.integers(0, 5000), max_size=10))
def test_line_splitter_is_bounded_and_cut_independent(data, cuts):
    whole = slcan.LineSplitter().feed(data)
    points = sorted({c % (len(data) + 1) for c in cuts})
    edges = [0, *points, len(data)]
    s = slcan.LineSplitter()
    chunked = []
    for a, b in itertools.pairwise(edges):
        chunked += s.feed(data[a:b])
        assert len(s._buf) <= slcan.MAX_LINE
    assert whole == chunked


@examples(300)
@given(st.lists(st.one_of(st.none(), lines), max_size=30))
def test_the_adapter_answers_any_command_sequence_without_raising(commands):
    adapter = slcan.SlcanAdapter()
    for line in commands:
        line = line if line is None else line.replace(b"\r", b"")
        reply, frame = adapter.handle(line)
        assert isinstance(reply, bytes) and reply
        if frame is not None:
            assert adapter.is_open and not adapter.listen_only
