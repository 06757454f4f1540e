"""A process stalled on purpose: one C call that keeps Python's GIL, so that no other thread of
the process runs meanwhile (as a process starved of the CPU, or one loading a large extension
library). Tests of what a stalled emulator or host does use it."""

from __future__ import annotations

import ctypes
import time


def hold_the_gil(seconds: float) -> float:
    """Sleep ``seconds`` in C without releasing the GIL (``ctypes.PyDLL`` calls keep it: the C
    library's ``usleep``). Returns how long it held, s."""
    t0 = time.perf_counter()
    ctypes.PyDLL(None).usleep(int(seconds * 1e6))
    return time.perf_counter() - t0
