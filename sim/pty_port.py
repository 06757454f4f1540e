"""``PtyPort``: a pseudo-terminal that stands in for a USB serial adapter (a U2D2 for the
Dynamixel bus, a CANable in SLCAN mode for the CAN bus), which can be pulled out and plugged
back.

The emulator owns the master side; a client opens ``port`` with pyserial or python-can as it
would open ``/dev/ttyUSB0``. Both sides are raw (no echo, no line discipline: bytes as sent).
The port keeps its own slave descriptor open, so clients may come and go without the pty
closing. ``unplug()`` closes it as an adapter pulled out of its socket would (the client's
next read or write fails with EIO); ``replug()`` opens a new pty, whose path differs. With
``link`` a symbolic link at that path follows the current pty (a stable name, as
``/dev/serial/by-id/...`` is for a real adapter), so a client can reopen it by name.
"""

from __future__ import annotations

import contextlib
import os
import termios
import threading
import tty
from collections.abc import Callable


class OnPty:
    """What a server on a ``PtyPort`` (its attribute ``pty``) shows of it: the paths, the unplug
    count, unplug and replug."""

    pty: PtyPort
    link = property(lambda self: self.pty.link)
    path = property(lambda self: self.pty.path, doc="the current pty, e.g. /dev/pts/7")
    port = property(lambda self: self.pty.port, doc="the link when there is one, else path")
    plugged = property(lambda self: self.pty.plugged)
    unplugs = property(lambda self: self.pty.unplugs)

    def unplug(self) -> None:
        """Close the pty, as an adapter pulled out of its USB socket."""
        self.pty.unplug()

    def replug(self) -> None:
        """Open a new pty (a new path; the link, if any, follows it)."""
        self.pty.replug()


class PtyPort:
    """A pseudo-terminal with unplug/replug and an optional stable link.

    Args:
        link: path of a symbolic link to the current pty (None: no link).
        on_open: called (under no lock) each time a new pty is opened, before the link moves
            to it: a freshly plugged adapter starts in its power-on state.
    """

    def __init__(
        self, link: str | os.PathLike[str] | None = None, on_open: Callable[[], None] | None = None
    ) -> None:
        self.link = None if link is None else os.fspath(link)
        self._on_open = on_open
        self._lock = threading.Lock()  # the descriptors change together
        self.master: int | None = None
        self.slave: int | None = None
        self.path = ""
        self.unplugs = 0
        self._open()

    @property
    def port(self) -> str:
        """What a client should open: the link when there is one, else the pty itself."""
        return self.link or self.path

    @property
    def plugged(self) -> bool:
        return self.master is not None

    def fds(self) -> tuple[int | None, int | None]:
        """(master, slave) as one consistent pair; (None, None) while unplugged."""
        with self._lock:
            return self.master, self.slave

    def flush_input(self) -> None:
        """Drop what the client side has not read (bytes the server wrote that no client took:
        a start-up check's late answers), as a client's own flush on opening would."""
        with self._lock:
            if self.slave is not None:
                with contextlib.suppress(termios.error):
                    termios.tcflush(self.slave, termios.TCIFLUSH)

    def _open(self) -> None:
        master, slave = os.openpty()
        tty.setraw(slave, termios.TCSANOW)
        tty.setraw(master, termios.TCSANOW)
        if self._on_open is not None:
            self._on_open()
        with self._lock:
            self.master, self.slave = master, slave
            self.path = os.ttyname(slave)
        if self.link is not None:
            tmp = f"{self.link}.{os.getpid()}.tmp"
            with contextlib.suppress(FileNotFoundError):
                os.unlink(tmp)
            os.symlink(self.path, tmp)
            os.replace(tmp, self.link)  # atomic: a client never sees the link missing

    def unplug(self) -> None:
        """Close the pty, as an adapter pulled out of its USB socket."""
        self._close_fds()
        self.unplugs += 1

    def replug(self) -> None:
        """Open a new pty (a new path; the link, if any, follows it); no-op while plugged."""
        if self.master is None:
            self._open()

    def close(self) -> None:
        """Close the pty and remove the link (the end of serving: not counted as an unplug)."""
        self._close_fds()
        if self.link is not None:
            with contextlib.suppress(OSError):
                if os.path.islink(self.link):
                    os.unlink(self.link)

    def _close_fds(self) -> None:
        with self._lock:
            fds, self.master, self.slave = (self.master, self.slave), None, None
        for fd in fds:
            if fd is not None:
                with contextlib.suppress(OSError):
                    os.close(fd)
