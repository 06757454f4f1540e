"""The twin: scenes load and step cleanly, the generator is in sync, the servos behave like an
XL-320, and states restore exactly."""

from __future__ import annotations

import math

import mujoco
import numpy as np
import pytest

from sim.models import make_scene
from sim.twin import MODELS, SCENE, SCENE_DISTRACTOR, Twin, TwinError


@pytest.mark.parametrize(
    "path", [MODELS / "ergo_jr.xml", SCENE, SCENE_DISTRACTOR], ids=["arm", "scene", "distractor"]
)
def test_every_scene_steps_one_second_under_random_controls_without_warnings(path):
    model = mujoco.MjModel.from_xml_path(str(path))
    data = mujoco.MjData(model)
    rng = np.random.default_rng(0)
    lo, hi = model.actuator_ctrlrange.T if model.actuator_ctrllimited.any() else (None, None)
    jnt_lo = model.jnt_range[model.actuator_trnid[:, 0], 0]
    jnt_hi = model.jnt_range[model.actuator_trnid[:, 0], 1]
    for _ in range(int(1.0 / model.opt.timestep)):
        data.ctrl[:] = rng.uniform(jnt_lo, jnt_hi)
        mujoco.mj_step(model, data)
    assert lo is None or hi is not None
    warnings = {mujoco.mjtWarning(i).name: w.number for i, w in enumerate(data.warning) if w.number}
    assert warnings == {}
    assert np.all(np.isfinite(data.qpos))


def test_committed_scene_matches_its_generator():
    assert SCENE.read_text() == make_scene.scene_xml()
    assert SCENE_DISTRACTOR.read_text() == make_scene.scene_xml(distractor=True)


def test_joint_ranges_are_the_ergo_jr_limits_in_radians():
    from robot.spec import ergo_jr_spec

    t = Twin()
    spec = ergo_jr_spec()
    for j in spec.joints:
        lo, hi = t.model.joint(j.name).range
        assert lo == pytest.approx(j.lower, abs=1e-5) and hi == pytest.approx(j.upper, abs=1e-5)


def test_a_30_degree_step_takes_about_0_2_s(twin):
    """XL-320-like actuator: 90% of a 30 degree step of m3 within 0.1-0.35 s."""
    step = math.radians(30)
    twin.set_targets(np.array([0, 0, step, 0, 0, 0]))
    t90 = None
    for i in range(200):
        twin.step()
        if t90 is None and twin.joint_positions()[2] >= 0.9 * step:
            t90 = (i + 1) * twin.timestep
    assert t90 is not None and 0.1 <= t90 <= 0.35, t90
    # and it settles without a large overshoot
    assert twin.joint_positions()[2] == pytest.approx(step, abs=math.radians(3))


def test_state_restores_exactly(twin):
    twin.set_targets(np.array([0.5, 1.0, 0.3, 0, 0.4, 0.2]))
    twin.step(0.3)
    saved = twin.get_state()
    twin.step(0.5)
    after = twin.get_state()
    twin.set_state(saved)
    twin.step(0.5)
    np.testing.assert_array_equal(twin.get_state(), after)


def test_state_of_another_shape_is_refused(twin):
    with pytest.raises(TwinError, match="shape"):
        twin.set_state(np.zeros(3))


def test_missing_scene_gives_a_clear_error(tmp_path):
    with pytest.raises(TwinError, match="cannot load twin scene"):
        Twin(tmp_path / "nope.xml")


def test_overhead_render_shows_the_ball_where_it_is(twin):
    """The ball is the only yellow-green thing; it moves in the image as it moves in the world."""
    import cv2

    def ball_pixel(xy):
        twin.reset(ball_xy=xy)
        img = twin.render("overhead")
        hsv = cv2.cvtColor(img, cv2.COLOR_BGR2HSV)
        mask = cv2.inRange(hsv, (27, 100, 70), (45, 255, 255))
        ys, xs = np.nonzero(mask)
        assert len(xs) > 10
        return xs.mean(), ys.mean()

    x1, y1 = ball_pixel((0.15, 0.0))
    x2, _ = ball_pixel((-0.15, 0.0))
    _, y3 = ball_pixel((0.0, 0.15))
    assert x1 > x2 + 20  # +x is to the right
    assert y3 < y1 - 10  # +y is up in the image


def test_torque_off_makes_the_arm_limp(twin):
    twin.set_targets(np.array([0, 1.2, 0, 0, 0, 0]))
    twin.step(0.6)
    held = twin.joint_positions()[1]
    twin.set_torque(False)
    twin.step(1.0)
    assert not twin.torque_enabled()
    assert twin.joint_positions()[1] > held + 0.05  # gravity pulls the leaning arm further down


def test_the_scene_renders_with_its_chosen_settings():
    """No shadow map, no multisampling, no shadow-casting light, a coarse floor grid: a model
    edit that brings back MuJoCo's 4096 x 4096 shadow map (15x the cost of a frame on a
    software renderer) fails here."""
    chosen = Twin()
    floor = chosen.model.geom("floor").id
    q = chosen.model.vis.quality
    assert (q.shadowsize, q.offsamples) == (make_scene.SHADOW_SIZE, make_scene.OFFSCREEN_SAMPLES)
    assert (q.shadowsize, q.offsamples) == (0, 0)
    assert not chosen.model.light_castshadow.any()
    assert chosen.model.geom_size[floor, 2] == make_scene.FLOOR_GRID


def test_the_removed_legacy_render_mode_is_refused_in_one_line_naming_it():
    from explore.rigs.rig import RigConfig, RigError, make_rig

    with pytest.raises(RigError, match=r"render_quality.*legacy render mode was removed"):
        make_rig(RigConfig(options={"render_quality": "legacy"}))
    make_rig(RigConfig(options={"render_quality": "chosen"}))  # run folders that name it


def test_the_observation_rendered_at_its_own_size_shows_the_ball_where_the_full_frame_does():
    """``SimCamera.read_square(64)`` (what the sim rig stores) against the 240 x 240 frame
    reduced to 64 x 64 (what it stored before): the ball's centroid within 0.25 px all round
    the ring (measured: 0.07 px median)."""
    from sim.camera import SimCamera
    from vision.observation import square_observation

    def centroid(bgr: np.ndarray) -> np.ndarray:
        import cv2

        hsv = cv2.cvtColor(bgr, cv2.COLOR_BGR2HSV).astype(float)
        w = ((hsv[..., 0] > 20) & (hsv[..., 0] < 45) & (hsv[..., 1] > 100)) * hsv[..., 2]
        ys, xs = np.mgrid[: bgr.shape[0], : bgr.shape[1]]
        return np.array([(w * xs).sum(), (w * ys).sum()]) / w.sum()

    twin = Twin(render_size=(240, 240))
    camera = SimCamera(twin)
    camera.connect()
    for ang in np.linspace(-math.pi, math.pi, 12, endpoint=False):
        r = 0.135 if ang < 0 else 0.165
        twin.reset(ball_xy=(r * math.cos(ang), r * math.sin(ang)))
        small = camera.read_square(64).image
        assert small.shape == (64, 64, 3) and small.dtype == np.uint8
        reduced = square_observation(camera.read().image, 64)
        assert np.linalg.norm(centroid(small) - centroid(reduced)) < 0.25, ang
    twin.close()
