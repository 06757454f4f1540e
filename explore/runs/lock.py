"""The writer's lock of a run folder: one process at a time appends to a run's history.

``RUN/writer.lock`` is held with an exclusive ``flock`` for the life of the writer (``ergo
explore``, a campaign trial: every ``open_run``), and says who holds it, as JSON: pid, host,
since (unix s) and the command line. A second writer is refused at once with one line naming
the holder's pid.

The kernel drops a ``flock`` when its holder dies (SIGKILL, a crash, a power cut), so the lock
of a dead writer never blocks anyone: the next writer takes it over and says so (the file then
still names the dead writer, who ended without blanking it). A writer that ends normally
blanks the file (spaces) before unlocking it. The file is never deleted: deleting a lock file
races with a writer that has just opened it (both would then lock different files).

A run folder may come from someone else: the lock file is opened without following a
symbolic link, must be a regular file with no other hard link, and is never truncated (the
holder's JSON is written over the first ``HOLDER_BYTES`` bytes, padded with spaces), so that a
``writer.lock`` pointing at another file can neither empty nor rewrite it.

A ``flock`` belongs to the open file, not to the process: two opens of one run in one process
exclude each other too. Over NFS, Linux emulates it with a POSIX record lock on the server.
"""

from __future__ import annotations

import contextlib
import errno
import fcntl
import json
import os
import socket
import stat
import sys
import time
from collections.abc import Iterator
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from explore.runs.layout import WRITER_LOCK_FILE
from explore.runs.store import RunStoreError

LOCK_FILE = WRITER_LOCK_FILE
# How long a writer that finds the lock taken, by nobody alive the file names, tries again
# before it is refused, s: the holder writes its name just after taking the lock, a reader's
# look (``holder_of``) lasts microseconds. A bound, not an expectation: guess.
HOLDER_WAIT_S = 1.0
# Bytes of the lock file the holder's JSON is written over (padded with spaces): the file is
# never truncated. The JSON takes about 150 bytes plus the command (at most 300 characters).
HOLDER_BYTES = 1024


class RunLockedError(RunStoreError):
    """Another process is writing this run (one line naming it)."""


@dataclass(frozen=True)
class RunLock:
    """A held lock. ``took_over``: what the file said of a writer that ended without releasing
    the lock (killed, crashed), or None when the lock was released cleanly or new."""

    path: Path
    took_over: dict[str, Any] | None

    def describe_takeover(self) -> str | None:
        """One line about the lock taken over, or None."""
        if self.took_over is None:
            return None
        return (
            f"{self.path.parent}: took over the lock of a writer that ended without releasing "
            f"it ({describe_holder(self.took_over)})"
        )


def describe_holder(info: dict[str, Any]) -> str:
    """The writer a lock file names, in words (pid, host, since when, command)."""
    if not info:
        return "a process that has not said who it is"
    pid, host = info.get("pid", "?"), info.get("host", "?")
    since = info.get("since")
    when = time.strftime("%Y-%m-%d %H:%M:%S", time.localtime(since)) if since else "?"
    command = info.get("command")
    text = f"pid {pid} on {host}, since {when}"
    return f"{text}: {command}" if command else text


def _read(fd: int) -> dict[str, Any]:
    try:
        data = os.pread(fd, 65536, 0)
        info = json.loads(data) if data.strip() else {}
    except (OSError, ValueError):
        return {}
    return info if isinstance(info, dict) else {}


def _open_lock_file(path: Path, flags: int) -> int:
    """Open the lock file without following a link; refuse one that is not the run's own
    (``RunStoreError``, one line): a symbolic link, a hard link, not a regular file."""
    try:
        fd = os.open(path, flags | os.O_NOFOLLOW | os.O_CLOEXEC, 0o644)
    except OSError as exc:
        if exc.errno == errno.ELOOP and path.is_symlink():
            raise RunStoreError(
                f"{path} is a symbolic link: a run folder must hold its own files (a folder "
                "received from someone else?); remove it"
            ) from exc
        raise
    st = os.fstat(fd)
    if not stat.S_ISREG(st.st_mode) or st.st_nlink > 1:
        os.close(fd)
        what = "not a regular file" if not stat.S_ISREG(st.st_mode) else "a hard link"
        raise RunStoreError(
            f"{path} is {what}: a run folder must hold its own files (a folder received from "
            "someone else?); remove it"
        )
    return fd


def _write_holder(fd: int, info: dict[str, Any] | None) -> None:
    """Write the holder (None: nobody) over the first ``HOLDER_BYTES`` bytes, padded with
    spaces; never truncates."""
    text = b"" if info is None else json.dumps(info).encode()
    if len(text) > HOLDER_BYTES - 1 and info is not None:
        text = json.dumps({k: v for k, v in info.items() if k != "command"}).encode()
    os.pwrite(fd, text.ljust(HOLDER_BYTES - 1) + b"\n", 0)


def _command() -> str:
    argv = [os.path.basename(sys.argv[0] or "python"), *sys.argv[1:]]
    return " ".join(argv)[:300]


def _alive(info: dict[str, Any]) -> bool:
    """Whether the writer ``info`` names may still run: a live process of this host, or one
    of another host (not knowable from here)."""
    pid = info.get("pid")
    if info.get("host") != socket.gethostname():
        return True
    if not isinstance(pid, int) or pid <= 0:
        return False
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    except PermissionError:
        return True  # it exists, under another user
    return True


@contextlib.contextmanager
def run_lock(run: str | os.PathLike[str]) -> Iterator[RunLock]:
    """Hold ``RUN/writer.lock`` (the folder must exist) for the block, or raise
    ``RunLockedError`` at once naming the holder.

    A reader asking ``holder_of`` holds the lock shared for a few microseconds: a writer that
    finds it taken while the file names nobody alive tries again (for up to
    ``HOLDER_WAIT_S``) rather than refusing itself on a reader's look."""
    run = Path(run)
    path = run / LOCK_FILE
    try:
        fd = _open_lock_file(path, os.O_RDWR | os.O_CREAT)
    except OSError as exc:
        raise RunStoreError(f"cannot open {path}: {exc.strerror or exc}") from exc
    try:
        deadline = time.monotonic() + HOLDER_WAIT_S
        while True:
            try:
                fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
                break
            except BlockingIOError:
                holder = _read(fd)
                if (holder and _alive(holder)) or time.monotonic() >= deadline:
                    raise RunLockedError(
                        f"{run} is being written by another process ({describe_holder(holder)}): "
                        "wait for it to end or stop it; two writers would duplicate episodes"
                    ) from None
                time.sleep(0.02)  # it has just taken the lock, or a reader is looking
        previous = _read(fd)
        info = {"pid": os.getpid(), "host": socket.gethostname(), "since": time.time(),
                "command": _command()}  # fmt: skip
        try:
            _write_holder(fd, info)
        except OSError as exc:  # a read-only file system, a full disk
            raise RunStoreError(f"cannot write {path}: {exc.strerror or exc}") from exc
        lock = RunLock(path, previous or None)
        try:
            yield lock
        finally:
            with contextlib.suppress(OSError):  # a full disk must not keep the lock
                _write_holder(fd, None)  # released cleanly: the next writer takes over nothing
    finally:
        os.close(fd)  # releases the flock


@contextlib.contextmanager
def _try_lock(run: str | os.PathLike[str], exclusive: bool) -> Iterator[tuple[int, bool]]:
    """For the block: the lock file's descriptor (-1 when there is no file: it is never
    created here) and whether the lock could be taken (it then is)."""
    path = Path(run) / LOCK_FILE
    try:
        fd = _open_lock_file(path, os.O_RDWR if exclusive else os.O_RDONLY)
    except FileNotFoundError:
        yield -1, True
        return
    except OSError as exc:  # a loop of links on the way, a folder that cannot be read
        raise RunStoreError(f"cannot open {path}: {exc.strerror or exc}") from exc
    try:
        try:
            fcntl.flock(fd, (fcntl.LOCK_EX if exclusive else fcntl.LOCK_SH) | fcntl.LOCK_NB)
        except BlockingIOError:
            yield fd, False
            return
        yield fd, True
    finally:
        os.close(fd)


def holder_of(run: str | os.PathLike[str]) -> dict[str, Any] | None:
    """Who holds the run's lock now (what the file says: empty when its holder has not
    written it yet), or None when nobody does."""
    with _try_lock(run, exclusive=False) as (fd, free):
        return None if free else _read(fd)


def is_being_written(run: str | os.PathLike[str]) -> bool:
    """Whether a writer (an ``ergo explore``, a campaign trial) holds the run's lock now:
    readers that need a finished history ask this, and never take the lock themselves."""
    return holder_of(run) is not None


def remove_lock_if_free(run: str | os.PathLike[str]) -> bool:
    """Delete ``RUN/writer.lock`` if nobody holds it (taken while deleting it); True if done
    or absent. Only for a run folder being removed."""
    with _try_lock(run, exclusive=True) as (fd, free):
        if free and fd >= 0:
            (Path(run) / LOCK_FILE).unlink()
        return free
