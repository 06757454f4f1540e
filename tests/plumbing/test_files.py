"""plumbing.files.atomic_write, the one atomic write of the project: the target holds the old
bytes or the new ones, never a part; a failure leaves no temporary file."""

from __future__ import annotations

import errno
import os

import numpy as np
import pytest

from plumbing.files import atomic_write, temporary_name


def test_bytes_text_and_a_writer_function_land_whole(tmp_path):
    atomic_write(tmp_path / "a.bin", b"\x00\x01")
    atomic_write(tmp_path / "b.json", '{"x": 1}')
    atomic_write(tmp_path / "c.npz", lambda tmp: np.savez_compressed(tmp, x=np.arange(3)))
    assert (tmp_path / "a.bin").read_bytes() == b"\x00\x01"
    assert (tmp_path / "b.json").read_text() == '{"x": 1}'
    assert np.load(tmp_path / "c.npz")["x"].tolist() == [0, 1, 2]  # numpy saw the .npz suffix
    assert sorted(p.name for p in tmp_path.iterdir()) == ["a.bin", "b.json", "c.npz"]


def test_a_failed_write_leaves_the_old_file_and_no_temporary_one(tmp_path, monkeypatch):
    target = tmp_path / "run.json"
    target.write_text("old")
    real_write = os.write

    def full_disk(fd: int, data: bytes) -> int:
        raise OSError(errno.ENOSPC, "No space left on device")

    monkeypatch.setattr(os, "write", full_disk)
    with pytest.raises(OSError, match="No space"):
        atomic_write(target, "new")
    monkeypatch.setattr(os, "write", real_write)
    with pytest.raises(ZeroDivisionError):
        atomic_write(target, lambda tmp: 1 / 0)
    assert target.read_text() == "old"
    assert [p.name for p in tmp_path.iterdir()] == ["run.json"]


def test_a_link_at_the_temporary_name_is_not_written_through(tmp_path):
    victim = tmp_path / "victim"
    victim.write_text("precious")
    target = tmp_path / "out.txt"
    temporary_name(target).symlink_to(victim)  # a dead writer's name, made a link by someone
    atomic_write(target, "data")
    assert victim.read_text() == "precious" and target.read_text() == "data"
