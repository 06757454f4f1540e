"""``ergo track --arena FILE`` reads the arena file as ``explore`` does: a file of another
version, with NaN or inf, or fitted with other intrinsics than the camera.json beside it, is
refused in one line (rc 2) before any camera is opened."""

from __future__ import annotations

import json

import numpy as np
import pytest

from calibration import store
from explore.cli import main


def saved_arena(tmp_path) -> tuple[dict, object]:
    camera = {
        "camera_matrix": [[600.0, 0, 320], [0, 600.0, 240], [0, 0, 1]],
        "dist_coeffs": [0.0] * 5,
        "image_size": [640, 480],
    }
    arena = {**camera, "homography": np.eye(3), "centre": [0.0, 0.0], "radius": 0.2}
    return camera, store.save("arena", "r", arena, tmp_path)


@pytest.mark.parametrize(
    ("edit", "named"),
    [
        (lambda d: d.__setitem__("version", 7), "'version' is 7"),
        (lambda d: d.__setitem__("version", "1"), "'version'"),
        (lambda d: d["data"]["homography"][0].__setitem__(0, float("nan")), "'homography'"),
        (lambda d: d["data"].__setitem__("radius", float("inf")), "'radius'"),
    ],
)
def test_a_bad_arena_file_is_refused_in_one_line(tmp_path, capsys, edit, named):
    _, path = saved_arena(tmp_path)
    doc = json.loads(path.read_text())
    edit(doc)
    path.write_text(json.dumps(doc))  # json writes NaN and Infinity, as a careless tool would
    rc = main(["track", "--camera", str(tmp_path / "no-such-video.mp4"), "--arena", str(path)])
    err = capsys.readouterr().err
    assert rc == 2 and named in err and str(path) in err and err.count("\n") == 1, err


def test_an_arena_older_than_the_camera_calibration_is_refused(tmp_path, capsys):
    camera, path = saved_arena(tmp_path)
    camera["camera_matrix"] = [[640.0, 0, 320], [0, 640.0, 240], [0, 0, 1]]
    store.save("camera", "r", {**camera, "rms_px": 0.2, "n_views": 12}, tmp_path)
    rc = main(["track", "--camera", str(tmp_path / "no-such-video.mp4"), "--arena", str(path)])
    err = capsys.readouterr().err
    assert rc == 2 and "fx 600.00 in the arena file, 640.00 in camera.json" in err, err
    assert err.count("\n") == 1
