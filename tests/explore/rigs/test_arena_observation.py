"""What a learned goal space sees on a physical rig is the twin's view: the camera's frame mapped
through the arena calibration onto the twin's overhead view (``vision.observation.
ArenaObservation``, ``explore.rigs.ball.TWIN_VIEW``), so that one model encodes both. Checked
against the twin's own render of the same scene: a camera of another size and lens in the twin's
place, and a stand-in's camera (another pose, another lens) with its exact calibration."""

from __future__ import annotations

import numpy as np
import pytest

from explore.rigs.arena import TWIN_VIEW
from explore.rigs.ball import CameraSensor, camera_sensor
from explore.rigs.rig import RigConfig
from sim.models.make_scene import BALL_RADIUS
from testkit.standin_views import ball_centroid
from testkit.standin_views import pixel_correlation as correlation
from vision.camera import Camera, Frame
from vision.observation import ArenaObservation, OverheadView, square_observation
from vision.rectify import ArenaModel, fit_homography, undistort_points

RING = [(0.15, 0.0), (0.0, 0.15), (-0.1, -0.1), (0.12, -0.09)]  # ball centres, m


def exact_model(camera) -> ArenaModel:
    """A ``sim.standin.hidden.HiddenCamera``'s arena model, from its own projection."""
    h = 0.2
    xy = np.array([[x, y] for x in (-h, 0.0, h) for y in (-h, 0.0, h)])
    px = camera.project(np.column_stack([xy, np.zeros(len(xy))]))
    homography = fit_homography(undistort_points(px, camera.camera_matrix, camera.dist_coeffs), xy)
    return ArenaModel(
        camera.camera_matrix, camera.dist_coeffs, camera.size, homography, np.zeros(2), h,
        camera.position,
    )  # fmt: skip


@pytest.fixture(scope="module")
def twin():
    """The committed twin and its overhead camera's 64 px observation."""
    from sim.camera import SimCamera
    from sim.twin import SCENE, Twin

    t = Twin(SCENE)
    camera = SimCamera(t)
    camera.connect()
    yield t, camera
    t.close()


def test_the_twin_view_is_the_twin_cameras_observation(twin):
    """Another camera in the twin's place (landscape, another resolution, a barrel lens) seen
    through its exact arena model is the twin's 64 px observation: the same orientation, scale
    and square."""
    from explore.rigs.sim import twin_arena_model
    from sim.camera import SimCamera

    t, ideal = twin
    other = SimCamera(t, size=(300, 400), dist_coeffs=(-0.25, 0.08, 0.001, -0.001))
    other.connect()
    observe = ArenaObservation(twin_arena_model(other), TWIN_VIEW, plane_height=BALL_RADIUS)
    for xy in RING:
        t.reset(xy)
        want = ideal.read_square(64).image
        got = observe(other.read().image, 64)
        assert got.shape == want.shape == (64, 64, 3) and got.dtype == np.uint8
        assert np.linalg.norm(ball_centroid(got) - ball_centroid(want)) < 0.3, xy
        assert correlation(got, want) > 0.97


def test_a_stand_in_camera_is_seen_as_the_twin_sees_its_arena(twin):
    """A stand-in's camera (its pose and lens drawn, 640 x 480) through its exact calibration:
    the ball where the twin's render puts it, and the picture far nearer the twin's than the
    raw frame's centre square (markers on its floor, which the twin's scene has not, are the
    rest)."""
    from sim.standin.hidden import draw_hidden
    from sim.standin.lens import ServedFrames
    from sim.standin.served import served_twin

    t, ideal = twin
    rig = draw_hidden(301)
    served, plan = served_twin(rig)
    frames = ServedFrames(served, plan)
    observe = ArenaObservation(exact_model(rig.camera), TWIN_VIEW, plane_height=BALL_RADIUS)
    try:
        for xy in RING:
            t.reset(xy)
            served.reset(xy)
            want = ideal.read_square(64).image
            frame = frames()
            got, before = observe(frame, 64), square_observation(frame, 64)
            assert np.linalg.norm(ball_centroid(got) - ball_centroid(want)) < 0.5, xy
            assert np.linalg.norm(ball_centroid(before) - ball_centroid(want)) > 2.0, xy
            assert correlation(got, want) > 0.85 > 0.6 > correlation(before, want)
    finally:
        frames.close()
        served.close()


def test_the_view_covers_the_twin_cameras_square_in_its_orientation():
    """Pixel centres of the view on a plane: +x to the right, +y up, the twin's scale."""
    view = OverheadView(height=0.55, fovy_deg=45.0)
    points = view.arena_points(4, plane_height=0.05)
    half = 0.5 * np.tan(np.radians(22.5)) * 3 / 4  # (0.55 - 0.05) m deep, pixel centres at 3/4
    np.testing.assert_allclose(points[0, 0], (-half, half))
    np.testing.assert_allclose(points[-1, -1], (half, -half))
    with pytest.raises(ValueError, match="below the view's camera"):
        view.arena_points(4, plane_height=0.6)


class _Still(Camera):
    """A camera that always shows one frame."""

    def __init__(self, image: np.ndarray) -> None:
        super().__init__()
        self.image = image

    def _connect(self) -> None:
        pass

    def _disconnect(self) -> None:
        pass

    def _read(self) -> Frame:
        return Frame(self.image, 0.0)


def test_a_physical_rig_sees_through_its_arena_calibration(tmp_path, monkeypatch):
    """``camera_sensor``: with the rig's arena calibration the observation is the twin's view
    of the frame; without one, its centre square (goal strategies are refused then)."""
    from calibration.store import save
    from sim.standin.hidden import draw_hidden

    camera = draw_hidden(301).camera
    model = exact_model(camera)
    frame = np.random.default_rng(0).integers(0, 255, (480, 640, 3), dtype=np.uint8)
    monkeypatch.setenv("ERGO_CALIBRATION_DIR", str(tmp_path))
    config = RigConfig("dynamixel", "s301", {"joint_calibration": "none"})
    with _Still(frame) as still:
        blind = camera_sensor(config, still)
        assert blind.blind is not None and blind.observe is square_observation
        np.testing.assert_array_equal(blind.locate(64).image, square_observation(frame, 64))
        save("arena", "s301", {**model.to_dict(), "ball_radius_m": BALL_RADIUS, "source": "test"})
        seeing = camera_sensor(RigConfig("dynamixel", "s301", {"joint_calibration": "none"}), still)
        assert isinstance(seeing, CameraSensor) and seeing.blind is None
        want = ArenaObservation(model, TWIN_VIEW, plane_height=BALL_RADIUS)(frame, 64)
        np.testing.assert_array_equal(seeing.locate(64).image, want)


@pytest.mark.parametrize("strategy", ["rge-sae", "rge-vae", "rge-online"])
def test_learned_goal_spaces_are_refused_without_an_arena_calibration(
    strategy, tmp_path, monkeypatch
):
    """Without an arena calibration a physical rig would observe the raw centre square: a
    learned goal space is refused as the engineered one is, in one line naming the command."""
    from explore.rigs.rig import RigError
    from explore.runs.config import RunConfig, StrategyConfig
    from explore.runs.open_run import open_run
    from testkit.untrained_models import save_untrained_models

    monkeypatch.setenv("ERGO_CALIBRATION_DIR", str(tmp_path / "calibration"))
    models = save_untrained_models(tmp_path / "models")
    options = {"sae": {"sae": models["sae"]}, "vae": {"vae": models["vae"]}}.get(
        strategy.split("-")[1], {}
    )
    rig = RigConfig("dynamixel", "nocal", {"port": "/dev/null-ergo-test"})  # never opened
    config = RunConfig(rig=rig, strategy=StrategyConfig(strategy, options), episodes=2)
    with pytest.raises(RigError) as caught:
        open_run(tmp_path / "run", config, mode="new")
    message = str(caught.value)
    assert "\n" not in message and "cannot locate the ball" in message
    assert "ergo calibrate arena --rig-id nocal" in message
    assert not (tmp_path / "run").exists()


@pytest.mark.parametrize(
    ("rig", "bus"),
    [("dynamixel", {"port": "/dev/null-ergo-test"}), ("canopen", {"can": "slcan:/dev/pts/99"})],
)
def test_both_buses_observe_and_film_the_twin_view(rig, bus, tmp_path, monkeypatch):
    """The physical rigs as built (unconnected): their sensor's observation and their
    ``record_video`` frames are the twin's view of the camera's frame."""
    from calibration.store import save
    from explore.rigs.rig import make_rig
    from sim.standin.hidden import draw_hidden

    model = exact_model(draw_hidden(302).camera)
    monkeypatch.setenv("ERGO_CALIBRATION_DIR", str(tmp_path))
    save("arena", "s302", {**model.to_dict(), "ball_radius_m": BALL_RADIUS, "source": "test"})
    options = {**bus, "camera": "0", "record_video": 32, "joint_calibration": "none"}
    built = make_rig(RigConfig(rig, "s302", options))
    frame = np.random.default_rng(1).integers(0, 255, (480, 640, 3), dtype=np.uint8)
    monkeypatch.setattr(built.camera, "read", lambda: Frame(frame, 0.0))
    view = ArenaObservation(model, TWIN_VIEW, plane_height=BALL_RADIUS)
    np.testing.assert_array_equal(built.sensor.locate(64).image, view(frame, 64))
    np.testing.assert_array_equal(built.video_frame(), view(frame, 32))


def test_without_the_cameras_position_the_view_goes_through_the_floor():
    """An arena calibration that could not place the camera (no intrinsics) maps through the
    floor (height 0), the one plane its homography knows; the view is still made."""
    from dataclasses import replace

    from sim.standin.hidden import draw_hidden

    model = replace(exact_model(draw_hidden(301).camera), camera_position=None)
    observe = ArenaObservation(model, TWIN_VIEW, plane_height=BALL_RADIUS)
    assert observe.plane_height == 0.0
    frame = np.full((480, 640, 3), 200, np.uint8)
    assert observe(frame, 64).shape == (64, 64, 3)
