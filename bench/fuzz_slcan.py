"""Fuzz the SLCAN codec, line splitter and adapter state machine (sim/canopen/slcan.py).

    python bench/fuzz_slcan.py                 # atheris if installed, else hypothesis
    python bench/fuzz_slcan.py --examples 200000

atheris could not be installed on this project's machine (no network, no wheel); the script
then falls back to a hypothesis-driven loop over the same target.

Checked for every input: the splitter never holds more than ``MAX_LINE`` bytes, every line
either parses to a frame that re-encodes to itself or raises ``SlcanError`` (nothing else),
and the adapter answers every line with a non-empty reply without raising. A failure prints
the input; add it to tests/test_fuzz_slcan.py as a regression test.
"""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from sim.canopen import slcan


def one_input(data: bytes) -> None:
    """The fuzz target: raises on a finding."""
    splitter = slcan.LineSplitter()
    adapter = slcan.SlcanAdapter()
    half = len(data) // 2
    lines = splitter.feed(data[:half])
    assert len(splitter._buf) <= slcan.MAX_LINE
    lines += splitter.feed(data[half:])
    assert len(splitter._buf) <= slcan.MAX_LINE
    for line in lines:
        reply, _ = adapter.handle(line)
        assert isinstance(reply, bytes) and reply, repr(line)
        if line is None:
            continue
        try:
            frame = slcan.decode_frame(line)
        except slcan.SlcanError:
            continue
        assert slcan.decode_frame(slcan.encode_frame(frame)) == frame, repr(line)


def _hypothesis_loop(examples: int) -> None:
    from hypothesis import HealthCheck, given, settings
    from hypothesis import strategies as st

    alphabet = "tTrRSsOLCVNF0123456789abcdefABCDEFxyz\r\n\a"
    data = st.one_of(st.binary(max_size=200), st.text(alphabet, max_size=200).map(str.encode))

    @settings(
        max_examples=examples, deadline=None, database=None,
        suppress_health_check=list(HealthCheck),
    )  # fmt: skip
    @given(data)
    def run(d: bytes) -> None:
        one_input(b"O\r" + d)  # open the channel first so frame lines reach the parser

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
