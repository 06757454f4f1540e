"""Torque off on SIGINT/SIGTERM: ``torque_off_on_signals`` turns an arm's torque off before the
usual exception unwinds, so a Ctrl-C never leaves a stiff arm behind; a watcher thread does it
without waiting for the main thread's C call in progress, and on a serial bus a guardian
process (``robot.torque_guardian``) writes the torque-off without waiting for the GIL. It only
uses the arm's public ``interrupt``, ``clear_interrupt`` and ``emergency_payload``.
"""

from __future__ import annotations

import contextlib
import logging
import os
import signal
import socket
import threading
from collections.abc import Iterator
from typing import TYPE_CHECKING

from robot.torque_guardian import Guardian

if TYPE_CHECKING:
    from robot.arm import Arm

log = logging.getLogger(__name__)


# Signals that stop a run: Ctrl-C and the polite kill (systemd, docker stop, kill).
STOP_SIGNALS = (signal.SIGINT, signal.SIGTERM)
# How long leaving the block waits for the watcher thread to end, s (it wakes at once; a
# bound against a hang, not an expectation).
WATCHER_JOIN_S = 1.0
# Real-time (SCHED_FIFO) priority asked for the watcher thread, so that on a loaded machine a
# signal does not wait for the scheduler to get round to it (measured: a 21 ms wake-up at
# load 10 on 2 cores without it). 10 is low among real-time priorities (1..99; Linux runs its
# threaded interrupt handlers at 50): a guess that outranks every ordinary task and nothing
# of the kernel's. Needs CAP_SYS_NICE (or an rtprio limit); without it the thread runs at
# normal priority, which only costs latency under load.
WATCHER_RT_PRIORITY = 10


def _raise_priority() -> bool:
    """Make the calling thread SCHED_FIFO at ``WATCHER_RT_PRIORITY`` if allowed; True if so.
    The thread only ever blocks on a socket or does a short torque-off, so it cannot starve
    the machine."""
    try:
        os.sched_setscheduler(
            threading.get_native_id(), os.SCHED_FIFO, os.sched_param(WATCHER_RT_PRIORITY)
        )
    except (AttributeError, OSError) as exc:  # not Linux, or not permitted
        log.debug("signal watcher stays at normal priority: %s", exc)
        return False
    return True


def _start_guardian(arm: Arm, forward_fd: int) -> Guardian | None:
    """The arm's torque-off guardian process (``robot.torque_guardian``), when its bus can
    have one; None otherwise, or when it cannot start (then the watcher thread alone acts)."""
    payload = arm.emergency_payload()
    if payload is None:
        return None
    try:
        return Guardian.start(payload, forward_fd, WATCHER_RT_PRIORITY, arm.on_crash)
    except OSError as exc:
        log.warning("no torque-off guardian for %s (%s): the watcher thread alone acts", arm, exc)
        return None


@contextlib.contextmanager
def torque_off_on_signals(arm: Arm) -> Iterator[None]:
    """Within the block, SIGINT and SIGTERM turn the arm's torque off at once, then raise
    ``KeyboardInterrupt`` (SIGINT) or ``SystemExit(143)`` (SIGTERM) in the main thread as usual.
    If code inside turns that into another exception, the block still ends with it (chained).

    Why a thread: Python runs a signal handler in the main thread between two bytecodes, so a
    handler alone waits for the C call in progress (a MuJoCo render of 0.1-0.2 s, a camera
    read, a batch of physics steps) before it can act. Here the C-level handler also writes
    the signal number to a socket (``signal.set_wakeup_fd``) that a watcher thread blocks on;
    the watcher turns torque off as soon as it holds the GIL and the bus, which the long C
    calls release. Whichever of the watcher and the main thread's handler comes first turns
    torque off; the other only raises (main thread) or returns (watcher). The arm is also
    marked interrupted, so no link recovery in progress turns torque back on. The watcher
    asks for a real-time priority (``WATCHER_RT_PRIORITY``) where the system allows it.

    The watcher still needs the GIL, which a thread waiting for a CPU on a loaded machine may
    hold for hundreds of ms: where the arm's bus is a serial port it can write to by path
    (``Arm.emergency_payload``: Dynamixel, SLCAN), a guardian process writes the torque-off
    bytes first, without the GIL (``robot.torque_guardian``), then wakes the watcher, which
    confirms it as usual.

    Only installs in the main thread (Python's rule); elsewhere it is a no-op. While inside,
    this replaces any other wakeup fd of the process (e.g. an asyncio loop's), restored after.
    """
    if threading.current_thread() is not threading.main_thread():
        yield
        return

    claim = threading.Lock()  # taken by whoever turns torque off first
    arm.clear_interrupt()  # a new block: an earlier signal no longer holds recoveries back

    def cut(signum: int, who: str) -> None:
        if not claim.acquire(blocking=False):
            return
        arm.interrupt()
        log.warning("signal %d: torque off (%s)", signum, who)

    raised: list[int] = []  # the signals whose handler raised in the main thread

    def interrupt(signum: int) -> BaseException:
        return KeyboardInterrupt() if signum == signal.SIGINT else SystemExit(128 + signum)

    def handler(signum: int, _frame: object) -> None:
        cut(signum, "signal handler")
        raised.append(signum)
        raise interrupt(signum)

    reader, writer = socket.socketpair()
    writer.setblocking(False)  # set_wakeup_fd needs a non-blocking fd
    stop = threading.Event()
    guardian = _start_guardian(arm, writer.fileno())

    def watch() -> None:
        _raise_priority()
        while True:
            try:
                data = reader.recv(64)
            except OSError:
                return
            if not data or stop.is_set():
                return
            for signum in data:
                if signum in STOP_SIGNALS:
                    cut(signum, "watcher thread")

    previous = {s: signal.signal(s, handler) for s in STOP_SIGNALS}
    wakeup = guardian.wakeup_fd if guardian is not None else writer.fileno()
    previous_fd = signal.set_wakeup_fd(wakeup, warn_on_full_buffer=False)
    watcher = threading.Thread(target=watch, name="torque-off-on-signals", daemon=True)
    watcher.start()
    try:
        yield
    except (KeyboardInterrupt, SystemExit):
        raise
    except BaseException as exc:
        # Library code hit by the interrupt may turn it into its own error (zipfile, in
        # numpy.savez: "Can't close the ZIP file while there is an open writing handle"): the
        # block still ends as the signal asked, so the caller exits with 130 or 143.
        if raised:
            raise interrupt(raised[0]) from exc
        raise
    finally:
        signal.set_wakeup_fd(previous_fd)
        for s, h in previous.items():
            signal.signal(s, h)
        if guardian is not None:
            guardian.stop()  # its write, if any, is stamped in the payload's ``sent_at``
        stop.set()
        with contextlib.suppress(OSError):
            writer.send(b"\0")
        watcher.join(WATCHER_JOIN_S)
        reader.close()
        writer.close()
