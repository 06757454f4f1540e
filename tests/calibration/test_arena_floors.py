"""The arena calibration finds the ball on floors of any colour: the twin's blue, grey, white,
black, red, green and wood-brown, the kerb in the floor's colour (as on an arena of one
colour), the arena's markers, wall and the arm's orange tool in view, the frame as an owner's
camera gives it (a distorted lens, sensor noise, a lighting gradient across the floor, JPEG).
`ergo calibrate arena --image FRAME` puts the ball within 5 mm of the truth and the tracker,
with the colour it sampled, follows the ball on that floor. On a grey or white floor the ball's
hue was the most common saturated one and was taken for the floor's ("no round saturated blob
apart from the floor (hue 36)"). Run with -s to see the errors measured."""

from __future__ import annotations

import re

import cv2
import numpy as np
import pytest

from calibration import store
from calibration.arena import MarkerLayout
from calibration.ball_colour import FLOOR_SIGMAS, find_saturated_blob, floor_colour
from calibration.store import CalibrationError
from sim.camera import SimCamera, write_marker_scene
from sim.models.make_scene import FLOOR_RGB
from sim.twin import Twin
from vision.rectify import ArenaModel
from vision.tracker import BallTracker, tracker_config_from_arena

SIZE = (480, 640)
LAYOUT = MarkerLayout()  # the layout write_marker_scene draws (and calibrate arena's default)
DIST = (-0.25, 0.08, 0.001, -0.0015, 0.0)  # a webcam's barrel distortion (as test_arena.py)
NOISE = 3.0  # sensor noise, levels (standard deviation)
JPEG_QUALITY = 75  # a webcam's MJPEG
# (r, g, b) of the floor and the kerb, 0..1; None: the twin's own (blue floor, lighter kerb)
FLOORS = {
    "twin-blue": None,
    "grey": (0.5, 0.5, 0.5),
    "white": (0.92, 0.92, 0.9),
    "black": (0.07, 0.07, 0.07),
    "red": (0.7, 0.12, 0.1),
    "green": (0.15, 0.5, 0.2),
    "wood": (0.6, 0.42, 0.25),
}
CALIBRATED_AT = (-0.1, -0.12)  # m: the ball while calibrating, on its ring
TRACKED_AT = [(0.15, 0.0), (0.0, 0.16), (-0.13, 0.05)]  # m: then the tracker's


def lighting(shape: tuple[int, int], gain: tuple[float, float] = (0.6, 1.15)) -> np.ndarray:
    """A lamp off to one side: light falling linearly across the frame's diagonal from
    ``gain[1]`` to ``gain[0]``, shape (H, W, 1)."""
    h, w = shape
    yy, xx = np.mgrid[0:h, 0:w]
    t = (xx / (w - 1) + yy / (h - 1)) / 2
    return (gain[1] + (gain[0] - gain[1]) * t)[..., None]


def owner_frame(cam: SimCamera) -> np.ndarray:
    """The camera's frame (lens and noise: ``SimCamera``) under uneven light, through JPEG."""
    lit = np.clip(cam.read().image * lighting(SIZE), 0, 255).astype(np.uint8)
    ok, jpeg = cv2.imencode(".jpg", lit, [cv2.IMWRITE_JPEG_QUALITY, JPEG_QUALITY])
    assert ok
    return cv2.imdecode(jpeg, cv2.IMREAD_COLOR)


def say(request: pytest.FixtureRequest, capsys: pytest.CaptureFixture, line: str) -> None:
    """Print a measured figure, with ``pytest -s`` only."""
    if request.config.getoption("capture") == "no":
        with capsys.disabled():
            print(f"\n{line}")


@pytest.fixture(params=list(FLOORS), ids=list(FLOORS))
def floor_twin(request, tmp_path):
    rgb = FLOORS[request.param]
    scene = write_marker_scene(tmp_path / "scene", LAYOUT.markers, LAYOUT.size_m, floor_rgb=rgb)
    twin = Twin(scene=scene, render_size=SIZE)
    yield request.param, twin
    twin.close()


def test_calibrate_arena_finds_the_ball_on_a_floor_of_any_colour(
    floor_twin, tmp_path, capsys, request
):
    from explore.cli import main

    name, twin = floor_twin
    cam = SimCamera(twin, size=SIZE, dist_coeffs=DIST, noise_std=NOISE, seed=11)
    cam.connect()
    k, d = cam.intrinsics()  # as `ergo calibrate camera` would have recovered them
    camera = {"camera_matrix": k, "dist_coeffs": d, "image_size": [SIZE[1], SIZE[0]],
              "rms_px": 0.2, "n_views": 15}  # fmt: skip
    store.save("camera", "rig", camera, tmp_path)
    twin.reset(ball_xy=CALIBRATED_AT)
    truth = twin.ball_position()[:2]
    frame = tmp_path / "arena.png"
    cv2.imwrite(str(frame), owner_frame(cam))
    rc = main(["calibrate", "arena", "--rig-id", "rig", "--dir", str(tmp_path), "--image",
               str(frame)])  # fmt: skip
    out = capsys.readouterr()
    assert rc == 0, f"{name}: {out.err}"
    m = re.search(r"-> arena \(([-+\d.]+), ([-+\d.]+)\) mm", out.out)
    assert m, out.out
    found = np.array([float(m.group(1)), float(m.group(2))]) / 1000
    error_mm = 1000 * float(np.linalg.norm(found - truth))

    # The tracker with the colour the calibration sampled sees one ball, where it is.
    data = store.load("arena", "rig", tmp_path)
    tracker = BallTracker(tracker_config_from_arena(data), ArenaModel.from_dict(data))
    tracked_mm = []
    for xy in TRACKED_AT:
        twin.reset(ball_xy=xy)
        obs = tracker.track(owner_frame(cam))
        assert obs.seen, f"{name} at {xy}: {obs.reason}"
        tracked_mm.append(
            1000 * float(np.linalg.norm(np.subtract(obs.xy, twin.ball_position()[:2])))
        )
    ranges = data["ball_hsv_ranges"]
    say(request, capsys, f"{name} floor: ball found {error_mm:.2f} mm from the truth; tracker "
        f"with its colour {max(tracked_mm):.2f} mm at most; ranges {ranges}")  # fmt: skip
    assert error_mm < 5.0 and max(tracked_mm) < 5.0


# ---- the floor's model on synthetic frames -------------------------------------------------
BALL_BGR = (31, 242, 199)  # the twin's ball (rgba 0.78 0.95 0.12), BGR levels


def synthetic_frame(floor_bgr: tuple[int, int, int], seed: int = 0) -> tuple[np.ndarray, dict]:
    """A 240 x 320 floor of one colour under a strong lighting gradient (0.45..1.1), a round
    shadow larger than the ball (the floor at 0.55), the ball (r 14 px), noise 3 levels and
    JPEG; returns the frame and the masks of the shadow, the ball and the plain floor."""
    h, w = 240, 320
    yy, xx = np.mgrid[0:h, 0:w]
    image = np.empty((h, w, 3), np.float64)
    image[:] = floor_bgr
    shadow = (xx - 90) ** 2 + (yy - 120) ** 2 <= 22**2
    image[shadow] *= 0.55
    ball = (xx - 230) ** 2 + (yy - 120) ** 2 <= 14**2
    image[ball] = BALL_BGR
    image *= lighting((h, w), (0.45, 1.1))
    image += np.random.default_rng(seed).normal(0.0, NOISE, image.shape)
    ok, jpeg = cv2.imencode(".jpg", np.clip(image, 0, 255).astype(np.uint8),
                            [cv2.IMWRITE_JPEG_QUALITY, JPEG_QUALITY])  # fmt: skip
    assert ok
    frame = cv2.imdecode(jpeg, cv2.IMREAD_COLOR)
    edge = cv2.dilate((shadow | ball).astype(np.uint8), np.ones((7, 7), np.uint8)) > 0
    inner = {k: cv2.erode(m.astype(np.uint8), np.ones((7, 7), np.uint8)) > 0
             for k, m in (("shadow", shadow), ("ball", ball))}  # fmt: skip
    return frame, {**inner, "floor": ~edge}


def levels(rgb: tuple[float, float, float] | None) -> tuple[int, int, int]:
    """BGR levels of a floor of ``FLOORS`` (None: the twin's blue)."""
    return tuple(round(255 * c) for c in reversed(rgb or FLOOR_RGB))


@pytest.mark.parametrize("name", list(FLOORS))
def test_the_floor_is_its_colour_in_every_shade_and_the_ball_is_not(name):
    """Lit from 45 % to 110 % and in a shadow, the floor stays the floor (within the gate of
    its spread, counted over 99.9 % of its pixels); the ball is far off it; and the round
    shadow, larger than the ball, is not taken for it (it is floor, even on a saturated
    floor)."""
    frame, masks = synthetic_frame(levels(FLOORS[name]))
    floor = floor_colour(frame)
    d = floor.distance(frame)
    assert np.mean(d[masks["floor"]] <= FLOOR_SIGMAS) > 0.999
    assert np.mean(d[masks["shadow"]] <= FLOOR_SIGMAS) > 0.99
    assert np.median(d[masks["ball"]]) > 3 * FLOOR_SIGMAS
    u, v = find_saturated_blob(frame)  # no arena model: the largest round blob
    assert np.hypot(u - 230, v - 120) < 1.5


def test_a_ball_of_the_floors_colour_is_refused_in_one_line_naming_the_floor():
    frame, _ = synthetic_frame(BALL_BGR)
    with pytest.raises(CalibrationError, match=r"no round saturated blob .*floor \(HSV 3\d, ") as e:
        find_saturated_blob(frame)
    assert "\n" not in str(e.value)


# ---- a served stand-in: a camera never seen, over MJPEG ------------------------------------
STANDIN_SEED = 301  # a development stand-in: its own camera pose, lens and ball (docs/standin.md)


@pytest.mark.parametrize("name", ["grey", "white"])
def test_calibrate_arena_live_on_a_stand_in_with_a_grey_or_white_floor(
    name, tmp_path, capsys, request
):
    """`ergo twin serve --stand-in SEED --floor-rgb R G B` in process: the stand-in's hidden
    camera pose and lens, its frames over MJPEG; `ergo calibrate arena --camera URL` finds the
    ball within 5 mm of where it lies. Its camera.json is the hidden camera (standing in for
    `ergo calibrate camera`, tested on its own)."""
    from explore.cli import main
    from sim.mjpeg_server import MjpegServer
    from sim.standin.hidden import draw_hidden
    from sim.standin.lens import ServedFrames
    from sim.standin.served import served_twin

    rig = draw_hidden(STANDIN_SEED)
    twin, plan = served_twin(rig, floor_rgb=FLOORS[name])
    frames = ServedFrames(twin, plan)
    try:
        twin.reset(ball_xy=(-0.1, 0.11))
        truth = twin.ball_position()[:2]
        camera = {"camera_matrix": rig.camera.camera_matrix, "dist_coeffs": rig.camera.dist_coeffs,
                  "image_size": list(rig.camera.size), "rms_px": 0.2, "n_views": 15}  # fmt: skip
        store.save("camera", "standin", camera, tmp_path)
        with MjpegServer(frames, fps=10) as server:
            rc = main(["calibrate", "arena", "--rig-id", "standin", "--dir", str(tmp_path),
                       "--camera", server.url])  # fmt: skip
    finally:
        frames.close()
        twin.close()
    out = capsys.readouterr()
    assert rc == 0, f"{name}: {out.err}"
    m = re.search(r"-> arena \(([-+\d.]+), ([-+\d.]+)\) mm", out.out)
    assert m, out.out
    error_mm = float(
        np.hypot(float(m.group(1)) - 1000 * truth[0], float(m.group(2)) - 1000 * truth[1])
    )
    say(request, capsys, f"stand-in {STANDIN_SEED}, {name} floor: ball found {error_mm:.2f} mm")
    assert error_mm < 5.0


def test_on_a_grey_floor_the_tool_is_never_taken_for_the_ball(tmp_path):
    """30 random arm poses (each joint uniform over 80 % of its range), the ball at random on
    its ring, as `ergo twin serve` streams the twin (240 x 240) on a grey floor: the ball found
    within 3 px or refused (partly hidden by the arm), never the orange tool. Measured: 27
    within 3 px, 1 at 4 px, 2 refused; the picker that took the most common saturated hue for
    the floor's was right in 11, refused 18 and took the tool in 1."""
    from calibration.arena import arena_from_markers
    from sim.camera import ideal_camera_matrix

    size = (240, 240)
    scene = write_marker_scene(tmp_path, LAYOUT.markers, LAYOUT.size_m, floor_rgb=FLOORS["grey"])
    twin = Twin(scene=scene, render_size=size)
    try:
        cam = SimCamera(twin, size=size)
        cam.connect()
        twin.reset()
        k = ideal_camera_matrix(float(twin.model.cam("overhead").fovy[0]), size)
        model = arena_from_markers(cam.read().image, LAYOUT, k, np.zeros(5)).model
        lo, hi = twin.model.jnt_range[:6].T
        rng = np.random.default_rng(42)
        outcomes = []
        for _ in range(30):
            angle, radius = rng.uniform(-np.pi, np.pi), rng.uniform(0.13, 0.17)
            twin.reset(ball_xy=(radius * np.cos(angle), radius * np.sin(angle)))
            twin.set_torque(True)
            twin.set_targets(rng.uniform(0.8 * lo, 0.8 * hi))
            twin.step(1.0)
            image = cam.read().image
            ball = cam.project(twin.ball_position()[None])[0]
            tool = cam.project(twin.data.site("tip").xpos[None])[0]
            try:
                pixel = np.array(find_saturated_blob(image, model, 0.03))
            except CalibrationError:
                outcomes.append("refused")
                continue
            off = float(np.linalg.norm(pixel - ball))
            outcomes.append(
                "ball" if off < 3 else "tool" if np.linalg.norm(pixel - tool) < 15 else off
            )
    finally:
        twin.close()
    assert "tool" not in outcomes
    assert outcomes.count("ball") >= 25, outcomes
