"""A full disk during a run: one line naming it, every complete episode kept, torque off, and
the command that resumes the run; the resumed run on the twin is the uninterrupted one.

The failure is the operating system's ``ENOSPC`` from the history's ``os.write``: injected
(after a number of appends) in-process, and for real on a 3 MB tmpfs where this process may
mount one (skipped, and said so, elsewhere).
"""

from __future__ import annotations

import errno
import os
import shutil
import subprocess
import sys
import uuid
from pathlib import Path

import pytest

import explore.runs.store as store_module
from explore.cli import main
from explore.rigs.rig import RigConfig, make_rig
from explore.runs.config import RunConfig
from explore.runs.open_run import open_run
from explore.runs.store import RunStore, RunStoreError

ROOT = Path(__file__).resolve().parents[2]
N = 8
FILL_AT = 5  # the append of episode 5 finds the disk full


class _FullAfter:
    """``os`` as the store sees it, whose ``write`` fails with ENOSPC after ``n`` appends to
    ``history.bin`` (each append is one write of the framed record, which a regular file takes
    whole; the fsync follows it or, on the twin, at most once a second)."""

    def __init__(self, n: int) -> None:
        self.left = n

    def __getattr__(self, name: str):
        return getattr(os, name)

    def write(self, fd: int, data) -> int:
        history = os.readlink(f"/proc/self/fd/{fd}").endswith("history.bin")
        if history and self.left <= 0:
            raise OSError(errno.ENOSPC, os.strerror(errno.ENOSPC))
        written = os.write(fd, data)
        if history:
            self.left -= 1
        return written


def _history(run: Path) -> list:
    return RunStore.read(run).records


@pytest.fixture(scope="module")
def reference(tmp_path_factory) -> Path:
    out = tmp_path_factory.mktemp("ref") / "run"
    args = ["explore", "--episodes", str(N), "--seed", "2", "--out", str(out), "--no-progress"]
    assert main([*args, "--rerun", "off"]) == 0
    return out


def test_a_full_disk_keeps_the_episodes_and_turns_torque_off(tmp_path, monkeypatch):
    monkeypatch.setattr(store_module, "os", _FullAfter(FILL_AT))
    rig = make_rig(RigConfig())
    run = open_run(tmp_path / "run", RunConfig(seed=2, episodes=N), rig=rig)
    with run, pytest.raises(RunStoreError) as info:
        run.explore()
    message = str(info.value)
    assert "\n" not in message and "No space left on device" in message
    assert f"the {FILL_AT} episode(s) before it are kept" in message
    assert not rig.arm.torque_enabled and not rig.sensor.twin.torque_enabled()  # torque off
    monkeypatch.undo()
    assert [r.episode for r in _history(tmp_path / "run")] == list(range(FILL_AT))


def test_ergo_explore_on_a_full_disk_says_one_line_with_the_resume_command(
    tmp_path, monkeypatch, capsys, reference
):
    out = tmp_path / "run"
    monkeypatch.setattr(store_module, "os", _FullAfter(FILL_AT))
    args = ["explore", "--episodes", str(N), "--seed", "2", "--out", str(out), "--no-progress"]
    assert main([*args, "--rerun", "off"]) == 2
    err = [ln for ln in capsys.readouterr().err.splitlines() if not ln.startswith("INFO ")]
    assert len(err) == 1, err
    assert err[0].startswith("ergo: error: cannot store episode 5 in ")
    assert f"run paused after {FILL_AT} episodes: resume with ergo explore --resume {out}" in err[0]
    monkeypatch.undo()
    assert main(["explore", "--resume", str(out), "--no-progress", "--rerun", "off"]) == 0
    a, b = _history(out), _history(reference)
    assert len(a) == N and all(x.equals(y) for x, y in zip(a, b, strict=True))


def _tmpfs(size: str) -> Path | None:
    where = Path(f"/tmp/ergo-full-{uuid.uuid4().hex[:8]}")
    where.mkdir()
    ok = subprocess.run(["mount", "-t", "tmpfs", "-o", f"size={size}", "tmpfs", str(where)],
                        capture_output=True).returncode == 0  # fmt: skip
    if not ok:
        where.rmdir()
        return None
    return where


@pytest.mark.slow
def test_a_real_full_disk_on_a_small_tmpfs(tmp_path):
    where = _tmpfs("3m") if shutil.which("mount") and os.geteuid() == 0 else None
    if where is None:
        pytest.skip("cannot mount a tmpfs here (needs root): the in-process tests cover it")
    try:
        out = where / "run"
        cmd = [sys.executable, "-m", "explore.cli", "explore", "--episodes", "1000",
               "--out", str(out), "--no-progress"]  # fmt: skip
        done = subprocess.run(cmd, cwd=ROOT, capture_output=True, text=True, timeout=600)
        err = [ln for ln in done.stderr.splitlines() if not ln.startswith("INFO ")]
        assert done.returncode == 2 and len(err) == 1, done.stderr
        assert "No space left on device" in err[0] and "run paused after" in err[0]
        stored = len(_history(out))
        assert stored > 0 and f"paused after {stored} episodes" in err[0]
        assert f"resume with ergo explore --resume {out}" in err[0]
        assert not list(out.glob("*.tmp*"))  # no half-written derived file left
    finally:
        subprocess.run(["umount", str(where)], check=False)
        where.rmdir()
