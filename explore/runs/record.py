"""The record of one episode, as stored in a run's history.

Shapes and units (lengths in the rig's unit: metres on the Ergo Jr rigs, the arm's reach on
ArmBalls): theta (n_params,) in [-1, 1] (48 DMP parameters on the Ergo Jr, 49 on ArmBalls); goal
(g,) in the strategy's goal space (g may be 0); context_ball, ball (2,) (NaN when not seen);
context_distractor, distractor (2,), the second ball of a scene with a distractor (NaN without
one: then they are not stored, and records written before they existed read as NaN); targets,
measured (T, n_joints) rad (the command sent at each tick of the movement, and the joints read at
the end of that tick); start_positions (n_joints,) rad, the joints read just before the first
command (empty in records written before it existed, and on ArmBalls); end_effector (T, 3);
image (64, 64, 3) BGR uint8; sim_state (k,) the twin's integration state after the episode
(empty on hardware and on ArmBalls); settle_s, duration_s seconds.

Stored form (``to_bytes``, "packed"): ``b"ERP1"``, the length of a JSON header (u32, little
endian), the header (the scalar fields, and each array's name, dtype and shape in order), then
the arrays' bytes (C order) compressed as one zlib stream (level 1). Records written before
2026-12-02 are compressed ``.npz`` files (``np.savez_compressed``'s layout, at zlib level 1);
``from_bytes`` reads both. Measured on 300 Arm-2-Balls records: the npz encoding took 3.2 ms to
write and 4.1 ms to read a record (17 zip entries each), more than the episode itself
(0.3 ms); the packed one takes about 0.2 ms each way for the same size (``bench/
bench_armballs_explore.py``).
"""

from __future__ import annotations

import io
import json
import math
import struct
import zlib
from dataclasses import dataclass, field, fields

import numpy as np

_ARRAY_FIELDS = (
    "theta", "goal", "context_ball", "ball", "targets", "measured", "end_effector", "image",
    "sim_state",
)  # fmt: skip
# stored only when known (finite somewhere); their defaults when absent
_OPTIONAL_FIELDS = ("context_distractor", "distractor", "start_positions")
_SCALAR_FIELDS = {
    "episode": int, "module": int, "kind": str, "ball_moved": bool, "settle_s": float,
    "duration_s": float,
}  # fmt: skip


# zlib level of a stored record: level 1 encodes one in half the time of numpy's default (6)
# for a 5% larger record (9.8 against 9.3 kB; measured 2026-12-01 on 100 twin episodes).
NPZ_LEVEL = 1
PACKED_MAGIC = b"ERP1"  # a packed record (an npz one starts with the zip marker b"PK")
_HEAD = struct.Struct("<I")


class RecordError(ValueError):
    """A stored record could not be decoded (wrong fields or types)."""


@dataclass
class EpisodeRecord:
    episode: int
    theta: np.ndarray
    goal: np.ndarray
    module: int
    kind: str
    context_ball: np.ndarray
    ball: np.ndarray
    ball_moved: bool
    targets: np.ndarray
    measured: np.ndarray
    end_effector: np.ndarray
    image: np.ndarray
    sim_state: np.ndarray
    settle_s: float
    duration_s: float
    context_distractor: np.ndarray = field(default_factory=lambda: np.full(2, np.nan))
    distractor: np.ndarray = field(default_factory=lambda: np.full(2, np.nan))
    start_positions: np.ndarray = field(default_factory=lambda: np.zeros(0))

    @property
    def final_end_effector(self) -> np.ndarray:
        """Tool tip at the end of the movement, shape (3,), m."""
        return self.end_effector[-1]

    def to_bytes(self) -> bytes:
        """Serialise in the packed form (module doc; no pickle)."""
        known = [n for n in _OPTIONAL_FIELDS if np.isfinite(getattr(self, n)).any()]
        arrays = [np.ascontiguousarray(getattr(self, n)) for n in (*_ARRAY_FIELDS, *known)]
        head = {
            "arrays": [
                [name, a.dtype.str, list(a.shape)]
                for name, a in zip((*_ARRAY_FIELDS, *known), arrays, strict=True)
            ],
            "scalars": {n: typ(getattr(self, n)) for n, typ in _SCALAR_FIELDS.items()},
        }
        if any(a.dtype.hasobject for a in arrays):
            raise RecordError("episode record arrays must not hold Python objects")
        text = json.dumps(head, separators=(",", ":")).encode()
        body = zlib.compress(b"".join(a.tobytes() for a in arrays), NPZ_LEVEL)
        return PACKED_MAGIC + _HEAD.pack(len(text)) + text + body

    @classmethod
    def from_bytes(cls, data: bytes) -> EpisodeRecord:
        """A record from its stored bytes, packed or npz (module doc)."""
        if data[:4] == PACKED_MAGIC:
            return cls._from_packed(data)
        try:
            with np.load(io.BytesIO(data), allow_pickle=False) as z:
                kw: dict[str, object] = {name: z[name] for name in _ARRAY_FIELDS}
                kw.update({n: z[n] for n in _OPTIONAL_FIELDS if n in z.files})
                for name, typ in _SCALAR_FIELDS.items():
                    kw[name] = typ(z[name].item())
        except (KeyError, ValueError, OSError) as exc:
            raise RecordError(f"episode record is not readable: {exc}") from exc
        return cls(**kw)  # type: ignore[arg-type]

    @classmethod
    def _from_packed(cls, data: bytes) -> EpisodeRecord:
        try:
            (n,) = _HEAD.unpack_from(data, len(PACKED_MAGIC))
            start = len(PACKED_MAGIC) + _HEAD.size
            head = json.loads(data[start : start + n])
            raw = bytearray(zlib.decompress(data[start + n :]))  # writable arrays
            kw: dict[str, object] = {}
            offset = 0
            for name, dtype, shape in head["arrays"]:
                dt = np.dtype(dtype)
                count = math.prod(shape)
                a = np.frombuffer(raw, dtype=dt, count=count, offset=offset).reshape(shape)
                offset += count * dt.itemsize
                kw[name] = a
            if offset != len(raw) or set(_ARRAY_FIELDS) - set(kw):
                raise ValueError("arrays do not match the header")
            for name, typ in _SCALAR_FIELDS.items():
                kw[name] = typ(head["scalars"][name])
        except (KeyError, ValueError, TypeError, struct.error, zlib.error) as exc:
            raise RecordError(f"episode record is not readable: {exc}") from exc
        return cls(**kw)  # type: ignore[arg-type]

    def equals(self, other: EpisodeRecord, ignore: tuple[str, ...] = ("duration_s",)) -> bool:
        """Field-by-field equality (arrays exactly), ignoring wall-clock fields."""
        for f in fields(self):
            if f.name in ignore:
                continue
            a, b = getattr(self, f.name), getattr(other, f.name)
            if isinstance(a, np.ndarray):
                if not np.array_equal(a, b, equal_nan=a.dtype.kind == "f"):
                    return False
            elif a != b:
                return False
        return True
