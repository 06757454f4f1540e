"""Run the twin in (scaled) real time in a background thread, for the bus emulators.

Bus emulators answer packets from their own thread; they read and write the twin under
``twin.lock`` while this loop steps physics in small slices on a monotonic schedule.
"""

from __future__ import annotations

import logging
import threading
import time

from sim.twin import Twin

log = logging.getLogger(__name__)


class RealtimeLoop:
    """Steps ``twin`` so that simulated time follows wall time times ``speed``.

    Args:
        twin: the twin to step.
        speed: simulated seconds per wall second (1.0 = real time).
        slice_s: simulated time advanced per iteration, s.
    """

    def __init__(self, twin: Twin, speed: float = 1.0, slice_s: float = 0.005) -> None:
        if speed <= 0:
            raise ValueError(f"speed must be positive, got {speed}")
        self.twin = twin
        self.speed = speed
        self.slice_s = slice_s
        self._stop = threading.Event()
        self._thread: threading.Thread | None = None
        self.overruns = 0

    def start(self) -> None:
        if self._thread is not None:
            return
        self._stop.clear()
        self._thread = threading.Thread(target=self._run, name="twin-realtime", daemon=True)
        self._thread.start()

    def stop(self) -> None:
        self._stop.set()
        if self._thread is not None:
            self._thread.join(timeout=2.0)
            self._thread = None

    def __enter__(self) -> RealtimeLoop:
        self.start()
        return self

    def __exit__(self, *exc: object) -> None:
        self.stop()

    def _run(self) -> None:
        period = self.slice_s / self.speed
        deadline = time.monotonic()
        while not self._stop.is_set():
            with self.twin.lock:
                self.twin.step(self.slice_s)
            deadline += period
            delay = deadline - time.monotonic()
            if delay > 0:
                self._stop.wait(delay)
            elif delay < -0.1:
                self.overruns += 1
                deadline = time.monotonic()
