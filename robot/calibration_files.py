"""Where a rig's calibration files live and how one is read as a document, at the bottom layer
so that every package can find a rig's files: ``calibration/store.py`` writes and validates
them, ``sim/servo_model.py`` reads a rig's fitted servos for ``ergo twin serve --rig-id``
(``sim/`` may not import ``calibration/``: tests/system/test_layering.py).

Layout: ``<root>/<rig_id>/<kind>.json`` where ``root`` is, in order of precedence, the
``--dir`` option, the ``ERGO_CALIBRATION_DIR`` environment variable, or
``~/.config/ergo-explore/calibration``.

Each file is ``{"schema": "ergo-explore/calibration", "kind": ..., "version": N, "rig_id": ...,
"created": ISO-8601 UTC, "data": {...}}``. ``read_document`` checks that envelope (one-line
errors naming the file and the field); each kind's payload is checked by its validator
(``calibration.store.VALIDATORS``).
"""

from __future__ import annotations

import json
import os
import re
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from plumbing.fields import Fields

SCHEMA = "ergo-explore/calibration"
ENV_DIR = "ERGO_CALIBRATION_DIR"
DEFAULT_DIR = Path("~/.config/ergo-explore/calibration")
KINDS = ("camera", "arena", "joints", "dynamics")
# Current payload version per kind; bump when a payload's fields change meaning.
VERSIONS = {"camera": 1, "arena": 1, "joints": 1, "dynamics": 1}
_RIG_ID = re.compile(r"^[A-Za-z0-9][A-Za-z0-9._-]{0,63}$")


class CalibrationError(ValueError):
    """A calibration could not be made, read or written; the message is one line."""


class CalibrationMissing(CalibrationError):
    """There is no calibration file where one was looked for (never made: not a bad file)."""


# ---- where files live --------------------------------------------------------------------
def calibration_root(directory: str | Path | None = None) -> Path:
    """The folder holding one subfolder per rig id (see the module docstring)."""
    if directory is not None:
        return Path(directory).expanduser()
    env = os.environ.get(ENV_DIR)
    if env:
        return Path(env).expanduser()
    return DEFAULT_DIR.expanduser()


def check_rig_id(rig_id: str) -> str:
    """``rig_id`` if it can name a folder (1-64 letters, digits, '.', '_', '-'), else a
    one-line ``CalibrationError``."""
    if not isinstance(rig_id, str) or not _RIG_ID.match(rig_id):
        raise CalibrationError(
            f"rig id {rig_id!r} must be 1-64 letters, digits, '.', '_' or '-' (no slash)"
        )
    return rig_id


def calibration_path(kind: str, rig_id: str, directory: str | Path | None = None) -> Path:
    """``<root>/<rig_id>/<kind>.json``."""
    if kind not in KINDS:
        raise CalibrationError(f"unknown calibration kind {kind!r}; known: {', '.join(KINDS)}")
    return calibration_root(directory) / check_rig_id(rig_id) / f"{kind}.json"


@dataclass(frozen=True)
class RigCalibration:
    """One rig's calibration files, resolved once and passed down: where its joints, camera,
    arena and dynamics files are (they may not exist). Made at a command's entry
    (``explore.rigs.rig.RigConfig.resolved`` for a run, ``ergo twin serve --rig-id``) and read
    by the rig (joints, arena), the twin (dynamics) and a run's inputs check.

    Attributes:
        rig_id: the rig's id.
        joints: its ``joints.json``, or the file named instead; None: no joint file is read.
        camera: the ``camera.json`` beside the arena file, which that file is checked against.
        arena: its ``arena.json``, or the file named instead.
        dynamics: its ``dynamics.json``.
    """

    rig_id: str
    joints: Path | None
    camera: Path
    arena: Path
    dynamics: Path

    @classmethod
    def find(
        cls,
        rig_id: str,
        directory: str | Path | None = None,
        *,
        arena: str | Path | None = None,
        joints: str | Path | None = None,
        read_joints: bool = True,
    ) -> RigCalibration:
        """Rig ``rig_id``'s files under ``calibration_root(directory)``; ``arena`` and
        ``joints`` name other files instead (``~`` expanded), ``read_joints=False`` none.
        A one-line ``CalibrationError`` for an id that cannot name a folder."""
        folder = calibration_root(directory) / check_rig_id(rig_id)
        arena_path = Path(arena).expanduser() if arena else folder / "arena.json"
        joints_path = Path(joints).expanduser() if joints else folder / "joints.json"
        return cls(
            rig_id,
            joints_path if read_joints else None,
            arena_path.with_name("camera.json"),
            arena_path,
            folder / "dynamics.json",
        )

    def existing(self, kinds: tuple[str, ...] = KINDS) -> list[tuple[str, Path]]:
        """(kind, path) of the files of ``kinds`` that exist, in that order."""
        paths = {k: getattr(self, k) for k in kinds}
        return [(k, p) for k, p in paths.items() if p is not None and p.is_file()]


# ---- reading -----------------------------------------------------------------------------
def read_document(path: str | Path, kind: str | None = None) -> dict[str, Any]:
    """Read one calibration file and check its envelope (schema, kind, version, rig id); the
    payload (``data``) is returned unchecked: its kind's validator checks it.

    Raises:
        CalibrationMissing: no file at ``path``.
        CalibrationError: an unreadable or foreign file, or a bad envelope field (one line).
    """
    path = Path(path)
    try:
        text = path.read_text()
    except FileNotFoundError:
        raise CalibrationMissing(f"no calibration file {path}") from None
    except OSError as exc:
        raise CalibrationError(f"cannot read {path}: {exc.strerror}") from None
    except UnicodeDecodeError as exc:
        raise CalibrationError(
            f"{path}: not a calibration file (binary data at byte {exc.start}, not UTF-8 JSON): "
            "restore it or calibrate again"
        ) from None
    try:
        doc = json.loads(text)
    except json.JSONDecodeError as exc:
        raise CalibrationError(
            f"{path}: not valid JSON (line {exc.lineno}, column {exc.colno}: {exc.msg})"
        ) from None
    top = Fields(str(path), doc, CalibrationError, name="data")
    if top.get("schema") != SCHEMA:
        top.fail("schema", f"must be {SCHEMA!r}, got {doc.get('schema')!r}")
    file_kind = top.string("kind")
    if file_kind not in VERSIONS or (kind is not None and file_kind != kind):
        top.fail("kind", f"must be {kind or ' or '.join(KINDS)!r}, got {file_kind!r}")
    version = top.get("version")
    if not isinstance(version, int) or isinstance(version, bool) or version < 1:
        top.fail("version", f"must be a positive integer, got {version!r}")
    if version > VERSIONS[file_kind]:
        top.fail(
            "version",
            f"is {version}, newer than this program reads ({VERSIONS[file_kind]}): upgrade",
        )
    top.string("rig_id")
    top.get("data")
    return doc
