"""The MP4 writer's encoder (SVT-AV1) leaves this process's scheduling as it found it: run as
root, SVT-AV1 makes its threads and the thread feeding it SCHED_FIFO at priority 99
(explore/export/video.py), which would outrank an arm's controller on every core."""

from __future__ import annotations

import os
import threading

import numpy as np
import pytest

from explore.export.video import Mp4Writer, ordinary_threads, thread_schedules

REAL_TIME = (os.SCHED_FIFO, os.SCHED_RR)


def test_encoding_leaves_every_thread_at_its_own_scheduling(tmp_path):
    before = thread_schedules()
    assert before and all(p not in REAL_TIME for p, _ in before.values())
    seen_during = {}
    with Mp4Writer(tmp_path / "a.mp4", fps=40, side=64) as writer:
        writer.add(np.zeros((4, 64, 64, 3), np.uint8))
        seen_during = thread_schedules()  # the encoder's threads are alive here
    assert len(seen_during) > len(before)  # the encoder started threads of its own
    # every thread alive, the encoder's included, at the ordinary policy, during and after
    for schedules in (seen_during, thread_schedules()):
        raised = {t: s for t, s in schedules.items() if s[0] in REAL_TIME}
        assert not raised, (raised, "euid", os.geteuid())
    assert thread_schedules()[threading.get_native_id()] == before[threading.get_native_id()]


def test_a_thread_raised_behind_our_back_gets_its_own_policy_back():
    before = thread_schedules()
    main = threading.get_native_id()
    try:
        os.sched_setscheduler(main, os.SCHED_FIFO, os.sched_param(1))
    except PermissionError:
        pytest.skip("raising a thread to SCHED_FIFO needs CAP_SYS_NICE (root)")
    started, stop = threading.Event(), threading.Event()
    tid: list[int] = []

    def worker() -> None:  # starts at SCHED_FIFO 1, inherited from the raised thread
        tid.append(threading.get_native_id())
        started.set()
        stop.wait(10)

    t = threading.Thread(target=worker)
    try:
        t.start()
        started.wait(10)
        assert thread_schedules()[tid[0]] == (os.SCHED_FIFO, 1)
        assert ordinary_threads(before) == 2  # this thread back, the new one made ordinary
        after = thread_schedules()
        assert after[main] == before[main]
        assert after[tid[0]] == (os.SCHED_OTHER, 0)
        assert ordinary_threads(before) == 0  # nothing left to undo
    finally:
        os.sched_setscheduler(main, *[before[main][0], os.sched_param(before[main][1])])
        stop.set()
        t.join(10)
