"""The twin's floor in another colour (``make_scene.scene_xml(floor_rgb=...)``, through
``write_marker_scene``, the served scene and ``ergo twin serve --floor-rgb``): only the floor
and the kerb change; a colour out of 0..1 is refused in one line. The committed scenes are the
generator's default text to the byte (tests/sim/test_twin.py), so the default render is
unchanged."""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from sim.camera import write_marker_scene
from sim.models.make_scene import scene_xml
from sim.twin import SCENE_DISTRACTOR, Twin

ROOT = Path(__file__).resolve().parents[2]
SIZE = (160, 160)
MARKERS: dict[int, tuple[float, float]] = {}  # the floor alone (a marker's edge blends with it)


def render(scene: Path) -> np.ndarray:
    twin = Twin(scene=scene, render_size=SIZE)
    try:
        twin.reset(ball_xy=(0.15, 0.0))
        return twin.render()
    finally:
        twin.close()


def test_only_the_floor_and_the_kerb_take_the_colour_asked(tmp_path):
    blue = render(write_marker_scene(tmp_path / "blue", MARKERS, 0.03))
    grey = render(write_marker_scene(tmp_path / "grey", MARKERS, 0.03, floor_rgb=(0.5, 0.5, 0.5)))
    changed = np.abs(blue.astype(int) - grey).max(axis=2) > 0
    # the floor (and the kerb) was blue (B well above R) wherever the render changed ...
    b, r = blue[..., 0].astype(int), blue[..., 2].astype(int)
    assert changed.mean() > 0.5 and np.all(b[changed] - r[changed] > 60)
    # ... and is grey there now (the light is white: R = G = B within rounding)
    assert np.ptp(grey[changed].astype(int), axis=1).max() <= 1
    # the ball, the wall and the arm are as they were, to the bit
    assert np.array_equal(blue[~changed], grey[~changed])


def test_a_floor_colour_out_of_0_to_1_is_refused(tmp_path):
    with pytest.raises(ValueError, match=r"three numbers in 0..1"):
        scene_xml(floor_rgb=(1.2, 0.0, 0.0))
    with pytest.raises(ValueError, match=r"twin's own scene only"):
        write_marker_scene(tmp_path, MARKERS, 0.03, scene=SCENE_DISTRACTOR, floor_rgb=(0, 0, 0))
    proc = subprocess.run(
        [sys.executable, "-m", "explore.cli", "twin", "serve", "--bus", "dynamixel",
         "--no-camera", "--floor-rgb", "1.5", "0", "0"],
        cwd=ROOT, capture_output=True, text=True, timeout=120,
    )  # fmt: skip
    assert proc.returncode == 2
    assert proc.stderr.strip().splitlines() == [
        "ergo: error: --floor-rgb: a colour is three numbers in 0..1 (r, g, b), got [1.5, 0.0, 0.0]"
    ]
