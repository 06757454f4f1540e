"""A torque-off that does not wait for the GIL: a guardian process that writes the bytes cutting
torque on a serial bus (a Dynamixel port, an SLCAN adapter) the moment a signal arrives.

Why a process: ``robot.signals`` wakes a watcher thread from the C-level signal handler, but
that thread still needs the GIL to run, and on a loaded machine the thread holding the GIL may
be waiting for a CPU for hundreds of ms (measured: a SIGINT answered 580 ms late at load 8 on
2 cores, the child at nice 10). A separate process has its own interpreter: it needs nothing
of the arm's process but a pipe and the bytes to write.

- The arm keeps the bytes that cut torque, exactly as its own torque-off would send them first,
  in a shared buffer (``EmergencyPayload``, a memfd with a sequence lock): constant for a
  Dynamixel bus (a broadcast WRITE of Torque Enable = 0), refreshed every cycle for CANopen
  (RPDO1 with "disable voltage", which leaves no CiA 402 state with the power stage on, and
  the current targets, then a SYNC).
- ``Guardian`` starts ``python -S -c GUARDIAN`` (standard library only, about 20 ms), which
  opens the port by its path (a second descriptor on the same device: the arm's own is
  untouched), takes a real-time priority where allowed, and blocks on a pipe. The arm's
  process makes that pipe its signal wakeup fd (``signal.set_wakeup_fd``): the C-level handler
  writes the signal number into it without the GIL. The guardian writes the payload to the port
  (one ``write``: a tty never interleaves it with the arm's own writes), stamps the time in the
  shared buffer, then passes the signal number on to the watcher thread (which confirms the
  torque-off the usual way). A SIGINT or SIGTERM sent to the guardian itself (Ctrl-C reaches the
  whole process group) does the same.
- The guardian ends when the pipe closes. When the block of ``torque_off_on_signals`` ends,
  ``Guardian.stop`` first writes ``DONE`` to the pipe (the arm's own torque-off follows): the
  guardian exits writing nothing. When the pipe closes without it, the arm's process died
  without its torque-off (SIGKILL, an OOM kill, a crash in a native library): the guardian
  writes the payload ``DEATH_WRITES`` times, ``DEATH_SPACING_S`` apart, then exits. Unless
  the user chose to hold (``on_death="hold"``, the rigs' option ``on_crash=hold``): then it
  writes nothing, and the servos keep their last target (on CANopen the drives' own heartbeat
  consumer is off too, ``robot.canopen.guard``).

On a real half-duplex bus the guardian's packet can collide with a servo's reply in progress;
the watcher's confirmed torque-off follows in any case.
"""

from __future__ import annotations

import contextlib
import logging
import mmap
import os
import struct
import subprocess
import sys
from dataclasses import dataclass

log = logging.getLogger(__name__)

# Shared buffer: u32 sequence (odd while being written), u32 length, f64 when the guardian last
# wrote the payload (time.monotonic, 0 before), then the payload.
_HEADER = struct.Struct("<IId")
PAYLOAD_CAPACITY = 4096  # bytes: 6 SLCAN RPDO lines and a SYNC take about 130
# The byte ``Guardian.stop`` writes before closing the pipe: the arm's process ends the block
# itself (a signal number is at most 64, so it is never one).
DONE = 0xFF
# What a guardian does when the arm's process dies without DONE: "limp" writes the payload,
# "hold" writes nothing (the servos keep their last target).
ON_DEATH = ("limp", "hold")
# After a death the payload is written this many times, this far apart, s: the dead process
# may have left half a packet (or an SLCAN line) on the port, which can swallow the first copy
# into a frame the receiver drops; the next copies then arrive whole (guess: the longest
# packet of the arm, a SYNC WRITE of six goals, is under 50 bytes, two copies of the payload).
DEATH_WRITES = 3
DEATH_SPACING_S = 0.02
# How long ending the block waits for the guardian to exit after its pipe closed, s (it exits
# at once; a bound against a hang).
GUARDIAN_EXIT_S = 1.0

GUARDIAN = r"""
import mmap, os, signal, struct, sys, time
port, shm_fd, pipe_fd, forward_fd, rt, on_death = sys.argv[1], *map(int, sys.argv[2:7])
H = struct.Struct("<IId")
DONE, WRITES, SPACING = @CONSTANTS@
shm = mmap.mmap(shm_fd, 0)
try:
    os.sched_setscheduler(0, os.SCHED_FIFO, os.sched_param(rt))
except (AttributeError, OSError):
    pass
FLAGS = os.O_WRONLY | os.O_NOCTTY | os.O_NONBLOCK | os.O_CLOEXEC
def open_port():
    try:
        return os.open(port, FLAGS)
    except OSError:
        return None
fd = open_port()
def payload():
    for _ in range(10000):  # the arm's process rewrites it in microseconds
        seq, n, _ = H.unpack_from(shm, 0)
        data = bytes(shm[H.size:H.size + n])
        if seq % 2 == 0 and H.unpack_from(shm, 0)[0] == seq:
            return data
    return data
def cut():
    global fd
    data = payload()
    if not data:
        return
    for attempt in (0, 1):
        if fd is None:
            fd = open_port()
        if fd is not None:
            try:
                os.write(fd, data)
                struct.pack_into("<d", shm, 8, time.monotonic())
                return
            except OSError:
                os.close(fd)
                fd = None
def on_signal(signum, frame):
    cut()
signal.signal(signal.SIGINT, on_signal)
signal.signal(signal.SIGTERM, on_signal)
print("ready", flush=True)
done = False
while True:
    try:
        data = os.read(pipe_fd, 64)
    except InterruptedError:
        continue
    if not data:
        break
    if DONE in data:
        done = True
        data = data.replace(bytes([DONE]), b"")
    if any(b in (signal.SIGINT, signal.SIGTERM) for b in data):
        cut()
    if data:
        try:
            os.write(forward_fd, data)
        except OSError:
            pass
if not done and on_death:
    for k in range(WRITES):
        if k:
            time.sleep(SPACING)
        cut()
"""

SCRIPT = GUARDIAN.replace("@CONSTANTS@", f"{DONE}, {DEATH_WRITES}, {DEATH_SPACING_S!r}")


class EmergencyPayload:
    """The bytes that cut torque, shared with a guardian process (a memfd).

    Args:
        port: the device the guardian writes them to (a path: ``/dev/ttyUSB0``, a pty or a
            stable link to one).
        data: the first payload.
    """

    def __init__(self, port: str, data: bytes = b"") -> None:
        self.port = port
        self.fd = os.memfd_create("ergo-torque-off", os.MFD_CLOEXEC)
        os.ftruncate(self.fd, _HEADER.size + PAYLOAD_CAPACITY)
        self._shm = mmap.mmap(self.fd, 0)
        self._seq = 0
        self.set(data)

    def set(self, data: bytes) -> None:
        """Replace the payload (the guardian never reads a half-written one)."""
        if len(data) > PAYLOAD_CAPACITY:
            raise ValueError(f"torque-off payload of {len(data)} bytes > {PAYLOAD_CAPACITY}")
        shm = self._shm
        self._seq += 1  # odd: being written
        struct.pack_into("<I", shm, 0, self._seq)
        struct.pack_into("<I", shm, 4, len(data))
        shm[_HEADER.size : _HEADER.size + len(data)] = data
        self._seq += 1
        struct.pack_into("<I", shm, 0, self._seq)

    def get(self) -> bytes:
        _, n, _ = _HEADER.unpack_from(self._shm, 0)
        return bytes(self._shm[_HEADER.size : _HEADER.size + n])

    @property
    def sent_at(self) -> float | None:
        """When a guardian last wrote the payload (time.monotonic), or None."""
        t = struct.unpack_from("<d", self._shm, 8)[0]
        return t or None

    def clear_sent(self) -> None:
        struct.pack_into("<d", self._shm, 8, 0.0)

    def close(self) -> None:
        with contextlib.suppress(BufferError, ValueError):
            self._shm.close()
        with contextlib.suppress(OSError):
            os.close(self.fd)


@dataclass
class Guardian:
    """A running guardian process. ``wakeup_fd``: the pipe to give ``signal.set_wakeup_fd``."""

    process: subprocess.Popen
    wakeup_fd: int
    payload: EmergencyPayload

    @classmethod
    def start(
        cls, payload: EmergencyPayload, forward_fd: int, rt_priority: int, on_death: str = "limp"
    ) -> Guardian:
        """Start one for ``payload``; it passes each signal number on to ``forward_fd``, and
        when the arm's process dies without ``stop`` it writes the payload (``on_death``
        "limp") or nothing ("hold"). Raises OSError when it cannot start."""
        if on_death not in ON_DEATH:
            raise ValueError(f"on_death must be one of {ON_DEATH}, got {on_death!r}")
        read_fd, write_fd = os.pipe()
        try:
            os.set_blocking(write_fd, False)  # set_wakeup_fd needs a non-blocking fd
            fds = (payload.fd, read_fd, forward_fd)
            args = [payload.port, *map(str, fds), str(rt_priority), str(int(on_death == "limp"))]
            proc = subprocess.Popen(
                [sys.executable, "-S", "-c", SCRIPT, *args],
                pass_fds=fds, stdin=subprocess.DEVNULL, stdout=subprocess.PIPE,
            )  # fmt: skip
        except BaseException:
            os.close(write_fd)
            os.close(read_fd)
            raise
        os.close(read_fd)
        ready = proc.stdout.readline() if proc.stdout is not None else b""
        if ready.strip() != b"ready":
            os.close(write_fd)
            proc.kill()
            proc.wait()
            raise OSError(f"torque-off guardian did not start (exit {proc.poll()})")
        payload.clear_sent()
        return cls(proc, write_fd, payload)

    def stop(self) -> None:
        """Tell it the arm's process ends the block itself (``DONE``), close its pipe and wait
        for it to exit (killed past ``GUARDIAN_EXIT_S``)."""
        with contextlib.suppress(OSError):
            os.write(self.wakeup_fd, bytes([DONE]))
        with contextlib.suppress(OSError):
            os.close(self.wakeup_fd)
        try:
            self.process.wait(timeout=GUARDIAN_EXIT_S)
        except subprocess.TimeoutExpired:
            self.process.kill()
            self.process.wait()
        if self.process.stdout is not None:
            self.process.stdout.close()


def serial_path(port: str) -> str | None:
    """The device path of a serial port name, or None for what a guardian cannot open (a
    pyserial URL such as ``loop://``, or an empty name)."""
    if not port or "://" in port:
        return None
    return port
