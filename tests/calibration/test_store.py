"""Calibration files: round trip, one-line errors naming the bad field, atomic writes, a bad
payload never replacing a good file, and where files live."""

from __future__ import annotations

import json
import re

import numpy as np
import pytest

from calibration import store
from calibration.store import CalibrationError


def camera_payload(**over):
    d = {
        "camera_matrix": np.array([[600.0, 0, 320], [0, 600.0, 240], [0, 0, 1]]),
        "dist_coeffs": [-0.2, 0.05, 0.0, 0.0, 0.0],
        "image_size": [640, 480],
        "rms_px": 0.21,
        "n_views": 12,
    }
    d.update(over)
    return d


def test_round_trip(tmp_path):
    path = store.save("camera", "rig-1", camera_payload(), tmp_path)
    assert path == tmp_path / "rig-1" / "camera.json"
    doc = json.loads(path.read_text())
    assert doc["schema"] == store.SCHEMA and doc["version"] == store.VERSIONS["camera"]
    assert doc["kind"] == "camera" and doc["rig_id"] == "rig-1" and doc["created"]
    data = store.load("camera", "rig-1", tmp_path)
    assert data["camera_matrix"][0][0] == 600.0 and data["image_size"] == [640, 480]
    assert list(path.parent.iterdir()) == [path]  # no temporary file left behind


def test_env_var_and_default_dir(tmp_path, monkeypatch):
    monkeypatch.setenv(store.ENV_DIR, str(tmp_path / "env"))
    assert store.calibration_root() == tmp_path / "env"
    assert store.calibration_root(tmp_path / "cli") == tmp_path / "cli"  # --dir wins
    monkeypatch.delenv(store.ENV_DIR)
    assert str(store.calibration_root()).endswith(".config/ergo-explore/calibration")
    with pytest.raises(CalibrationError, match="rig id"):
        store.calibration_path("camera", "../evil", tmp_path)


def test_bad_payload_is_refused_and_good_file_kept(tmp_path):
    path = store.save("camera", "r", camera_payload(), tmp_path)
    before = path.read_text()
    with pytest.raises(CalibrationError) as err:
        store.save("camera", "r", camera_payload(rms_px=float("nan")), tmp_path)
    msg = str(err.value)
    assert "'rms_px'" in msg and "not written" in msg and "\n" not in msg
    with pytest.raises(CalibrationError, match="'camera_matrix'"):
        store.save("camera", "r", camera_payload(camera_matrix=[[1, 0], [0, 1]]), tmp_path)
    assert path.read_text() == before
    assert [p.name for p in path.parent.iterdir()] == ["camera.json"]


@pytest.mark.parametrize(
    ("edit", "field"),
    [
        (lambda d: d["data"].pop("dist_coeffs"), "'dist_coeffs' is missing"),
        (lambda d: d["data"].__setitem__("image_size", [640]), "'image_size'"),
        (lambda d: d["data"]["camera_matrix"].__setitem__(2, [0, 1, 1]), "'camera_matrix'"),
        (lambda d: d.__setitem__("version", 99), "'version' is 99, newer"),
        (lambda d: d.__setitem__("schema", "other"), "'schema'"),
        (lambda d: d.__setitem__("kind", "arena"), "'kind'"),
    ],
)
def test_corrupt_file_one_line_error_naming_field(tmp_path, edit, field):
    path = store.save("camera", "r", camera_payload(), tmp_path)
    doc = json.loads(path.read_text())
    edit(doc)
    path.write_text(json.dumps(doc))
    with pytest.raises(CalibrationError) as err:
        store.load("camera", "r", tmp_path)
    msg = str(err.value)
    assert field in msg and str(path) in msg and "\n" not in msg


def test_not_json_and_missing(tmp_path):
    path = tmp_path / "r" / "arena.json"
    path.parent.mkdir()
    path.write_text('{"schema": ')
    with pytest.raises(CalibrationError, match=r"not valid JSON \(line 1"):
        store.load("arena", "r", tmp_path)
    with pytest.raises(CalibrationError, match="no calibration file"):
        store.load("joints", "r", tmp_path)


def test_joints_and_arena_validation(tmp_path):
    good = {
        "names": ["m1", "m2"],
        "offsets": [0.1, -0.2],
        "directions": [1, -1],
        "lower": [-1.0, -1.5],
        "upper": [1.0, 2.0],
    }
    store.save("joints", "r", good, tmp_path)
    with pytest.raises(CalibrationError, match="'directions'"):
        store.save("joints", "r", {**good, "directions": [1, 0]}, tmp_path)
    with pytest.raises(CalibrationError, match="'lower' of joint m2"):
        store.save("joints", "r", {**good, "lower": [-1.0, 3.0]}, tmp_path)
    arena = {
        "camera_matrix": camera_payload()["camera_matrix"],
        "dist_coeffs": [0.0] * 5,
        "image_size": [640, 480],
        "homography": np.eye(3),
        "centre": [0.0, 0.0],
        "radius": 0.2,
        "camera_position": [0.0, 0.0, 0.55],
        "ball_hsv_ranges": [[[27, 45, 70], [38, 255, 255]]],
    }
    store.save("arena", "r", arena, tmp_path)
    with pytest.raises(CalibrationError, match=r"'ball_hsv_ranges\[0\]'"):
        store.save(
            "arena", "r", {**arena, "ball_hsv_ranges": [[[40, 0, 0], [30, 255, 255]]]}, tmp_path
        )
    with pytest.raises(CalibrationError, match="'camera_position'"):
        store.save("arena", "r", {**arena, "camera_position": [0, 0, -1]}, tmp_path)


def arena_payload(camera: dict) -> dict:
    return {
        "camera_matrix": camera["camera_matrix"],
        "dist_coeffs": camera["dist_coeffs"],
        "image_size": camera["image_size"],
        "homography": np.eye(3),
        "centre": [0.0, 0.0],
        "radius": 0.2,
    }


def test_an_arena_made_before_the_camera_was_recalibrated_is_refused(tmp_path):
    store.save("camera", "r", camera_payload(), tmp_path)
    store.save("arena", "r", arena_payload(camera_payload()), tmp_path)
    assert store.load("arena", "r", tmp_path)["radius"] == 0.2  # the same intrinsics: fine
    recalibrated = np.array([[612.5, 0, 321], [0, 611.0, 239], [0, 0, 1]])
    store.save("camera", "r", camera_payload(camera_matrix=recalibrated), tmp_path)
    for load in (
        lambda: store.load("arena", "r", tmp_path),
        lambda: store.load_arena_file(tmp_path / "r" / "arena.json"),
    ):
        with pytest.raises(CalibrationError) as err:
            load()
        msg = str(err.value)
        assert "fx 600.00 in the arena file, 612.50 in camera.json" in msg, msg
        assert "ergo calibrate arena --rig-id r" in msg and "\n" not in msg
    store.save("camera", "r", camera_payload(dist_coeffs=[-0.1, 0.0, 0.0, 0.0, 0.0]), tmp_path)
    with pytest.raises(CalibrationError, match="dist_coeffs differs"):
        store.load("arena", "r", tmp_path)


def test_an_arena_without_a_camera_file_beside_it_is_read_as_it_is(tmp_path):
    path = store.save("arena", "r", arena_payload(camera_payload()), tmp_path)
    assert store.load_arena_file(path)["radius"] == 0.2


def test_calibrate_show_gives_each_file_with_its_age_and_hash(tmp_path, capsys):
    from explore.cli import main

    camera = camera_payload(std_px={"fx": 1.2, "fy": 1.1, "cx": 0.5, "cy": 0.4})
    paths = {
        "camera": store.save("camera", "r", camera, tmp_path),
        "arena": store.save("arena", "r", arena_payload(camera_payload()), tmp_path),
        "joints": store.save("joints", "r", {
            "names": ["m1", "m2"], "offsets": [0.1, -0.2], "directions": [1, -1],
            "lower": [-1.0, -1.5], "upper": [1.0, 2.0],
        }, tmp_path),
    }  # fmt: skip
    doc = json.loads(paths["joints"].read_text())
    doc["created"] = "2020-01-01T00:00:00+00:00"  # an old calibration
    paths["joints"].write_text(json.dumps(doc))
    assert main(["calibrate", "show", "--rig-id", "r", "--dir", str(tmp_path)]) == 0
    lines = capsys.readouterr().out.strip().splitlines()
    kinds = ["camera", "arena", "joints", "dynamics"]
    assert [line.split(":")[0] for line in lines] == kinds
    assert lines[3].startswith("dynamics: none (")  # no servo fit made (tests/calibration/dynamics)
    for line, path in zip(lines, paths.values(), strict=False):
        assert f"({path}, made " in line and f"sha256 {store.file_sha256(path)[:12]})" in line
    assert "made just now" in lines[0] and "fx 600.0 +-1.2" in lines[0]
    assert re.search(r"made \d+ days ago", lines[2]) and "m2 -11.5 deg -1 [-86, +115]" in lines[2]


def test_a_camera_json_that_is_a_folder_beside_an_arena_is_refused_not_skipped(tmp_path):
    path = store.save("arena", "r", arena_payload(camera_payload()), tmp_path)
    (tmp_path / "r" / "camera.json").mkdir()
    with pytest.raises(CalibrationError) as err:
        store.load_arena_file(path)
    assert "camera.json" in str(err.value) and "\n" not in str(err.value)


def test_saving_over_a_folder_names_the_file_not_its_temporary(tmp_path):
    (tmp_path / "r" / "arena.json").mkdir(parents=True)
    with pytest.raises(CalibrationError) as err:
        store.save("arena", "r", arena_payload(camera_payload()), tmp_path)
    msg = str(err.value)
    assert msg == f"{tmp_path / 'r' / 'arena.json'} is a directory: nothing written"
    assert not [p for p in (tmp_path / "r").iterdir() if p.name != "arena.json"]  # no leftover
