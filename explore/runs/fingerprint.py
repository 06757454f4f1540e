"""A run's fingerprint: one SHA-256 over what the run explored, so that two runs compare in one
line (``ergo runs fingerprint RUN [RUN ...]``; ``run.json`` keeps the last one under
``FINGERPRINT_KEY``).

What it covers, per episode in order: the motor parameters, the goal, its module and the
episode's kind, the ball (and distractor) before and after, whether the ball moved, the joint
targets sent and the joints measured, the tool tip's path, the joints at the start, the twin's
integration state after the episode, and the metric (ball and tool-tip cells after it). What it
leaves out: wall and clock times (``duration_s``, ``settle_s``: on a physical rig they are the
clock's), and the outcome image and camera frames (a render: its pixels depend on the GL
driver; where the ball and the arm were is in the positions). The history's framing, its
compression and ``run.json`` are not part of it: a run resumed, salvaged or copied has the
fingerprint of the episodes it holds.

Canonical bytes (version ``VERSION``), fed to SHA-256 in this order:

- ``b"ergo-explore run fingerprint 1\\n"``;
- per episode: the integers episode, module, ball moved (0 or 1), ball cells, tool-tip cells,
  each int64 little endian; the kind, UTF-8, then one zero byte; then each array of
  ``ARRAY_FIELDS`` in that order: its number of dimensions and each dimension (int64 little
  endian), then its values as float64 little endian in C order, every NaN written as the one
  quiet NaN ``0x7ff8000000000000`` (an unseen ball is NaN however it was computed).

A run made on the twin or ArmBalls by a strategy without a neural network has the same
fingerprint on every x86-64 machine (docs/determinism.md says what is covered and how it is
tested); a run on a physical arm has its own, like any measurement.
"""

from __future__ import annotations

import hashlib
import os
import struct
from collections.abc import Iterable
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from explore.learner.scene import Scene
from explore.rigs.rig import RigConfig, rig_scene
from explore.runs.config import RunConfig
from explore.runs.metrics import MetricsLog
from explore.runs.record import EpisodeRecord
from explore.runs.store import read_history

VERSION = 1
HEADER = b"ergo-explore run fingerprint 1\n"
FINGERPRINT_KEY = "fingerprint"  # run.json's key: {"sha256", "episodes", "version"}
ARRAY_FIELDS = (
    "theta", "goal", "context_ball", "ball", "context_distractor", "distractor", "targets",
    "measured", "end_effector", "start_positions", "sim_state",
)  # fmt: skip
_INTS = struct.Struct("<5q")
_QUIET_NAN = np.float64(np.nan)  # 0x7ff8000000000000


def canonical_array(a: np.ndarray) -> bytes:
    """An array's canonical bytes: ndim and shape (int64 little endian), then float64 little
    endian values in C order, NaN as the one quiet NaN."""
    v = np.ascontiguousarray(np.asarray(a, dtype="<f8"))
    v = np.where(np.isnan(v), _QUIET_NAN, v)
    shape = struct.pack(f"<{1 + v.ndim}q", v.ndim, *v.shape)
    return shape + v.astype("<f8").tobytes()


def episode_bytes(record: EpisodeRecord, ball_cells: int, ee_cells: int) -> bytes:
    """One episode's canonical bytes (module doc)."""
    head = _INTS.pack(
        int(record.episode), int(record.module), int(bool(record.ball_moved)), int(ball_cells),
        int(ee_cells),
    )  # fmt: skip
    kind = str(record.kind).encode() + b"\0"
    return head + kind + b"".join(canonical_array(getattr(record, f)) for f in ARRAY_FIELDS)


class Fingerprint:
    """The fingerprint of a run so far, fed one episode at a time (with its metrics row)."""

    def __init__(self) -> None:
        self._hash = hashlib.sha256(HEADER)
        self.episodes = 0
        self.ball_cells = 0

    def add(self, record: EpisodeRecord, row: dict[str, Any]) -> None:
        """Account episode ``record`` and its metrics row (``MetricsLog.update``'s)."""
        self.ball_cells = int(row["ball_cells"])  # type: ignore[call-overload]
        self._hash.update(episode_bytes(record, self.ball_cells, int(row["ee_cells"])))
        self.episodes += 1

    def hexdigest(self) -> str:
        return self._hash.hexdigest()

    def record(self) -> dict[str, Any]:
        """What ``run.json`` keeps (``FINGERPRINT_KEY``)."""
        return {"sha256": self.hexdigest(), "episodes": self.episodes, "version": VERSION}


def fingerprint_records(records: Iterable[EpisodeRecord], scene: Scene) -> Fingerprint:
    """The fingerprint of ``records`` (in order) counted on ``scene``'s grids."""
    metrics = MetricsLog(Path(os.devnull), scene)  # counts only: nothing is written
    out = Fingerprint()
    for rec in records:
        out.add(rec, metrics.update(rec))
    return out


@dataclass(frozen=True)
class RunFingerprint:
    """A run folder's fingerprint as computed from its history, and the one ``run.json``
    recorded (None if none; it may be of fewer episodes, or of an older code's)."""

    run: Path
    fingerprint: Fingerprint
    recorded: dict[str, Any] | None
    torn_bytes: int


def fingerprint_run(run: str | Path) -> RunFingerprint:
    """Compute ``run``'s fingerprint from its history (any run, old ones too). A
    ``RunStoreError`` (one line) for a folder that is not a run or a corrupt history."""
    history = read_history(run)
    config = RunConfig.of_run(history.meta.get("config"), Path(run) / "run.json")
    rig = config.rig
    scene = rig_scene(RigConfig(rig.name, rig.rig_id, dict(rig.options)))
    recorded = history.meta.get(FINGERPRINT_KEY)
    return RunFingerprint(
        Path(run), fingerprint_records(history.records, scene),
        recorded if isinstance(recorded, dict) else None, history.torn_bytes,
    )  # fmt: skip
