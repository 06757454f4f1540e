"""One exchange at a time on a bus, and the emergency that preempts it: the thread-safety of a
torque-off from another thread (the signal watcher of ``robot.signals``, a safety monitor),
written once for the Dynamixel bus and the CANopen network.

- ``hold()``: the context of one exchange (re-entrant in its thread, which becomes the owner).
- ``check()``: called by an exchange at every wait; raises the guard's error when another
  thread is preempting the bus, so the exchange gives up at once instead of running its
  timeouts and retries out.
- ``preempt()``: the context of an emergency from any thread: exchanges of other threads give
  up at their next ``check()`` (``wake`` rouses the ones asleep on a condition), then this
  thread holds the bus. In the thread that already holds it (a signal handler that interrupted
  an exchange) it simply nests.
- ``defer(action)``: in the owner thread, run ``action`` when its outermost ``hold`` ends (a
  backend whose own locks a nested exchange would break, as python-can's and canopen's).
"""

from __future__ import annotations

import contextlib
import threading
import time
from collections.abc import Callable, Iterator


class BusGuard:
    """Args:
    preempted_error: makes the exception ``check()`` raises (one line, naming the bus).
    wake: called when a preemption starts, to rouse exchanges waiting on a condition.
    """

    def __init__(
        self, preempted_error: Callable[[], Exception], wake: Callable[[], None] | None = None
    ) -> None:
        self._lock = threading.RLock()
        self._owner: int | None = None
        self._preempt = threading.Event()
        self._preempt_by: int | None = None
        self._deferred: list[Callable[[], None]] = []
        self._error = preempted_error
        self._wake = wake

    @property
    def owned_by_me(self) -> bool:
        """Whether the calling thread holds the bus (inside ``hold``)."""
        return self._owner == threading.get_ident()

    @property
    def preempted(self) -> bool:
        """Whether another thread is preempting the bus (for a wait's predicate)."""
        return self._preempt.is_set() and self._preempt_by != threading.get_ident()

    def check(self) -> None:
        """Raise the guard's error if another thread is preempting the bus."""
        if self.preempted:
            raise self._error()

    def wait_unpreempted(self, timeout_s: float) -> bool:
        """Wait (at most ``timeout_s``) until no other thread is preempting the bus; whether
        that came. For an exchange that gave up to a preemption and will try again."""
        deadline = time.monotonic() + timeout_s
        while self.preempted:
            if time.monotonic() > deadline:
                return False
            time.sleep(0.001)
        return True

    @contextlib.contextmanager
    def hold(self) -> Iterator[None]:
        """Hold the bus for one exchange; deferred actions run when the outermost ends."""
        self._lock.acquire()
        try:
            outer, self._owner = self._owner, threading.get_ident()
        except BaseException:  # a signal between acquire and here: do not keep the lock
            self._lock.release()
            raise
        try:
            yield
        finally:
            self._owner = outer
            self._lock.release()
            if outer is None and self._deferred:
                actions, self._deferred = self._deferred, []
                for action in actions:
                    action()

    def defer(self, action: Callable[[], None]) -> None:
        """Run ``action`` once the owner's outermost ``hold`` ends (once, however often
        deferred meanwhile)."""
        if action not in self._deferred:
            self._deferred.append(action)

    @contextlib.contextmanager
    def preempt(self) -> Iterator[None]:
        """Hold the bus for an emergency, preempting the exchange of any other thread."""
        me = threading.get_ident()
        if self._owner == me:
            yield
            return
        self._preempt_by = me
        self._preempt.set()
        try:
            if self._wake is not None:
                self._wake()
            with self.hold():
                yield
        finally:
            self._preempt.clear()
            self._preempt_by = None
