"""Planar kinematics of the ArmBalls arm: joint commands in [-1, 1] -> link points and hand.

Joint k's absolute angle is pi times the sum of the commands of joints 0..k (the original's
ArmBalls.act: ``pi * cumsum(action)``), so a command of 1 on joint 0 alone turns the whole arm
by pi rad. The base is at the origin; with every command at 0 the arm lies along +x. Sines and
cosines are ``plumbing.fixed_order``'s (the C library's variant depends on the CPU), so a
scene is the same bits on every machine.
"""

from __future__ import annotations

import numpy as np

from plumbing.fixed_order import matmul, sin_cos


def joint_angles(commands: np.ndarray) -> np.ndarray:
    """Absolute angle of each link, rad.

    Args:
        commands: joint commands, shape (..., n_joints), normally in [-1, 1].

    Returns:
        shape (..., n_joints): pi * cumulative sum over the last axis.
    """
    return np.pi * np.cumsum(np.asarray(commands, dtype=float), axis=-1)


def link_points(commands: np.ndarray, link_lengths: np.ndarray) -> np.ndarray:
    """End point of every link (the last one is the hand).

    Args:
        commands: shape (..., n_joints).
        link_lengths: shape (n_joints,).

    Returns:
        shape (..., n_joints, 2): (x, y) of each link's far end.
    """
    sin, cos = sin_cos(joint_angles(commands))
    lengths = np.asarray(link_lengths, dtype=float)
    steps = np.stack([cos * lengths, sin * lengths], axis=-1)
    return np.cumsum(steps, axis=-2)


def hand_position(commands: np.ndarray, link_lengths: np.ndarray) -> np.ndarray:
    """The hand (the last link's end).

    Args:
        commands: shape (..., n_joints).
        link_lengths: shape (n_joints,).

    Returns:
        shape (..., 2): (x, y).
    """
    sin, cos = sin_cos(joint_angles(commands))
    lengths = np.asarray(link_lengths, dtype=float)
    # summed link after link, as ``link_points``' cumulative sum (never BLAS's order)
    return np.stack([matmul(cos, lengths), matmul(sin, lengths)], axis=-1)
