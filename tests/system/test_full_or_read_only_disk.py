"""A full disk and a read-only file system under every command that writes (issue 29): one
line each (``ergo: error: ...``), never a traceback, and nothing already stored lost or left
half-written: a new run leaves nothing behind (before: only ``run.json.tmp``), an export no
partial folder, a salvage no partial copy, a resume, report or export of a run never touches
its history.

For real, not simulated: ``disk_faults.py`` mounts a small tmpfs in a private user and mount
namespace (``unshare -rm``: no privilege needed on the machine, the mount invisible to other
processes), fills it (ENOSPC) or remounts it read-only (EROFS), and runs the commands there.
Skipped, saying why, where user namespaces are not allowed.
"""

from __future__ import annotations

import json
import shutil
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from explore.cli import main
from explore.runs.layout import HISTORY_FILE
from explore.runs.repair import survey

DRIVER = Path(__file__).with_name("disk_faults.py")
ROOT = Path(__file__).resolve().parents[2]


def _namespaces_work() -> str | None:
    if shutil.which("unshare") is None:
        return "no unshare command"
    probe = subprocess.run(["unshare", "-rm", "true"], capture_output=True, text=True)
    return None if probe.returncode == 0 else f"unshare -rm refused: {probe.stderr.strip()}"


@pytest.fixture(scope="module")
def report(tmp_path_factory) -> dict:
    why = _namespaces_work()
    if why:
        pytest.skip(f"cannot mount a private tmpfs here ({why})")
    root = tmp_path_factory.mktemp("disk")
    run = root / "run"
    assert main(["explore", "--episodes", "3", "--seed", "4", "--out", str(run),
                 "--no-progress", "--rerun", "off"]) == 0  # fmt: skip
    damaged = root / "damaged"
    shutil.copytree(run, damaged)
    hist = damaged / HISTORY_FILE
    data = bytearray(hist.read_bytes())
    data[survey(damaged).good[1].start + 100] ^= 0xFF  # inside episode 1: salvage has work
    hist.write_bytes(bytes(data))
    rng = np.random.default_rng(0)
    np.savez(root / "d.npz", images=rng.integers(0, 255, (8, 64, 64, 3), dtype=np.uint8))
    m = root / "mnt"
    cmds_full = [
        ["explore", "--episodes", "2", "--out", f"{m}/new", "--no-progress", "--rerun", "off"],
        ["export", "lerobot", f"{m}/run", "--out", f"{m}/ds", "--no-video"],
        ["report", f"{m}/run", "--out", f"{m}/rep"],
        ["vae", "train", "--data", f"{m}/d.npz", "--out", f"{m}/model", "--iterations", "2",
         "--batch", "4", "--no-progress"],
        ["dataset", "outcomes", "--n", "2", "--out", f"{m}/x.npz", "--no-progress"],
        ["runs", "salvage", f"{m}/damaged"],
    ]  # fmt: skip
    cmds_ro = [
        ["explore", "--resume", f"{m}/run", "--episodes", "5", "--no-progress", "--rerun", "off"],
        ["runs", "salvage", f"{m}/damaged"],
        ["report", f"{m}/run", "--out", f"{m}/rep2"],
        ["export", "lerobot", f"{m}/run", "--out", f"{m}/ds2", "--no-video"],
        ["vae", "train", "--data", f"{m}/d.npz", "--out", f"{m}/model2", "--iterations", "2",
         "--batch", "4", "--no-progress"],
    ]  # fmt: skip
    plan = {"mount": str(m), "size_kb": 4096,
            "copy": {"run": str(run), "damaged": str(damaged), "d.npz": str(root / "d.npz")},
            "phases": [{"fill": True, "commands": cmds_full},
                       {"readonly": True, "commands": cmds_ro}]}  # fmt: skip
    (root / "plan.json").write_text(json.dumps(plan))
    cmd = ["unshare", "-rm", sys.executable, str(DRIVER), str(root / "plan.json"),
           str(root / "r.json")]  # fmt: skip
    done = subprocess.run(cmd, cwd=ROOT, capture_output=True, text=True, timeout=600)
    assert done.returncode == 0, done.stderr[-3000:]
    return json.loads((root / "r.json").read_text())


def _errors(stderr: str) -> list[str]:
    return [ln for ln in stderr.splitlines() if ln and not ln.startswith(("INFO ", "WARNING "))]


CASES = [("full", i) for i in range(6)] + [("read-only", i) for i in range(5)]


@pytest.mark.parametrize(("fs", "i"), CASES, ids=[
    "full-new-run", "full-export", "full-report", "full-train", "full-dataset", "full-salvage",
    "ro-resume", "ro-salvage", "ro-report", "ro-export", "ro-train",
])  # fmt: skip
def test_one_line_and_nothing_lost(report, fs, i):
    c = report["commands"][i if fs == "full" else 6 + i]
    errors = _errors(c["stderr"])
    assert c["rc"] == 2 and len(errors) == 1 and errors[0].startswith("ergo: error: "), c
    assert "Traceback" not in c["stderr"]
    word = "No space left on device" if fs == "full" else "Read-only file system"
    assert word in errors[0], errors[0]
    initial, after = report["initial"], c["after"]
    for name in ("run/history.bin", "damaged/history.bin", "run/run.json", "d.npz"):
        assert after[name] == initial[name], name  # nothing stored was touched
    made = set(after) - set(initial)
    assert not [p for p in made if ".partial" in p or ".tmp" in p], made
    if c["args"][0] == "explore" and "--out" in c["args"]:
        assert not [p for p in after if p.startswith("new")], after  # nothing left behind
    if c["args"][:2] == ["runs", "salvage"]:
        assert not [p for p in after if p.startswith("damaged/salvage/")], after
