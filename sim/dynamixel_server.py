"""``ergo twin serve --bus dynamixel``: the twin behind a real serial port (a pseudo-terminal)
speaking Dynamixel Protocol 2.0 as six XL-320, and its overhead camera as an MJPEG stream.

    $ ergo twin serve --bus dynamixel
    dynamixel bus on /dev/pts/7
    camera on http://127.0.0.1:41234/stream.mjpg

Any program that drives a real Ergo Jr through a serial port then drives the twin, e.g.
``ergo bus scan --port /dev/pts/7`` or a ``dynamixel`` rig with ``port: /dev/pts/7`` and
``camera: http://127.0.0.1:41234/stream.mjpg``. The twin runs in real time
(``sim.realtime.RealtimeLoop``); faults are injected from the flags (see ``sim/cli.py``).
"""

from __future__ import annotations

import argparse
import contextlib
import logging
import os
import select
import sys
import termios
import threading
import time
import tty

from sim.dynamixel_emulator import DEFAULT_OVERLOAD_AFTER_S, DynamixelEmulator, FaultConfig

log = logging.getLogger(__name__)

# How often the serving loop wakes up to check for stop, s (not a protocol figure).
POLL_S = 0.05


class PtyBusServer:
    """Serves a ``DynamixelEmulator`` on a new pseudo-terminal.

    ``path`` is the slave side to open with pyserial (e.g. ``/dev/pts/7``). The server keeps its
    own slave descriptor open, so clients may come and go without the pty closing.

    ``unplug()`` closes the pty as a USB adapter pulled out would (the client's next read or
    write fails with EIO); ``replug()`` opens a new one, whose path differs. With ``link`` the
    server keeps a symbolic link at that path pointing to the current pty (a stable name, as
    ``/dev/serial/by-id/...`` is for a real adapter), so a client can reopen it by name.

    Args:
        emulator: who answers.
        link: path of a symbolic link to the current pty (None: no link).
    """

    def __init__(self, emulator: DynamixelEmulator, link: str | os.PathLike[str] | None = None):
        self.emulator = emulator
        self.link = None if link is None else os.fspath(link)
        self._fd_lock = threading.Lock()
        self._master: int | None = None
        self._slave: int | None = None
        self.path = ""
        self._open_pty()
        self._stop = threading.Event()
        self._thread: threading.Thread | None = None
        self.bytes_in = 0
        self.bytes_out = 0
        self.unplugs = 0

    @property
    def port(self) -> str:
        """What a client should open: the link when there is one, else the pty itself."""
        return self.link or self.path

    @property
    def plugged(self) -> bool:
        return self._master is not None

    def _open_pty(self) -> None:
        master, slave = os.openpty()
        tty.setraw(slave, termios.TCSANOW)  # no echo, no line discipline: bytes as sent
        tty.setraw(master, termios.TCSANOW)
        with self._fd_lock:
            self._master, self._slave = master, slave
            self.path = os.ttyname(slave)
        if self.link is not None:
            tmp = f"{self.link}.{os.getpid()}.tmp"
            with contextlib.suppress(FileNotFoundError):
                os.unlink(tmp)
            os.symlink(self.path, tmp)
            os.replace(tmp, self.link)  # atomic: a client never sees the link missing

    def unplug(self) -> None:
        """Close the pty, as an adapter pulled out of its USB socket."""
        with self._fd_lock:
            fds, self._master, self._slave = (self._master, self._slave), None, None
        for fd in fds:
            if fd is not None:
                with contextlib.suppress(OSError):
                    os.close(fd)
        self.unplugs += 1

    def replug(self) -> None:
        """Open a new pty (a new path; the link, if any, follows it)."""
        if self._master is None:
            self._open_pty()

    def serve_forever(self) -> None:
        """Answer packets until ``stop()`` (call from any thread) or KeyboardInterrupt."""
        while not self._stop.is_set():
            master = self._master
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
        self.unplug()
        self.unplugs -= 1
        if self.link is not None:
            with contextlib.suppress(OSError):
                if os.path.islink(self.link):
                    os.unlink(self.link)

    def __enter__(self) -> PtyBusServer:
        self.start()
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()


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
    from sim.realtime import RealtimeLoop
    from sim.twin import Twin

    try:
        faults = faults_from_args(args)
    except ValueError as exc:
        print(f"ergo: error: {exc}", file=sys.stderr)
        return 2
    if faults.overload_servo is not None and not 1 <= faults.overload_servo <= 6:
        print(
            f"ergo: error: --overload-servo {faults.overload_servo} is not in 1..6", file=sys.stderr
        )
        return 2
    twin = Twin()
    emulator = DynamixelEmulator(twin, faults=faults)
    with (
        RealtimeLoop(twin, speed=float(getattr(args, "speed", 1.0))),
        PtyBusServer(emulator, link=getattr(args, "link", None)) as server,
    ):
        from sim.mjpeg_server import serve_until_interrupted

        announce = [f"dynamixel bus on {server.path}"]
        if server.link:
            announce.append(f"dynamixel bus link {server.link}")
        return serve_until_interrupted(twin, args, announce)
