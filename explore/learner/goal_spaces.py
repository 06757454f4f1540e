"""Goal spaces: how an episode's outcome (and its context) is described to the meta-policy.

A goal space turns a finished episode (an ``experience.Experience``) into
- a context vector c (what the scene looked like before the move), shape (context_dim,);
- an outcome vector o (what the move produced), shape (dim,), or None when not seen;
and splits the outcome's coordinates into modules (index groups) for modular goal exploration.

Engineered (EFR): the position (x, y) of each object of the scene (the ball, the distractor) in a
form defined on the rig's scene (``explore.learner.scene.Scene``), from ``record.ball`` /
``context_ball`` (the twin's ground truth for now; the tracker provides the same (x, y) on
hardware; ArmBalls' state):
- ``"wrap-safe"`` (the twin's default): (r_n, cos t, sin t) around the arena's centre, r_n the
  radius mapped from the scene's ring onto [-1, 1], continuous all around the ring;
- ``"polar"``: (r_n, t / pi), the paper's features on the rig, with its discontinuity at t = +-pi;
- ``"cartesian"`` (the only form of a scene without a ring, ArmBalls): (x / h, y / h), h the
  half width of the scene's square, in [-1, 1] (ArmBalls' engineered features are the balls'
  positions, docs/armballs.md).

Learned: the VAE's latent means of ``record.image`` (see ``LatentGoalSpace``), or the image
positions of a spatial autoencoder's features (``spatial_goal_space``).
"""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence
from typing import Any

import numpy as np

from explore.learner.scene import CARTESIAN, FORMS, Scene
from vision.spatial_code import distinct_features

POLAR_FORMS = FORMS  # every engineered form (explore/learner/scene.py)
Features = Callable[[np.ndarray], np.ndarray]
_ATAN2 = np.frompyfunc(math.atan2, 2, 1)  # the C library's, elementwise


def _radius(xy: np.ndarray) -> np.ndarray:
    """sqrt(x^2 + y^2) of (..., 2), elementwise (no libm hypot: the same bits everywhere)."""
    x, y = xy[..., 0], xy[..., 1]
    return np.sqrt(x * x + y * y)


def ring_polar_features(xy: np.ndarray, ring: tuple[float, float]) -> np.ndarray:
    """The ``"polar"`` form: ball (x, y), shape (..., 2) -> (r_n, t / pi), shape (..., 2),
    t = atan2(y, x), r_n the radius mapped from ``ring`` = (r_min, r_max) onto [-1, 1]
    (not ``vision.rectify.polar_features``, the tracker's (r, cos t, sin t) in metres).
    The angle is the C library's ``atan2`` (numpy's own runs a SIMD version chosen by CPU;
    docs/determinism.md)."""
    xy = np.asarray(xy, dtype=float)
    mid, half = (ring[0] + ring[1]) / 2, (ring[1] - ring[0]) / 2
    t = np.asarray(_ATAN2(xy[..., 1], xy[..., 0]), dtype=float)
    return np.stack([(_radius(xy) - mid) / half, t / np.pi], axis=-1)


def wrap_safe_features(xy: np.ndarray, ring: tuple[float, float]) -> np.ndarray:
    """The ``"wrap-safe"`` form: ball (x, y), shape (..., 2) -> (r_n, cos t, sin t), shape
    (..., 3), r_n as in ``ring_polar_features``; cos t = x / r and sin t = y / r ((1, 0) at
    the centre), exactly rounded divisions: the same bits on every machine."""
    xy = np.asarray(xy, dtype=float)
    mid, half = (ring[0] + ring[1]) / 2, (ring[1] - ring[0]) / 2
    r = _radius(xy)
    centre = r == 0
    safe = np.where(centre, 1.0, r)
    cos_t = np.where(centre, 1.0, xy[..., 0] / safe)
    sin_t = np.where(centre, 0.0, xy[..., 1] / safe)
    return np.stack([(r - mid) / half, cos_t, sin_t], axis=-1)


def form_features(form: str, scene: Scene) -> tuple[Features, int]:
    """The map (x, y) (..., 2) -> features (..., d) of ``form`` on ``scene``, and d. Raises
    ``ValueError`` (one line) for a form the scene does not define."""
    if form not in scene.forms:
        raise ValueError(
            f"engineered form {form!r} is not defined on {scene.name}; "
            f"choose one of {', '.join(scene.forms)}"
        )
    if form == CARTESIAN:
        h = scene.ball_half_width
        return (lambda xy: np.asarray(xy, dtype=float) / h), 2
    ring = scene.ring
    assert ring is not None
    if form == "polar":
        return (lambda xy: ring_polar_features(xy, ring)), 2
    return (lambda xy: wrap_safe_features(xy, ring)), 3


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
    """The ball's engineered features; optionally the distractor's, and the arm's final tool
    tip (x, y) / the scene's reach, each as a module of its own.

    Args:
        form: ``"wrap-safe"``, ``"polar"`` or ``"cartesian"`` (module doc); None: the scene's
            default (the twin's: wrap-safe; ArmBalls': cartesian).
        hand_module: add the end effector as a module (for MGE-EFR: one module per object, as
            the paper's engineered modules). Records without a known tool tip skip it.
        distractor: add the distractor's features (same form) as a module, after the ball's,
            and to the context: the engineered description of a scene with two balls.
            Records without a distractor seen skip that module.
        scene: the rig's scene (required: the learner knows no rig's).

    Outcome: [ball, distractor (if), hand (if)]; context: [ball, distractor (if)] before the
    move.
    """

    def __init__(
        self,
        form: str | None = None,
        hand_module: bool = False,
        distractor: bool = False,
        *,
        scene: Scene,
    ) -> None:
        form = scene.default_form if form is None else form
        if form not in POLAR_FORMS:
            raise ValueError(f"unknown polar form {form!r}; choose one of {', '.join(POLAR_FORMS)}")
        self.form = form
        self.scene = scene
        self.features, self.ball_dim = form_features(form, scene)
        self.hand_scale = scene.hand_half_width
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
            tip = np.asarray(record.end_effector, dtype=float)[-1, :2] / self.hand_scale
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
            only (docs/results.md, ``experiments/goal_space.py``).
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
