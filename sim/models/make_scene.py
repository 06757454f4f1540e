"""Writes ``scene.xml`` (the arena around the Ergo Jr) and ``scene_distractor.xml`` (the same
with a second ball, the distractor) from the geometry constants below.

Run ``python sim/models/make_scene.py`` after changing a constant; tests/sim/test_twin.py checks
that the committed scene.xml matches this generator.

Geometry (chosen and measured, see docs/twin.md): the ball rolls on a ring between an inner
kerb and an outer wall, centred on the arm's base, inside the arm's reach.
"""

from __future__ import annotations

import math
from pathlib import Path

INNER_RADIUS = 0.10  # m, kerb around the base (collides with the ball only)
OUTER_RADIUS = 0.20  # m, inner face of the outer wall
WALL_HEIGHT = 0.04  # m
# Invisible ball-only guard above the wall, up to this height: the arm could pin the ball
# against a 4 cm wall and pop it out of the arena (measured: 2 of 6 runs of 1000 random episodes
# with symmetric DMP ranges ended with the ball out of reach for good). On a real rig a person
# puts it back; the twin keeps it in. The arm passes through the guard (it collides with the
# ball only), as a real arm reaches over the wall.
GUARD_HEIGHT = 0.30  # m (chosen: above anything the arm can lift the ball to)
# The wall stops the ball only; the arm passes through it. When it collided with the arm, the
# tool hooked behind it in 7 of 150 random episodes (about 5%) and the linear way back to rest
# dragged it against the wall: 3 of the 7 were still jammed 3.5 s later, at full load, and
# the outcome image showed the arm in that pose (measured 2026-11-23, docs/twin.md). Whether
# the real arm can reach behind its wall is not known; a real arm that jams is stopped by the
# load watchdog during the settle (explore/rigs/arm_episodes.py).
WALL_CONAFFINITY = 2  # ball only (the kerb's and the guard's); 1 would make it stop the arm
KERB_HEIGHT = 0.02  # m
N_WALL_BOXES = 32
BALL_RADIUS = 0.03  # m, small foam ball (the real rig's ball is of this size; guess)
BALL_MASS = 0.01  # kg, foam (guess); easy to push, as on the real rig
BALL_START = (0.15, 0.0)  # m, initial ball position on the ring
ARENA_RADIUS = OUTER_RADIUS  # the metric's bounding square is [-R, R]^2
CAMERA_HEIGHT = 0.55  # m above the floor
CAMERA_FOVY = 45.0  # degrees: the arena's square fits the frame with a margin
# The arena's four ArUco markers, as a person lays them to calibrate the arena (the layout
# `ergo calibrate arena` looks for by default, calibration/arena.py; tests/sim/standin checks
# the two agree): DICT_4X4_50 ids 0..3 of 30 mm, centred on the floor's corners outside the
# wall, where the 0.55 m high 45-degree camera still sees them. A choice, not a standard. The
# served twin (`ergo twin serve`, sim/standin/) shows them on its floor; the committed scenes do
# not (their images are the learner's, and the tests').
ARENA_MARKERS = {0: (-0.19, 0.19), 1: (0.19, 0.19), 2: (0.19, -0.19), 3: (-0.19, -0.19)}  # m
ARENA_MARKER_SIZE = 0.03  # m, side of each marker's black square
ARENA_MARKER_DICTIONARY = "DICT_4X4_50"  # cv2.aruco predefined dictionary
# Render settings, chosen (docs/twin.md, "Render settings"): the light is straight above, so
# the ball's shadow lies under the ball, hidden from the overhead camera, and the arm at rest
# shades only itself; a real rig under ceiling lights sees soft shadows or none. MuJoCo's
# defaults (a 4096 x 4096 shadow map, 4x multisampling) cost 43.5 ms a frame on Mesa's software
# renderer at 64 x 64, against about 1-3.5 ms with no shadow-casting light and no
# multisampling (measured 2026-12-01; ``sim.twin.Twin(render_quality="legacy")`` brings them
# back). The outcome
# image is rendered at its own 64 x 64 (explore/rigs/sim.py): without multisampling the ball's
# centroid in it is 0.07 px (median) from that of an 8x-multisampled 480 x 480 render reduced
# to 64 x 64 (measured 2026-12-01 over 40 ring positions), 0.5 mm in the arena.
SHADOW_SIZE = 0  # px: no shadow map (no light casts shadows)
OFFSCREEN_SAMPLES = 0  # no multisample anti-aliasing
LIGHT_CASTS_SHADOW = False
FLOOR_GRID = 0.5  # m, spacing of the floor's render grid (rendering only; see the scene)
# The floor's and the kerb's colours (r, g, b in 0..1; chosen): a blue floor, HSV hue about
# 115 in OpenCV units, away from the ball's yellow-green and the tool's orange, and a lighter
# blue kerb. ``scene_xml(floor_rgb=...)`` draws the floor, and the kerb with it, in another
# colour, as an owner's arena may be (tests/calibration/test_arena_floors.py); the committed
# scenes keep these.
FLOOR_RGB = (0.12, 0.22, 0.7)
KERB_RGB = (0.2, 0.3, 0.75)


def wall_boxes() -> str:
    """The visible wall and the invisible guard above it, both stopping the ball only."""
    half_len = OUTER_RADIUS * math.tan(math.pi / N_WALL_BOXES) + 0.004
    lines = []
    r = OUTER_RADIUS + 0.005
    guard_half = (GUARD_HEIGHT - WALL_HEIGHT) / 2
    for k in range(N_WALL_BOXES):
        a = 2 * math.pi * k / N_WALL_BOXES
        x, y = r * math.cos(a), r * math.sin(a)
        lines.append(
            f'    <geom name="wall{k}" class="wall" pos="{x:.5f} {y:.5f} {WALL_HEIGHT / 2:.4f}" '
            f'euler="0 0 {a:.5f}" size="0.005 {half_len:.5f} {WALL_HEIGHT / 2:.4f}"/>'
        )
        lines.append(
            f'    <geom name="guard{k}" class="guard" pos="{x:.5f} {y:.5f} '
            f'{WALL_HEIGHT + guard_half:.4f}" euler="0 0 {a:.5f}" '
            f'size="0.005 {half_len:.5f} {guard_half:.4f}"/>'
        )
    return "\n".join(lines)


# The distractor (scene_distractor.xml): a second ball of another colour that nothing can move
# but the rig between episodes (sim.twin.Twin.place_distractor: a random walk on the ball's
# ring). It collides with nothing, so the arm and the ball pass through it (a mocap body:
# kinematic, its position part of the twin's saved state). Red, a hue the ball tracker's
# yellow-green and blue ranges exclude. Chosen, for the distractor experiment (docs/twin.md).
DISTRACTOR_RADIUS = BALL_RADIUS  # m
DISTRACTOR_START = (-0.15, 0.0)  # m, opposite the ball's start
DISTRACTOR_RGBA = "0.9 0.12 0.12 1"


def distractor_body() -> str:
    x, y = DISTRACTOR_START
    return f"""
    <!-- the distractor: moved only between episodes, collides with nothing (make_scene.py) -->
    <body name="distractor" mocap="true" pos="{x} {y} {DISTRACTOR_RADIUS}">
      <geom name="distractor" type="sphere" size="{DISTRACTOR_RADIUS}" contype="0"
            conaffinity="0" rgba="{DISTRACTOR_RGBA}"/>
    </body>"""


def rgb_text(rgb: tuple[float, ...]) -> str:
    """An MJCF colour, "r g b", from (r, g, b) in 0..1.

    Raises:
        ValueError: not three numbers in 0..1.
    """
    values = tuple(float(c) for c in rgb)
    if len(values) != 3 or not all(0.0 <= c <= 1.0 for c in values):
        raise ValueError(f"a colour is three numbers in 0..1 (r, g, b), got {rgb!r}")
    return " ".join(f"{c:g}" for c in values)


def scene_xml(distractor: bool = False, floor_rgb: tuple[float, float, float] | None = None) -> str:
    """The scene's MJCF text; ``distractor``: with the second ball; ``floor_rgb``: the floor
    and the kerb in that colour (r, g, b in 0..1; default: ``FLOOR_RGB`` and ``KERB_RGB``, the
    committed scenes' text to the byte).

    Raises:
        ValueError: ``floor_rgb`` is not three numbers in 0..1.
    """
    extra = distractor_body() if distractor else ""
    if floor_rgb is None:
        floor, kerb = rgb_text(FLOOR_RGB), rgb_text(KERB_RGB)
        floor_note = "blue arena floor (HSV hue about 115 in OpenCV units)"
    else:
        floor = kerb = rgb_text(floor_rgb)
        floor_note = "arena floor, and the kerb, of another colour than the twin's blue"
    mpos = (
        f'\n         mpos="{DISTRACTOR_START[0]} {DISTRACTOR_START[1]} {DISTRACTOR_RADIUS}"'
        if distractor
        else ""
    )
    return f"""<!-- Generated by sim/models/make_scene.py: edit the constants there, not this file. -->
<mujoco model="ergo_jr_arena">
  <include file="ergo_jr.xml"/>
  <compiler angle="radian"/>
  <!-- 5 ms steps: stable with the XL-320-like actuators, about 10 ms of CPU per episode. -->
  <option timestep="0.005" integrator="implicitfast" cone="elliptic"/>

  <statistic center="0 0 0.1" extent="0.5"/>
  <visual>
    <headlight diffuse="0.6 0.6 0.6" ambient="0.35 0.35 0.35" specular="0 0 0"/>
    <global offwidth="640" offheight="640"/>
    <!-- chosen in make_scene.py (SHADOW_SIZE, OFFSCREEN_SAMPLES): see docs/twin.md -->
    <quality shadowsize="{SHADOW_SIZE}" offsamples="{OFFSCREEN_SAMPLES}"/>
  </visual>

  <default>
    <default class="wall">
      <geom type="box" contype="0" conaffinity="{WALL_CONAFFINITY}" rgba="0.85 0.85 0.8 1"/>
    </default>
    <!-- ball only (conaffinity 2, as the kerb), invisible (group 3 is not rendered by default) -->
    <default class="guard">
      <geom type="box" contype="0" conaffinity="2" rgba="1 1 1 0" group="3"/>
    </default>
  </default>

  <asset>
    <texture name="floor_tex" type="2d" builtin="flat" rgb1="{floor}" width="64" height="64"/>
    <material name="floor_mat" texture="floor_tex"/>
  </asset>

  <worldbody>
    <light name="top" pos="0 0 1.2" dir="0 0 -1" diffuse="0.5 0.5 0.5" directional="true"
           castshadow="{str(LIGHT_CASTS_SHADOW).lower()}"/>
    <!-- {floor_note}; the third size is the spacing of
         the grid it is drawn with (rendering only): 0.5 m, 2 x 2 quads, draws the same pixels as
         the 100 x 100 of 0.01 m in half the time of a 64 x 64 frame (measured 2026-12-01) -->
    <geom name="floor" type="plane" size="0.5 0.5 {FLOOR_GRID}" material="floor_mat" contype="0" conaffinity="1"
          friction="0.8 0.005 0.0001"/>
    <!-- kerb around the base: keeps the ball on its ring, collides with the ball only -->
    <geom name="kerb" type="cylinder" size="{INNER_RADIUS} {KERB_HEIGHT / 2}" pos="0 0 {KERB_HEIGHT / 2}"
          contype="0" conaffinity="2" rgba="{kerb} 1"/>
{wall_boxes()}
    <!-- yellow-green ball; condim 6 with rolling friction so that it stops (measured, README.md) -->
    <body name="ball" pos="{BALL_START[0]} {BALL_START[1]} {BALL_RADIUS}">
      <freejoint name="ball"/>
      <geom name="ball" type="sphere" size="{BALL_RADIUS}" mass="{BALL_MASS}" condim="6"
            friction="0.8 0.01 0.004" contype="3" conaffinity="1" rgba="0.78 0.95 0.12 1"/>
    </body>{extra}
    <camera name="overhead" pos="0 0 {CAMERA_HEIGHT}" xyaxes="1 0 0 0 1 0" fovy="{CAMERA_FOVY}"/>
    <camera name="side" pos="0.36 -0.36 0.34" xyaxes="1 1 0 -0.45 0.45 0.77" fovy="45"/>
  </worldbody>

  <keyframe>
    <key name="home" qpos="0 0 0 0 0 0 {BALL_START[0]} {BALL_START[1]} {BALL_RADIUS} 1 0 0 0"
         ctrl="0 0 0 0 0 0"{mpos}/>
  </keyframe>
</mujoco>
"""


SCENE_FILES = {False: "scene.xml", True: "scene_distractor.xml"}


def main() -> None:
    for distractor, name in SCENE_FILES.items():
        out = Path(__file__).with_name(name)
        out.write_text(scene_xml(distractor))
        print(f"wrote {out}")


if __name__ == "__main__":
    main()
