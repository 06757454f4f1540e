"""A pseudo-terminal proxy that injects wire faults between a host and a serial device.

The device is anything on a tty path (the Dynamixel emulator's or the SLCAN bridge's pty,
``ergo twin serve``'s, or a real adapter); the proxy opens it as a client and offers the host a
new pty (``path``, or a stable symbolic link ``link``). Bytes are copied both ways; the stream
toward the host (and, if asked, toward the device) is cut into the wire's units (SLCAN lines,
Dynamixel packets: ``slcan_units``, ``dynamixel_units``) and each unit may be

- dropped (``Faults.drop_rate``): a frame or status packet lost;
- truncated (``Faults.truncate_rate``): a random prefix of it sent, the rest lost;
- delayed (``Faults.delay_rate``, ``Faults.delay_s``): held back, and everything behind it
  (the order is kept, as on a slow link);

and random bytes can be written toward the host (``garbage(seconds)``: ``Faults.garbage_rate``
bytes per second between units, and 1-8 random bytes before each unit, so that no unit comes
through untouched): a noisy line, a wrong baud rate, a confused adapter.

A test-only tool (tests/robot/contract, tests/system); run as a script it stands between a
host and a device until interrupted, e.g. to reproduce a fault by hand::

    python tests/wire_proxy.py /dev/pts/7 --framing slcan --garbage-after 5 --garbage-s 4

prints ``proxy on /dev/pts/9`` (the path the host opens).
"""

from __future__ import annotations

import argparse
import contextlib
import os
import random
import select
import sys
import termios
import threading
import time
import tty
from collections import deque
from collections.abc import Callable
from dataclasses import dataclass

# How often the threads wake to look for stop, s (not a protocol figure).
POLL_S = 0.02
# Random bytes per second written by ``garbage`` (about a 115200 baud line's worth: 11.5 kB/s;
# a guess at what a noisy line or a wrong baud rate gives).
DEFAULT_GARBAGE_RATE = 11_520
DYNAMIXEL_HEADER = b"\xff\xff\xfd\x00"

#: Cuts a byte stream into the wire's units: (complete units, rest to keep for the next chunk).
Framer = Callable[[bytes], tuple[list[bytes], bytes]]


def slcan_units(buf: bytes) -> tuple[list[bytes], bytes]:
    """SLCAN (Lawicel) lines, each with its CR (or a BEL answer on its own)."""
    units, start = [], 0
    for i, b in enumerate(buf):
        if b in (0x0D, 0x07):
            units.append(buf[start : i + 1])
            start = i + 1
    return units, buf[start:]


def dynamixel_units(buf: bytes) -> tuple[list[bytes], bytes]:
    """Dynamixel Protocol 2.0 packets (header, id, u16 length, then ``length`` bytes); bytes
    before a header are a unit of their own."""
    units = []
    while buf:
        at = buf.find(DYNAMIXEL_HEADER)
        if at < 0:
            keep = next((k for k in (3, 2, 1) if buf.endswith(DYNAMIXEL_HEADER[:k])), 0)
            if len(buf) > keep:
                units.append(buf[: len(buf) - keep])
            return units, buf[len(buf) - keep :]
        if at > 0:
            units.append(buf[:at])
            buf = buf[at:]
        if len(buf) < 7:
            return units, buf
        end = 7 + int.from_bytes(buf[5:7], "little")
        if len(buf) < end:
            return units, buf
        units.append(buf[:end])
        buf = buf[end:]
    return units, b""


FRAMERS: dict[str, Framer] = {"slcan": slcan_units, "dynamixel": dynamixel_units}


@dataclass
class Faults:
    """What happens to the units going one way (rates are fractions of units in [0, 1]).

    Attributes:
        drop_rate: units lost.
        truncate_rate: units cut to a random prefix (at least one byte lost).
        delay_rate: units held back by ``delay_s`` (and all behind them).
        delay_s: how long a delayed unit is held, s.
        garbage_rate: random bytes per second written this way while ``garbage`` runs.
    """

    drop_rate: float = 0.0
    truncate_rate: float = 0.0
    delay_rate: float = 0.0
    delay_s: float = 0.03
    garbage_rate: float = DEFAULT_GARBAGE_RATE


@dataclass
class Counts:
    units: int = 0
    dropped: int = 0
    truncated: int = 0
    delayed: int = 0
    garbage_bytes: int = 0


def _raw_pty() -> tuple[int, int]:
    master, slave = os.openpty()
    tty.setraw(master, termios.TCSANOW)
    tty.setraw(slave, termios.TCSANOW)
    return master, slave


class _Direction:
    """One way through the proxy: read ``src``, cut into units, apply faults, write ``dst``
    (through a FIFO with release times, so that a delay holds everything behind it)."""

    def __init__(self, proxy: WireProxy, src: int, dst: int, framer: Framer, name: str) -> None:
        self.proxy, self.src, self.dst, self.framer, self.name = proxy, src, dst, framer, name
        self.faults = Faults()
        self.counts = Counts()
        self.rest = b""
        self.queue: deque[tuple[float, bytes]] = deque()
        self.cond = threading.Condition()
        self.write_lock = threading.Lock()
        self.garbage_until = 0.0

    def _fate(self, unit: bytes) -> tuple[bytes | None, float]:
        f, rng = self.faults, self.proxy.rng
        self.counts.units += 1
        if f.drop_rate and rng.random() < f.drop_rate:
            self.counts.dropped += 1
            return None, 0.0
        if f.truncate_rate and len(unit) > 1 and rng.random() < f.truncate_rate:
            self.counts.truncated += 1
            unit = unit[: rng.randrange(1, len(unit))]
        if f.delay_rate and rng.random() < f.delay_rate:
            self.counts.delayed += 1
            return unit, f.delay_s
        return unit, 0.0

    def read_loop(self) -> None:
        while not self.proxy.stopping.is_set():
            try:
                ready, _, _ = select.select([self.src], [], [], POLL_S)
                if not ready:
                    continue
                chunk = os.read(self.src, 4096)
            except OSError:  # EIO: no client on the host's side yet, or the device went away
                time.sleep(POLL_S)
                continue
            if not chunk:
                time.sleep(POLL_S)
                continue
            units, self.rest = self.framer(self.rest + chunk)
            now = time.monotonic()
            with self.cond:
                for unit in units:
                    data, delay = self._fate(unit)
                    if data is not None:
                        self.queue.append((now + delay, data))
                self.cond.notify_all()

    def write_loop(self) -> None:
        while not self.proxy.stopping.is_set():
            with self.cond:
                if not self.queue:
                    self.cond.wait(POLL_S)
                    continue
                release, data = self.queue[0]
                wait = release - time.monotonic()
                if wait > 0:
                    self.cond.wait(min(wait, POLL_S))
                    continue
                self.queue.popleft()
            if time.monotonic() < self.garbage_until:  # a noisy line: garbage in every unit
                rng = self.proxy.rng
                data = rng.randbytes(rng.randrange(1, 9)) + data
                self.counts.garbage_bytes += len(data)
            self.write(data)

    def write(self, data: bytes) -> None:
        with self.write_lock, contextlib.suppress(OSError):
            os.write(self.dst, data)

    def garbage_loop(self) -> None:
        chunk_s = 0.005
        while not self.proxy.stopping.is_set():
            if time.monotonic() >= self.garbage_until:
                time.sleep(POLL_S / 4)
                continue
            n = max(1, round(self.faults.garbage_rate * chunk_s))
            self.write(self.proxy.rng.randbytes(n))
            self.counts.garbage_bytes += n
            time.sleep(chunk_s)


class WireProxy:
    """The proxy between a host and ``device``.

    Args:
        device: the tty path of the device (an emulator's pty, a real adapter).
        framing: ``"slcan"`` or ``"dynamixel"`` (how the streams are cut into units).
        link: a symbolic link to the host's pty (a stable name), or None.
        seed: seed of the fault draws and of the garbage.

    Attributes:
        to_host, to_device: the two directions; set ``.faults`` on each, read ``.counts``.
    """

    def __init__(
        self,
        device: str,
        framing: str = "slcan",
        link: str | os.PathLike[str] | None = None,
        seed: int = 0,
    ) -> None:
        framer = FRAMERS[framing]
        self.rng = random.Random(seed)
        self.stopping = threading.Event()
        self.device = os.open(device, os.O_RDWR | os.O_NOCTTY)
        tty.setraw(self.device, termios.TCSANOW)
        self.master, self.slave = _raw_pty()
        self.path = os.ttyname(self.slave)
        self.link = None if link is None else os.fspath(link)
        if self.link is not None:
            with contextlib.suppress(FileNotFoundError):
                os.unlink(self.link)
            os.symlink(self.path, self.link)
        self.to_host = _Direction(self, self.device, self.master, framer, "to host")
        self.to_device = _Direction(self, self.master, self.device, framer, "to device")
        self._threads: list[threading.Thread] = []

    @property
    def port(self) -> str:
        """What the host opens: the link when there is one, else the pty."""
        return self.link or self.path

    def start(self) -> WireProxy:
        for d in (self.to_host, self.to_device):
            for loop in (d.read_loop, d.write_loop, d.garbage_loop):
                t = threading.Thread(target=loop, name=f"proxy {d.name}", daemon=True)
                t.start()
                self._threads.append(t)
        return self

    def garbage(self, seconds: float, toward: str = "host") -> None:
        """Write random bytes toward the host (or ``"device"``) for ``seconds`` from now, at
        that direction's ``faults.garbage_rate``; returns at once."""
        d = self.to_host if toward == "host" else self.to_device
        d.garbage_until = time.monotonic() + seconds

    def clear(self) -> None:
        """No faults from now on (garbage stopped, rates 0); what is queued still goes out."""
        for d in (self.to_host, self.to_device):
            d.faults = Faults()
            d.garbage_until = 0.0

    def close(self) -> None:
        self.stopping.set()
        for t in self._threads:
            t.join(timeout=2.0)
        self._threads.clear()
        for fd in (self.master, self.slave, self.device):
            with contextlib.suppress(OSError):
                os.close(fd)
        if self.link is not None:
            with contextlib.suppress(OSError):
                os.unlink(self.link)

    def __enter__(self) -> WireProxy:
        return self.start()

    def __exit__(self, *exc: object) -> None:
        self.close()


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(prog="python tests/wire_proxy.py", description=__doc__)
    p.add_argument("device", help="the device's tty (e.g. the emulator's /dev/pts/N)")
    p.add_argument("--framing", choices=sorted(FRAMERS), default="slcan")
    p.add_argument("--link", default=None)
    p.add_argument("--seed", type=int, default=0)
    p.add_argument("--garbage-after", type=float, default=None, help="s before the garbage")
    p.add_argument("--garbage-s", type=float, default=4.0, help="how long the garbage lasts, s")
    p.add_argument("--drop-rate", type=float, default=0.0)
    p.add_argument("--truncate-rate", type=float, default=0.0)
    p.add_argument("--delay-rate", type=float, default=0.0)
    p.add_argument("--delay-s", type=float, default=0.03)
    args = p.parse_args(argv)
    with WireProxy(args.device, args.framing, args.link, args.seed) as proxy:
        proxy.to_host.faults = Faults(
            args.drop_rate, args.truncate_rate, args.delay_rate, args.delay_s
        )
        print(f"proxy on {proxy.port}", flush=True)
        try:
            if args.garbage_after is not None:
                time.sleep(args.garbage_after)
                print(f"garbage toward the host for {args.garbage_s} s", flush=True)
                proxy.garbage(args.garbage_s)
            while True:
                time.sleep(1.0)
        except KeyboardInterrupt:
            pass
        print(f"to host: {proxy.to_host.counts}", flush=True)
    return 0


if __name__ == "__main__":
    sys.exit(main())
