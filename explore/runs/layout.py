"""The layout of a run folder: the name of every file in it, and the framing of its history.
The one place of both; ``store`` (reading and appending), ``repair`` (``ergo runs check`` and
``salvage``), ``lock``, ``open_run``, the metric, the campaigns' trials and the reports take
their names from here. What each file holds and when it is written: ``explore/runs/store.py``.

``RUN/``:
- ``run.json`` (``RUN_FILE``): format, config, creation time, the input files it depends on
  (under ``INPUTS_KEY``, ``explore/runs/inputs.py``) and the prior it is warmed by (under
  ``PRIOR_KEY``, ``explore/runs/prior.py``);
- ``history.bin`` (``HISTORY_FILE``): the episodes, each framed (``frame``) as
  ``b"EREC" | u32 length | u32 CRC-32 of the payload | payload``, little endian;
- ``history.synced`` (``SYNCED_FILE``): a length of the history known to be on disk;
- ``frames/episode-NNNNNN.npz`` (``FRAMES_DIR``, ``frames_path``): camera frames;
- ``writer.lock`` (``WRITER_LOCK_FILE``): the writer's lock (``explore/runs/lock.py``);
- ``reality_gap.csv`` (``REALITY_GAP_FILE``): a run warmed by a prior, its episodes answered
  by the prior, with the prior's outcome beside the arm's (``explore/runs/prior.py``);
- ``metrics.csv`` (``METRICS_FILE``), ``faults.json`` (``FAULTS_FILE``), ``trial.json``
  (``TRIAL_FILE``, a campaign's trial), ``coverage.png`` (``COVERAGE_FILE``), ``recording.rrd``
  (``RECORDING_FILE``, the rerun recording);
- ``salvage/N/`` (``SALVAGE_DIR``): what ``ergo runs salvage`` or a resume moved out of the
  history: ``damaged.bin``, ``kept.bin``, ``salvage.json``.
"""

from __future__ import annotations

import struct
import zlib
from pathlib import Path

RUN_FILE = "run.json"
HISTORY_FILE = "history.bin"
SYNCED_FILE = "history.synced"
METRICS_FILE = "metrics.csv"
FAULTS_FILE = "faults.json"  # the arm's fault and recovery counters, summed over sessions
TRIAL_FILE = "trial.json"  # a campaign trial's worker and result (explore/campaigns/trial.py)
COVERAGE_FILE = "coverage.png"
RECORDING_NAME = "recording"  # RUN/recording.rrd, then RUN/recording-2.rrd, ... on resumes
RECORDING_FILE = f"{RECORDING_NAME}.rrd"  # the rerun recording (explore/report/recorder.py)
FRAMES_DIR = "frames"
WRITER_LOCK_FILE = "writer.lock"  # the writer's lock (explore/runs/lock.py), not run data
SALVAGE_DIR = "salvage"  # damaged or torn history moved aside (explore/runs/repair.py)
DAMAGED_FILE = "damaged.bin"  # in salvage/N/: the damaged bytes, one span after the other
KEPT_FILE = "kept.bin"  # in salvage/N/: good records after the damage, framed as the history
SALVAGE_REPORT = "salvage.json"  # in salvage/N/: every piece of the old history, where it went
INPUTS_KEY = "inputs"  # run.json's key of the input files a run depends on
# run.json's key of the episode count a resume's ``--episodes`` changed the plan to (the last
# one): the config keeps the count the run was made with
PLANNED_KEY = "planned_episodes"
PRIOR_KEY = "prior"  # run.json's key of the prior a run is warmed by (explore/runs/prior.py)
REALITY_GAP_FILE = "reality_gap.csv"  # the prior's outcomes beside the arm's (runs/prior.py)

# Files a writer of the run opens for writing (besides writer.lock, checked by the lock), and
# the folders whose files it writes: ``store.check_own_files`` refuses a link among them.
WRITER_FILES = (
    RUN_FILE, f"{RUN_FILE}.tmp", HISTORY_FILE, SYNCED_FILE, METRICS_FILE, f"{METRICS_FILE}.tmp",
    FAULTS_FILE, f"{FAULTS_FILE}.tmp", f"{FAULTS_FILE}.bad", TRIAL_FILE, COVERAGE_FILE,
    REALITY_GAP_FILE, f"{REALITY_GAP_FILE}.tmp",
)  # fmt: skip
WRITER_DIRS = (FRAMES_DIR, SALVAGE_DIR)
# What a new run writes before its first episode is stored (``open_run.discard_empty_run``
# removes only these, and only from a run that holds no episode).
NEW_RUN_FILES = (
    HISTORY_FILE, METRICS_FILE, FAULTS_FILE, TRIAL_FILE, RECORDING_FILE, RUN_FILE,
    f"{RUN_FILE}.tmp", REALITY_GAP_FILE,
)  # fmt: skip


def frames_path(run: str | Path, episode: int) -> Path:
    """Where episode ``episode``'s camera frames are kept: ``RUN/frames/episode-NNNNNN.npz``."""
    return Path(run) / FRAMES_DIR / f"episode-{episode:06d}.npz"


# ---- the framing of history.bin (and of a salvage's kept.bin) ---------------------------------
MAGIC = b"EREC"
HEADER = struct.Struct("<4sII")  # marker, payload length (bytes), CRC-32 of the payload


def frame(payload: bytes) -> bytes:
    """One record as stored: the header (marker, length, CRC-32) then ``payload``."""
    return HEADER.pack(MAGIC, len(payload), zlib.crc32(payload)) + payload


def frame_at(data: bytes | memoryview, pos: int) -> tuple[int, int, str]:
    """The frame at ``pos`` of ``data``: (payload start, end, why it is bad: "" when its
    marker and checksum hold). ``end`` is where the header says the frame ends (it may lie
    past the data); a torn header gives (len(data), len(data), "torn header")."""
    n = len(data)
    if n - pos < HEADER.size:
        return n, n, "torn header"
    magic, length, crc = HEADER.unpack_from(data, pos)
    start, end = pos + HEADER.size, pos + HEADER.size + length
    if magic != MAGIC:
        return start, end, "bad record marker"
    if end > n:
        return start, end, "record runs past the end of the file"
    if zlib.crc32(data[start:end]) != crc:
        return start, end, "checksum mismatch"
    return start, end, ""


def next_frame(data: bytes, after: int) -> int | None:
    """Offset of the first frame starting after ``after`` whose marker and checksum hold (a
    good record's frame), or None. What tells a torn tail (nothing good after it) from damage
    in the middle (a damaged length field makes a record look as if it ran past the end)."""
    at = after
    while (at := data.find(MAGIC, at + 1)) >= 0:
        if len(data) - at < HEADER.size:
            return None
        if frame_at(data, at)[2] == "":
            return at
    return None
