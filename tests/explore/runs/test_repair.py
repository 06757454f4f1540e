"""Damaged and shortened histories: ``ergo runs check`` says what a history holds,
``ergo runs salvage`` keeps every good record (nothing deleted: the old file can be put back
together from the pieces), and the run then resumes; on the deterministic twin the resumed
run is the uninterrupted one. A history cut short, emptied or deleted is re-run with a line
saying how many episodes were missing."""

from __future__ import annotations

import json
import shutil
from pathlib import Path

import pytest

from explore.cli import main
from explore.runs.layout import (
    DAMAGED_FILE,
    HEADER,
    HISTORY_FILE,
    KEPT_FILE,
    SALVAGE_DIR,
    SALVAGE_REPORT,
)
from explore.runs.lock import run_lock
from explore.runs.repair import iter_records, survey
from explore.runs.store import RunStore

N = 10


def ergo(*args: str) -> int:
    if args[0] == "explore":
        args = (*args, "--no-progress", "--rerun", "off")
    return main(list(args))


@pytest.fixture(scope="module")
def reference(tmp_path_factory) -> Path:
    out = tmp_path_factory.mktemp("ref") / "run"
    assert ergo("explore", "--episodes", str(N), "--seed", "5", "--out", str(out)) == 0
    return out


@pytest.fixture
def run(reference, tmp_path) -> Path:
    copy = tmp_path / "run"
    shutil.copytree(reference, copy)
    return copy


def _offsets(run: Path) -> list[int]:
    return [p.start for p in survey(run).good]


def _history(run: Path) -> list:
    return RunStore.read(run).records


def _same_history(a: Path, b: Path) -> bool:
    ra, rb = _history(a), _history(b)
    return len(ra) == len(rb) and all(x.equals(y) for x, y in zip(ra, rb, strict=True))


def test_a_healthy_run_checks_ok(reference, capsys):
    assert ergo("runs", "check", str(reference)) == 0
    out = capsys.readouterr().out
    assert f"{N} good record(s), 0 damaged" in out and "ok: resumable as it is" in out


def test_a_flipped_byte_is_salvaged_losslessly_and_the_resumed_run_is_the_uninterrupted_one(
    run, reference, capsys
):
    hist = run / HISTORY_FILE
    original = hist.read_bytes()
    starts = _offsets(run)
    at = starts[4] + HEADER.size + 100  # inside episode 4's payload
    damaged = bytearray(original)
    damaged[at] ^= 0xFF
    hist.write_bytes(bytes(damaged))

    assert ergo("explore", "--resume", str(run)) == 2  # refused, and the file left alone
    err = capsys.readouterr().err
    assert "checksum mismatch" in err and f"ergo runs salvage {run}" in err
    assert err.count("\n") == 1 and hist.read_bytes() == bytes(damaged)

    assert ergo("runs", "check", str(run)) == 1
    out = capsys.readouterr().out
    assert "9 good record(s), 1 damaged span(s)" in out and "episodes 0..3 (4)" in out
    assert "good records after it: 5 (episodes 5..9)" in out
    assert "10 episode(s) stored: 6 missing" in out

    assert ergo("runs", "salvage", str(run)) == 0
    line = capsys.readouterr().out
    assert "kept episodes 0..3 (4)" in line and "5 good record(s)" in line
    assert f"resume with: ergo explore --resume {run}" in line
    folder = run / SALVAGE_DIR / "1"
    report = json.loads((folder / SALVAGE_REPORT).read_text())
    assert report["kept_in_history"] == 4 and report["good_records_moved"] == 5
    files = {HISTORY_FILE: hist.read_bytes(), KEPT_FILE: (folder / KEPT_FILE).read_bytes(),
             DAMAGED_FILE: (folder / DAMAGED_FILE).read_bytes()}  # fmt: skip
    rebuilt = b"".join(files[p["file"]][p["at"] : p["at"] + p["end"] - p["start"]]
                       for p in report["pieces"])  # fmt: skip
    assert rebuilt == bytes(damaged)  # every byte is somewhere: nothing was deleted
    assert [r.episode for r in iter_records(folder / KEPT_FILE)] == [5, 6, 7, 8, 9]
    damaged_span = [p for p in report["pieces"] if p["kind"] == "damaged"]
    assert [(p["start"], p["end"]) for p in damaged_span] == [(starts[4], starts[5])]
    assert len(files[DAMAGED_FILE]) == report["damaged_bytes_moved"] == starts[5] - starts[4]

    assert ergo("runs", "check", str(run)) == 0  # resumable now (6 short of what it had)
    assert "6 episode(s) short" in capsys.readouterr().out
    assert ergo("explore", "--resume", str(run)) == 0
    assert "6 episode(s) missing" in capsys.readouterr().err
    assert _same_history(run, reference)  # the twin re-created what was lost


def test_duplicated_episodes_of_two_writers_are_moved_aside(run, capsys):
    hist = run / HISTORY_FILE
    data = hist.read_bytes()
    starts = _offsets(run)
    hist.write_bytes(data + data[starts[7] :])  # episodes 7..9 appended twice
    assert ergo("report", str(run)) == 2  # not counted as 13 episodes
    assert "record 10 is episode 7: missing or duplicated" in capsys.readouterr().err
    assert ergo("runs", "check", str(run)) == 1
    assert "good records after it: 3 (episodes 7..9)" in capsys.readouterr().out
    assert ergo("runs", "salvage", str(run)) == 0
    assert "kept episodes 0..9 (10)" in capsys.readouterr().out
    assert hist.read_bytes() == data
    assert ergo("explore", "--resume", str(run)) == 0
    assert len(_history(run)) == N


@pytest.mark.parametrize("how", ["cut short", "emptied", "deleted"])
def test_a_history_that_lost_episodes_is_rerun_with_a_line_saying_how_many(
    how, run, reference, capsys
):
    hist = run / HISTORY_FILE
    if how == "cut short":
        hist.write_bytes(hist.read_bytes()[: _offsets(run)[6]])
    elif how == "emptied":
        hist.write_bytes(b"")
    else:
        hist.unlink()
    lost = {"cut short": 4, "emptied": N, "deleted": N}[how]
    assert ergo("runs", "check", str(run)) == 0
    assert f"{lost} missing from the history" in capsys.readouterr().out
    assert ergo("explore", "--resume", str(run)) == 0
    err = capsys.readouterr().err
    assert f"{lost} episode(s) missing (history.bin cut short, emptied or deleted)" in err
    assert _same_history(run, reference)


def test_salvage_is_refused_while_a_writer_holds_the_run(run, capsys):
    hist = run / HISTORY_FILE
    hist.write_bytes(hist.read_bytes()[:-1] + b"\0" + b"junk" * 10)
    before = hist.read_bytes()
    with run_lock(run):
        assert ergo("runs", "salvage", str(run)) == 2
    assert "being written by another process" in capsys.readouterr().err
    assert hist.read_bytes() == before and not (run / SALVAGE_DIR).exists()
