"""Checking and salvaging a run's history (``ergo runs check RUN``, ``ergo runs salvage RUN``).

``survey`` walks ``history.bin`` without trusting it (the framing is in
``explore/runs/store.py``): at each offset, a record whose marker and checksum hold and whose
payload decodes is good; anything else is damaged, up to the next offset where a good record
starts (found by its marker, then its checksum: a payload holding the marker by chance fails
its own checksum there). A damaged last record that runs to the end of the file is a torn
tail (a crash mid-append), which opening the run cuts anyway. The run can resume from its
longest prefix of good records numbered 0, 1, 2, ...

``salvage`` (under the run's writer lock) keeps that prefix as the history and moves
everything after it, without losing a byte, to ``RUN/salvage/N/`` (N = 1, 2, ...: a later
salvage never overwrites an earlier one):

- ``damaged.bin``: the bytes of the damaged spans (and a torn tail), one after the other;
- ``kept.bin``: the good records after the first damage, framed as in ``history.bin``
  (``iter_records`` reads them). They cannot be replayed without the episodes lost before
  them, so the resumed run re-runs those episodes; on the deterministic twin it re-creates
  them exactly;
- ``salvage.json``: every piece of the old history (offsets, what it was, which file and
  where it went now), the counts. Concatenating the pieces in order gives the old file back.

How many episodes a run had stored is witnessed by ``metrics.csv``, which the writer appends
after each stored episode (and rewrites from the history on resume): a history cut short,
emptied or deleted shows as fewer episodes than it recorded (``Survey.missing``).
"""

from __future__ import annotations

import contextlib
import json
import os
import shutil
import time
from collections.abc import Iterator
from dataclasses import dataclass, field
from pathlib import Path
from typing import Literal

from explore.runs.layout import (
    DAMAGED_FILE,
    FRAMES_DIR,
    HEADER,
    HISTORY_FILE,
    KEPT_FILE,
    RUN_FILE,
    SALVAGE_REPORT,
    frame_at,
    next_frame,
)
from explore.runs.lock import run_lock
from explore.runs.metrics import recorded_episodes
from explore.runs.record import EpisodeRecord, RecordError
from explore.runs.store import (
    RunStore,
    RunStoreError,
    check_own_files,
    fsync_dir,
    fsync_write,
    new_salvage_folder,
    read_frames,
)

Kind = Literal["record", "damaged", "torn"]


@dataclass(frozen=True)
class Piece:
    """A span of ``history.bin``: ``start``/``end`` byte offsets; ``episode`` of a good record;
    ``why`` a damaged span is damaged."""

    start: int
    end: int
    kind: Kind
    episode: int | None = None
    why: str = ""

    @property
    def size(self) -> int:
        return self.end - self.start


@dataclass
class Survey:
    """What ``history.bin`` holds.

    Attributes:
        size: bytes of the file (0 when missing).
        pieces: the file cut into good records and damaged spans, in order, covering it all.
        prefix: episodes 0..prefix-1 stored in order from the start, with nothing between.
        prefix_end: byte offset where that prefix ends.
        recorded: episodes the run had stored as ``metrics.csv`` says, None without it.
        exists: whether ``history.bin`` exists.
        config_error: why ``run.json``'s config cannot be run (None: it can).
        frames: for a run that keeps camera frames (``RUN/frames/``): episodes of the
            resumable history with readable frames; None for a run without.
        frames_missing, frames_bad: episodes without a frames file, and (episode, why) of
            those whose file cannot be read.
    """

    size: int
    pieces: list[Piece] = field(default_factory=list)
    prefix: int = 0
    prefix_end: int = 0
    recorded: int | None = None
    exists: bool = True
    config_error: str | None = None
    frames: int | None = None
    frames_missing: list[int] = field(default_factory=list)
    frames_bad: list[tuple[int, str]] = field(default_factory=list)

    @property
    def good(self) -> list[Piece]:
        return [p for p in self.pieces if p.kind == "record"]

    @property
    def damaged(self) -> list[Piece]:
        return [p for p in self.pieces if p.kind == "damaged"]

    @property
    def torn(self) -> Piece | None:
        return next((p for p in self.pieces if p.kind == "torn"), None)

    @property
    def beyond(self) -> list[Piece]:
        """Good records after the resumable prefix (after a damage, a gap or a duplicate)."""
        return [p for p in self.good if p.start >= self.prefix_end]

    @property
    def missing(self) -> int:
        """Episodes the run had stored that its resumable history lacks."""
        return max(0, (self.recorded or 0) - self.prefix)

    @property
    def resumable(self) -> bool:
        """Whether ``ergo explore --resume`` can continue the run as it is."""
        return not self.needs_salvage and self.config_error is None

    @property
    def needs_salvage(self) -> bool:
        """Whether the run cannot be resumed as it is (damage, or records that do not follow
        on)."""
        return bool(self.damaged or self.beyond)


def _record_at(data: bytes, pos: int) -> tuple[int, int | None, str]:
    """(end, episode, why) of the record at ``pos``: episode None and ``why`` when it is not
    a good record; end is then where its header says it ends (may be past the data)."""
    start, end, why = frame_at(data, pos)
    if why == "bad record marker":
        return pos + 1, None, why
    if why:
        return end, None, why
    try:
        rec = EpisodeRecord.from_bytes(data[start:end])
    except RecordError as exc:
        return end, None, f"undecodable record ({exc})"
    return end, rec.episode, ""


def _next_good(data: bytes, pos: int) -> int:
    """Offset of the next good record after ``pos``, or ``len(data)``."""
    at = pos
    while (at := next_frame(data, at)) is not None:
        if _record_at(data, at)[1] is not None:
            return at
    return len(data)


def survey_bytes(data: bytes) -> Survey:
    """Cut ``data`` (a ``history.bin``'s bytes) into pieces; no witness (see ``survey``)."""
    s = Survey(size=len(data))
    pos = 0
    in_prefix = True
    while pos < len(data):
        end, episode, why = _record_at(data, pos)
        if episode is not None:
            s.pieces.append(Piece(pos, end, "record", episode))
            if in_prefix and episode == s.prefix:
                s.prefix += 1
                s.prefix_end = end
            else:
                in_prefix = False
            pos = end
            continue
        nxt = _next_good(data, pos)
        torn = nxt == len(data) and why != "bad record marker" and end >= len(data)
        s.pieces.append(Piece(pos, nxt, "torn" if torn else "damaged", why=why))
        in_prefix = in_prefix and torn
        pos = nxt
    return s


def survey(run: str | Path) -> Survey:
    """Survey ``RUN/history.bin`` (read only: safe while another process writes the run)."""
    from explore.runs.config import RunConfig

    run = Path(run)
    meta = RunStore.read_meta(run)  # a one-line error for a folder that holds no run
    path = run / HISTORY_FILE
    try:
        data = path.read_bytes()
        s = survey_bytes(data)
    except FileNotFoundError:
        s = Survey(size=0, exists=False)
    except OSError as exc:
        raise RunStoreError(f"cannot read {path}: {exc.strerror or exc}") from exc
    s.recorded = recorded_episodes(run)
    try:
        RunConfig.from_dict(meta["config"], where=run / RUN_FILE)
    except RunStoreError as exc:
        s.config_error = str(exc)
    if (run / FRAMES_DIR).is_dir():
        for episode in range(s.prefix):
            try:
                if read_frames(run, episode) is None:
                    s.frames_missing.append(episode)
            except RunStoreError as exc:
                s.frames_bad.append((episode, str(exc)))
        s.frames = s.prefix - len(s.frames_missing) - len(s.frames_bad)
    return s


def _episodes(pieces: list[Piece]) -> str:
    eps = [p.episode for p in pieces if p.episode is not None]
    if not eps:
        return "none"
    if eps == list(range(eps[0], eps[-1] + 1)):
        return f"{eps[0]}..{eps[-1]}" if len(eps) > 1 else str(eps[0])
    return ", ".join(map(str, eps[:8])) + (", ..." if len(eps) > 8 else "")


def describe(run: Path, s: Survey) -> list[str]:
    """The lines ``ergo runs check`` prints (the last one is the verdict)."""
    lines = []
    if not s.exists:
        lines.append("history.bin: missing")
    else:
        dmg = s.damaged
        where = ", ".join(f"{p.size} bytes at byte {p.start} ({p.why})" for p in dmg[:3])
        lines.append(
            f"history.bin: {s.size} bytes, {len(s.good)} good record(s), {len(dmg)} damaged "
            f"span(s){': ' + where if dmg else ''}"
            + (f"{'...' if len(dmg) > 3 else ''}" if dmg else "")
            + (f", a torn tail of {s.torn.size} bytes (cut on resume)" if s.torn else "")
        )
    lines.append(f"resumable history: episodes {_episodes(s.good[: s.prefix])} ({s.prefix})")
    if s.beyond:
        lines.append(
            f"good records after it: {len(s.beyond)} (episodes {_episodes(s.beyond)}); they do "
            "not follow on and cannot be replayed"
        )
    if s.recorded is not None:
        lines.append(
            f"metrics.csv recorded {s.recorded} episode(s) stored: "
            + (f"{s.missing} missing from the history" if s.missing else "none missing")
        )
    if s.frames is not None:
        line = f"frames: {s.frames} of {s.prefix} episode(s) with readable camera frames"
        if s.frames_missing:
            line += f"; missing: episode(s) {_list(s.frames_missing)}"
        if s.frames_bad:
            line += f"; unreadable: {'; '.join(why for _, why in s.frames_bad[:3])}"
            line += "..." if len(s.frames_bad) > 3 else ""
        lines.append(line)
    if s.config_error is not None:
        lines.append(f"run.json: {s.config_error}")
    if s.needs_salvage:
        lines.append(
            f"damaged: `ergo runs salvage {run}` keeps episodes 0..{s.prefix - 1} as the "
            "history, moves the rest aside (nothing deleted) and lets the run resume"
            if s.prefix
            else f"damaged: `ergo runs salvage {run}` moves the history aside (nothing "
            "deleted) and lets the run start again from episode 0"
        )
    elif s.config_error is not None:
        lines.append("not resumable: run.json cannot be run (above); restore it from a copy")
    elif s.missing:
        lines.append(
            f"resumable, {s.missing} episode(s) short of what it had stored: "
            f"`ergo explore --resume {run}` re-runs them"
        )
    elif s.frames_missing or s.frames_bad:
        lost = len(s.frames_missing) + len(s.frames_bad)
        lines.append(
            f"resumable as it is, but {lost} episode(s) lack readable camera frames (above): "
            "a video export leaves them out"
        )
    else:
        lines.append("ok: resumable as it is")
    return lines


def _list(episodes: list[int]) -> str:
    return ", ".join(map(str, episodes[:8])) + (", ..." if len(episodes) > 8 else "")


@dataclass(frozen=True)
class SalvageResult:
    """What ``salvage`` did: ``folder`` where the rest went (None when nothing needed moving)."""

    kept: int
    beyond: int
    damaged_bytes: int
    folder: Path | None
    missing: int


def salvage(run: str | Path) -> SalvageResult:
    """Keep the resumable prefix of ``RUN/history.bin`` and move the rest to
    ``RUN/salvage/N/`` (see the module's docstring). Takes the run's writer lock: refused
    (``RunLockedError``) while another process writes the run."""
    run = Path(run)
    RunStore.read_meta(run)
    with run_lock(run):
        check_own_files(run)
        path = run / HISTORY_FILE
        data = path.read_bytes() if path.exists() else b""
        s = survey_bytes(data)
        s.recorded = recorded_episodes(run)
        rest = [p for p in s.pieces if p.start >= s.prefix_end]
        if not rest:
            return SalvageResult(s.prefix, 0, 0, None, s.missing)
        try:
            folder = new_salvage_folder(run)
        except OSError as exc:
            raise RunStoreError(
                f"cannot salvage {run}: {exc.strerror or exc}; history.bin left as it was"
            ) from exc
        damaged = [p for p in rest if p.kind != "record"]
        kept = [p for p in rest if p.kind == "record"]
        try:
            fsync_write(folder / DAMAGED_FILE, (data[p.start : p.end] for p in damaged))
            fsync_write(folder / KEPT_FILE, (data[p.start : p.end] for p in kept))
            placed: list[dict[str, object]] = []
            offsets = {DAMAGED_FILE: 0, KEPT_FILE: 0}
            for p in s.pieces:
                if p.start < s.prefix_end:
                    to, at = HISTORY_FILE, p.start
                else:
                    to = KEPT_FILE if p.kind == "record" else DAMAGED_FILE
                    at = offsets[to]
                    offsets[to] += p.size
                placed.append(
                    {"start": p.start, "end": p.end, "kind": p.kind, "episode": p.episode,
                     "why": p.why, "file": to, "at": at}
                )  # fmt: skip
            report = {
                "salvaged": time.strftime("%Y-%m-%dT%H:%M:%S%z"),
                "history_bytes_before": len(data),
                "kept_in_history": s.prefix,
                "good_records_moved": len(kept),
                "damaged_bytes_moved": sum(p.size for p in damaged),
                "recorded_in_metrics": s.recorded,
                "pieces": placed,
            }
            fsync_write(folder / SALVAGE_REPORT, iter([json.dumps(report, indent=1).encode()]))
            fsync_dir(folder)
            with open(path, "r+b") as f:  # the rest is safe on disk: cut it from the history
                f.truncate(s.prefix_end)
                os.fsync(f.fileno())
        except OSError as exc:
            shutil.rmtree(folder, ignore_errors=True)  # a partial copy: history.bin has it all
            with contextlib.suppress(OSError):
                folder.parent.rmdir()  # salvage/ itself, if this made it and nothing else is in
            raise RunStoreError(
                f"cannot salvage {run}: {exc.strerror or exc}; history.bin left as it was"
            ) from exc
        return SalvageResult(s.prefix, len(kept), sum(p.size for p in damaged), folder, s.missing)


def iter_records(path: str | Path) -> Iterator[EpisodeRecord]:
    """The good records of a file framed as ``history.bin`` (e.g. a salvage's ``kept.bin``),
    skipping anything damaged."""
    data = Path(path).read_bytes()
    for p in survey_bytes(data).good:
        yield EpisodeRecord.from_bytes(data[p.start + HEADER.size : p.end])
