"""``ergo twin serve --bus canopen``: the twin as six CiA 402 drives on a CAN bus, reached
through an SLCAN adapter emulated on a pseudo-terminal (and its camera as an MJPEG stream).

    $ ergo twin serve --bus canopen
    canopen bus (slcan) on /dev/pts/7
    camera on http://127.0.0.1:41234/stream.mjpg

The pty behaves like a CANable (SLCAN firmware) on /dev/ttyACM0: any python-can program opens
it as ``slcan:/dev/pts/7``, e.g. ``ergo bus scan --can slcan:/dev/pts/7`` or a ``canopen`` rig
with ``can: slcan:/dev/pts/7`` and ``camera: http://127.0.0.1:41234/stream.mjpg``.

Inside, the SLCAN adapter (``sim.canopen.slcan``) is bridged to python-can's in-process
``virtual`` bus on which the emulated drives (``sim.canopen.drives``) live; the twin runs in
real time (``sim.realtime.RealtimeLoop``). The served twin, its camera and its hands (and, with
``--stand-in SEED``, a rig the software has never seen) come from ``sim.standin.served``.
Faults come from the flags of ``sim/cli.py``: ``--drop-rate`` loses PDO/SYNC frames,
``--delay-ms`` delays the TPDOs, ``--overload-servo ID`` makes that node fault with a following
error (EMCY 0x8611) after some time enabled.
``--corrupt-rate`` does not apply: on CAN a corrupted frame fails its CRC and is retransmitted
by the controller (ISO 11898-1), so the host never sees it.
"""

from __future__ import annotations

import argparse
import contextlib
import fcntl
import logging
import os
import select
import struct
import sys
import termios
import threading
import time
from collections.abc import Sequence
from typing import TYPE_CHECKING, Any

from plumbing.cli_errors import error
from sim.canopen.heartbeats import BridgeRecord, HeartbeatProducer
from sim.canopen.slcan import CanFrame, LineSplitter, SlcanAdapter, SlcanError, encode_frame
from sim.pty_port import OnPty, PtyPort

if TYPE_CHECKING:
    from sim.canopen.drives import EmulatedDrives
    from sim.standin.served import ServedRig

log = logging.getLogger(__name__)

# How often the threads wake up to check for stop, s (not a protocol figure).
POLL_S = 0.05
# Seconds a node stays in OPERATION ENABLED before ``--overload-servo`` trips it (guess: long
# enough for a connect and a few moves).
DEFAULT_OVERLOAD_AFTER_S = 2.0


class SlcanPtyBridge(OnPty):
    """An SLCAN adapter on a new pseudo-terminal (``sim.pty_port.PtyPort``), bridged to a
    python-can bus.

    The host writes SLCAN lines to ``path``; frames it transmits go onto ``bus``; frames on
    ``bus`` are written back as SLCAN lines while the adapter is open. Clients may come and go;
    frames left unread by a client that died with the channel open are flushed when the next one
    sends ``C``. ``unplug()`` and ``replug()`` pull the adapter out and plug it back (a new
    path; the adapter closed, as at power-on); with ``link``, ``slcan:LINK`` follows it.

    Args:
        bus: a python-can bus (the emulated drives' side).
        link: path of a symbolic link to the current pty (None: no link).
    """

    def __init__(
        self,
        bus: Any,
        link: str | os.PathLike[str] | None = None,
        heartbeats: HeartbeatProducer | None = None,
        record: BridgeRecord | None = None,
    ) -> None:
        self.bus = bus
        self.heartbeats = heartbeats
        self.record = record
        self.adapter = SlcanAdapter()
        self._splitter = LineSplitter()
        self.pty = PtyPort(link, on_open=self._power_on)
        if heartbeats is not None:
            heartbeats.set_port(self.pty.master)
        self._write_lock = threading.Lock()
        self._stop = threading.Event()
        self._threads: list[threading.Thread] = []
        self.frames_in = 0  # host -> bus
        self.frames_out = 0  # bus -> host
        self.frames_dropped = 0  # bus -> host, pty full or adapter closed

    def _power_on(self) -> None:
        self.adapter = SlcanAdapter()  # a freshly plugged adapter starts closed
        self._splitter = LineSplitter()
        if self.heartbeats is not None:
            self.heartbeats.set_open(False)

    def unplug(self) -> None:
        """Close the pty, as an adapter pulled out of its USB socket (the heartbeat producer's
        copy of it first)."""
        if self.heartbeats is not None:
            self.heartbeats.set_port(None)
        self.pty.unplug()

    def replug(self) -> None:
        """Open a new pty (a new path; the link, if any, follows it)."""
        self.pty.replug()
        if self.heartbeats is not None and self.pty.master is not None:
            self.heartbeats.set_port(self.pty.master)

    # ---- lifecycle -------------------------------------------------------------------------
    def start(self) -> None:
        if self._threads:
            return
        self._stop.clear()
        for target, name in ((self._host_to_bus, "slcan-rx"), (self._bus_to_host, "slcan-tx")):
            t = threading.Thread(target=target, name=name, daemon=True)
            t.start()
            self._threads.append(t)

    def stop(self) -> None:
        self._stop.set()
        for t in self._threads:
            t.join(timeout=2.0)
        self._threads.clear()

    def close(self) -> None:
        self.stop()
        if self.heartbeats is not None:
            self.heartbeats.set_port(None)
        self.pty.close()

    def __enter__(self) -> SlcanPtyBridge:
        self.start()
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()

    # ---- threads ---------------------------------------------------------------------------
    def _write(self, data: bytes, drop_if_full: bool) -> bool:
        """Write whole lines to the host; with ``drop_if_full`` give up (whole) when the pty is
        full, so a host that stopped reading never blocks the bus."""
        with self._write_lock:
            master = self.pty.master
            if master is None:  # unplugged
                return False
            try:
                if drop_if_full:
                    _, writable, _ = select.select([], [master], [], 0)
                    if not writable:
                        return False
                os.write(master, data)
            except (OSError, ValueError):
                return False
        return True

    def backlog(self) -> bool:
        """Whether bytes from the host wait unread in the pty."""
        master, _ = self.pty.fds()
        if master is None:
            return False
        try:
            return struct.unpack("i", fcntl.ioctl(master, termios.FIONREAD, b"\0" * 4))[0] > 0
        except OSError:
            return False

    def _host_to_bus(self) -> None:
        import can

        while not self._stop.is_set():
            master, slave = self.pty.fds()
            if master is None or slave is None:  # unplugged
                time.sleep(POLL_S)
                continue
            try:
                ready, _, _ = select.select([master], [], [], POLL_S)
                if not ready:
                    continue
                chunk = os.read(master, 4096)
            except (OSError, ValueError):  # EIO without a client; EBADF once unplugged
                time.sleep(POLL_S)
                continue
            for line in self._splitter.feed(chunk):
                was_open = self.adapter.is_open
                reply, frame = self.adapter.handle(line)
                if self.heartbeats is not None and self.adapter.is_open != was_open:
                    self.heartbeats.set_open(self.adapter.is_open)
                if was_open and line is not None and line[:1] == b"C":
                    # A client opening the port sends C first (python-can's slcanBus does, before
                    # it reads anything): frames queued for a client that died with the channel
                    # open are dropped here. Only then: flushing while a client is between its
                    # select() and read() makes pyserial raise "device reports readiness to
                    # read but returned no data" (seen when O also flushed).
                    with contextlib.suppress(termios.error):
                        termios.tcflush(slave, termios.TCIFLUSH)
                if frame is not None:
                    msg = can.Message(
                        arbitration_id=frame.can_id,
                        data=frame.data,
                        is_extended_id=frame.extended,
                        is_remote_frame=frame.remote,
                        dlc=frame.dlc,
                    )
                    try:
                        self.bus.send(msg)
                        self.frames_in += 1
                    except can.CanError as exc:
                        log.warning("slcan bridge: frame not sent: %s", exc)
                        reply = b"\a"
                self._write(reply, drop_if_full=False)

    def _bus_to_host(self) -> None:
        while not self._stop.is_set():
            msg = self.bus.recv(timeout=POLL_S)
            if msg is None or msg.is_error_frame:
                continue
            if not self.adapter.is_open:
                self.frames_dropped += 1
                if self.record is not None:
                    self.record.reset()
                continue
            try:
                frame = CanFrame(
                    msg.arbitration_id,
                    b"" if msg.is_remote_frame else bytes(msg.data),
                    msg.is_extended_id,
                    msg.is_remote_frame,
                    msg.dlc,
                )
            except SlcanError as exc:
                log.warning("slcan bridge: frame not representable: %s", exc)
                continue
            if self._write(encode_frame(frame), drop_if_full=True):
                self.frames_out += 1
                if self.record is not None:
                    self.record.record(msg.arbitration_id, msg.timestamp)
            else:
                self.frames_dropped += 1


# How long the start-up check waits for each node's SDO answer, s: a sixth of the python
# canopen library's SDO timeout (0.3 s, ``canopen.sdo.SdoClient.RESPONSE_TIMEOUT``), so that a
# client's first SDO right after the bus's line is answered well within its own. Guess.
READY_SDO_S = 0.05
# SDO upload request (CiA 301: command 0x40) of the device type, object 0x1000 sub 0
SDO_READ_DEVICE_TYPE = bytes([0x40, 0x00, 0x10, 0x00, 0, 0, 0, 0])


def unanswered_nodes(bridge: SlcanPtyBridge, ids: Sequence[int]) -> list[int]:
    """The node ids whose drive did not answer one SDO read of its device type each (no retry,
    ``READY_SDO_S``) through ``bridge``'s pty, opened as a client opens it (``slcan:PATH``)."""
    import can

    from robot.canopen.bus import CanBusError, open_bus

    try:
        bus = open_bus(f"slcan:{bridge.path}")
    except CanBusError:
        return list(ids)
    silent = []
    try:
        for i in ids:
            bus.send(can.Message(arbitration_id=0x600 + i, data=SDO_READ_DEVICE_TYPE,
                                 is_extended_id=False))  # fmt: skip
            deadline = time.monotonic() + READY_SDO_S
            while (left := deadline - time.monotonic()) > 0:
                msg = bus.recv(timeout=left)
                if msg is not None and msg.arbitration_id == 0x580 + i:
                    break
            else:
                silent.append(i)
    except can.CanError:
        return list(ids)
    finally:
        bus.shutdown()
    return silent


def drives_for(rig: ServedRig, bus: str, **options: Any) -> EmulatedDrives:
    """The served rig's six drives on ``bus`` (``INTERFACE:CHANNEL``), mounted as its hidden
    mounting says (their zero marks ``rig.can_offsets``); ``options`` go to
    ``EmulatedDrives`` (faults)."""
    from sim.canopen.drives import EmulatedDrives

    # the drives' convention: joint = offset + direction * drive angle (robot.canopen.units)
    offsets = -rig.directions * rig.can_offsets
    return EmulatedDrives(rig.twin, bus, directions=rig.directions, offsets=offsets, **options)


def serve(args: argparse.Namespace) -> int:
    """Serve until interrupted (SIGINT/SIGTERM); returns the exit code. Prints the pty path and
    the camera URL, one line each, flushed, so that a parent process can read them."""
    import signal

    import can

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
    drop_rate = float(getattr(args, "drop_rate", 0.0) or 0.0)
    delay_ms = float(getattr(args, "delay_ms", 0.0) or 0.0)
    overload = getattr(args, "overload_servo", None)
    if not 0.0 <= drop_rate < 1.0:
        return error(f"--drop-rate {drop_rate} is not in [0, 1)")
    if delay_ms < 0:
        return error(f"--delay-ms {delay_ms} is negative")
    if overload is not None and not 1 <= overload <= 6:
        return error(f"--overload-servo {overload} is not a node id in 1..6")
    if float(getattr(args, "corrupt_rate", 0.0) or 0.0) > 0:
        print(
            "ergo: warning: --corrupt-rate ignored on CAN (the CRC rejects a corrupted frame and "
            "the controller retransmits it)",
            file=sys.stderr,
        )

    try:
        rig = open_served_rig(args)
    except StandinError as exc:
        return error(exc)

    def _terminate(signum: int, _frame: object) -> None:
        raise KeyboardInterrupt

    previous = signal.signal(signal.SIGTERM, _terminate)
    channel = f"ergo-canopen-{os.getpid()}"
    twin = rig.twin
    # the drives' heartbeats on time (sim.canopen.heartbeats); "threads": the serving process's
    threads = getattr(args, "heartbeats", "process") == "threads"
    producer = None if threads else HeartbeatProducer()
    drives = drives_for(
        rig,
        f"virtual:{channel}",
        heartbeats=None if producer is None else producer.task,
        drop_rate=drop_rate,
        tpdo_delay_s=delay_ms / 1000.0,
        seed=int(getattr(args, "seed", 0) or 0),
    )
    if overload is not None:
        after = float(getattr(args, "overload_after_s", DEFAULT_OVERLOAD_AFTER_S))
        drives.schedule_following_error(int(overload), after)
    bridge_bus = can.Bus(interface="virtual", channel=channel)
    record = (
        BridgeRecord(lambda node: drives.drive(node).od_int(0x1017) / 1000) if threads else None
    )
    try:
        with (
            RealtimeLoop(twin, speed=float(getattr(args, "speed", 1.0) or 1.0)),
            drives,
            SlcanPtyBridge(bridge_bus, getattr(args, "link", None), producer, record) as bridge,
        ):
            drives.host_backlog = bridge.backlog
            announce = [f"canopen bus (slcan) on {bridge.path}"]
            if bridge.link:
                announce.append(f"canopen bus link {bridge.link}")
            log.info("%s", priority)
            return serve_until_interrupted(
                rig, args, announce, lambda: unanswered_nodes(bridge, SERVED_IDS)
            )
    finally:
        if producer is not None:
            log.info("%s", producer.summary())
            producer.stop()
        if record is not None:
            log.info("%s", record.summary())
        bridge_bus.shutdown()
        signal.signal(signal.SIGTERM, previous)


def main(argv: list[str] | None = None) -> int:
    """``python -m sim.canopen.server [--speed S] [--drop-rate P] ...`` without the ``ergo``
    command (tests and benchmarks start it like this)."""
    p = argparse.ArgumentParser(prog="python -m sim.canopen.server")
    p.add_argument("--speed", type=float, default=1.0)
    p.add_argument("--drop-rate", type=float, default=0.0)
    p.add_argument("--delay-ms", type=float, default=0.0)
    p.add_argument("--overload-servo", type=int, default=None)
    p.add_argument("--overload-after-s", type=float, default=DEFAULT_OVERLOAD_AFTER_S)
    p.add_argument("--seed", type=int, default=0)
    p.add_argument("--link", default=None, help="keep a symbolic link to the pty at this path")
    p.add_argument("--camera-port", type=int, default=0)
    p.add_argument("--no-camera", action="store_true")
    p.add_argument("--hands-port", type=int, default=0)
    p.add_argument("--stand-in", type=int, default=None, metavar="SEED")
    p.add_argument("--hidden", default=None, metavar="PATH")
    p.add_argument("--zero-marks", default="horn", choices=("horn", "anywhere"))
    p.add_argument("--heartbeats", default="process", choices=("process", "threads"))
    return serve(p.parse_args(argv))


if __name__ == "__main__":
    logging.basicConfig(level=logging.WARNING, format="%(levelname)s %(name)s: %(message)s")
    sys.exit(main())
