"""Fuzz the Dynamixel Protocol 2.0 streaming decoder.

    python bench/fuzz_dynamixel.py                 # atheris if installed, else hypothesis
    python bench/fuzz_dynamixel.py --examples 200000

With atheris (``pip install atheris``; it needs clang/libFuzzer and no wheel exists for every
platform: on this project's machine it could not be installed, no network) it runs a
coverage-guided libFuzzer loop over ``one_input``. Without it, a hypothesis-driven loop feeds
the same target with structured streams (headers, stuffing, valid status packets, garbage).

The properties checked for every input: the decoder never raises, its buffer never exceeds
one maximal frame, and cutting the input into two chunks anywhere decodes the same items.
A failure prints the input; add it to tests/test_fuzz_dynamixel.py as a regression test.
"""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from robot.dynamixel import protocol as proto


def _key(item: object) -> tuple:
    return (type(item).__name__, *vars(item).values())


def one_input(data: bytes) -> None:
    """The fuzz target: raises AssertionError (or anything else) on a finding."""
    whole = proto.Decoder()
    items = whole.feed(data)
    cut = (data[0] * 7 + 3) % (len(data) + 1) if data else 0
    chunked = proto.Decoder()
    got = chunked.feed(data[:cut])
    assert chunked.pending <= proto.PREFIX_SIZE + chunked.max_length
    got += chunked.feed(data[cut:])
    assert [_key(i) for i in items] == [_key(i) for i in got], data.hex()
    for item in items:
        if isinstance(item, proto.StatusPacket | proto.InstructionPacket):
            assert [_key(p) for p in proto.decode_all(item.encode())] == [_key(item)]


def _hypothesis_loop(examples: int) -> None:
    from hypothesis import HealthCheck, given, settings
    from hypothesis import strategies as st

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

    @settings(
        max_examples=examples, deadline=None, database=None,
        suppress_health_check=list(HealthCheck),
    )  # fmt: skip
    @given(st.lists(fragments, max_size=40).map(b"".join))
    def run(data: bytes) -> None:
        one_input(data)

    run()


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--examples", type=int, default=20_000, help="hypothesis examples")
    ap.add_argument("--no-atheris", action="store_true", help="use the hypothesis loop")
    args, rest = ap.parse_known_args()
    try:
        if args.no_atheris:
            raise ImportError
        import atheris  # type: ignore[import-not-found]
    except ImportError:
        t0 = time.perf_counter()
        _hypothesis_loop(args.examples)
        dt = time.perf_counter() - t0
        print(f"hypothesis loop (atheris not installed): {args.examples} examples, no finding, "
              f"{dt:.1f} s")  # fmt: skip
        return 0
    atheris.Setup([sys.argv[0], *rest], one_input)
    atheris.Fuzz()
    return 0


if __name__ == "__main__":
    sys.exit(main())
