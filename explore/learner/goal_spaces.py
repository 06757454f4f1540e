"""Goal spaces: how an episode's outcome (and its context) is described to the meta-policy.

A goal space turns a finished episode (an ``experience.Experience``) into
- a context vector c (what the scene looked like before the move), shape (context_dim,);
- an outcome vector o (what the move produced), shape (dim,), or None when not seen;
and splits the outcome's coordinates into modules (index groups) for modular goal exploration.

Engineered (EFR): the ball's polar coordinates around the arena centre (the arm's base, the
origin), normalised to about [-1, 1], from ``record.ball``/``context_ball`` (the twin's ground
truth for now; the tracker provides the same (x, y) on hardware). Two forms:
- ``"polar"``: (r_n, t / pi), the paper's features, with its discontinuity at t = +-pi;
- ``"wrap-safe"`` (default): (r_n, cos t, sin t), continuous all around the ring.

Learned: the VAE's latent means of ``record.image`` (see ``LatentGoalSpace``), or the image
positions of a spatial autoencoder's features (``spatial_goal_space``).
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any

import numpy as np

from robot.spec import ERGO_JR_REACH_M
from sim.models.make_scene import BALL_RADIUS, INNER_RADIUS, OUTER_RADIUS
from vision.spatial_code import distinct_features

# The ball's centre lies between these radii, m (the twin's ring between its kerb and its wall,
# less the ball's radius: 0.13-0.17 m; sim/models/make_scene.py): r_n = (r - R_MID) / R_HALF maps
# that band onto [-1, 1].
R_MIN, R_MAX = INNER_RADIUS + BALL_RADIUS, OUTER_RADIUS - BALL_RADIUS
R_MID = (R_MIN + R_MAX) / 2
R_HALF = (R_MAX - R_MIN) / 2
# End-effector module (MGE-EFR): the arm's horizontal reach, m (robot/spec.py).
REACH = ERGO_JR_REACH_M
POLAR_FORMS = ("wrap-safe", "polar")


def polar_features(xy: np.ndarray) -> np.ndarray:
    """Ball (x, y) m, shape (..., 2) -> (r_n, t / pi), shape (..., 2), t = atan2(y, x)."""
    xy = np.asarray(xy, dtype=float)
    r = np.hypot(xy[..., 0], xy[..., 1])
    t = np.arctan2(xy[..., 1], xy[..., 0])
    return np.stack([(r - R_MID) / R_HALF, t / np.pi], axis=-1)


def wrap_safe_features(xy: np.ndarray) -> np.ndarray:
    """Ball (x, y) m, shape (..., 2) -> (r_n, cos t, sin t), shape (..., 3)."""
    xy = np.asarray(xy, dtype=float)
    r = np.hypot(xy[..., 0], xy[..., 1])
    t = np.arctan2(xy[..., 1], xy[..., 0])
    return np.stack([(r - R_MID) / R_HALF, np.cos(t), np.sin(t)], axis=-1)


class GoalSpace:
    """Base class. Subclasses set ``dim``, ``context_dim``, ``modules`` and the two maps.

    Attributes:
        dim: size of the outcome vector.
        context_dim: size of the context vector.
        modules: coordinate index arrays, one per module (a partition or cover of range(dim)).
        module_kl: per module, a score of how informative it is (for ranking), or None.
    """

    dim: int
    context_dim: int
    modules: list[np.ndarray]

    def outcome(self, record: Any) -> np.ndarray | None:
        """Outcome vector of a record, shape (dim,), or None when not seen."""
        raise NotImplementedError

    def context(self, record: Any) -> np.ndarray:
        """Context vector of a record (the scene before its move), shape (context_dim,)."""
        raise NotImplementedError

    def module_outcomes(self, o: np.ndarray | None) -> list[np.ndarray | None]:
        """Split an outcome into its modules' coordinates."""
        return [None if o is None else o[idx] for idx in self.modules]


class EngineeredGoalSpace(GoalSpace):
    """Ball polar features; optionally the distractor's, and the arm's final tool tip (x, y) /
    REACH, each as a module of its own.

    Args:
        form: ``"wrap-safe"`` (r_n, cos t, sin t) or ``"polar"`` (r_n, t / pi).
        hand_module: add the end effector as a module (for MGE-EFR: one module per object, as
            the paper's engineered modules). Records without a known tool tip skip it.
        distractor: add the distractor's features (same form) as a module, after the ball's,
            and to the context: the engineered description of a scene with two balls.
            Records without a distractor seen skip that module.

    Outcome: [ball, distractor (if), hand (if)]; context: [ball, distractor (if)] before the
    move.
    """

    def __init__(
        self, form: str = "wrap-safe", hand_module: bool = False, distractor: bool = False
    ) -> None:
        if form not in POLAR_FORMS:
            raise ValueError(f"unknown polar form {form!r}; choose one of {', '.join(POLAR_FORMS)}")
        self.form = form
        self.features = wrap_safe_features if form == "wrap-safe" else polar_features
        self.ball_dim = 3 if form == "wrap-safe" else 2
        self.hand_module = hand_module
        self.distractor = distractor
        objects = 2 if distractor else 1
        self.context_dim = objects * self.ball_dim
        self.dim = self.context_dim + (2 if hand_module else 0)
        self.modules = [
            np.arange(k * self.ball_dim, (k + 1) * self.ball_dim) for k in range(objects)
        ]
        if hand_module:
            self.modules.append(np.arange(self.context_dim, self.dim))

    def _objects(self, ball: np.ndarray, distractor: np.ndarray | None) -> np.ndarray:
        """Features of the scene's objects (ball, distractor if this space has one): NaN
        where not seen."""
        o = self.features(np.asarray(ball, dtype=float)[:2])
        if not self.distractor:
            return o
        d = np.full(2, np.nan) if distractor is None else np.asarray(distractor, dtype=float)
        return np.concatenate([o, self.features(d[:2])])

    def outcome(self, record: Any) -> np.ndarray | None:
        ball = np.asarray(record.ball, dtype=float)[:2]
        if not np.all(np.isfinite(ball)):
            return None
        # a NaN distractor: its module skips the record
        o = self._objects(ball, getattr(record, "distractor", None))
        if self.hand_module:
            tip = np.asarray(record.end_effector, dtype=float)[-1, :2] / REACH
            o = np.concatenate([o, tip])  # NaN tip -> the hand module skips this record
        return o

    def module_outcomes(self, o: np.ndarray | None) -> list[np.ndarray | None]:
        out = super().module_outcomes(o)
        return [None if v is None or not np.all(np.isfinite(v)) else v for v in out]

    def context(self, record: Any) -> np.ndarray:
        return self.context_of(record.context_ball, getattr(record, "context_distractor", None))

    def context_of(self, ball: np.ndarray, distractor: np.ndarray | None) -> np.ndarray:
        """Context from the ball's and the distractor's positions (m), shape (context_dim,);
        zeros for an object not seen."""
        c = self._objects(ball, distractor)
        return np.where(np.isfinite(c), c, 0.0)


def kl_ranked_modules(kl_per_latent: Sequence[float], size: int = 2) -> list[np.ndarray]:
    """Latent indices grouped into modules of ``size``, most informative (largest KL) first:
    the paper's MGE modules (consecutive pairs of latents ranked by KL; 10 latents -> 5)."""
    order = np.argsort(-np.asarray(kl_per_latent, dtype=float), kind="stable")
    if len(order) % size:
        raise ValueError(f"{len(order)} latents do not split into modules of {size}")
    return [np.sort(order[i : i + size]) for i in range(0, len(order), size)]


class LatentGoalSpace(GoalSpace):
    """VAE latent means of the outcome image.

    The record holds no image of the context (only its ball); the context is the latent of the
    previous episode's outcome image (the scene the arm returned from; zeros before the first),
    which the strategy tracks itself. ``encode`` maps BGR uint8 images (n, 64, 64, 3) to latent
    means (n, latent_dim).

    Args:
        encode: the representation's encoder.
        latent_dim: size of the latent.
        kl_per_latent: KL of each latent over the training data (ranks the modules).
        modular: one module per pair of latents ranked by KL (MGE), else one module (RGE).
        zscore: None for the raw latent means (the paper's), or ``(mean, std)``, each of
            length latent_dim: the latent means' statistics over the outcome database, and the
            outcome is ``(mu - mean) / std``. Raw means of a beta-VAE can spread over 1e-4 in
            one latent and 2e-3 in another, so nearest neighbours in them follow a few latents
            only (docs/results.md, ``bench/bench_goal_space.py``).
    """

    def __init__(
        self,
        encode: Any,
        latent_dim: int,
        kl_per_latent: Sequence[float] | None = None,
        modular: bool = False,
        zscore: tuple[Sequence[float], Sequence[float]] | None = None,
    ) -> None:
        self.encode = encode
        self.dim = latent_dim
        self.context_dim = latent_dim
        self.shift = np.zeros(latent_dim)
        self.scale = np.ones(latent_dim)
        if zscore is not None:
            mean, std = (np.asarray(v, dtype=float) for v in zscore)
            if mean.shape != (latent_dim,) or std.shape != (latent_dim,):
                raise ValueError(
                    f"latent statistics have shapes {mean.shape} and {std.shape}, "
                    f"expected ({latent_dim},)"
                )
            if not (np.all(np.isfinite(mean)) and np.all(np.isfinite(std)) and np.all(std > 0)):
                raise ValueError("latent statistics must be finite with std > 0")
            self.shift, self.scale = mean, std
        if modular:
            kl = kl_per_latent if kl_per_latent is not None else np.arange(latent_dim)[::-1]
            self.modules = kl_ranked_modules(kl)
        else:
            self.modules = [np.arange(latent_dim)]

    def outcome(self, record: Any) -> np.ndarray | None:
        image = np.asarray(record.image)
        if image.ndim != 3:
            return None
        return self.outcomes(image[None])[0]

    def outcomes(self, images: np.ndarray) -> np.ndarray:
        """Outcomes of BGR uint8 images (n, 64, 64, 3) at once, shape (n, dim)."""
        mu = np.asarray(self.encode(images), dtype=float)
        return (mu - self.shift) / self.scale

    def context(self, record: Any) -> np.ndarray:
        raise NotImplementedError("latent contexts are tracked by the strategy (previous outcome)")


def spatial_goal_space(
    encode: Any,
    code_std: Sequence[float],
    modular: bool,
    code_corr: Sequence[Sequence[float]] | None = None,
) -> LatentGoalSpace:
    """The goal space of a spatial autoencoder: the image positions (x, y) of its distinct
    moving features (``distinct_features``), one module per feature for MGE (object-centred:
    a feature follows one thing), the whole for RGE. ``encode`` maps BGR uint8 images (n, 64,
    64, 3) to codes (n, 2 * features); the outcome keeps the kept features' coordinates."""
    live = distinct_features(code_std, code_corr)
    keep = np.array([i for k in live for i in (2 * k, 2 * k + 1)])

    def encode_live(images: np.ndarray) -> np.ndarray:
        return np.asarray(encode(images))[:, keep]

    space = LatentGoalSpace(encode_live, len(keep), modular=False)
    if modular:
        space.modules = [np.array([2 * i, 2 * i + 1]) for i in range(len(live))]
    space.features = live
    return space
