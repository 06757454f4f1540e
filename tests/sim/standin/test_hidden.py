"""The stand-in's hidden parameters: a pure function of the seed, inside the ranges
docs/standin.md states, the camera always showing the arena, written and read back exactly."""

from __future__ import annotations

import json
import math

import numpy as np
import pytest

from sim.models.make_scene import ARENA_MARKER_DICTIONARY, ARENA_MARKER_SIZE, ARENA_MARKERS
from sim.servo_model import NOMINAL
from sim.standin import hidden as H
from testkit.standin_truth import read_hidden

SEEDS = range(40)


def test_the_same_seed_gives_the_same_rig_and_another_seed_another():
    a, b = H.draw_hidden(11), H.draw_hidden(11)
    assert json.dumps(a.to_dict()) == json.dumps(b.to_dict())
    c = H.draw_hidden(12)
    assert not np.allclose(a.offsets, c.offsets)
    assert not np.allclose(a.camera.camera_matrix, c.camera.camera_matrix)
    assert a.servos != c.servos


@pytest.mark.parametrize("seed", SEEDS)
def test_every_draw_is_inside_its_ranges(seed):
    rig = H.draw_hidden(seed)
    assert set(rig.directions) <= {-1.0, 1.0}
    assert np.all(np.abs(np.degrees(rig.offsets)) <= H.ASSEMBLY_ERROR_DEG + H.TOOTH_DEG + 1e-9)
    cam = rig.camera
    k = cam.camera_matrix
    assert abs(k[1, 1] / H.NOMINAL_FOCAL_PX - 1) <= H.FOCAL_SPREAD + 1e-9
    assert abs(k[0, 0] / k[1, 1] - 1) <= H.ASPECT_SPREAD + 1e-9
    w, h = cam.size
    assert abs(k[0, 2] - (w - 1) / 2) <= H.PRINCIPAL_SPREAD_PX
    assert abs(k[1, 2] - (h - 1) / 2) <= H.PRINCIPAL_SPREAD_PX
    assert H.K1_RANGE[0] <= cam.dist_coeffs[0] <= H.K1_RANGE[1]
    assert H.HEIGHT_RANGE_M[0] <= cam.position[2] <= H.HEIGHT_RANGE_M[1]
    assert np.allclose(cam.rotation @ cam.rotation.T, np.eye(3))
    axis = cam.rotation.T @ np.array([0.0, 0.0, 1.0])  # the optical axis in the world
    assert math.degrees(math.acos(-axis[2])) <= H.MAX_TILT_DEG + 1e-6
    # the arena, its markers with their quiet zone, in view
    px = cam.project(H.arena_points())
    assert px.min() >= H.VIEW_MARGIN_PX and np.all(px.max(axis=0) <= np.array([w, h]) - 1)
    bound = H.RIG_FACTOR * H.JOINT_FACTOR + 1e-9
    for name in ("kp", "damping", "armature"):
        ratio = rig.servos.array(name) / NOMINAL.array(name)
        assert np.all((ratio <= bound) & (ratio >= 1 / bound)), name
    assert H.DELAY_RANGE_S[0] <= rig.servos.delay_s <= H.DELAY_RANGE_S[1]
    assert H.BALL_RING_M[0] <= math.hypot(*rig.ball_xy) <= H.BALL_RING_M[1]


def test_the_draws_cover_their_ranges():
    """Over 40 seeds both directions, tooth errors and barrel lenses all occur: a stand-in
    tests what it claims to."""
    rigs = [H.draw_hidden(s) for s in SEEDS]
    directions = np.concatenate([r.directions for r in rigs])
    offsets = np.degrees(np.concatenate([r.offsets for r in rigs]))
    assert (directions < 0).mean() == pytest.approx(0.5, abs=0.15)
    assert (np.abs(offsets) > H.ASSEMBLY_ERROR_DEG).mean() == pytest.approx(0.3, abs=0.12)
    k1 = np.array([r.camera.dist_coeffs[0] for r in rigs])
    assert k1.min() < -0.2 and k1.max() > 0.0
    kp = np.array([r.servos.kp[0] / NOMINAL.kp[0] for r in rigs])
    assert kp.min() < 0.7 and kp.max() > 1.5


def test_the_nominal_rig_is_the_committed_scene():
    rig = H.nominal_rig()
    assert rig.seed is None and np.all(rig.directions == 1) and not np.any(rig.offsets)
    assert rig.servos == NOMINAL and not np.any(rig.camera.dist_coeffs)
    # straight down from 0.55 m: the base projects to the image centre
    assert rig.camera.project(np.zeros((1, 3)))[0] == pytest.approx([119.5, 119.5])


def test_written_and_read_back(tmp_path):
    rig = H.draw_hidden(5)
    path = H.write_hidden(rig, tmp_path / "h.json")
    back = read_hidden(path)
    assert back.seed == 5 and back.servos == rig.servos and back.ball_xy == rig.ball_xy
    assert np.array_equal(back.offsets, rig.offsets)
    assert np.array_equal(back.directions, rig.directions)
    for name in ("camera_matrix", "dist_coeffs", "position", "rotation"):
        assert np.array_equal(getattr(back.camera, name), getattr(rig.camera, name))
    data = json.loads(path.read_text())
    steps = np.array(data["joints"]["dynamixel_steps_at_zero"])
    assert steps == pytest.approx(512 + rig.offsets / (math.radians(300) / 1023))


def test_bad_seeds_and_files_are_one_line(tmp_path):
    for seed in (-1, 1.5, "3", True):
        with pytest.raises(H.StandinError, match="integer >= 0"):
            H.draw_hidden(seed)
    with pytest.raises(H.StandinError, match="cannot read"):
        read_hidden(tmp_path / "missing.json")
    (tmp_path / "bad.json").write_text('{"seed": 1}')
    with pytest.raises(H.StandinError, match="not a stand-in's hidden file"):
        read_hidden(tmp_path / "bad.json")


def test_the_served_markers_are_the_arena_calibrations_default_layout():
    """One layout on both sides: what the served floor shows is what ``ergo calibrate arena``
    looks for by default."""
    from calibration.arena import DEFAULT_MARKER_SIZE_M, DEFAULT_MARKERS, MarkerLayout

    assert DEFAULT_MARKERS == ARENA_MARKERS
    assert DEFAULT_MARKER_SIZE_M == ARENA_MARKER_SIZE
    assert MarkerLayout().dictionary == ARENA_MARKER_DICTIONARY
