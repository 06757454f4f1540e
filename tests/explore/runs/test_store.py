"""The run store: durable appends, torn tails cut, corruption and foreign folders refused."""

from __future__ import annotations

import json
import os

import numpy as np
import pytest

from explore.runs.layout import HISTORY_FILE, RUN_FILE
from explore.runs.record import EpisodeRecord, RecordError
from explore.runs.store import RunStore, RunStoreError


def make_record(k: int) -> EpisodeRecord:
    rng = np.random.default_rng(k)
    return EpisodeRecord(
        episode=k, theta=rng.uniform(-1, 1, 48), goal=np.zeros(0), module=-1, kind="random",
        context_ball=np.array([0.15, 0.0]), ball=np.array([np.nan, 0.1]), ball_moved=bool(k % 2),
        targets=rng.normal(size=(40, 6)), measured=rng.normal(size=(40, 6)),
        end_effector=rng.normal(size=(40, 3)),
        image=rng.integers(0, 255, (64, 64, 3), dtype=np.uint8), sim_state=rng.normal(size=30),
        settle_s=0.5, duration_s=0.01,
    )  # fmt: skip


def test_records_round_trip(tmp_path):
    with RunStore.create(tmp_path / "run", {"seed": 1}) as s:
        for k in range(3):
            s.append(make_record(k))
    again = RunStore.open(tmp_path / "run")
    assert len(again) == 3 and again.config == {"seed": 1}
    assert all(a.equals(make_record(k)) for k, a in enumerate(again))


def test_records_written_as_npz_before_the_packed_form_still_read(tmp_path):
    import io

    from explore.runs.record import PACKED_MAGIC, EpisodeRecord

    rec = make_record(4)
    assert rec.to_bytes()[:4] == PACKED_MAGIC
    fields = ("theta", "goal", "context_ball", "ball", "targets", "measured", "end_effector",
              "image", "sim_state", "episode", "module", "kind", "ball_moved", "settle_s",
              "duration_s")  # fmt: skip
    buf = io.BytesIO()
    np.savez_compressed(buf, **{f: np.asarray(getattr(rec, f)) for f in fields})
    old = EpisodeRecord.from_bytes(buf.getvalue())
    assert old.equals(rec) and np.all(np.isnan(old.distractor))
    with pytest.raises(RecordError):
        EpisodeRecord.from_bytes(PACKED_MAGIC + b"\x05\x00\x00\x00{}")


@pytest.mark.parametrize("cut", [1, 7, 12, 200])
def test_a_torn_last_record_is_cut_and_the_rest_kept(tmp_path, cut):
    with RunStore.create(tmp_path / "run", {}) as s:
        for k in range(3):
            s.append(make_record(k))
    hist = tmp_path / "run" / HISTORY_FILE
    data = hist.read_bytes()
    hist.write_bytes(data[:-cut])
    s = RunStore.open(tmp_path / "run")
    assert len(s) == 2 and s.truncated_bytes > 0
    s.append(make_record(2))  # appending continues cleanly after the cut
    s.close()
    assert len(RunStore.open(tmp_path / "run")) == 3


def test_corruption_in_the_middle_is_refused_and_nothing_is_written(tmp_path):
    with RunStore.create(tmp_path / "run", {}) as s:
        for k in range(3):
            s.append(make_record(k))
    hist = tmp_path / "run" / HISTORY_FILE
    data = bytearray(hist.read_bytes())
    data[100] ^= 0xFF  # inside the first payload
    hist.write_bytes(bytes(data))
    with pytest.raises(RunStoreError, match="corrupt at byte 0: checksum"):
        RunStore.open(tmp_path / "run")
    assert hist.read_bytes() == bytes(data)


def test_appending_out_of_order_is_refused(tmp_path):
    with RunStore.create(tmp_path / "run", {}) as s, pytest.raises(RunStoreError, match="after 0"):
        s.append(make_record(1))


def test_foreign_old_and_broken_folders_get_one_line_errors(tmp_path):
    with pytest.raises(RunStoreError, match="no such directory"):
        RunStore.open(tmp_path / "missing")
    (tmp_path / "empty").mkdir()
    with pytest.raises(RunStoreError, match=r"no run\.json"):
        RunStore.open(tmp_path / "empty")
    (tmp_path / "foreign").mkdir()
    (tmp_path / "foreign" / RUN_FILE).write_text(json.dumps({"app": "other"}))
    with pytest.raises(RunStoreError, match="field 'app'"):
        RunStore.open(tmp_path / "foreign")
    (tmp_path / "old").mkdir()
    (tmp_path / "old" / RUN_FILE).write_text(json.dumps({"app": "ergo-explore", "format": 0}))
    with pytest.raises(RunStoreError, match="field 'format'"):
        RunStore.open(tmp_path / "old")
    (tmp_path / "bad").mkdir()
    (tmp_path / "bad" / RUN_FILE).write_text("{nope")
    with pytest.raises(RunStoreError, match="not valid JSON"):
        RunStore.open(tmp_path / "bad")


def test_create_refuses_a_non_empty_folder(tmp_path):
    (tmp_path / "x").mkdir()
    (tmp_path / "x" / "keep.txt").write_text("mine")
    with pytest.raises(RunStoreError, match="not empty"):
        RunStore.create(tmp_path / "x", {})
    assert (tmp_path / "x" / "keep.txt").read_text() == "mine"


def _unsynced_run(path, monkeypatch, n=6, synced_after=2):
    """A run with a 1 s sync interval whose clock stands still after the ``synced_after``-th
    append: the history holds ``n`` records, ``history.synced`` the length of the first
    ``synced_after``. Returns (history bytes, synced length)."""
    from explore.runs import store as store_module

    now = [0.0]
    monkeypatch.setattr(store_module.time, "monotonic", lambda: now[0])
    s = RunStore.create(path, {})
    s.sync_interval_s = 1.0
    for k in range(n):
        s.append(make_record(k))
        now[0] += 1.0 if k + 1 < synced_after else 0.0
    os.close(s._fd)  # a crash: no close(), no final sync
    s._fd = None
    return (path / HISTORY_FILE).read_bytes(), store_module.read_synced(path)


def test_with_a_sync_interval_the_synced_length_follows_each_fsync_and_close(tmp_path, monkeypatch):
    from explore.runs import store as store_module

    data, synced = _unsynced_run(tmp_path / "run", monkeypatch)
    first_two = sum(len(make_record(k).to_bytes()) + 12 for k in range(2))
    assert synced == first_two < len(data)  # the two timed syncs, none for the still clock
    with RunStore.open(tmp_path / "run") as s:
        assert len(s) == 6  # a killed process loses nothing: every record was flushed
    assert store_module.read_synced(tmp_path / "run") == len(data)  # close syncs


def _record_spans(data):
    from explore.runs.store import _scan

    return [(a - 12, b) for a, b in _scan(data)[0]]  # each record's frame, header included


@pytest.mark.parametrize("damage", ["lost", "zeros", "prefix", "hole"])
def test_a_power_cut_tail_past_the_synced_length_is_cut_and_resumes(tmp_path, monkeypatch, damage):
    """What a power cut may leave of the bytes written after the last fsync: nothing, zeros,
    a prefix, or later records on disk with an earlier one missing (writeback in any order).
    Everything from the first bad record on is cut; the records before stay."""
    data, synced = _unsynced_run(tmp_path / "run", monkeypatch)
    spans = _record_spans(data)
    assert spans[2][0] == synced
    disk = bytearray(data)
    if damage == "lost":
        disk = disk[:synced]
    elif damage == "zeros":
        disk[synced:] = bytes(len(disk) - synced)
    elif damage == "prefix":
        disk = disk[: spans[3][0] + 100]
    else:  # record 3 never reached the disk, records 4 and 5 did
        a, b = spans[3]
        disk[a:b] = bytes(b - a)
    (tmp_path / "run" / HISTORY_FILE).write_bytes(bytes(disk))
    keep = {"lost": 2, "zeros": 2, "prefix": 3, "hole": 3}[damage]
    s = RunStore.open(tmp_path / "run")
    assert len(s) == keep and s.truncated_bytes == len(disk) - spans[keep][0]
    for k in range(keep, 6):  # the resume runs the cut episodes again
        s.append(make_record(k))
    s.close()
    again = RunStore.open(tmp_path / "run")
    assert all(a.equals(make_record(k)) for k, a in enumerate(again)) and len(again) == 6
    assert (tmp_path / "run" / HISTORY_FILE).read_bytes() == data


def test_damage_before_the_synced_length_is_still_refused_as_corruption(tmp_path, monkeypatch):
    data, synced = _unsynced_run(tmp_path / "run", monkeypatch)
    a, b = _record_spans(data)[1]
    assert b <= synced  # synced: a power cut cannot have touched it
    disk = bytearray(data)
    disk[a:b] = bytes(b - a)
    (tmp_path / "run" / HISTORY_FILE).write_bytes(bytes(disk))
    with pytest.raises(RunStoreError, match=f"corrupt at byte {a}"):
        RunStore.open(tmp_path / "run")
    assert (tmp_path / "run" / HISTORY_FILE).read_bytes() == bytes(disk)


def test_a_store_with_a_sync_interval_opened_and_closed_without_appending_writes_nothing(tmp_path):
    with RunStore.create(tmp_path / "run", {}) as s:
        s.sync_interval_s = 1.0
        for k in range(3):
            s.append(make_record(k))
    before = {p.name: (p.stat().st_mtime_ns, p.read_bytes()) for p in (tmp_path / "run").iterdir()}
    assert "history.synced" in before
    with RunStore.open(tmp_path / "run") as s:
        s.sync_interval_s = 1.0
    after = {p.name: (p.stat().st_mtime_ns, p.read_bytes()) for p in (tmp_path / "run").iterdir()}
    assert after == before
