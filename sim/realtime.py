"""Run the twin in (scaled) real time, for the bus emulators: simulated time follows wall time.

A physical arm's time never lags behind the host's: a servo read at wall time t reports its
position at t, and a goal written at t starts acting at t. The twin's physics runs in a thread
that a loaded machine may not schedule for tens or hundreds of ms, so the loop keeps the time
consistent two ways:

- **catch-up on demand**: the loop registers itself as the twin's pacer (``Twin.pacer``), and
  an emulator calls ``twin.catch_up()`` under ``twin.lock`` before it reads or writes the
  twin's state for a request; the physics is then stepped up to the current wall time (to the
  last 5 ms physics step at or before it). A reading answered at wall time t shows the joints
  at t (``Twin.joint_positions_now``: the last step's carried on by their velocities), a
  command's delay counts from t (``Twin.set_targets``), however late the loop's thread runs.
- **the background loop** does the same every ``slice_s`` (for what moves between requests:
  the ball, the hands, the camera's frames). Behind by more than ``REBASE_S`` (an absurd
  lag: the process was stopped, or the machine suspended), it drops the lag instead of
  stepping through it, and counts it.

Rendering never happens here (a render only copies the scene under the lock): a catch-up costs
physics steps only, about 6 ms per simulated second of the served stand-in's scene (measured
2026-12-03 on this project's 2-core machine, load 2).
"""

from __future__ import annotations

import contextlib
import logging
import math
import os
import threading
import time

from sim.twin import Twin

log = logging.getLogger(__name__)
# Behind wall time by more than this, the loop drops the lag instead of stepping through it
# (simulated time then trails wall time by it for good), and counts a re-base. Guess: far
# beyond any scheduling delay of a loaded machine (the worst seen: 1.7 s at load 12,
# docs/dynamics.md); stepping 5 s costs about 30 ms of physics.
REBASE_S = 5.0
# The lags counted in the summary, s: one 5 ms physics step, and a 40 Hz control tick minus 5 ms.
LATE_S = (0.005, 0.020)
# The nice value a served rig takes where the system allows it (CAP_SYS_NICE, root): a real
# arm's drives have processors of their own, so a busy host must not slow their answers. Its
# weight (9548 against 1024 at nice 0, the kernel's table) outweighs 8 busy processes at nice 0
# in the same scheduling group; the server needs about a third of a core (measured: `ps` on a
# served stand-in during a bus run), so it cannot starve the host. Guess, checked with
# tests/stress/can_heartbeat.py (docs/canopen_heartbeats.md).
SERVED_NICE = -10


def serve_ahead_of_the_host(nice: int = SERVED_NICE) -> str:
    """Raise every thread of this process (those started before, such as the BLAS library's
    pool, and, by inheritance, those the calling thread starts after) to ``nice`` where
    allowed. Returns one line saying which priority the served rig runs at."""
    try:
        tasks = [int(t) for t in os.listdir("/proc/self/task")]
    except OSError:  # no /proc: the calling thread only
        tasks = [0]
    try:
        for tid in [0, *tasks]:
            with contextlib.suppress(ProcessLookupError):  # a thread that ended meanwhile
                if os.getpriority(os.PRIO_PROCESS, tid) > nice:
                    os.setpriority(os.PRIO_PROCESS, tid, nice)
    except (AttributeError, OSError) as exc:  # not permitted (no CAP_SYS_NICE) or not POSIX
        return (
            f"served at the ordinary priority (nice {nice} needs CAP_SYS_NICE: {exc}); on a "
            "busy host its answers may come late"
        )
    return f"served at nice {os.getpriority(os.PRIO_PROCESS, 0)}, ahead of the host's programs"


class RealtimeLoop:
    """Keeps ``twin``'s simulated time at wall time times ``speed`` (see the module docstring).

    Args:
        twin: the twin to step; the loop is its pacer (``twin.pacer``) while it runs.
        speed: simulated seconds per wall second (1.0 = real time).
        slice_s: how often the background thread catches up, simulated s.

    Counters (the summary line reports them): ``iterations``, the background thread's
    wake-ups; ``max_lag_s`` and ``late``, how late that thread came to step (woken and the
    twin's lock taken) behind its schedule (wall s: how far the twin's time would have lagged
    without catch-up on demand); ``overruns`` and ``dropped_s``, the re-bases and the
    simulated s they dropped; ``requests``, ``request_max_lag_s`` and ``request_late``, how
    far behind wall time each request found the twin before catching it up (wall s: the time
    warp it would have seen before).
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
        self.max_lag_s = 0.0  # the most wall s the thread woke late (behind its schedule)
        self.late = {LATE_S[0]: 0, LATE_S[1]: 0}  # wake-ups more than 5 / 20 ms behind
        self.dropped_s = 0.0  # simulated s never stepped: the lag dropped at the re-bases
        self.requests = 0  # catch-ups asked by requests (twin.catch_up)
        self.request_max_lag_s = 0.0
        self.request_late = {LATE_S[0]: 0, LATE_S[1]: 0}
        self._started = 0.0
        self._wall0 = 0.0  # wall time (monotonic s) at which simulated time was _sim0
        self._sim0 = 0.0
        self._last_sim = 0.0  # the twin's time after the last catch-up, s

    # ---- lifecycle ---------------------------------------------------------------------------
    def start(self) -> None:
        if self._thread is not None:
            return
        self._stop.clear()
        with self.twin.lock:
            if self.twin.pacer is not None and self.twin.pacer is not self:
                raise RuntimeError("this twin is already paced by another real-time loop")
            self._started = self._wall0 = time.monotonic()
            self._sim0 = self._last_sim = self.twin.time
            self.twin.pacer = self
        self._thread = threading.Thread(target=self._run, name="twin-realtime", daemon=True)
        self._thread.start()

    def stop(self) -> None:
        self._stop.set()
        if self._thread is not None:
            self._thread.join(timeout=2.0)
            self._thread = None
            with self.twin.lock:
                if self.twin.pacer is self:
                    self.twin.pacer = None
            log.info("%s", self.summary())

    def __enter__(self) -> RealtimeLoop:
        self.start()
        return self

    def __exit__(self, *exc: object) -> None:
        self.stop()

    # ---- the clock ---------------------------------------------------------------------------
    def target_time(self, wall: float | None = None) -> float:
        """The simulated time (s) the twin should show at wall time ``wall`` (monotonic s;
        default now)."""
        wall = time.monotonic() if wall is None else wall
        return self._sim0 + (wall - self._wall0) * self.speed

    def restart(self) -> None:
        """The twin's time was set (``Twin.reset``, ``Twin.set_state``): simulated time follows
        wall time from it, now."""
        with self.twin.lock:
            self._wall0, self._sim0 = time.monotonic(), self.twin.time
            self._last_sim = self.twin.time

    def catch_up(self, request: bool = True) -> float:
        """Step the twin up to the current wall time (to the last physics step at or before
        it); returns how far behind it was, wall s. Takes
        ``twin.lock`` (callers usually hold it already: it is re-entrant). ``request``: a
        request's catch-up (counted apart from the background loop's)."""
        twin = self.twin
        with twin.lock:
            now = time.monotonic()
            if twin.time < self._last_sim - 1e-9:  # its time set back other than by restart:
                self._wall0, self._sim0 = now, twin.time  # it follows wall time from there
            behind = self.target_time(now) - twin.time  # simulated s
            lag = behind / self.speed
            if request:
                self.requests += 1
                self.request_max_lag_s = max(self.request_max_lag_s, lag)
                for bound in LATE_S:
                    self.request_late[bound] += lag > bound
            if lag > REBASE_S:
                # an absurd lag: drop it (counted), then step as usual from the new base
                self.overruns += 1
                self.dropped_s += behind
                self._wall0, self._sim0 = now, twin.time
                self._last_sim = twin.time
                return lag
            # the last step at or before the present (1e-9: float sums of steps, a guess far
            # below a step); readings carry the joints on to the present (joint_positions_now)
            n = math.floor(behind / twin.timestep + 1e-9)
            if n > 0:
                twin.step(n * twin.timestep)
            self._last_sim = twin.time
            return lag

    def summary(self) -> str:
        """One line: how far the twin's time lagged behind wall time since ``start``."""
        n = max(self.iterations, 1)
        r = max(self.requests, 1)
        wall = time.monotonic() - self._started
        return (
            f"real-time loop: {self.iterations} slices in {wall:.1f} s; lag at most "
            f"{self.max_lag_s * 1e3:.0f} ms; over {LATE_S[0] * 1e3:.0f} ms in "
            f"{100 * self.late[LATE_S[0]] / n:.1f} % of slices, over {LATE_S[1] * 1e3:.0f} ms "
            f"in {100 * self.late[LATE_S[1]] / n:.1f} %; {self.overruns} re-bases dropped "
            f"{self.dropped_s:.2f} s of simulated time; {self.requests} requests caught up "
            f"(behind over {LATE_S[0] * 1e3:.0f} ms in {100 * self.request_late[LATE_S[0]] / r:.1f}"
            f" %, over {LATE_S[1] * 1e3:.0f} ms in {100 * self.request_late[LATE_S[1]] / r:.1f} %,"
            f" at most {self.request_max_lag_s * 1e3:.0f} ms)"
        )

    def _run(self) -> None:
        period = self.slice_s / self.speed
        planned = time.monotonic()  # when this thread meant to wake, monotonic s
        while not self._stop.is_set():
            with self.twin.lock:  # how late the thread came to step, wall s (woken, locked)
                lag = time.monotonic() - planned
                self.catch_up(request=False)
                # wake when the twin is one slice behind wall time again
                ahead = (self.twin.time - self.target_time()) / self.speed
                wait = max(0.0, ahead + period)
                planned = time.monotonic() + wait
            self.iterations += 1
            self.max_lag_s = max(self.max_lag_s, lag)
            for bound in LATE_S:
                self.late[bound] += lag > bound
            self._stop.wait(wait)
