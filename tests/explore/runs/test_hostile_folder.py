"""A run folder received from someone else must not make a command touch files outside it,
and odd paths get one line (issue 29): a ``writer.lock`` (or another file the writer writes)
that is a symbolic or hard link to a file elsewhere is refused and the file left as it was
(before: ``ergo explore --resume`` emptied it); a loop of links given to export; two exports
to one ``--out``; ``ergo runs check`` on a run.json that cannot be run."""

from __future__ import annotations

import json
import os
import shutil
import subprocess
import sys
from pathlib import Path

import pytest

from explore.cli import main
from explore.runs.layout import (
    FAULTS_FILE,
    FRAMES_DIR,
    HISTORY_FILE,
    METRICS_FILE,
    RUN_FILE,
    SALVAGE_DIR,
    WRITER_LOCK_FILE,
)

VICTIM = b"precious data\n" * 100


def ergo(*args: str) -> int:
    if args[0] == "explore":
        args = (*args, "--no-progress", "--rerun", "off")
    return main(list(args))


@pytest.fixture(scope="module")
def reference(tmp_path_factory) -> Path:
    out = tmp_path_factory.mktemp("ref") / "run"
    assert ergo("explore", "--episodes", "3", "--seed", "2", "--out", str(out)) == 0
    return out


@pytest.fixture
def run(reference, tmp_path) -> Path:
    copy = tmp_path / "run"
    shutil.copytree(reference, copy)
    return copy


@pytest.fixture
def victim(tmp_path) -> Path:
    path = tmp_path / "victim"
    path.write_bytes(VICTIM)
    return path


def _one_line(capsys) -> str:
    err = capsys.readouterr().err
    lines = [ln for ln in err.splitlines() if not ln.startswith("INFO ")]
    assert len(lines) == 1, err
    return lines[0]


def _resume_through_link(run: Path, target: Path, victim: Path, link: str, capsys) -> str:
    """Make ``target`` (a file of ``run``) a ``link`` ("symbolic" or "hard") to ``victim``,
    resume the run (refused: exit code 2) and return its one error line."""
    if link == "symbolic":
        target.symlink_to(victim)
    else:
        os.link(victim, target)
    assert ergo("explore", "--resume", str(run), "--episodes", "5") == 2
    return _one_line(capsys)


@pytest.mark.parametrize("link", ["symbolic", "hard"])
@pytest.mark.parametrize(
    # run.json.tmp: an older version's temporary file, a name the writer still refuses as a link
    "name",
    [WRITER_LOCK_FILE, HISTORY_FILE, METRICS_FILE, FAULTS_FILE, f"{RUN_FILE}.tmp"],
)
def test_a_linked_file_in_a_received_run_is_refused_and_left_alone(run, victim, capsys, name, link):
    target = run / name
    if name == HISTORY_FILE:  # the victim holds the history's bytes: a valid run to resume
        victim.write_bytes(target.read_bytes())
    before = victim.read_bytes()
    target.unlink(missing_ok=True)
    line = _resume_through_link(run, target, victim, link, capsys)
    assert name in line and ("symbolic link" in line or "hard link" in line), line
    assert victim.read_bytes() == before
    if name in (WRITER_LOCK_FILE, HISTORY_FILE):
        assert ergo("runs", "salvage", str(run)) == 2
        assert name in _one_line(capsys) and victim.read_bytes() == before
    if name == WRITER_LOCK_FILE:  # checked too: one line, not a traceback
        assert ergo("runs", "check", str(run)) == 2
        assert name in _one_line(capsys) and victim.read_bytes() == before


@pytest.mark.parametrize("link", ["symbolic", "hard"])
def test_a_linked_frames_file_is_refused_and_left_alone(run, victim, capsys, link):
    """The camera frames the writer would write next (``frames/episode-000003.npz``) linked to
    a file elsewhere."""
    target = run / FRAMES_DIR / "episode-000003.npz"
    target.parent.mkdir()
    line = _resume_through_link(run, target, victim, link, capsys)
    assert "episode-000003.npz" in line and f"{link} link" in line, line
    assert victim.read_bytes() == VICTIM


def test_a_salvage_folder_linked_elsewhere_is_refused(run, tmp_path, capsys):
    hist = run / HISTORY_FILE
    hist.write_bytes(hist.read_bytes()[:-50] + b"x" * 10)  # damaged: salvage has work
    elsewhere = tmp_path / "elsewhere"
    elsewhere.mkdir()
    (run / SALVAGE_DIR).symlink_to(elsewhere)
    assert ergo("runs", "salvage", str(run)) == 2
    assert "salvage" in _one_line(capsys) and not any(elsewhere.iterdir())


def test_a_loop_of_links_given_to_export_is_one_line(tmp_path, capsys):
    loop = tmp_path / "loop"
    loop.symlink_to(loop)
    for args in (
        ["export", "lerobot", str(loop), "--out", str(tmp_path / "ds")],
        ["export", "lerobot", str(loop / "run"), "--out", str(tmp_path / "ds")],
        ["runs", "check", str(loop)],
        ["report", str(loop)],
    ):
        assert ergo(*args) == 2, args
        assert "Traceback" not in _one_line(capsys)


def test_two_exports_to_one_out_never_remove_each_other(reference, tmp_path):
    """Each export writes into its own partial folder (before: one shared name, which each
    removed at its start, so two exports broke each other)."""
    out = tmp_path / "ds"
    cmd = [sys.executable, "-m", "explore.cli", "export", "lerobot", str(reference), "--out",
           str(out), "--no-video"]  # fmt: skip
    procs = [subprocess.Popen(cmd, stderr=subprocess.PIPE, text=True) for _ in range(2)]
    results = [(p.wait(timeout=300), p.stderr.read()) for p in procs]
    codes = sorted(rc for rc, _ in results)
    assert codes[0] == 0, results  # at least one wrote the dataset
    for rc, err in results:
        assert "Traceback" not in err, err
        if rc:
            assert rc == 2 and err.count("\n") == 1, err
            assert "another export" in err or "not empty" in err, err
    info = json.loads((out / "meta/info.json").read_text())
    assert info["total_episodes"] == 3
    assert not list(tmp_path.glob(".ds.partial*"))


def test_runs_check_does_not_call_an_invalid_run_json_resumable(run, capsys):
    meta = json.loads((run / RUN_FILE).read_text())
    meta["config"]["seed"] = "abc"
    (run / RUN_FILE).write_text(json.dumps(meta))
    assert ergo("runs", "check", str(run)) == 1
    out = capsys.readouterr().out
    assert "ok: resumable" not in out and "not resumable: run.json" in out and "seed" in out
