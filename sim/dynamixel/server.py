"""``ergo twin serve --bus dynamixel``: the twin behind a real serial port (a pseudo-terminal)
speaking Dynamixel Protocol 2.0 as six XL-320, and its overhead camera as an MJPEG stream.

    $ ergo twin serve --bus dynamixel
    dynamixel bus on /dev/pts/7
    camera on http://127.0.0.1:41234/stream.mjpg

Any program that drives a real Ergo Jr through a serial port then drives the twin, e.g.
``ergo bus scan --port /dev/pts/7`` or a ``dynamixel`` rig with ``port: /dev/pts/7`` and
``camera: http://127.0.0.1:41234/stream.mjpg``. The twin runs in real time
(``sim.realtime.RealtimeLoop``); faults are injected from the flags (see ``sim/cli.py``). The
served twin, its camera and its hands (and, with ``--stand-in SEED``, a rig the software has
never seen) come from ``sim.standin.served``.
"""

from __future__ import annotations

import argparse
import logging
import os
import select
import threading
import time
from collections.abc import Sequence

from plumbing.cli_errors import error
from sim.dynamixel.emulator import DEFAULT_OVERLOAD_AFTER_S, DynamixelEmulator, FaultConfig
from sim.pty_port import OnPty, PtyPort

log = logging.getLogger(__name__)

# How often the serving loop wakes up to check for stop, s (not a protocol figure).
POLL_S = 0.05


class PtyBusServer(OnPty):
    """Serves a ``DynamixelEmulator`` on a new pseudo-terminal (``sim.pty_port.PtyPort``).

    ``path`` is the slave side to open with pyserial (e.g. ``/dev/pts/7``); ``port`` the link
    when there is one. ``unplug()`` and ``replug()`` pull the adapter out and plug it back.

    Args:
        emulator: who answers.
        link: path of a symbolic link to the current pty (None: no link).
    """

    def __init__(self, emulator: DynamixelEmulator, link: str | os.PathLike[str] | None = None):
        self.emulator = emulator
        self.pty = PtyPort(link)
        self._stop = threading.Event()
        self._thread: threading.Thread | None = None
        self.bytes_in = 0
        self.bytes_out = 0

    def serve_forever(self) -> None:
        """Answer packets until ``stop()`` (call from any thread) or KeyboardInterrupt."""
        while not self._stop.is_set():
            master = self.pty.master
            if master is None:  # unplugged
                time.sleep(POLL_S)
                continue
            try:
                ready, _, _ = select.select([master], [], [], POLL_S)
                if not ready:
                    continue
                data = os.read(master, 4096)
            except (OSError, ValueError):  # EIO without a slave open; EBADF once unplugged
                time.sleep(POLL_S)
                continue
            if not data:
                continue
            t0 = time.monotonic()
            self.bytes_in += len(data)
            for delay, wire in self.emulator.handle_bytes(data):
                wait = t0 + delay - time.monotonic()
                if wait > 0:
                    time.sleep(wait)
                try:
                    os.write(master, wire)
                except OSError:  # unplugged meanwhile
                    break
                self.bytes_out += len(wire)

    def start(self) -> None:
        """Serve in a daemon thread."""
        if self._thread is None:
            self._stop.clear()
            self._thread = threading.Thread(
                target=self.serve_forever, name="dynamixel-pty", daemon=True
            )
            self._thread.start()

    def stop(self) -> None:
        self._stop.set()
        if self._thread is not None:
            self._thread.join(timeout=2.0)
            self._thread = None

    def close(self) -> None:
        self.stop()
        self.pty.close()

    def __enter__(self) -> PtyBusServer:
        self.start()
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()


# How long the start-up check waits for each ping's answer, s: below the ROBOTIS SDK's ping
# timeout at 1 Mbps (34 ms, measured: the SDK gave up on ids 1-4 pinged right after the bus's
# line while the camera started).
READY_PING_S = 0.02


def unanswered_ids(server: PtyBusServer, ids: Sequence[int]) -> list[int]:
    """The ids that did not answer one ping each (no retry, ``READY_PING_S``) through
    ``server``'s pty, opened as a client opens it; what the client left unread is flushed."""
    from robot.dynamixel.bus import BusError, DynamixelBus

    bus = DynamixelBus(server.path, retries=0, latency_s=READY_PING_S, max_latency_s=READY_PING_S)
    silent = []
    try:
        bus.open()
        for i in ids:
            try:
                bus.ping(i)
            except BusError:
                silent.append(i)
    except BusError:  # the port itself would not open (not yet): every id is silent
        return list(ids)
    finally:
        bus.close()
        time.sleep(READY_PING_S)  # a late answer lands, then is flushed with the rest
        server.pty.flush_input()
    return silent


def faults_from_args(args: argparse.Namespace) -> FaultConfig:
    """The ``--drop-rate --corrupt-rate --delay-ms --overload-servo --seed`` flags (and
    ``--late-rate`` where the command line has it)."""
    return FaultConfig(
        drop_rate=float(getattr(args, "drop_rate", 0.0) or 0.0),
        corrupt_rate=float(getattr(args, "corrupt_rate", 0.0) or 0.0),
        extra_delay_s=float(getattr(args, "delay_ms", 0.0) or 0.0) / 1000.0,
        late_rate=float(getattr(args, "late_rate", 0.0) or 0.0),
        overload_servo=getattr(args, "overload_servo", None),
        overload_after_s=float(getattr(args, "overload_after_s", DEFAULT_OVERLOAD_AFTER_S)),
        seed=int(getattr(args, "seed", 0) or 0),
    )


def serve(args: argparse.Namespace) -> int:
    """Serve until interrupted; returns the exit code. Prints the pty path and the camera URL
    (one line each, flushed) so that a parent process can read them."""
    from sim.realtime import RealtimeLoop, serve_ahead_of_the_host
    from sim.standin.served import (
        SERVED_IDS,
        StandinError,
        open_served_rig,
        serve_until_interrupted,
    )

    # first, in the main thread: the physics, bus and camera threads inherit the priority (said
    # once serving, so that a bad flag stays one line)
    priority = serve_ahead_of_the_host()
    try:
        faults = faults_from_args(args)
    except ValueError as exc:
        return error(exc)
    if faults.overload_servo is not None and not 1 <= faults.overload_servo <= 6:
        return error(f"--overload-servo {faults.overload_servo} is not in 1..6")
    try:
        rig = open_served_rig(args)
    except StandinError as exc:
        return error(exc)
    emulator = DynamixelEmulator(
        rig.twin, faults=faults, directions=rig.directions, offsets=rig.offsets
    )
    with (
        RealtimeLoop(rig.twin, speed=float(getattr(args, "speed", 1.0))),
        PtyBusServer(emulator, link=getattr(args, "link", None)) as server,
    ):
        announce = [f"dynamixel bus on {server.path}"]
        if server.link:
            announce.append(f"dynamixel bus link {server.link}")
        log.info("%s", priority)
        return serve_until_interrupted(
            rig, args, announce, lambda: unanswered_ids(server, SERVED_IDS)
        )
