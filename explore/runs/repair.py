"""Checking and salvaging a run's history (``ergo runs check RUN``, ``ergo runs salvage RUN``).

``survey`` walks ``history.bin`` without trusting it, by the rule that opening the run uses
(``explore/runs/walk.py``, honouring ``history.synced`` as a resume does): at each offset, a
record whose marker and checksum hold and whose payload decodes is good; anything else is
damaged, up to the next offset where a good record starts (found by its marker, then its
checksum: a payload holding the marker by chance fails its own checksum there). A bad last
record (no good record after it), or a bad record past ``history.synced``, starts the torn
tail (a crash mid-append, a power cut), which opening the run cuts by itself. The run can
resume from its longest prefix of good records numbered 0, 1, 2, ...

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

from explore.runs.layout import (
    DAMAGED_FILE,
    FRAMES_DIR,
    HISTORY_FILE,
    KEPT_FILE,
    RUN_FILE,
    SALVAGE_REPORT,
)
from explore.runs.lock import run_lock
from explore.runs.metrics import recorded_episodes
from explore.runs.record import EpisodeRecord
from explore.runs.store import (
    RunStore,
    RunStoreError,
    check_own_files,
    fsync_dir,
    fsync_write,
    new_salvage_folder,
    read_frames,
    read_synced,
)
from explore.runs.walk import Piece, walk


@dataclass
class Survey:
    """What ``history.bin`` holds.

    Attributes:
        size: bytes of the file (0 when missing).
        pieces: the file cut into good records and damaged spans, in order, covering it all.
        prefix: episodes 0..prefix-1 stored in order from the start, with nothing between.
        prefix_end: byte offset where that prefix ends.
        synced: the length of the history known to be on disk (``history.synced``), None for
            a run that fsyncs every append.
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
    synced: int | None = None
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


def survey_bytes(data: bytes, synced: int | None = None) -> Survey:
    """Cut ``data`` (a history's bytes) into pieces by the rule of ``explore/runs/walk.py``;
    ``synced``: the length known to be on disk (``history.synced``); no witness (see
    ``survey``)."""
    s = Survey(size=len(data), synced=synced)
    in_prefix = True
    for piece, _ in walk(data, synced):
        s.pieces.append(piece)
        if piece.kind == "torn":
            break
        if in_prefix and piece.kind == "record" and piece.episode == s.prefix:
            s.prefix += 1
            s.prefix_end = piece.end
        else:
            in_prefix = False
    return s


def survey(run: str | Path) -> Survey:
    """Survey ``RUN/history.bin`` (read only: safe while another process writes the run)."""
    from explore.runs.config import RunConfig

    run = Path(run)
    meta = RunStore.read_meta(run)  # a one-line error for a folder that holds no run
    path = run / HISTORY_FILE
    try:
        data = path.read_bytes()
        s = survey_bytes(data, read_synced(run))
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
            + (f", a torn tail of {s.torn.size} bytes ({_torn(s)}cut on resume)" if s.torn else "")
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


def _torn(s: Survey) -> str:
    """Why the torn tail is cut, for a tail past ``history.synced``."""
    torn = s.torn
    if torn is None or s.synced is None or torn.start < s.synced:
        return ""
    return "past history.synced, the length known on disk: a power cut's unsynced tail, "


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
        s = survey_bytes(data, read_synced(run))
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
    for _, rec in walk(Path(path).read_bytes()):
        if rec is not None:
            yield rec
