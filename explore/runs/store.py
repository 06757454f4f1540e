"""The run folder: where the truth of a run lives.

Layout of ``RUN/``:
- ``run.json``: format version, the run's config (rig, strategy, seed, episodes), creation
  time. Written once, atomically (temporary file + rename).
- ``history.bin``: append-only episode records. Each is framed as
  ``b"EREC" | u32 length | u32 CRC-32 of the payload | payload`` (little endian), the payload
  an ``EpisodeRecord`` (``explore.runs.record``: packed, or npz before 2026-12-02). Each append
  is flushed before the episode counts as done, so a SIGKILL loses at most the episode in
  flight (the rest is in the kernel's page cache), and fsync'ed (by default after every
  episode: ``sync_interval_s`` = 0), so that a crash of the machine loses no more either (it
  may leave that record in any shape: cut short, zeros in it; below). A rig
  whose episodes cost well under the 2 ms an fsync takes (ArmBalls) syncs at most every
  ``sync_interval_s`` seconds (``Rig.sync_interval_s``) and on close: a power cut can then cost
  it the episodes of the last interval, which a resume detects and runs again (below).
- ``history.synced`` (only with ``sync_interval_s`` > 0): a length of ``history.bin`` known to
  be on disk, u64 little endian, written and fsync'ed after each fsync of the history returned
  (so it may lag the history, never lead it). After a power cut, whatever the disk kept of the
  bytes past it (nothing, zeros, a prefix, records with holes) is the unsynced tail and is cut;
  damage before it is corruption, unless it is the last record (below).
- ``frames/episode-NNNNNN.npz`` (with the rig option ``record_video``): the overhead camera at
  every control tick of episode N, ``frames`` (T, side, side, 3) BGR uint8, written atomically
  (fsync'ed) before the episode's record is appended; a file past the last record is what a
  crash left of the episode in flight, replaced when that episode is run again.
- ``writer.lock``: held (an exclusive ``flock``) by the one process writing the run, and
  naming it (``explore/runs/lock.py``: ``run_lock``); readers never take it, those that need a
  finished history ask whether it is held (``lock.is_being_written``).
- ``metrics.csv``: cells reached after every episode (derived; rebuilt from the history on
  resume).
- ``coverage.png`` and whatever later stages write (models, figures, recordings).

On open, a torn tail is moved aside to ``RUN/salvage/N/`` (the bytes kept, never deleted; its
episodes are run again) and cut from the history: a bad record with no good record anywhere
after it (the last record, in whatever shape a crash or a power cut left it: cut short, zeros,
a zeroed length), and everything from the first bad record on when it lies past
``history.synced`` (a power cut's unsynced tail). Any other bad record is damage: it raises
``RunStoreError`` naming the offset and the good record after it, without touching the file
(``ergo runs salvage`` keeps what can be kept). The rule, shared with ``ergo runs check``:
``explore/runs/walk.py``.

A run folder may come from someone else: the writer refuses one whose files it would write
are symbolic links, hard links or not regular files (``check_own_files``), and opens them
without following links, so that a received folder cannot make it write outside itself.
"""

from __future__ import annotations

import contextlib
import io
import json
import math
import os
import stat
import struct
import time
import zipfile
import zlib
from collections.abc import Iterator
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from explore.runs.layout import (
    DAMAGED_FILE,
    HEADER,
    HISTORY_FILE,
    RUN_FILE,
    SALVAGE_DIR,
    SALVAGE_REPORT,
    SYNCED_FILE,
    WRITER_DIRS,
    WRITER_FILES,
    WRITER_LOCK_FILE,
    frame,
    frames_path,
)
from explore.runs.record import EpisodeRecord
from explore.runs.walk import walk
from plumbing.files import NOFOLLOW, atomic_write

RUN_FORMAT = 1
APP = "ergo-explore"
_SYNCED = struct.Struct("<Q")  # history.synced: u64 little endian


class RunStoreError(RuntimeError):
    """A run folder is missing, foreign, from another version, or corrupt."""


def check_own_files(run: Path) -> None:
    """Refuse (``RunStoreError``, one line) a run folder whose files a writer would write are
    not its own: a symbolic link, a file with other hard links, or not a regular file (a
    folder, a device) at one of ``WRITER_FILES`` or in ``WRITER_DIRS``. A run received from
    someone else could otherwise make the writer write, append to or empty files outside it."""
    names = [run / n for n in WRITER_FILES]
    for d in WRITER_DIRS:
        sub = run / d
        if sub.is_symlink() or (sub.exists() and not sub.is_dir()):
            raise RunStoreError(
                _not_own(sub, "a symbolic link" if sub.is_symlink() else "not a folder")
            )
        if sub.is_dir():
            names += sorted(sub.rglob("*"))
    for path in names:
        try:
            st = os.lstat(path)
        except FileNotFoundError:
            continue
        except OSError as exc:
            raise RunStoreError(f"cannot look at {path}: {exc.strerror or exc}") from exc
        if stat.S_ISLNK(st.st_mode):
            raise RunStoreError(_not_own(path, "a symbolic link"))
        if stat.S_ISDIR(st.st_mode) and path.parent != run:
            continue  # salvage/1/ and the like
        if not stat.S_ISREG(st.st_mode):
            raise RunStoreError(_not_own(path, "not a regular file"))
        if st.st_nlink > 1:
            raise RunStoreError(_not_own(path, f"a hard link ({st.st_nlink} names for one file)"))


def _not_own(path: Path, what: str) -> str:
    return (
        f"{path} is {what}: a run folder must hold its own files (a folder received from "
        f"someone else?); replace it with a copy of the file, or remove it"
    )


def make_run_dir(path: Path) -> None:
    """Create the run folder ``path`` (and its parents); one line when that cannot be done
    (a parent is a regular file, no permission, a full disk)."""
    for parent in (path, *path.parents):
        if parent.exists() and not parent.is_dir():
            raise RunStoreError(f"cannot make the run folder {path}: {parent} is a file")
    try:
        path.mkdir(parents=True, exist_ok=True)
    except OSError as exc:
        raise RunStoreError(f"cannot make the run folder {path}: {exc.strerror or exc}") from exc


def salvage_hint(run: Path) -> str:
    """What to do about a damaged history, for the end of an error line."""
    return f"`ergo runs check {run}` says what can be kept, `ergo runs salvage {run}` keeps it"


def _scan(
    data: bytes,
    synced: int | None = None,
    hint: str = "",
    keep: list[EpisodeRecord] | None = None,
) -> tuple[list[tuple[int, int]], int]:
    """The records of ``data`` (a history's bytes) that a run resumes from, by the one rule of
    ``explore/runs/walk.py``.

    Args:
        synced: the length known to be on disk (``history.synced``; None: the run fsyncs every
            append).
        hint: the end of an error line (what to do about it).
        keep: gets the decoded records, in order.

    Returns:
        spans: (start, end) of each record's payload, episodes 0, 1, 2... in order.
        good_end: where a torn tail starts (``len(data)`` if none).
    Raises RunStoreError (one line) on damage (a bad record that is not the torn tail) or a
    record out of order.
    """
    spans: list[tuple[int, int]] = []
    for piece, rec in walk(data, synced):
        if piece.kind == "torn":
            return spans, piece.start
        if rec is None:
            raise RunStoreError(
                f"{HISTORY_FILE} is corrupt at byte {piece.start}: {piece.why}, and a good "
                f"record follows at byte {piece.end}{hint}"
            )
        if rec.episode != len(spans):
            raise RunStoreError(
                f"{HISTORY_FILE} record {len(spans)} is episode {rec.episode}: missing or "
                f"duplicated{hint}"
            )
        spans.append((piece.start + HEADER.size, piece.end))
        if keep is not None:
            keep.append(rec)
    return spans, len(data)


class RunStore:
    """A run folder opened for reading and appending. Use ``create`` or ``open``."""

    def __init__(self, path: Path, meta: dict[str, Any]) -> None:
        self.path = path
        self.meta = meta
        self.records: list[EpisodeRecord] = []
        self._fd: int | None = None  # history.bin, O_APPEND, unbuffered
        self.truncated_bytes = 0  # torn bytes moved out of history.bin by ``open``
        self.moved_aside: Path | None = None  # where ``open`` moved them (RUN/salvage/N)
        self.torn_bytes = 0  # torn bytes found after the last record (cut by ``open`` only)
        #: seconds between two fsyncs of the history (0: every append)
        self.sync_interval_s = 0.0
        self._synced = -math.inf  # the first append syncs (and starts ``history.synced``)
        self._size = 0  # bytes of history.bin written through this store
        self._synced_length: int | None = None  # what history.synced holds (None: no file)

    # ---- construction ----------------------------------------------------------------------
    @classmethod
    def create(cls, path: str | Path, config: dict[str, Any]) -> RunStore:
        """Make a new run folder; refuses a non-empty existing folder (its writer's lock file,
        ``explore/runs/lock.py``, aside)."""
        path = Path(path)
        make_run_dir(path)
        found = sorted(p.name for p in path.iterdir() if p.name != WRITER_LOCK_FILE)
        if found and all(name.startswith(f"{RUN_FILE}.tmp") for name in found):
            for name in found:  # a kill during a previous create's atomic write: nothing made
                (path / name).unlink()
            found = []
        if found:
            raise RunStoreError(
                f"{path} exists and is not empty: use --resume {path} or a new --out"
            )
        meta = {
            "app": APP,
            "format": RUN_FORMAT,
            "created": time.strftime("%Y-%m-%dT%H:%M:%S%z"),
            "config": config,
        }
        atomic_write(path / RUN_FILE, json.dumps(meta, indent=2, sort_keys=True))
        store = cls(path, meta)
        store._open_for_append()
        return store

    @classmethod
    def open(cls, path: str | Path) -> RunStore:
        """Open an existing run for appending, verifying its history and cutting a torn last
        record. Only its writer may do this (``open_run``, under the run's lock): a reader
        uses ``read``."""
        path = Path(path)
        meta = cls.read_meta(path)
        store = cls(path, meta)
        store._load()
        store._open_for_append()
        return store

    @classmethod
    def read(cls, path: str | Path) -> RunStore:
        """Open an existing run for reading only: its history verified as by ``open``, but a
        torn last record (perhaps an append in progress in another process) is left alone,
        and nothing can be appended."""
        path = Path(path)
        store = cls(path, cls.read_meta(path))
        store._load(repair=False)
        return store

    @staticmethod
    def is_run(path: str | Path) -> bool:
        return (Path(path) / RUN_FILE).is_file()

    @staticmethod
    def read_meta(path: Path) -> dict[str, Any]:
        meta_path = path / RUN_FILE
        if not path.is_dir():
            raise RunStoreError(f"{path} is not a run folder (no such directory)")
        if not meta_path.is_file():
            raise RunStoreError(f"{path} is not a run folder (no {RUN_FILE})")
        try:
            meta = json.loads(meta_path.read_text())
        except (json.JSONDecodeError, UnicodeDecodeError) as exc:
            raise RunStoreError(f"{meta_path} is not valid JSON: {exc}") from exc
        if not isinstance(meta, dict) or meta.get("app") != APP:
            raise RunStoreError(f"{meta_path} is not an {APP} run (field 'app')")
        if meta.get("format") != RUN_FORMAT:
            raise RunStoreError(
                f"{meta_path} has format {meta.get('format')!r}; this version reads format "
                f"{RUN_FORMAT} (field 'format')"
            )
        if not isinstance(meta.get("config"), dict):
            raise RunStoreError(f"{meta_path} has no 'config' object")
        return meta

    def replace_meta(self, meta: dict[str, Any]) -> None:
        """Replace ``run.json`` atomically (as ``create`` writes it) and this store's copy."""
        atomic_write(self.path / RUN_FILE, json.dumps(meta, indent=2, sort_keys=True))
        self.meta = meta

    # ---- history ---------------------------------------------------------------------------
    @property
    def history_path(self) -> Path:
        return self.path / HISTORY_FILE

    @property
    def config(self) -> dict[str, Any]:
        return self.meta["config"]

    def __len__(self) -> int:
        return len(self.records)

    def __iter__(self) -> Iterator[EpisodeRecord]:
        return iter(self.records)

    def _load(self, repair: bool = True) -> None:
        if not self.history_path.exists():
            return
        data = self.history_path.read_bytes()
        self._synced_length = read_synced(self.path)
        hint = f" in {self.path}: {salvage_hint(self.path)}"
        records: list[EpisodeRecord] = []
        _, good_end = _scan(data, self._synced_length, hint, keep=records)
        self.records = records
        self.torn_bytes = len(data) - good_end
        if self.torn_bytes and repair:
            # a crash during the last append (the episode in flight), or a power cut's unsynced
            # tail: the bytes from the first bad record on are moved aside (kept, not
            # deleted: on hardware that episode cannot be run again the same), then cut from
            # the history; the episodes are run again
            try:
                self.moved_aside = move_tail_aside(self.path, data, good_end, len(self.records))
                with open(self.history_path, "r+b") as f:
                    f.truncate(good_end)
                    os.fsync(f.fileno())
                if self._synced_length is not None:
                    self._write_synced(good_end)
            except OSError as exc:
                raise RunStoreError(
                    f"cannot move the torn last record of {self.history_path} aside "
                    f"({self.torn_bytes} bytes): {exc.strerror or exc}; history.bin left as it "
                    "was"
                ) from exc
            self.truncated_bytes = self.torn_bytes

    def _open_for_append(self) -> None:
        flags = os.O_WRONLY | os.O_APPEND | os.O_CREAT | NOFOLLOW
        try:
            self._fd = os.open(self.history_path, flags, 0o644)
        except OSError as exc:
            raise RunStoreError(
                f"cannot open {self.history_path} for appending: {exc.strerror or exc}"
            ) from exc
        self._size = os.fstat(self._fd).st_size

    def _sync(self) -> None:
        """fsync the history, then record (durably) how much of it is on disk."""
        assert self._fd is not None
        os.fsync(self._fd)
        self._synced = time.monotonic()
        if (self.sync_interval_s > 0 or self._synced_length is not None) and (
            self._size != self._synced_length
        ):  # a run that appended nothing writes nothing
            self._write_synced(self._size)

    def _write_synced(self, length: int) -> None:
        self._synced_length = length
        path = self.path / SYNCED_FILE
        new = not path.exists()
        fd = os.open(path, os.O_WRONLY | os.O_CREAT | NOFOLLOW, 0o644)
        try:
            os.pwrite(fd, _SYNCED.pack(length), 0)
            os.fsync(fd)
        finally:
            os.close(fd)
        if new:  # its directory entry on disk too
            dir_fd = os.open(self.path, os.O_RDONLY)
            try:
                os.fsync(dir_fd)
            finally:
                os.close(dir_fd)

    def append(self, record: EpisodeRecord) -> None:
        """Append one episode: written unbuffered (a killed process loses nothing of it) and
        fsync'ed, after every append or at most every ``sync_interval_s`` seconds (module doc).

        A write or sync that fails (a full disk, a quota, an I/O error) is undone: the file is
        cut back to the episodes before it, and ``RunStoreError`` says so in one line."""
        if self._fd is None:
            raise RunStoreError(f"{self.path} is not open for appending")
        if record.episode != len(self.records):
            raise RunStoreError(
                f"episode {record.episode} appended after {len(self.records)} episodes"
            )
        payload = record.to_bytes()
        framed = memoryview(frame(payload))
        size = self._size
        try:
            while framed:  # unbuffered: in the page cache, nothing left in a buffer to land later
                framed = framed[os.write(self._fd, framed) :]
            self._size = os.fstat(self._fd).st_size
            if time.monotonic() - self._synced >= self.sync_interval_s:
                self._sync()
        except OSError as exc:
            with contextlib.suppress(OSError):  # cutting frees space: it works on a full disk
                os.ftruncate(self._fd, size)
                os.fsync(self._fd)
            self._size = size
            raise RunStoreError(
                f"cannot store episode {record.episode} in {self.history_path}: "
                f"{exc.strerror or exc}; the {len(self.records)} episode(s) before it are kept"
            ) from exc
        self.records.append(record)

    def write_frames(self, episode: int, frames: np.ndarray) -> Path:
        """Keep episode ``episode``'s camera frames (T, side, side, 3) uint8 durably (temporary
        file, fsync, rename): call it before appending the episode's record."""
        path = frames_path(self.path, episode)
        path.parent.mkdir(exist_ok=True)
        buf = io.BytesIO()
        np.savez_compressed(buf, frames=np.asarray(frames, dtype=np.uint8))
        return atomic_write(path, buf.getvalue())

    def close(self) -> None:
        if self._fd is not None:
            try:
                self._sync()
            finally:
                fd, self._fd = self._fd, None
                os.close(fd)

    def __enter__(self) -> RunStore:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()


def new_salvage_folder(run: Path) -> Path:
    """A new, empty ``RUN/salvage/N/`` (N = 1, 2, ...: never an earlier one)."""
    base = run / SALVAGE_DIR
    if base.is_symlink():
        raise RunStoreError(_not_own(base, "a symbolic link"))
    base.mkdir(exist_ok=True)
    k = 1
    while True:
        folder = base / str(k)
        try:
            folder.mkdir()
            return folder
        except FileExistsError:
            k += 1


def fsync_write(path: Path, chunks: Iterator[bytes]) -> int:
    """Write a new file (never an existing one) from ``chunks``, fsync'ed; returns its size."""
    n = 0
    with open(path, "xb") as f:
        for chunk in chunks:
            f.write(chunk)
            n += len(chunk)
        f.flush()
        os.fsync(f.fileno())
    return n


def fsync_dir(path: Path) -> None:
    fd = os.open(path, os.O_RDONLY)
    try:
        os.fsync(fd)
    finally:
        os.close(fd)


def move_tail_aside(run: Path, data: bytes, start: int, records: int) -> Path:
    """Copy ``data[start:]`` (a torn last record, or a power cut's unsynced tail, of the
    history ``data``) to a new ``RUN/salvage/N/damaged.bin`` with its ``salvage.json`` (as
    ``ergo runs salvage`` writes them: the history's pieces, where each went), fsync'ed,
    before the caller cuts it from the history. Returns the folder."""
    folder = new_salvage_folder(run)
    size = len(data) - start
    fsync_write(folder / DAMAGED_FILE, iter([data[start:]]))
    report = {
        "salvaged": time.strftime("%Y-%m-%dT%H:%M:%S%z"),
        "by": "resume (a torn last record: a crash mid-append, or a power cut's unsynced tail)",
        "history_bytes_before": len(data),
        "kept_in_history": records,
        "good_records_moved": 0,
        "damaged_bytes_moved": size,
        "pieces": [
            {"start": 0, "end": start, "kind": "records", "file": HISTORY_FILE, "at": 0},
            {"start": start, "end": len(data), "kind": "torn", "file": DAMAGED_FILE, "at": 0},
        ],
    }
    fsync_write(folder / SALVAGE_REPORT, iter([json.dumps(report, indent=1).encode()]))
    fsync_dir(folder)
    return folder


def read_synced(run: str | Path) -> int | None:
    """The length of ``RUN/history.bin`` known to be on disk (``history.synced``), or None
    when the run keeps none (it fsyncs every append)."""
    try:
        raw = (Path(run) / SYNCED_FILE).read_bytes()
    except FileNotFoundError:
        return None
    return _SYNCED.unpack(raw[: _SYNCED.size])[0] if len(raw) >= _SYNCED.size else None


@dataclass(frozen=True)
class History:
    """A run's stored episodes as read by ``read_history``.

    Attributes:
        meta: ``run.json`` (checked as ``RunStore.read_meta`` checks it).
        records: the complete records, in order.
        torn_bytes: bytes of a torn last record after them (a crash mid-append, or a power
            cut's unsynced tail; 0 if none), left in the file (``RunStore.open`` cuts them when
            the run is resumed).
    """

    meta: dict[str, Any]
    records: list[EpisodeRecord]
    torn_bytes: int


def read_history(run: str | Path) -> History:
    """A run's history, checked as ``RunStore.open`` checks it, without modifying the folder:
    a ``RunStoreError`` (one line) for a folder that is not a run, or a corrupt history."""
    store = RunStore.read(run)
    return History(store.meta, store.records, store.torn_bytes)


def read_frames(run: str | Path, episode: int) -> np.ndarray | None:
    """Episode ``episode``'s camera frames (T, side, side, 3) BGR uint8, or None when the run
    kept none for it; a ``RunStoreError`` for a file that is not readable."""
    path = frames_path(run, episode)
    if not path.exists():
        return None
    try:
        with np.load(path, allow_pickle=False) as z:
            frames = z["frames"]
    except (OSError, ValueError, KeyError, EOFError, zlib.error, zipfile.BadZipFile) as exc:
        raise RunStoreError(f"{path} is not readable: {exc or type(exc).__name__}") from exc
    if frames.ndim != 4 or frames.shape[-1] != 3 or frames.dtype != np.uint8:
        raise RunStoreError(f"{path} holds frames of shape {frames.shape}, not (T, S, S, 3) uint8")
    return frames


def iter_history(run: Path, left_out: list[int] | None = None) -> Iterator[EpisodeRecord]:
    """Read a run's stored episodes without modifying the folder (no torn-tail repair, no
    append handle): safe on a run that another process is still writing. ``left_out``: gets
    the bytes of a torn last record left out (0 if none), for a reader to say so."""
    path = Path(run) / HISTORY_FILE
    if not path.exists():
        return
    data = path.read_bytes()
    hint = f" in {run}: {salvage_hint(Path(run))}"
    spans, good_end = _scan(data, read_synced(run), hint)  # the whole file checked first
    if left_out is not None:
        left_out.append(len(data) - good_end)
    for a, b in spans:  # decoded again, one at a time: a long run is not held in memory
        yield EpisodeRecord.from_bytes(data[a:b])
