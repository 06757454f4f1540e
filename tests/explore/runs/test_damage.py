"""Damage to ``history.bin`` that must never cost a good record (issue 29): a flipped bit in a
record's length field is damage, not a torn tail (resume refuses, salvage keeps the rest); a
damaged last record is moved aside, never deleted; readers say what they leave out. The
battery at the end flips any single bit or cuts the file at any length."""

from __future__ import annotations

import json
import shutil
from pathlib import Path

import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from explore.cli import main
from explore.runs.layout import (
    DAMAGED_FILE,
    HEADER,
    HISTORY_FILE,
    KEPT_FILE,
    SALVAGE_DIR,
    SALVAGE_REPORT,
)
from explore.runs.repair import iter_records, salvage, survey
from explore.runs.store import RunStore, RunStoreError, read_history

N = 10


def ergo(*args: str) -> int:
    if args[0] == "explore":
        args = (*args, "--no-progress", "--rerun", "off")
    return main(list(args))


@pytest.fixture(scope="module")
def reference(tmp_path_factory) -> Path:
    out = tmp_path_factory.mktemp("ref") / "run"
    assert ergo("explore", "--episodes", str(N), "--seed", "3", "--out", str(out)) == 0
    return out


@pytest.fixture
def run(reference, tmp_path) -> Path:
    copy = tmp_path / "run"
    shutil.copytree(reference, copy)
    return copy


def _starts(run: Path) -> list[int]:
    return [p.start for p in survey(run).good]


def test_a_flipped_bit_in_a_length_field_is_damage_and_no_good_record_is_cut(run, capsys):
    """The issue's case: bit 4 of byte 6 of record 3's frame (its u32 length) makes the
    record seem to run past the end of the file, as a torn tail would. Before, resume cut
    records 3..9 for good and export/report quietly used 3 episodes."""
    hist = run / HISTORY_FILE
    at = _starts(run)[3] + 6
    damaged = bytearray(hist.read_bytes())
    damaged[at] ^= 1 << 4
    hist.write_bytes(bytes(damaged))

    assert ergo("explore", "--resume", str(run)) == 2  # refused, nothing cut
    err = capsys.readouterr().err
    assert "record runs past the end of the file, and a good record follows" in err, err
    assert f"ergo runs salvage {run}" in err and err.count("\n") == 1
    assert hist.read_bytes() == bytes(damaged)
    for reader in (
        ("report", str(run)),
        ("export", "lerobot", str(run), "--out", str(run.parent / "ds")),
    ):
        assert ergo(*reader) == 2  # readers refuse rather than quietly use episodes 0..2
        err = capsys.readouterr().err
        assert "corrupt at byte" in err and err.count("\n") == 1, (reader, err)
    assert ergo("runs", "check", str(run)) == 1
    assert "good records after it: 6 (episodes 4..9)" in capsys.readouterr().out
    assert ergo("runs", "salvage", str(run)) == 0
    kept = [r.episode for r in iter_records(run / SALVAGE_DIR / "1" / KEPT_FILE)]
    assert kept == [4, 5, 6, 7, 8, 9] and len(RunStore.read(run).records) == 3


def test_a_damaged_last_record_is_moved_aside_not_deleted(run, capsys):
    hist = run / HISTORY_FILE
    data = hist.read_bytes()
    last = _starts(run)[-1]
    hist.write_bytes(data[:-100])  # a crash mid-append: the last record torn
    assert ergo("runs", "check", str(run)) == 0
    assert "a torn tail of" in capsys.readouterr().out
    assert ergo("explore", "--resume", str(run)) == 0
    err = capsys.readouterr().err
    folder = run / SALVAGE_DIR / "1"
    assert f"moved a torn last record ({len(data) - 100 - last} bytes" in err and str(folder) in err
    assert (folder / DAMAGED_FILE).read_bytes() == data[last:-100]  # kept, byte for byte
    report = json.loads((folder / SALVAGE_REPORT).read_text())
    assert (
        report["kept_in_history"] == N - 1
        and report["damaged_bytes_moved"] == len(data) - 100 - last
    )
    assert len(RunStore.read(run).records) == N  # the episode run again


def test_readers_say_what_they_leave_out(run, caplog, capsys):
    """A torn tail left in place (a reader never repairs): ``read_history`` counts its bytes,
    which export and report name; ``runs check`` names it too."""
    hist = run / HISTORY_FILE
    data = hist.read_bytes()
    last = _starts(run)[-1]
    hist.write_bytes(data[:-7])
    history = read_history(run)
    assert len(history.records) == N - 1
    assert history.torn_bytes == len(data) - 7 - last
    assert ergo("report", str(run), "--out", str(run.parent / "report")) == 0
    assert f"left out a torn last record ({history.torn_bytes} bytes" in caplog.text
    capsys.readouterr()
    out = run.parent / "ds"
    assert ergo("export", "lerobot", str(run), "--out", str(out), "--no-video") == 0
    err = capsys.readouterr().err
    assert f"left out a torn last record ({history.torn_bytes} bytes" in err, err
    info = json.loads((out / "meta" / "info.json").read_text())
    assert info["total_episodes"] == N - 1
    assert ergo("runs", "check", str(run)) == 0
    assert f"a torn tail of {history.torn_bytes} bytes" in capsys.readouterr().out
    assert hist.read_bytes() == data[:-7]  # no reader repaired it


# ---- the damage battery ------------------------------------------------------------------------


@pytest.fixture(scope="module")
def small(tmp_path_factory) -> tuple[bytes, list[tuple[int, int]], Path]:
    """A 5-episode run built once: (history bytes, (start, end) of each record frame, run)."""
    out = tmp_path_factory.mktemp("small") / "run"
    assert ergo("explore", "--episodes", "5", "--seed", "1", "--out", str(out)) == 0
    data = (out / HISTORY_FILE).read_bytes()
    pieces = [(p.start, p.end) for p in survey(out).good]
    return data, pieces, out


def _damage(
    data: bytes, pieces: list[tuple[int, int]], draw: st.DataObject
) -> tuple[bytes, set[int]]:
    """Damage ``data`` one way: a single bit flipped anywhere (often in a header), or the file
    cut at any length. Returns the damaged bytes and the records left untouched."""
    if draw.draw(st.booleans(), label="cut"):
        cut = draw.draw(st.integers(0, len(data) - 1), label="length")
        return data[:cut], {i for i, (_, b) in enumerate(pieces) if b <= cut}
    in_header = draw.draw(st.booleans(), label="in a header")
    if in_header:
        i = draw.draw(st.integers(0, len(pieces) - 1), label="record")
        at = pieces[i][0] + draw.draw(st.integers(0, HEADER.size - 1), label="header byte")
    else:
        at = draw.draw(st.integers(0, len(data) - 1), label="byte")
    bit = draw.draw(st.integers(0, 7), label="bit")
    out = bytearray(data)
    out[at] ^= 1 << bit
    return bytes(out), {i for i, (a, b) in enumerate(pieces) if not a <= at < b}


def _resume_keeps_every_undamaged_record(
    source: Path, run: Path, damaged: bytes, intact: set[int], originals: list[bytes]
) -> None:
    """``source``'s run copied to ``run`` with ``damaged`` as its history: a reader returns a
    prefix and counts what it leaves out (or refuses in one line); a resume (or a salvage, then
    a resume) keeps each ``intact`` record in the history or moves it aside, and every byte of
    the damaged file is in the history or under ``RUN/salvage/``."""
    shutil.copytree(source, run)
    (run / HISTORY_FILE).write_bytes(damaged)

    # a reader says what it leaves out, or refuses in one line
    try:
        h = read_history(run)
        assert [r.to_bytes() for r in h.records] == originals[: len(h.records)]
        kept_end = len(damaged) - h.torn_bytes
        assert kept_end == (_frame_ends(originals)[len(h.records) - 1] if h.records else 0)
    except RunStoreError as exc:
        assert "\n" not in str(exc)

    # resume: opens (moving a torn tail aside), or refuses and salvage makes it resumable
    try:
        store = RunStore.open(run)
    except RunStoreError:
        salvage(run)
        store = RunStore.open(run)
    store.close()
    kept = [r.to_bytes() for r in store.records]
    aside = [
        r.to_bytes()
        for f in sorted((run / SALVAGE_DIR).glob(f"*/{KEPT_FILE}"))
        for r in iter_records(f)
    ]
    for i in intact:  # still in the history, or moved aside: never deleted
        assert originals[i] in kept or originals[i] in aside, (i, len(kept), len(aside))
    # and every byte of the damaged file is somewhere
    moved = (
        sum(
            (f / name).stat().st_size
            for f in (run / SALVAGE_DIR).glob("*")
            for name in (KEPT_FILE, DAMAGED_FILE)
            if (f / name).exists()
        )
        if (run / SALVAGE_DIR).exists()
        else 0
    )
    assert (run / HISTORY_FILE).stat().st_size + moved == len(damaged)


def _frame_ends(originals: list[bytes]) -> list[int]:
    """Where each record's frame ends in the undamaged history, bytes."""
    ends, at = [], 0
    for payload in originals:
        at += HEADER.size + len(payload)
        ends.append(at)
    return ends


@settings(max_examples=40, deadline=None, suppress_health_check=list(HealthCheck))
@given(draw=st.data())
def test_no_single_bit_flip_or_cut_loses_an_undamaged_record(small, tmp_path_factory, draw):
    data, pieces, source = small
    originals = [r.to_bytes() for r in RunStore.read(source).records]
    damaged, intact = _damage(data, pieces, draw)
    run = tmp_path_factory.mktemp("battery") / "run"
    _resume_keeps_every_undamaged_record(source, run, damaged, intact, originals)


@pytest.mark.slow  # 540 cases: 29 s at load 13 on 2 cores
def test_every_bit_of_every_record_header_and_every_cut_in_a_header(small, tmp_path):
    """Exhaustively where the length field misled resume: each of the 96 bits of each record's
    12-byte frame header (marker, length, checksum) flipped, and the file cut at every byte
    of each header (the property above samples the rest of the file)."""
    data, pieces, source = small
    originals = [r.to_bytes() for r in RunStore.read(source).records]
    assert [b for _, b in pieces] == _frame_ends(originals)
    cases = 0
    for i, (start, _end) in enumerate(pieces):
        for at in range(start, start + HEADER.size):
            for bit in range(8):
                flipped = bytearray(data)
                flipped[at] ^= 1 << bit
                intact = {j for j in range(len(pieces)) if j != i}
                run = tmp_path / f"flip-{at}-{bit}"
                _resume_keeps_every_undamaged_record(source, run, bytes(flipped), intact, originals)
                cases += 1
            intact = set(range(i))  # cut inside record i's header: records 0..i-1 whole
            run = tmp_path / f"cut-{at}"
            _resume_keeps_every_undamaged_record(source, run, data[:at], intact, originals)
            cases += 1
    assert cases == len(pieces) * HEADER.size * 9
