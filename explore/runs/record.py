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

import functools
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
        """A record from its stored bytes, packed or npz (module doc).

        Bytes that are not such a record (empty, a bare ``.npy``, an array or field this class
        does not have, a wrong type, a truncated or inconsistent stream...) raise
        ``RecordError`` with one line, never another exception: a history's bytes come from a
        disk, and a frame whose checksum holds may still hold no record (``b"EREC"`` and eight
        zero bytes frame an empty payload)."""
        if data[:4] == PACKED_MAGIC:
            return cls._from_packed(data)
        if data[:2] != b"PK":
            raise RecordError(
                f"episode record is not readable: it starts with {bytes(data[:4])!r}, neither "
                f"a packed record ({PACKED_MAGIC!r}) nor an npz one (b'PK')"
                if data
                else "episode record is not readable: it is empty"
            )
        try:
            return cls._from_npz(data)
        except RecordError:
            raise
        except Exception as exc:  # any kind: see below
            # numpy and zipfile raise many kinds on damaged bytes (EOFError, BadZipFile,
            # NotImplementedError for an unknown compression, RuntimeError for an encrypted
            # member, MemoryError for an array shape no memory holds...); this reads nothing
            # but ``data``, so whatever it raises is the bytes' fault
            raise _unreadable(exc) from exc

    @classmethod
    def _from_npz(cls, data: bytes) -> EpisodeRecord:
        with np.load(io.BytesIO(data), allow_pickle=False) as z:
            if not isinstance(z, np.lib.npyio.NpzFile):
                raise RecordError("episode record is not readable: not an npz archive")
            kw: dict[str, object] = {}
            for name in (*_ARRAY_FIELDS, *(n for n in _OPTIONAL_FIELDS if n in z.files)):
                kw[name] = _checked_array(name, z[name])
            for name, typ in _SCALAR_FIELDS.items():
                kw[name] = typ(z[name].item())
        return cls(**kw)  # type: ignore[arg-type]

    @classmethod
    def _from_packed(cls, data: bytes) -> EpisodeRecord:
        try:
            (n,) = _HEAD.unpack_from(data, len(PACKED_MAGIC))
            start = len(PACKED_MAGIC) + _HEAD.size
            if start + n > len(data):
                raise RecordError(
                    f"episode record is not readable: its header ({n} bytes) runs past its "
                    f"end ({len(data)} bytes)"
                )
            head = json.loads(data[start : start + n])
        except (ValueError, struct.error, RecursionError) as exc:  # JSON, UTF-8, a short head
            raise _unreadable(exc) from exc
        if not isinstance(head, dict):
            raise RecordError("episode record is not readable: its header is not an object")
        layout = _packed_layout(head.get("arrays"))
        kw: dict[str, object] = _packed_scalars(head.get("scalars"))
        body = data[start + n :]
        size = sum(count * dt.itemsize for _, dt, _, count in layout)
        if size > _MAX_ZLIB_RATIO * len(body) + _MAX_ZLIB_RATIO:
            raise RecordError(
                f"episode record is not readable: its header declares {size} bytes of arrays, "
                f"more than {len(body)} compressed bytes can hold"
            )
        try:
            inflate = zlib.decompressobj()
            raw = bytearray(inflate.decompress(body, size + 1))  # writable arrays
        except zlib.error as exc:
            raise _unreadable(exc) from exc
        if len(raw) != size or not inflate.eof:
            found = (
                f"{len(raw)} stored"
                if inflate.eof
                else "more stored"
                if len(raw) > size
                else f"a stream cut short after {len(raw)}"
            )
            raise RecordError(
                "episode record is not readable: its arrays do not match the header "
                f"({size} bytes declared, {found})"
            )
        offset = 0
        for name, dt, shape, count in layout:
            kw[name] = np.frombuffer(raw, dtype=dt, count=count, offset=offset).reshape(shape)
            offset += count * dt.itemsize
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


# deflate's largest expansion: 1032 bytes out for 1 byte in (zlib's technical details,
# https://zlib.net/zlib_tech.html, "Maximum compression factor"); a header declaring more than
# that describes arrays the stream cannot hold, refused before anything is allocated
_MAX_ZLIB_RATIO = 1032
_KNOWN_ARRAYS = frozenset((*_ARRAY_FIELDS, *_OPTIONAL_FIELDS))
_ARRAY_KINDS = "biuf"  # numbers: bool, signed and unsigned integers, floats (what records hold)
_MAX_NDIM = 8  # a record's arrays have at most 3 dimensions (the image): a generous bound


def _unreadable(exc: BaseException) -> RecordError:
    why = str(exc).splitlines()[0] if str(exc).strip() else type(exc).__name__
    return RecordError(f"episode record is not readable: {why}")


def _checked_array(name: str, a: np.ndarray) -> np.ndarray:
    """``a`` as stored for field ``name``: an array of numbers (RecordError otherwise)."""
    if not isinstance(a, np.ndarray) or a.dtype.kind not in _ARRAY_KINDS or a.ndim > _MAX_NDIM:
        raise RecordError(f"episode record is not readable: {name} is not an array of numbers")
    return a


def _packed_layout(arrays: object) -> list[tuple[str, np.dtype, tuple[int, ...], int]]:
    """(name, dtype, shape, element count) of each array a packed header lists, checked: the
    names this class has (each once, the required ones all there), dtypes of numbers, shapes
    of non-negative integers (``RecordError`` otherwise)."""
    if not isinstance(arrays, list):
        raise RecordError("episode record is not readable: its header lists no arrays")
    layout, seen = [], set()
    for entry in arrays:
        if not (isinstance(entry, list) and len(entry) == 3):
            raise RecordError(f"episode record is not readable: array entry {entry!r:.40}")
        name, dtype, shape = entry
        if not isinstance(name, str) or name not in _KNOWN_ARRAYS:
            raise RecordError(f"episode record is not readable: unknown array {name!r:.40}")
        if name in seen:
            raise RecordError(f"episode record is not readable: array {name} listed twice")
        seen.add(name)
        dt = _dtype(dtype) if isinstance(dtype, str) else None
        if dt is None or dt.kind not in _ARRAY_KINDS or dt.shape or dt.itemsize == 0:
            raise RecordError(f"episode record is not readable: {name} has dtype {dtype!r:.40}")
        if not (
            isinstance(shape, list)
            and len(shape) <= _MAX_NDIM
            and all(type(d) is int and d >= 0 for d in shape)  # no bool, no float
        ):
            raise RecordError(f"episode record is not readable: {name} has shape {shape!r:.40}")
        layout.append((name, dt, tuple(shape), math.prod(shape)))
    missing = [n for n in _ARRAY_FIELDS if n not in seen]
    if missing:
        raise RecordError(f"episode record is not readable: no array {', '.join(missing)}")
    return layout


@functools.lru_cache(maxsize=64)
def _dtype(text: str) -> np.dtype | None:
    """The dtype a header names (None for a name numpy does not parse); cached: parsing the
    same few names took half the time of decoding a small record."""
    try:
        return np.dtype(text)
    except Exception:  # numpy's dtype parser raises several kinds
        return None


def _packed_scalars(scalars: object) -> dict[str, object]:
    """The scalar fields of a packed header, each of its JSON type (``RecordError`` otherwise;
    a float field takes an integer too, a bool is no number)."""
    if not isinstance(scalars, dict):
        raise RecordError("episode record is not readable: its header lists no scalars")
    out: dict[str, object] = {}
    for name, typ in _SCALAR_FIELDS.items():
        v = scalars.get(name)
        ok = (
            isinstance(v, (int, float)) and not isinstance(v, bool)
            if typ is float
            else isinstance(v, typ) and (typ is bool or not isinstance(v, bool))
        )
        if not ok or (typ is float and not _fits_float(v)):
            raise RecordError(f"episode record is not readable: {name} is {v!r:.40}")
        out[name] = typ(v)
    return out


def _fits_float(v: float) -> bool:
    try:
        float(v)
    except OverflowError:  # an integer past 1e308
        return False
    return True
