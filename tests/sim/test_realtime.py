"""The real-time loop's account of its lag (sim/realtime.py): a stall longer than the re-base
bound is counted, and the simulated time it dropped is about the stall's length."""

from __future__ import annotations

import time

from sim.realtime import REBASE_S, RealtimeLoop
from sim.twin import Twin

STALL_S = 0.4  # the loop held off its twin this long (wall s): four re-base bounds


def test_a_stall_is_counted_and_its_dropped_time_reported():
    twin = Twin(render_size=(16, 16))
    loop = RealtimeLoop(twin)
    t0 = time.monotonic()
    with loop:
        time.sleep(0.2)
        with twin.lock:  # the loop cannot step: it falls STALL_S behind, then re-bases
            time.sleep(STALL_S)
        time.sleep(0.2)
    wall = time.monotonic() - t0
    assert loop.overruns >= 1
    assert loop.max_lag_s >= STALL_S - 0.05
    # the stall's lag dropped (less what the loop caught up before its re-base bound)
    assert STALL_S - REBASE_S - 0.05 <= loop.dropped_s <= STALL_S + 0.2
    assert twin.time <= wall - loop.dropped_s + 0.01  # the twin's clock trails wall time
    line = loop.summary()
    assert "re-bases dropped" in line and "\n" not in line
