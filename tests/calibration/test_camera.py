"""Camera intrinsics from synthetic ChArUco views: a known camera (intrinsics + distortion)
renders the board at known poses; the calibration must recover it. Refusals: too few views,
views that do not cover the image, views without tilt."""

from __future__ import annotations

import re

import cv2
import numpy as np
import pytest

from calibration import charuco, store
from calibration.charuco import BoardSpec, calibrate, detect_view
from calibration.store import CalibrationError
from testkit.synthetic_views import look_at_pose, random_views, render_plane_view
from vision.rectify import undistort_points

SIZE = (480, 640)  # (height, width)
K_TRUE = np.array([[610.0, 0.0, 322.0], [0.0, 605.0, 236.0], [0.0, 0.0, 1.0]])
D_TRUE = np.array([-0.21, 0.09, 0.0012, -0.0009, 0.0])  # webcam-like (made up), k3 = 0
PX_PER_M = 4000.0  # board texture resolution (0.25 mm per texel)
MARGIN = 120  # white paper around the board, texels


@pytest.fixture(scope="module")
def spec():
    return BoardSpec()


@pytest.fixture(scope="module")
def board_image(spec):
    return spec.image(PX_PER_M, margin_px=MARGIN)


def render(board_image, rvec, tvec, rng, noise=2.0):
    img = render_plane_view(
        board_image, PX_PER_M, K_TRUE, D_TRUE, rvec, tvec, SIZE, origin_px=(MARGIN, MARGIN)
    )
    return np.clip(img + rng.normal(0.0, noise, img.shape), 0, 255).astype(np.uint8)


@pytest.fixture(scope="module")
def views(spec, board_image):
    rng = np.random.default_rng(7)
    out, images = [], []
    for i, (rvec, tvec) in enumerate(random_views(spec.size_m, 12, seed=2)):
        img = render(board_image, rvec, tvec, rng)
        v = detect_view(img, spec, f"view{i}")
        if v is not None:
            out.append(v)
            images.append(img)
    return out, images


def test_board_points_match_the_generated_image(spec):
    """The board image and matchImagePoints agree on where the corners are (OpenCV 5 layout)."""
    img = spec.image(PX_PER_M)
    v = detect_view(img, spec)
    assert v is not None and v.object_points.shape[1] == 3 and v.image_points.shape[1] == 2
    assert len(v.object_points) == (spec.squares[0] - 1) * (spec.squares[1] - 1)
    np.testing.assert_allclose(v.object_points[:, :2] * PX_PER_M - 0.5, v.image_points, atol=0.05)


def test_intrinsics_recovered(views):
    vs, _ = views
    assert len(vs) >= 10
    res = calibrate(vs, (SIZE[1], SIZE[0]))
    assert res.rms_px < 0.5  # measured about 0.07 px
    k = res.camera_matrix
    # Stated tolerances: focal lengths within 0.5 %, principal point within 3 px, k1 within
    # 0.01, and the undistortion of every pixel within 1 px of the true camera's.
    assert k[0, 0] == pytest.approx(K_TRUE[0, 0], rel=0.005)
    assert k[1, 1] == pytest.approx(K_TRUE[1, 1], rel=0.005)
    assert abs(k[0, 2] - K_TRUE[0, 2]) < 3.0 and abs(k[1, 2] - K_TRUE[1, 2]) < 3.0
    assert res.dist_coeffs[0] == pytest.approx(D_TRUE[0], abs=0.01)
    grid = np.array([[u, v] for u in np.linspace(0, 639, 17) for v in np.linspace(0, 479, 13)])
    diff = undistort_points(grid, K_TRUE, D_TRUE) - undistort_points(grid, k, res.dist_coeffs)
    assert np.max(np.linalg.norm(diff, axis=1)) < 1.0


def test_the_result_carries_its_uncertainty_and_held_out_errors(views):
    vs, _ = views
    res = calibrate(vs, (SIZE[1], SIZE[0]))
    k = res.camera_matrix
    assert set(res.std_px) == {"fx", "fy", "cx", "cy"}
    # the truth lies within 4 sd of the estimate (the sd is the larger of OpenCV's and the
    # held-out spread), and the sd is small: a well-spread set of views
    for name, est, true in (("fx", k[0, 0], 610.0), ("cx", k[0, 2], 322.0), ("cy", k[1, 2], 236.0)):
        assert abs(est - true) <= 4 * res.std_px[name] + 0.3, (name, est, res.std_px)
        assert res.std_px[name] < charuco.MAX_SD_OF_FOCAL * 610.0
    assert res.held_out_per_view_px.shape == (len(vs),)
    assert res.rms_px <= res.held_out_rms_px < 1.5 * res.rms_px
    assert res.to_dict()["std_px"]["fx"] == res.std_px["fx"]


def test_too_few_views_refused(views):
    vs, _ = views
    with pytest.raises(CalibrationError, match=r"only 4 usable board views \(need >= 5"):
        calibrate(vs[:4], (SIZE[1], SIZE[0]))


def test_views_that_leave_the_focal_length_unknown_are_refused_naming_what_to_add(
    spec, board_image
):
    """Ten views of the board square on, in the middle of the image: the focal length and
    the distance trade off, so fx is known to hundreds of pixels; the one line says so and
    asks for the views that were missing (corners, tilt)."""
    rng = np.random.default_rng(1)
    w, h = spec.size_m
    vs = []
    for i in range(10):
        centre = np.array([w / 2, h / 2, 0.0])
        rvec, tvec = look_at_pose(centre, centre + np.array((0.002 * i, 0.0, -0.45)), roll=0.01 * i)
        v = detect_view(render(board_image, rvec, tvec, rng), spec, str(i))
        assert v is not None
        vs.append(v)
    with pytest.raises(CalibrationError) as caught:
        calibrate(vs, (SIZE[1], SIZE[0]))
    message = str(caught.value)
    assert re.match(r"f[xy] known to \+-\d+\.\d px \(\d+\.\d% of the focal length", message)
    assert "add views near the image corners" in message and "tilted by 20-45 deg" in message
    assert "\n" not in message


def test_cli_from_folder_and_print_board(views, tmp_path, capsys):
    from explore.cli import main

    _, images = views
    folder = tmp_path / "shots"
    folder.mkdir()
    for i, img in enumerate(images):
        cv2.imwrite(str(folder / f"{i:02d}.png"), img)
    board = tmp_path / "board.png"
    rc = main(
        [
            "calibrate",
            "camera",
            "--rig-id",
            "bench",
            "--dir",
            str(tmp_path / "cal"),
            "--images",
            str(folder),
            "--print-board",
            str(board),
        ]
    )
    out = capsys.readouterr().out
    assert rc == 0, out
    assert "RMS reprojection error" in out and "saved" in out
    data = store.load("camera", "bench", tmp_path / "cal")
    assert data["rms_px"] < 0.5 and data["n_views"] == len(images)
    # 300 dpi: the board (210 x 150 mm) plus a one-square margin, within rounding.
    h, w = cv2.imread(str(board)).shape[:2]
    assert abs(h - (0.15 + 0.06) * 300 / 0.0254) < 2 and abs(w - (0.21 + 0.06) * 300 / 0.0254) < 2
    # Too few views: a one-line error, exit code 2, and the good file is kept.
    few = tmp_path / "few"
    few.mkdir()
    for i, img in enumerate(images[:3]):
        cv2.imwrite(str(few / f"{i}.png"), img)
    before = (tmp_path / "cal" / "bench" / "camera.json").read_text()
    rc = main(
        [
            "calibrate",
            "camera",
            "--rig-id",
            "bench",
            "--dir",
            str(tmp_path / "cal"),
            "--images",
            str(few),
        ]
    )
    err = capsys.readouterr().err
    assert rc == 2 and "only 3 usable board views" in err and err.count("\n") == 1
    assert (tmp_path / "cal" / "bench" / "camera.json").read_text() == before


def test_cli_from_recorded_video(views, tmp_path, capsys):
    """``--camera`` with a recorded video replays every frame (lossless FFV1 here)."""
    from explore.cli import main

    _, images = views
    path = tmp_path / "board.mkv"
    writer = cv2.VideoWriter(str(path), cv2.VideoWriter.fourcc(*"FFV1"), 10.0, (SIZE[1], SIZE[0]))
    assert writer.isOpened()
    for img in images:
        writer.write(cv2.cvtColor(img, cv2.COLOR_GRAY2BGR) if img.ndim == 2 else img)
    writer.release()
    rc = main(
        [
            "calibrate",
            "camera",
            "--rig-id",
            "vid",
            "--dir",
            str(tmp_path),
            "--camera",
            str(path),
            "--views",
            "20",
        ]
    )
    out = capsys.readouterr()
    assert rc == 0, out.err
    assert store.load("camera", "vid", tmp_path)["rms_px"] < 0.5


def test_an_error_every_view_shares_is_in_the_standard_deviations():
    """Each board corner moved by the same small error in every view (a print or a lens that
    errs the same way at that corner; 0.05 px sd): the views' jackknife, which takes the views
    as independent, cannot see it; leaving each corner out of every view does, and the reported
    sd and 95 % intervals carry it (with those errors absent they stay OpenCV's size)."""
    spec = BoardSpec()
    board = cv2.aruco.CharucoBoard(
        spec.squares, spec.square_m, spec.marker_m,
        cv2.aruco.getPredefinedDictionary(getattr(cv2.aruco, spec.dictionary)),
    )  # fmt: skip
    obj = np.asarray(board.getChessboardCorners(), float)
    flags = cv2.CALIB_FIX_K3
    rng = np.random.default_rng(3)
    shared = rng.normal(0.0, 0.05, (len(obj), 2))
    poses = random_views(spec.size_m, 15, seed=5)
    views = []
    for i, (rvec, tvec) in enumerate(poses):
        px, _ = cv2.projectPoints(obj, rvec, tvec, K_TRUE, D_TRUE)
        noise = rng.normal(0.0, 0.02, (len(obj), 2))
        views.append(charuco.BoardView(obj, px.reshape(-1, 2) + shared + noise, f"v{i}"))
    by_views, _ = charuco.held_out(views, (SIZE[1], SIZE[0]), flags)
    by_corners = charuco.corner_spread(views, (SIZE[1], SIZE[0]), flags)
    # the principal point most (views spread over the image pin the focal lengths' share)
    assert np.all(by_corners[2:] > 2 * by_views[2:]), (by_corners, by_views)  # cx, cy
    res = calibrate(views, (SIZE[1], SIZE[0]))
    sd = np.array([res.std_px[n] for n in ("fx", "fy", "cx", "cy")])
    assert np.all(sd >= by_corners - 1e-9)
    truth = {"fx": K_TRUE[0, 0], "fy": K_TRUE[1, 1], "cx": K_TRUE[0, 2], "cy": K_TRUE[1, 2]}
    for name, (lo, hi) in res.intervals_95().items():
        assert lo <= truth[name] <= hi, (name, lo, truth[name], hi)
    assert res.to_dict()["intervals_95"]["cx"] == list(res.intervals_95()["cx"])
