"""Walking a history's bytes (``history.bin``, a salvage's ``kept.bin``): which spans are good
records, which are damage, and where a torn tail starts. The one rule that opening and reading
a run (``explore/runs/store.py``) and ``ergo runs check`` / ``ergo runs salvage``
(``explore/runs/repair.py``) share.

A *good record* is a frame (``layout.frame``) whose marker and checksum hold and whose payload
decodes (``EpisodeRecord.from_bytes``). Anything else at an offset is a *bad record*: a wrong
marker, a header cut short, a length running past the end of the file, a checksum mismatch, or
a payload that holds no record (``b"EREC"`` and eight zero bytes frame an empty payload whose
checksum, 0, holds).

A bad record at byte ``p`` starts the **torn tail** (everything from ``p`` to the end of the
file: cut when the run is resumed, after being moved aside, never deleted) when

1. no good record starts anywhere after ``p``: it is the last record, left in whatever shape a
   crash or a power cut left the append in flight (cut short in its header or its payload,
   zeros anywhere in it, a length zeroed). A run fsyncs each append before the next one
   (``sync_interval_s`` = 0), so a power cut can damage no record but the last; or
2. ``p`` lies at or past ``history.synced`` (a run that fsyncs on an interval): everything
   written after the last fsync may be lost in any shape, good records after a lost one
   included (writeback in any order).

Any other bad record is **damage**, spanning up to the next good record: damage in the middle
of a file is told from a torn last record by that good record after it (a damaged length field
makes a record seem to run past the end of the file, as a tear would; a zeroed record in the
middle is followed by the good ones after it). Resuming refuses it; ``ergo runs salvage`` keeps
every good record.
"""

from __future__ import annotations

from collections.abc import Iterator
from dataclasses import dataclass
from typing import Literal

from explore.runs.layout import frame_at, next_frame
from explore.runs.record import EpisodeRecord, RecordError

Kind = Literal["record", "damaged", "torn"]


@dataclass(frozen=True)
class Piece:
    """A span of a history: ``start``/``end`` byte offsets; ``episode`` of a good record;
    ``why`` a damaged span or a torn tail is bad (the first bad record's reason)."""

    start: int
    end: int
    kind: Kind
    episode: int | None = None
    why: str = ""

    @property
    def size(self) -> int:
        return self.end - self.start


def record_at(data: bytes, pos: int) -> tuple[int, EpisodeRecord | None, str]:
    """(end, record, why) at byte ``pos`` of ``data``: the record None and ``why`` when it is
    not a good record; ``end`` is then where its header says it ends (perhaps past the data;
    ``pos + 1`` after a bad marker)."""
    start, end, why = frame_at(data, pos)
    if why == "bad record marker":
        return pos + 1, None, why
    if why:
        return end, None, why
    try:
        return end, EpisodeRecord.from_bytes(data[start:end]), ""
    except RecordError as exc:
        return end, None, f"undecodable record ({exc})"


def next_good(data: bytes, pos: int) -> int:
    """Offset of the first good record starting after ``pos``, or ``len(data)``."""
    at = pos
    while (at := next_frame(data, at)) is not None:
        if record_at(data, at)[1] is not None:
            return at
    return len(data)


def walk(data: bytes, synced: int | None = None) -> Iterator[tuple[Piece, EpisodeRecord | None]]:
    """Cut ``data`` into pieces covering it all, in order, each with its decoded record (None
    for a damaged span or the torn tail, which comes last). ``synced``: the length known to be
    on disk (``history.synced``; None for a run that fsyncs every append). The rule: module
    doc."""
    pos, n = 0, len(data)
    while pos < n:
        end, rec, why = record_at(data, pos)
        if rec is not None:
            yield Piece(pos, end, "record", rec.episode), rec
            pos = end
            continue
        nxt = next_good(data, pos)
        if nxt == n or (synced is not None and pos >= synced):
            yield Piece(pos, n, "torn", why=why), None
            return
        yield Piece(pos, nxt, "damaged", why=why), None
        pos = nxt
