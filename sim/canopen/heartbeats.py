"""The served drives' heartbeats, produced on time by a process of their own.

A real drive's heartbeat comes from its own firmware on its own processor: it is never late
because the host, or anything else on the host's machine, is busy. The emulated drives share
one Python process with the twin, its camera and its hands: their heartbeats, produced by the
``canopen`` library (one python-can thread per node, ``send_periodic``) and written to the
pty by the SLCAN bridge's thread, need the process's GIL and its share of the CPU. On a
loaded machine both were late: at load 16-21 on 2 cores, heartbeats of 0.5 s came out up to
0.91 s apart as produced (0.93 s as written) and the host stopped on "no heartbeat" (0.75 s)
(``tests/stress/can_heartbeat.py ... -- --heartbeats threads``; docs/canopen_heartbeats.md).

So ``ergo twin serve --bus canopen`` produces them in a small process (``HeartbeatProducer``:
``python -S``, the standard library only, real-time priority where allowed, as the torque
guardian of ``robot.torque_guardian``) that writes each heartbeat's SLCAN line straight to
the adapter's pty (the bridge hands it the pty's descriptor; one ``write`` per line: a tty
never interleaves it with the bridge's own lines). The drives keep their state: the
``canopen`` library asks for a heartbeat as usual (``send_periodic`` on the drives'
network, ``sim.canopen.faulty``), and gets a ``HeartbeatTask`` that tells the producer the
node's period and NMT state byte (0x1017, boot-up, NMT commands, a stopped heartbeat: as
before). Heartbeats go out only while the host has the adapter open, as the bridge's frames.

The producer keeps, per node: heartbeats written, dropped (the pty full for ``WRITE_RETRY_S``:
the host not reading), late (a gap over ``LATE_FACTOR`` x the period) and the longest gap, in a
shared memory block that ``summary`` reads (``ergo twin serve``'s last log line).

``ergo twin serve --heartbeats threads`` leaves them to the serving process's threads (the
``canopen`` library's periodic tasks), for comparison; ``BridgeRecord`` then keeps the same
record of the heartbeats the bridge writes, with the gaps as produced and the wait between.
"""

from __future__ import annotations

import contextlib
import logging
import mmap
import os
import socket
import struct
import subprocess
import sys
import threading
import time
from collections.abc import Callable

log = logging.getLogger(__name__)

HEARTBEAT_BASE = 0x700  # COB-ID of a node's heartbeat: 0x700 + node id (CiA 301)
# The host's factor on the heartbeat time before a node counts as lost (CanArmConfig's
# heartbeat_factor default, 1.5): a written gap over it is "late".
LATE_FACTOR = 1.5
# The producer's real-time priority where allowed (SCHED_FIFO), as robot.signals' watcher and
# the torque guardian (guess: above every ordinary task, below the kernel's threaded
# interrupts at 50).
RT_PRIORITY = 10
# How long ``set_port(None)`` waits for the producer to close its copy of the pty, s (it does
# at once once it runs; a bound against a hang, long enough for a producer still starting up
# on a loaded machine).
ACK_S = 10.0
# How long the producer tries to write a heartbeat before it counts it dropped, s. The pty's
# descriptor is non-blocking (shared with the bridge), and a write finds the tty's write lock
# held whenever the bridge writes a line at that instant (EAGAIN from the kernel, not a full
# buffer): such a heartbeat was dropped while the host read everything, and the host stopped
# on it (0.75 s of silence, 1 heartbeat dropped in 976). A real adapter never drops a frame
# because the host writes to it. Retried every millisecond for this long (chosen: a tenth of
# the shortest heartbeat the tests give a drive, 0.1 s; a buffer full for longer is dropped).
WRITE_RETRY_S = 0.01
# Shared block: u32 real-time (1 when the producer got SCHED_FIFO), then per node id 0..127:
# u32 written, u32 dropped, u32 late, f32 longest gap (s).
_HEAD = struct.Struct("<I")
_NODE = struct.Struct("<IIIf")
_SHM_SIZE = _HEAD.size + 128 * _NODE.size

PRODUCER = r"""
import mmap, os, select, socket, struct, sys, time
sock_fd, shm_fd, rt = map(int, sys.argv[1:4])
factor = float(sys.argv[4])
RETRY_S = float(sys.argv[5])
sock = socket.socket(fileno=sock_fd)
shm = mmap.mmap(shm_fd, 0)
NODE = struct.Struct("<IIIf")
try:
    os.sched_setscheduler(0, os.SCHED_FIFO, os.sched_param(rt))
    struct.pack_into("<I", shm, 0, 1)
except (AttributeError, OSError):
    pass
master, is_open = None, False
nodes = {}  # node id -> [state byte, period s, next due, last written]
stats = {}  # node id -> [written, dropped, late, longest gap]
def close_master():
    global master
    if master is not None:
        os.close(master)
        master = None
def write(node, v, now):
    s = stats.setdefault(node, [0, 0, 0, 0.0])
    line = b"t%03X1%02X\r" % (0x700 + node, v[0])
    writable, end = False, time.monotonic() + RETRY_S
    while master is not None and not writable:
        try:
            if select.select([], [master], [], max(0.0, end - time.monotonic()))[1]:
                os.write(master, line)
                writable = True
        except BlockingIOError:
            pass  # the bridge holds the tty's write lock this instant: again in a moment
        except OSError:
            break
        if writable or time.monotonic() >= end:
            break
        time.sleep(0.001)
    if not writable:
        s[1] += 1
    else:
        s[0] += 1
        if v[3] is not None:
            gap = now - v[3]
            s[3] = max(s[3], gap)
            s[2] += gap > factor * v[1]
        v[3] = now
    NODE.pack_into(shm, 4 + node * NODE.size, s[0], s[1], s[2], s[3])
while True:
    now = time.monotonic()
    due = min((v[2] for v in nodes.values()), default=now + 1.0)
    ready = select.select([sock], [], [], max(0.0, due - now))[0]
    if ready:
        try:
            msg, fds, _, _ = socket.recv_fds(sock, 64, 1)
        except OSError:
            break
        if not msg:
            break
        kind = msg[:1]
        if kind == b"P":
            close_master()
            master = fds[0] if fds else None
        elif kind == b"U":
            close_master()
            for fd in fds:
                os.close(fd)
            sock.send(b"k")
        elif kind == b"O":
            is_open = msg[1:2] == b"\x01"
            for v in nodes.values():
                v[3] = None  # a new client: its gaps start afresh
        elif kind == b"H":
            node, state, period_ms = struct.unpack_from("<BBH", msg, 1)
            if period_ms:
                nodes[node] = [state, period_ms / 1000.0, time.monotonic(), None]
            else:
                nodes.pop(node, None)
        elif kind == b"S":
            node, state = struct.unpack_from("<BB", msg, 1)
            if node in nodes:
                nodes[node][0] = state
        continue
    now = time.monotonic()
    for node, v in list(nodes.items()):
        if v[2] > now:
            continue
        v[2] += v[1]
        if v[2] <= now:  # behind by more than a period: no burst, the next one a period on
            v[2] = now + v[1]
        if is_open and master is not None:
            write(node, v, now)
close_master()
"""


class HeartbeatTask:
    """What ``canopen``'s NMT slave holds for a node's heartbeat (as python-can's periodic
    task): ``update`` the state byte, ``stop``."""

    def __init__(self, producer: HeartbeatProducer, node: int) -> None:
        self.producer = producer
        self.node = node

    def update(self, data: bytes) -> None:
        self.producer.send(b"S" + struct.pack("<BB", self.node, bytes(data)[0]))

    def stop(self) -> None:
        self.producer.send(b"H" + struct.pack("<BBH", self.node, 0, 0))


class HeartbeatProducer:
    """The process that writes the drives' heartbeats to the adapter's pty.

    Args:
        late_factor: a written gap over this times the period counts as late.
        rt_priority: SCHED_FIFO priority to take where allowed.
    """

    def __init__(self, late_factor: float = LATE_FACTOR, rt_priority: int = RT_PRIORITY) -> None:
        self.late_factor = late_factor
        self._shm_fd = os.memfd_create("ergo-heartbeats", os.MFD_CLOEXEC)
        os.ftruncate(self._shm_fd, _SHM_SIZE)
        self._shm = mmap.mmap(self._shm_fd, 0)
        self._sock, child = socket.socketpair(socket.AF_UNIX, socket.SOCK_SEQPACKET)
        self._lock = threading.Lock()
        try:
            self.process = subprocess.Popen(
                [sys.executable, "-S", "-c", PRODUCER, str(child.fileno()),
                 str(self._shm_fd), str(rt_priority), repr(late_factor), repr(WRITE_RETRY_S)],
                pass_fds=(child.fileno(), self._shm_fd),
                stdin=subprocess.DEVNULL,
            )  # fmt: skip
        finally:
            child.close()

    # ---- what the drives and the bridge tell it --------------------------------------------
    def send(self, message: bytes, fds: tuple[int, ...] = ()) -> None:
        """One message to the producer (never raises: a producer gone is logged once)."""
        with self._lock:
            try:
                socket.send_fds(self._sock, [message], list(fds))
            except OSError as exc:
                log.debug("heartbeat producer: %s", exc)

    def task(self, node: int, data: bytes, period_s: float) -> HeartbeatTask:
        """Start node ``node``'s heartbeat (state byte ``data[0]``, every ``period_s``): the
        first at once, as python-can's periodic task."""
        period_ms = max(1, min(0xFFFF, round(period_s * 1000)))
        self.send(b"H" + struct.pack("<BBH", node, bytes(data)[0], period_ms))
        return HeartbeatTask(self, node)

    def set_port(self, master: int | None) -> None:
        """The pty's master descriptor to write to (a copy is sent), or None: unplugged; then
        returns once the producer closed its copy (the pty must close with the bridge's)."""
        if master is not None:
            self.send(b"P", (master,))
            return
        with self._lock:
            try:
                self._sock.send(b"U")
                self._sock.settimeout(ACK_S)
                self._sock.recv(1)
            except OSError as exc:  # the pty may stay open while the producer holds it
                log.warning("heartbeat producer did not let go of the pty: %s", exc)
            finally:
                self._sock.settimeout(None)

    def set_open(self, is_open: bool) -> None:
        """Whether the host has the adapter open (heartbeats go out only then)."""
        self.send(b"O" + (b"\x01" if is_open else b"\x00"))

    # ---- what it did -----------------------------------------------------------------------
    @property
    def realtime(self) -> bool:
        """Whether the producer runs at a real-time priority."""
        return bool(_HEAD.unpack_from(self._shm, 0)[0])

    def stats(self) -> dict[int, tuple[int, int, int, float]]:
        """Per node that sent any: (written, dropped, late, longest gap s)."""
        out = {}
        for node in range(128):
            row = _NODE.unpack_from(self._shm, _HEAD.size + node * _NODE.size)
            if row[0] or row[1]:
                out[node] = row
        return out

    def summary(self) -> str:
        """One line: heartbeats written, dropped, late, the longest gap, the priority."""
        rows = self.stats().values()
        if not rows:
            return "drives' heartbeats: none written to the host"
        return (
            f"drives' heartbeats: {sum(r[0] for r in rows)} written to the host, "
            f"{sum(r[1] for r in rows)} dropped (the pty full), {sum(r[2] for r in rows)} late "
            f"(a gap over {self.late_factor} x the heartbeat time); longest gap "
            f"{max(r[3] for r in rows):.3f} s; producer at "
            f"{'a real-time' if self.realtime else 'an ordinary'} priority"
        )

    def stop(self) -> None:
        """End the producer (closing its socket ends it) and wait for it."""
        with self._lock, contextlib.suppress(OSError):
            self._sock.close()
        try:
            self.process.wait(timeout=ACK_S)
        except subprocess.TimeoutExpired:
            self.process.kill()
            self.process.wait()
        with contextlib.suppress(BufferError, ValueError):
            self._shm.close()
        with contextlib.suppress(OSError):
            os.close(self._shm_fd)

    def __enter__(self) -> HeartbeatProducer:
        return self

    def __exit__(self, *exc: object) -> None:
        self.stop()


class BridgeRecord:
    """The record of the heartbeats the SLCAN bridge writes to the host (``--heartbeats
    threads``): per node, written gaps over ``late_factor`` x its period, the longest gap as
    written and as produced (python-can's stamp on the drives' bus), the longest wait in
    between.

    Args:
        period_s: the heartbeat time a node produces now, s, by node id.
        late_factor: a written gap over this times the period counts as late.
    """

    def __init__(self, period_s: Callable[[int], float], late_factor: float = LATE_FACTOR) -> None:
        self.period_s = period_s
        self.late_factor = late_factor
        self.last: dict[int, tuple[float, float]] = {}  # node -> (produced, written), wall s
        self.written = self.late = 0
        self.longest = self.longest_produced = self.wait = 0.0
        self._lock = threading.Lock()

    def reset(self) -> None:
        """No client: the next one's gaps start afresh."""
        with self._lock:
            self.last.clear()

    def record(self, can_id: int, produced_at: float) -> None:
        """A frame written to the host now; counted if it is a heartbeat (``produced_at``:
        its stamp on the drives' bus, wall s)."""
        node = can_id - HEARTBEAT_BASE
        if not 1 <= node <= 127:
            return
        now = time.time()
        with self._lock:
            self.written += 1
            self.wait = max(self.wait, now - produced_at)
            if node in self.last:
                produced, written = self.last[node]
                gap = now - written
                self.longest = max(self.longest, gap)
                self.longest_produced = max(self.longest_produced, produced_at - produced)
                self.late += gap > self.late_factor * self.period_s(node)
            self.last[node] = (produced_at, now)

    def summary(self) -> str:
        return (
            f"drives' heartbeats (the serving process's threads): {self.written} written to the "
            f"host, {self.late} late (a gap over {self.late_factor} x the heartbeat time); "
            f"longest gap {self.longest:.3f} s as written, {self.longest_produced:.3f} s as "
            f"produced; longest wait in the emulator {self.wait:.3f} s"
        )
