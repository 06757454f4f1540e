"""The one atomic file write of the project: every file a reader must never see half-written
(a run's ``run.json``, ``metrics.csv``, camera frames and figures, a campaign's files, the
calibration files, the recordings of ``ergo calibrate dynamics``, the VAE's weights, a
stand-in's hidden file) is written here. In ``robot/``, the bottom layer, so that every
package may use it (docs/architecture.md).

A write goes to a temporary file beside the target, is fsync'ed, then renamed over the target
(``os.replace``, atomic on POSIX): a reader sees the old file or the new one, a crash or a
full disk leaves the old one (and no temporary file, except after a SIGKILL or a power cut:
its name says whose it was)."""

from __future__ import annotations

import contextlib
import os
import threading
from collections.abc import Callable
from pathlib import Path

# open flags of a file a writer makes: never through a symbolic link
NOFOLLOW = os.O_NOFOLLOW | os.O_CLOEXEC


def temporary_name(path: Path) -> Path:
    """Where ``atomic_write`` writes ``path`` first: ``NAME.tmp-PID-THREAD`` plus the target's
    suffix (``coverage.png.tmp-12-34.png``: a writer that picks the format by the suffix, as
    matplotlib and numpy do, writes the right one). This writer's own: two processes or
    threads writing one file (two ``ergo experiment`` writing ``campaign.json``) never rename
    each other's."""
    return path.with_name(f"{path.name}.tmp-{os.getpid()}-{threading.get_ident()}{path.suffix}")


def atomic_write(
    path: str | os.PathLike[str], data: bytes | str | Callable[[Path], object]
) -> Path:
    """Write ``path`` atomically (module doc) and return it.

    Args:
        path: the target; its folder must exist.
        data: the bytes, or the text (UTF-8), or a function that writes the file whose path it
            is given (``lambda tmp: np.savez_compressed(tmp, ...)``, ``torch.save``,
            ``fig.savefig``).

    The temporary file (``temporary_name``) is made anew (``O_EXCL``, never through a link: a
    link at its name cannot redirect the write). Any failure (a full disk, a quota, an error
    of ``data``'s function, Ctrl-C) removes it, leaves ``path`` as it was and is raised."""
    path = Path(path)
    tmp = temporary_name(path)
    with contextlib.suppress(FileNotFoundError):
        os.unlink(tmp)  # a dead writer's, whose pid and thread id were the same
    fd = os.open(tmp, os.O_WRONLY | os.O_CREAT | os.O_EXCL | NOFOLLOW, 0o644)
    try:
        try:
            if callable(data):
                os.close(fd)
                fd = -1
                data(tmp)
                fd = os.open(tmp, os.O_RDONLY | NOFOLLOW)
            else:
                view = memoryview(data.encode() if isinstance(data, str) else data)
                while view:
                    view = view[os.write(fd, view) :]
            os.fsync(fd)
        finally:
            if fd >= 0:
                os.close(fd)
        os.replace(tmp, path)
    except BaseException:
        with contextlib.suppress(OSError):
            os.unlink(tmp)
        raise
    return path
