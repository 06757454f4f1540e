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
# Behind its schedule by more than this, the loop gives up catching up and re-bases (the lag
# is dropped: simulated time then trails wall time for good). Guess: twenty 5 ms slices.
REBASE_S = 0.1
# The lags counted in the summary, s: a slice's length, and a 40 Hz control tick minus 5 ms.
LATE_S = (0.005, 0.020)


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
        # How far the twin's time fell behind wall time (measured, reported at stop):
        self.iterations = 0
        self.max_lag_s = 0.0  # the most wall s the loop was behind its schedule
        self.late = {LATE_S[0]: 0, LATE_S[1]: 0}  # iterations more than 5 / 20 ms behind
        self.dropped_s = 0.0  # simulated s never stepped: the lag dropped at the re-bases
        self._started = 0.0

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
            log.info("%s", self.summary())

    def summary(self) -> str:
        """One line: how far the twin's time lagged behind wall time since ``start``."""
        n = max(self.iterations, 1)
        wall = time.monotonic() - self._started
        return (
            f"real-time loop: {self.iterations} slices in {wall:.1f} s; lag at most "
            f"{self.max_lag_s * 1e3:.0f} ms; over {LATE_S[0] * 1e3:.0f} ms in "
            f"{100 * self.late[LATE_S[0]] / n:.1f} % of slices, over {LATE_S[1] * 1e3:.0f} ms "
            f"in {100 * self.late[LATE_S[1]] / n:.1f} %; {self.overruns} re-bases dropped "
            f"{self.dropped_s:.2f} s of simulated time"
        )

    def __enter__(self) -> RealtimeLoop:
        self.start()
        return self

    def __exit__(self, *exc: object) -> None:
        self.stop()

    def _run(self) -> None:
        period = self.slice_s / self.speed
        deadline = self._started = time.monotonic()
        while not self._stop.is_set():
            with self.twin.lock:
                self.twin.step(self.slice_s)
            deadline += period
            delay = deadline - time.monotonic()
            self.iterations += 1
            lag = -delay
            self.max_lag_s = max(self.max_lag_s, lag)
            for bound in LATE_S:
                self.late[bound] += lag > bound
            if delay > 0:
                self._stop.wait(delay)
            elif delay < -REBASE_S:
                self.overruns += 1
                self.dropped_s += lag * self.speed
                deadline = time.monotonic()
