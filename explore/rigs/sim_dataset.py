"""Outcome database for pre-training representations: twin scenes rendered as the rig sees them.

Each scene: the ball placed uniformly over its ring (uniform in area between radii 0.13 and 0.17
m, where the ball's centre can lie; uniform angle), the arm at its rest pose (``arm="rest"``,
the default: an episode's outcome is observed there, explore/rigs/arm_episodes.py) or driven towards
random joint targets inside its limits (``arm="random"``, the paper's database, in which the
arm's pose varies), ``settle_s`` seconds of physics, then the overhead view rendered at 64x64
exactly as an episode's outcome on the twin (``sim.camera.SimCamera.read_square``). The ball's
position is read after the arm moved (the arm may have pushed it).

The paper pre-trained its VAEs on such a database of the environment's possible outcomes.
"""

from __future__ import annotations

import sys
from pathlib import Path

import numpy as np

from explore.rigs.arena import R_MAX, R_MIN
from plumbing.files import atomic_write
from robot.spec import ergo_jr_spec
from vision.observation import OBSERVATION_SIZE

SETTLE_S = 0.3  # s of physics towards the random pose: a 30-degree step takes ~0.2 s (docs/twin)
ARM_POSES = ("rest", "random")  # arm at its rest pose (as in an episode's outcome) or random


def ring_positions(n: int, rng: np.random.Generator) -> np.ndarray:
    """Ball centres uniform in area over the ring R_MIN..R_MAX, shape (n, 2), m."""
    r = np.sqrt(rng.uniform(R_MIN**2, R_MAX**2, n))
    t = rng.uniform(-np.pi, np.pi, n)
    return np.stack([r * np.cos(t), r * np.sin(t)], axis=1)


def make_outcome_dataset(
    n: int,
    seed: int = 0,
    settle_s: float = SETTLE_S,
    progress: bool = True,
    arm: str = "rest",
    distractor: bool = False,
) -> dict[str, np.ndarray]:
    """Render ``n`` scenes with the arm at rest (``arm="rest"``) or in random poses (``"random"``),
    rendered as the sim rig renders its outcome images. ``distractor``: the scene with the
    distractor, placed uniformly over the ring too, independently of the ball (as its walk
    leaves it in the long run).

    Returns:
        images: (n, 64, 64, 3) BGR uint8; ball: (n, 2) m after the arm moved; placed: (n, 2) m
        where the ball was put; joints: (n, 6) rad, the arm's pose at the render; with the
        distractor also distractor: (n, 2) m.
    """
    from sim.camera import SimCamera
    from sim.twin import JOINTS, SCENE, SCENE_DISTRACTOR, Twin

    if arm not in ARM_POSES:
        raise ValueError(f"arm={arm!r}: expected one of {', '.join(ARM_POSES)}")
    rng = np.random.default_rng(seed)
    twin = Twin(SCENE_DISTRACTOR if distractor else SCENE)
    camera = SimCamera(twin)
    camera.connect()
    lo = np.array([twin.model.joint(j).range[0] for j in JOINTS])
    hi = np.array([twin.model.joint(j).range[1] for j in JOINTS])
    size = OBSERVATION_SIZE
    placed = ring_positions(n, rng)
    others = ring_positions(n, rng) if distractor else None
    targets = rng.uniform(lo, hi, (n, len(JOINTS)))
    if arm == "rest":
        targets[:] = ergo_jr_spec().rest
    images = np.empty((n, size, size, 3), dtype=np.uint8)
    ball = np.empty((n, 2))
    joints = np.empty((n, len(JOINTS)))
    bar = None
    if progress:
        from tqdm import tqdm

        bar = tqdm(total=n, unit="img", file=sys.stderr, mininterval=1.0, desc="outcomes")
    try:
        for i in range(n):
            twin.reset(tuple(placed[i]))
            if others is not None:
                twin.place_distractor(others[i])
            twin.set_targets(targets[i])
            twin.step(settle_s)
            images[i] = camera.read_square(size).image
            ball[i] = twin.ball_position()[:2]
            joints[i] = twin.joint_positions()
            if bar is not None:
                bar.update(1)
    finally:
        if bar is not None:
            bar.close()
        twin.close()
    out = {"images": images, "ball": ball, "placed": placed, "joints": joints}
    if others is not None:
        out["distractor"] = others
    return out


def save_dataset(path: str | Path, data: dict[str, np.ndarray]) -> None:
    """Write a dataset as a compressed ``.npz`` (no pickle), atomically."""
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    # a full disk: no half-written file left, an older dataset kept (plumbing.files)
    atomic_write(path, lambda tmp: np.savez_compressed(tmp, **data))
