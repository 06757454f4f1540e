"""The end of a history after a crash or a power cut, and the one rule by which opening a run
(``RunStore.open``, ``RunStore.read``) and ``ergo runs check`` tell a torn tail from damage
(``explore/runs/walk.py``): a bad record with no good record after it is the last record, torn
whatever its shape (zeros, a torn length, a torn payload), with or without
``history.synced``; a bad record past ``history.synced`` starts the unsynced tail; any other is
damage, refused. The power-cut table tries every position of the last record; the property
gives arbitrary bytes to the store and to the check."""

from __future__ import annotations

import itertools
import json
import os
import shutil
import struct
from collections import Counter
from pathlib import Path

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from explore.cli import main
from explore.runs.config import RunConfig
from explore.runs.layout import (
    DAMAGED_FILE,
    HEADER,
    HISTORY_FILE,
    RUN_FILE,
    SALVAGE_DIR,
    SYNCED_FILE,
    frame,
)
from explore.runs.record import EpisodeRecord
from explore.runs.repair import survey
from explore.runs.store import RunStore, RunStoreError, read_synced

N = 4  # records in each history
ZERO_FRAME = b"EREC" + bytes(8)  # length 0, CRC-32 of nothing (0): its checksum holds


def rec(k: int) -> EpisodeRecord:
    """Episode ``k``, a few hundred bytes packed (every position of a record is tried)."""
    z = np.zeros
    return EpisodeRecord(
        episode=k, theta=np.linspace(-1, 1, 4) * (k + 1) / 7, goal=z(0), module=-1,
        kind="random", context_ball=np.array([0.1, -0.05]), ball=np.array([0.12, 0.03 * k]),
        ball_moved=bool(k % 2), targets=np.full((3, 6), 0.1 * k), measured=np.full((3, 6), 0.2),
        end_effector=np.full((3, 3), k / 3), image=np.full((2, 2, 3), k, np.uint8),
        sim_state=z(0), settle_s=0.25, duration_s=0.0,
    )  # fmt: skip


PAYLOADS = [rec(k).to_bytes() for k in range(N)]
HISTORY = b"".join(frame(p) for p in PAYLOADS)
STARTS = list(itertools.accumulate((HEADER.size + len(p) for p in PAYLOADS), initial=0))[:N]
RUN_JSON = json.dumps(
    {"app": "ergo-explore", "format": 1, "created": "", "config": RunConfig().to_dict()}
)


def make_run(path: Path, history: bytes, synced: bytes | int | None = None) -> Path:
    """A run folder (a valid twin config) holding ``history``; ``synced``: the length
    ``history.synced`` holds (its raw bytes if bytes; None: no such file, a run that fsyncs
    every append)."""
    path.mkdir(parents=True)
    (path / RUN_FILE).write_text(RUN_JSON)
    (path / HISTORY_FILE).write_bytes(history)
    if synced is not None:
        raw = synced if isinstance(synced, bytes) else struct.pack("<Q", synced)
        (path / SYNCED_FILE).write_bytes(raw)
    return path


def check(run: Path, capsys) -> tuple[int, str]:
    """``ergo runs check RUN``: (exit code, what it printed), stderr at most one line."""
    capsys.readouterr()
    rc = main(["runs", "check", str(run)])
    out, err = capsys.readouterr()
    assert err.count("\n") <= 1 and "Traceback" not in err, err
    return rc, out


def records(store: RunStore) -> list[bytes]:
    return [r.to_bytes() for r in store.records]


# ---- a frame whose checksum holds but which holds no record ------------------------------------


def test_a_zero_length_frame_at_the_end_is_a_torn_tail_and_in_the_middle_damage(tmp_path, capsys):
    """``b"EREC"`` and eight zero bytes: length 0 and CRC 0, which is the CRC-32 of nothing.
    Appended to a history it made ``RunStore.open`` and the survey raise EOFError (``ergo runs
    check`` printed a traceback). At the end it is what a power cut leaves when the record's
    marker reached the disk and nothing after it did: a torn tail, moved aside. Between two
    good records it is damage: one line, nothing touched."""
    end = make_run(tmp_path / "end", HISTORY + ZERO_FRAME)
    rc, out = check(end, capsys)
    assert rc == 0 and "a torn tail of 12 bytes (cut on resume)" in out, out
    with RunStore.open(end) as store:
        assert records(store) == PAYLOADS and store.truncated_bytes == HEADER.size
    assert (end / SALVAGE_DIR / "1" / DAMAGED_FILE).read_bytes() == ZERO_FRAME
    assert (end / HISTORY_FILE).read_bytes() == HISTORY

    at = STARTS[2]
    middle = make_run(tmp_path / "middle", HISTORY[:at] + ZERO_FRAME + HISTORY[at:])
    with pytest.raises(RunStoreError) as info:
        RunStore.open(middle)
    line = str(info.value)
    assert "\n" not in line and f"corrupt at byte {at}: undecodable record" in line
    assert f"a good record follows at byte {at + HEADER.size}" in line
    rc, out = check(middle, capsys)
    assert rc == 1 and f"1 damaged span(s): 12 bytes at byte {at} (undecodable" in out, out
    assert (middle / HISTORY_FILE).read_bytes() == HISTORY[:at] + ZERO_FRAME + HISTORY[at:]


# ---- a run that fsyncs every append: the last record as a power cut left it --------------------


@pytest.mark.parametrize(
    "shape",
    ["the whole record zeroed", "zeroed from its length on", "its length zeroed",
     "its checksum zeroed"],
)  # fmt: skip
def test_a_power_cut_in_the_last_record_of_a_run_syncing_every_append_resumes(tmp_path, shape):
    """A run with no ``history.synced`` (every append fsync'ed: the arm rigs): the append in
    flight may reach the disk as zeros anywhere. Refused before as "corrupt at byte N: bad
    record marker" (or an EOFError, or a checksum mismatch): the whole file counted as
    durable."""
    last = STARTS[-1]
    disk = bytearray(HISTORY)
    a, b = {
        "the whole record zeroed": (0, len(HISTORY) - last),
        "zeroed from its length on": (4, len(HISTORY) - last),
        "its length zeroed": (4, 8),
        "its checksum zeroed": (8, 12),
    }[shape]
    disk[last + a : last + b] = bytes(b - a)
    run = make_run(tmp_path / "run", bytes(disk))
    with RunStore.open(run) as store:
        assert records(store) == PAYLOADS[:-1], shape
        assert store.truncated_bytes == len(disk) - last
        store.append(rec(N - 1))  # the episode run again
    assert (run / HISTORY_FILE).read_bytes() == HISTORY
    assert (run / SALVAGE_DIR / "1" / DAMAGED_FILE).read_bytes() == bytes(disk[last:])


# ---- ergo runs check and history.synced ----------------------------------------------------------


@pytest.mark.parametrize("shape", ["zeros", "hole"])
def test_runs_check_honours_history_synced_as_the_resume_does(tmp_path, capsys, shape):
    """A run that fsyncs on an interval, its last two records unsynced: a power cut zeroed
    them (``zeros``), or only the first of them (``hole``: the later one reached the disk).
    The resume cuts both by itself; the check called it damage needing ``salvage``, with
    ``resumable`` False."""
    synced = STARTS[N - 2]
    disk = bytearray(HISTORY)
    end = len(HISTORY) if shape == "zeros" else STARTS[N - 1]
    disk[synced:end] = bytes(end - synced)
    run = make_run(tmp_path / "run", bytes(disk), synced)
    s = survey(run)
    assert s.resumable and not s.needs_salvage and s.prefix == N - 2
    assert s.torn is not None and (s.torn.start, s.torn.end) == (synced, len(disk))
    rc, out = check(run, capsys)
    assert rc == 0 and "ok: resumable as it is" in out, out
    assert f"a torn tail of {len(disk) - synced} bytes (past history.synced" in out
    with RunStore.open(run) as store:  # the resume agrees
        assert records(store) == PAYLOADS[: N - 2]
        for k in range(N - 2, N):
            store.append(rec(k))
    assert (run / HISTORY_FILE).read_bytes() == HISTORY and read_synced(run) == len(HISTORY)


# ---- damage in the middle is still damage --------------------------------------------------------


def _zero(data: bytes, a: int, b: int) -> bytes:
    return data[:a] + bytes(b - a) + data[b:]


MIDDLE = STARTS[1]
MIDDLE_DAMAGE = {
    "a record zeroed": _zero(HISTORY, MIDDLE, STARTS[2]),
    "its marker zeroed": _zero(HISTORY, MIDDLE, MIDDLE + 4),
    "its length zeroed": _zero(HISTORY, MIDDLE + 4, MIDDLE + 8),
    "its length made longer": HISTORY[: MIDDLE + 6] + b"\x7f" + HISTORY[MIDDLE + 7 :],
    "a byte of its payload flipped": HISTORY[: MIDDLE + 40]
    + bytes([HISTORY[MIDDLE + 40] ^ 0xFF])
    + HISTORY[MIDDLE + 41 :],
    "it and the last record zeroed": _zero(
        _zero(HISTORY, MIDDLE, STARTS[2]), STARTS[-1], len(HISTORY)
    ),
}


@pytest.mark.parametrize("synced", [None, len(HISTORY)], ids=["no synced", "all synced"])
@pytest.mark.parametrize("damage", list(MIDDLE_DAMAGE))
def test_damage_with_a_good_record_after_it_is_refused(tmp_path, capsys, damage, synced):
    """What tells a torn last record from damage is the good record after it: zeros or a
    changed header in the middle of a file are refused in one line (nothing touched), and the
    check says ``salvage``."""
    disk = MIDDLE_DAMAGE[damage]
    assert disk != HISTORY
    run = make_run(tmp_path / "run", disk, synced)
    with pytest.raises(RunStoreError) as info:
        RunStore.open(run)
    line = str(info.value)
    assert "\n" not in line and f"corrupt at byte {MIDDLE}" in line and "a good record" in line
    assert (run / HISTORY_FILE).read_bytes() == disk
    rc, out = check(run, capsys)
    assert rc == 1 and "damaged: `ergo runs salvage" in out, out


# ---- the power-cut table ----------------------------------------------------------------------

SHAPES = ("zeros", "torn")  # zeros from the position to the record's end; the file cut there
SYNCED = {"none": None, "last unsynced": STARTS[-1], "last two unsynced": STARTS[-2]}


def _power_cut(shape: str, at: int) -> bytes:
    """The history with its last record damaged from byte ``at`` of its frame on."""
    cut = STARTS[-1] + at
    return HISTORY[:cut] + (bytes(len(HISTORY) - cut) if shape == "zeros" else b"")


def test_the_power_cut_table_every_shape_at_every_position_resumes(tmp_path, monkeypatch, capsys):
    """Zeros from each byte of the last record's frame to its end, and the file cut at each
    byte (in the length field: a torn length; past the header: a torn payload), each without
    ``history.synced`` and with the last one or two records past it. At every position the
    check says resumable with the tail torn, and a reader (the resume's own reading, without
    the cut) keeps every good record and counts the rest. At every byte of the header and every
    8th of the payload (and its last), the resume itself runs: it keeps every good record,
    moves the tail aside byte for byte, and the episode appended again gives the uninterrupted
    history back. fsync is skipped here (this is about which bytes go where, not about
    durability)."""
    monkeypatch.setattr(os, "fsync", lambda fd: None)
    last, size = STARTS[-1], len(HISTORY) - STARTS[-1]
    table: Counter[tuple[str, str, str, str]] = Counter()
    for (mode, synced), shape in itertools.product(SYNCED.items(), SHAPES):
        run = make_run(tmp_path / f"{mode}-{shape}", HISTORY, synced)
        for at in range(size):
            disk = _power_cut(shape, at)
            reset(run, disk, synced)
            tail, where = len(disk) - last, (mode, shape, at)
            s = survey(run)
            assert s.resumable and s.prefix == N - 1 and s.recorded is None, where
            assert (s.torn.size if s.torn else 0) == tail, where
            reader = RunStore.read(run)
            assert records(reader) == PAYLOADS[:-1] and reader.torn_bytes == tail, where
            part = "length" if at < HEADER.size else "payload"
            table[(mode, shape, part, "checked")] += 1
            if not (at < HEADER.size or at % 8 == 0 or at == size - 1):
                continue
            with RunStore.open(run) as store:
                assert records(store) == PAYLOADS[:-1] and store.truncated_bytes == tail, where
                store.append(rec(N - 1))
            assert (run / HISTORY_FILE).read_bytes() == HISTORY, where
            if tail:
                assert (store.moved_aside / DAMAGED_FILE).read_bytes() == disk[last:], where
            table[(mode, shape, part, "resumed")] += 1
    rc, out = check(make_run(tmp_path / "cli", _power_cut("zeros", 0)), capsys)
    assert rc == 0 and "ok: resumable as it is" in out
    with capsys.disabled():
        print(f"\npower-cut table (the last of {N} records: {size} bytes), all resumable:")
        for mode, shape, part in itertools.product(SYNCED, SHAPES, ("length", "payload")):
            n, resumed = (
                table[(mode, shape, part, "checked")],
                table[(mode, shape, part, "resumed")],
            )
            print(
                f"  synced: {mode:18} {shape:6} in its {part:8} {n:4} positions ({resumed} resumed)"
            )
    assert sum(n for k, n in table.items() if k[3] == "checked") == len(SYNCED) * len(SHAPES) * size


def reset(run: Path, history: bytes, synced: int | bytes | None) -> None:
    """Give ``run`` another history (and ``history.synced``), and remove what a resume moved
    aside. The files are overwritten in place, not emptied, and one folder serves many
    cases: freeing a block costs milliseconds on a disk mounted with ``discard``."""
    _overwrite(run / HISTORY_FILE, history)
    if synced is None:
        (run / SYNCED_FILE).unlink(missing_ok=True)
    else:
        raw = synced if isinstance(synced, bytes) else struct.pack("<Q", synced)
        _overwrite(run / SYNCED_FILE, raw)
    for folder in (run / SALVAGE_DIR).glob("*"):
        shutil.rmtree(folder)


def _overwrite(path: Path, data: bytes) -> None:
    fd = os.open(path, os.O_WRONLY | os.O_CREAT, 0o644)
    try:
        os.pwrite(fd, data, 0)
        os.ftruncate(fd, len(data))
    finally:
        os.close(fd)


# ---- the property: any bytes given to the store and the check --------------------------------


def _examples(n: int) -> settings:
    """``n`` examples in the suite; the ``fuzz`` profile's count under ``--hypothesis-profile
    fuzz`` (tests/conftest.py)."""
    fuzzing = settings.get_current_profile_name() == "fuzz"
    common = {"deadline": None, "suppress_health_check": list(HealthCheck)}
    return settings(**common) if fuzzing else settings(max_examples=n, **common)


@st.composite
def histories(draw: st.DrawFn) -> bytes:
    """Arbitrary bytes, or the good history changed a few ways: bytes flipped or zeroed, the
    file cut, frames inserted (the zero-length one, a good one out of place, random ones)."""
    if draw(st.booleans()):
        return draw(st.binary(max_size=300))
    data = bytearray(HISTORY)
    for _ in range(draw(st.integers(0, 4))):
        at = draw(st.integers(0, len(data)))
        op = draw(st.sampled_from(["flip", "zeros", "cut", "insert", "frame"]))
        if op == "flip" and at < len(data):
            data[at] ^= 1 << draw(st.integers(0, 7))
        elif op == "zeros":
            n = draw(st.integers(1, 300))
            data[at : at + n] = bytes(len(data[at : at + n]))
        elif op == "cut":
            del data[at:]
        elif op == "insert":
            data[at:at] = draw(st.binary(min_size=1, max_size=40))
        else:
            inner = draw(st.sampled_from([b"", PAYLOADS[0], PAYLOADS[-1]]) | st.binary(max_size=40))
            data[at:at] = frame(inner)
    return bytes(data)


synced_files = st.none() | st.integers(0, len(HISTORY) + 50) | st.binary(max_size=12)
HISTORY_EXAMPLES = 150


def test_any_history_opens_or_checks_to_records_or_one_line(tmp_path_factory, capsys):
    """The class behind the crash: arbitrary history bytes (and an arbitrary
    ``history.synced``) given to ``RunStore.read``, ``RunStore.open`` and ``ergo runs check``
    end in records or one line (``RunStoreError``, ``ergo: error:``), never another exception;
    and the check and the store agree, by their one rule: the check calls the history
    resumable exactly when the store opens it, with the same records and the same torn tail."""
    seen: Counter[str] = Counter()
    run = make_run(tmp_path_factory.mktemp("histories") / "run", b"")

    @_examples(HISTORY_EXAMPLES)
    @given(histories(), synced_files)
    def opens_or_one_line(data: bytes, synced: int | bytes | None) -> None:
        seen["examples"] += 1
        reset(run, data, synced)
        s = survey(run)
        try:
            reader = RunStore.read(run)
        except RunStoreError as exc:
            assert "\n" not in str(exc) and s.needs_salvage, str(exc)
            seen["refused"] += 1
        else:
            assert not s.needs_salvage and len(reader) == s.prefix
            assert reader.torn_bytes == (s.torn.size if s.torn else 0)
            seen["torn" if reader.torn_bytes else "whole"] += 1
        rc, _ = check(run, capsys)
        assert rc == (1 if s.needs_salvage else 0)
        try:
            with RunStore.open(run) as store:
                assert len(store) == s.prefix
            assert (run / HISTORY_FILE).read_bytes() == data[: s.prefix_end]
        except RunStoreError as exc:
            assert "\n" not in str(exc) and s.needs_salvage, str(exc)
            assert (run / HISTORY_FILE).read_bytes() == data  # nothing touched

    opens_or_one_line()
    with capsys.disabled():
        print(f"\nhistories given to the store and the check: {dict(seen)}")
    assert seen["examples"] >= min(HISTORY_EXAMPLES, 100)
    assert seen["refused"] and seen["torn"] and seen["whole"]
