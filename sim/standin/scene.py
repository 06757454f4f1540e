"""The served scene: the twin's arena as a person sets it up to calibrate, written into a
folder for ``sim.twin.Twin(scene=...)``.

On top of ``sim/models/scene.xml`` it has:
- the arena's four ArUco markers on the floor (``make_scene.ARENA_MARKERS``, drawn by
  ``sim.camera.write_marker_scene``), outside the wall, where the ball never goes;
- the overhead camera at the served pose with the render's field of view
  (``sim.standin.lens.render_plan``), and an offscreen buffer large enough for that render;
- the ball at its starting place (the ``home`` keyframe);
- a calibration board: a thin box on a mocap body (``board``, collides with nothing), kept
  below the floor until the hands hold it up, its image a texture (``board_tex``) that
  ``sim.standin.hands`` draws at run time;
- one hand per joint: an inactive joint equality (``hand_m1`` .. ``hand_m6``) that, once
  active, holds the joint at the angle in its ``eq_data[0]``, as a hand holds a limp joint.

None of it changes the physics of the arm or the ball until the hands act: the board collides
with nothing and the equalities start inactive.
"""

from __future__ import annotations

import re
from pathlib import Path

from robot.spec import ERGO_JR_JOINTS
from sim.camera import write_marker_scene
from sim.models.make_scene import (
    ARENA_MARKER_DICTIONARY,
    ARENA_MARKER_SIZE,
    ARENA_MARKERS,
    BALL_RADIUS,
)
from sim.standin.hidden import HiddenRig
from sim.standin.lens import RenderPlan

BOARD_BODY = "board"
BOARD_TEXTURE = "board_tex"
BOARD_TEXTURE_PX = 1024  # side of the board's texture: 146 px per square of a 7-square board
BOARD_THICKNESS_M = 0.003  # foam board (guess)
BOARD_AWAY = (0.0, 0.0, -1.0)  # m: below the floor, out of sight
# The hand's grip: an equality's stiffness. solref (time constant, damping ratio) 0.01 s (two
# 5 ms steps, the shortest MuJoCo allows) and solimp near 1 make it nearly rigid: under the
# arm's weight a held joint sits within 0.01 deg of the hand's angle (measured,
# tests/sim/standin/test_hands.py).
HAND_SOLREF = "0.01 1"
HAND_SOLIMP = "0.99 0.999 0.001 0.5 2"


def hand_name(joint: str) -> str:
    """The equality constraint of the hand on ``joint``."""
    return f"hand_{joint}"


def write_served_scene(
    out_dir: str | Path,
    rig: HiddenRig,
    plan: RenderPlan,
    floor_rgb: tuple[float, float, float] | None = None,
) -> Path:
    """Write the served scene of ``rig`` into ``out_dir``; returns the scene file's path.

    Args:
        out_dir: a folder (created) for the scene, the arm's model and the floor's texture.
        rig: the served rig (its camera pose and the ball's start are used).
        plan: the camera's render (its size and ``fovy``).
        floor_rgb: the floor's and the kerb's colour, (r, g, b) in 0..1 (default: the twin's
            blue floor; ``sim.models.make_scene.scene_xml``).
    """
    import cv2

    dictionary = getattr(cv2.aruco, ARENA_MARKER_DICTIONARY)
    scene = write_marker_scene(
        out_dir, ARENA_MARKERS, ARENA_MARKER_SIZE, dictionary, floor_rgb=floor_rgb
    )
    text = scene.read_text()
    h, w = plan.size
    side = max(640, h, w)
    text = _sub(r'offwidth="\d+" offheight="\d+"', f'offwidth="{side}" offheight="{side}"', text)
    cam = rig.camera
    x, y, z = cam.position
    qw, qx, qy, qz = cam.mujoco_quat()
    text = _sub(
        r'<camera name="overhead"[^>]*/>',
        f'<camera name="overhead" pos="{x:.9f} {y:.9f} {z:.9f}" '
        f'quat="{qw:.12f} {qx:.12f} {qy:.12f} {qz:.12f}" fovy="{plan.fovy_deg:.9f}"/>',
        text,
    )
    bx, by = rig.ball_xy
    text = _sub(
        r'(<key name="home" qpos="(?:\S+ ){6})\S+ \S+ \S+',
        rf"\g<1>{bx:.9f} {by:.9f} {BALL_RADIUS}",
        text,
    )
    n = BOARD_TEXTURE_PX
    text = text.replace(
        "</asset>",
        f'  <texture name="{BOARD_TEXTURE}" type="2d" builtin="flat" rgb1="1 1 1" '
        f'width="{n}" height="{n}"/>\n'
        f'    <material name="board_mat" texture="{BOARD_TEXTURE}" texuniform="false" '
        'texrepeat="1 1" specular="0" shininess="0"/>\n  </asset>',
        1,
    )
    bx0, by0, bz0 = BOARD_AWAY
    text = text.replace(
        "</worldbody>",
        "  <!-- the calibration board the hands hold (sim/standin/hands.py) -->\n"
        f'    <body name="{BOARD_BODY}" mocap="true" pos="{bx0} {by0} {bz0}">\n'
        f'      <geom name="{BOARD_BODY}" type="box" size="0.1 0.1 {BOARD_THICKNESS_M / 2}" '
        'material="board_mat" contype="0" conaffinity="0"/>\n'
        "    </body>\n  </worldbody>",
        1,
    )
    hands = "\n".join(
        f'    <joint name="{hand_name(j)}" joint1="{j}" polycoef="0 0 0 0 0" active="false" '
        f'solref="{HAND_SOLREF}" solimp="{HAND_SOLIMP}"/>'
        for j in ERGO_JR_JOINTS
    )
    text = text.replace(
        "<keyframe>",
        f"<!-- a hand on each joint (sim/standin/hands.py) -->\n  <equality>\n{hands}\n"
        "  </equality>\n\n  <keyframe>",
        1,
    )
    scene.write_text(text)
    return scene


def _sub(pattern: str, replacement: str, text: str) -> str:
    """``re.sub`` that must replace exactly once (the scene's layout changed otherwise)."""
    out, n = re.subn(pattern, replacement, text, count=1)
    if n != 1:
        raise ValueError(f"served scene: {pattern!r} not found in the twin's scene")
    return out
