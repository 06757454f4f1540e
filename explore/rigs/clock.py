"""Clocks of a rig: the twin's clock steps physics, a real clock sleeps on a monotonic schedule."""

from __future__ import annotations

import time
from typing import Protocol


class Clock(Protocol):
    """Advances time by one control period (or any duration) and tells the time, s."""

    def now(self) -> float: ...

    def advance(self, seconds: float) -> None:
        """Let ``seconds`` pass since the previous deadline (not since now)."""
        ...

    def restart(self) -> None:
        """Make the next deadline relative to now (after a pause)."""
        ...


class TwinClock:
    """Time is the twin's: ``advance`` steps the physics."""

    def __init__(self, twin: object) -> None:
        self.twin = twin

    def now(self) -> float:
        return self.twin.time  # type: ignore[attr-defined]

    def advance(self, seconds: float) -> None:
        self.twin.step(seconds)  # type: ignore[attr-defined]

    def restart(self) -> None:
        pass


class RealClock:
    """Wall time: ``advance`` sleeps until the next deadline on a monotonic schedule, so the
    control rate does not drift with the time spent computing. If the loop falls behind by more
    than one period it re-bases instead of bursting to catch up; ``overruns`` counts those."""

    def __init__(self) -> None:
        self._deadline = time.monotonic()
        self.overruns = 0

    def now(self) -> float:
        return time.monotonic()

    def advance(self, seconds: float) -> None:
        self._deadline += seconds
        delay = self._deadline - time.monotonic()
        if delay > 0:
            time.sleep(delay)
        elif delay < -seconds:
            self.overruns += 1
            self._deadline = time.monotonic()

    def restart(self) -> None:
        self._deadline = time.monotonic()
