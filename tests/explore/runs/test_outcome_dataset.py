"""``ergo dataset outcomes --run RUN``: the outcome images a run recorded make a dataset that
``ergo sae train`` / ``ergo vae train`` read (the arm's own database); the run is read, never
changed; a run whose images are not the twin's view (a physical rig without an arena
calibration), a folder that is not a run and flags that render scenes are refused in one
line."""

from __future__ import annotations

import hashlib
from pathlib import Path

import numpy as np
import pytest

from explore.cli import main
from explore.runs.outcome_dataset import DatasetError, check_images_are_views
from explore.runs.store import read_history


def folder_bytes(folder: Path) -> dict[str, str]:
    """Every file under ``folder``: its relative path -> the SHA-256 of its bytes."""
    return {
        str(p.relative_to(folder)): hashlib.sha256(p.read_bytes()).hexdigest()
        for p in sorted(folder.rglob("*"))
        if p.is_file()
    }


@pytest.fixture(scope="module")
def twin_run(tmp_path_factory) -> Path:
    run = tmp_path_factory.mktemp("runs") / "rpe"
    code = main(["explore", "--rig", "sim", "--strategy", "rpe", "--episodes", "6", "--seed",
                 "0", "--out", str(run), "--no-progress"])  # fmt: skip
    assert code == 0
    return run


def test_a_runs_outcome_images_make_a_dataset_and_the_run_is_unchanged(twin_run, tmp_path, capsys):
    from vision.vae_train import load_images

    before = folder_bytes(twin_run)
    out = tmp_path / "arm.npz"
    assert main(["dataset", "outcomes", "--run", str(twin_run), "--out", str(out)]) == 0
    assert f"{out}: 6 images (64, 64, 3) from {twin_run}" in capsys.readouterr().out
    assert folder_bytes(twin_run) == before  # read, never changed
    records = read_history(twin_run).records
    with np.load(out) as z:
        np.testing.assert_array_equal(z["images"], np.stack([r.image for r in records]))
        np.testing.assert_array_equal(z["ball"], np.stack([r.ball for r in records]))
        np.testing.assert_array_equal(z["episode"], [r.episode for r in records])
    assert load_images(out).shape == (6, 64, 64, 3)  # what `ergo sae train --data` reads
    first = tmp_path / "first.npz"
    assert (
        main(["dataset", "outcomes", "--run", str(twin_run), "--n", "4", "--out", str(first)]) == 0
    )
    with np.load(first) as z:
        assert z["images"].shape[0] == 4


@pytest.mark.parametrize(
    ("extra", "message"),
    [
        (["--arm", "random"], "--arm random: render scenes; --run takes a run's images"),
        (["--rig", "armballs"], "--rig: render scenes"),
        (["--seed", "3"], "--seed: render scenes"),
    ],
)
def test_flags_that_render_scenes_are_refused_with_a_run(
    twin_run, tmp_path, capsys, extra, message
):
    args = ["dataset", "outcomes", "--run", str(twin_run), "--out", str(tmp_path / "d.npz")]
    assert main(args + extra) == 2
    err = capsys.readouterr().err
    assert message in err and err.count("\n") == 1
    assert not (tmp_path / "d.npz").exists()


def test_a_folder_that_is_not_a_run_is_one_line(tmp_path, capsys):
    assert (
        main(["dataset", "outcomes", "--run", str(tmp_path), "--out", str(tmp_path / "d.npz")]) == 2
    )
    err = capsys.readouterr().err
    assert err.startswith("ergo: error:") and err.count("\n") == 1


def test_a_physical_run_without_an_arena_calibration_is_refused():
    """Its images are the raw frame's centre square: no model of the twin's view shares them."""
    meta = {"config": {"rig": {"name": "dynamixel", "rig_id": "ergo1"}}, "inputs": [
        {"kind": "joints", "path": "/j.json", "sha256": "0"}]}  # fmt: skip
    with pytest.raises(DatasetError, match=r"ergo calibrate arena --rig-id ergo1"):
        check_images_are_views(Path("RUN"), meta)
    meta["inputs"].append({"kind": "arena", "path": "/a.json", "sha256": "1"})
    check_images_are_views(Path("RUN"), meta)  # with it: the twin's view
    check_images_are_views(Path("RUN"), {"config": {"rig": {"name": "sim"}}})  # the twin's own
