"""ArmBalls / Arm-2-Balls: the state, the catch rule, the distractor's walk, whole episodes.

The rules (the original's ArmBalls.act, latentgoalexplo/environments/armballs.py, read for
facts), applied at every step t = 0..T-1 after the joint command of that step is set:

1. the hand moves to the forward kinematics of the command (``kinematics.hand_position``);
2. the ball is caught once the hand comes strictly closer than ``catch_radius`` to its
   centre, and from that step on it sits at the hand;
3. the distractor (Arm-2-Balls only) takes a Gaussian step of ``distractor_noise`` per axis and
   is clipped to [-distractor_limit, distractor_limit]; the arm never moves it, and it never
   moves the ball.

Every episode starts from the same scene (the original resets the ball, the distractor and
the arm at each episode): ball at ``ball_start``, distractor at ``distractor_start``, all
commands 0 (hand at (1, 0)). The outcome is the scene after the last step; the published
metric counts the ball's final position of each episode only (``results/
Experiment_Visualization.ipynb``: the ratio of 30 x 30 cells over [-1, 1]^2 holding at least
one of the first n final positions), not the positions it passed through.

Randomness (the distractor only) comes from a ``numpy.random.Generator``: T x 2 standard
normal draws per episode, in step order, so a batch of N episodes draws exactly what N single
episodes would in turn.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from plumbing.fixed_order import distance
from sim.armballs.config import ArmBallsConfig
from sim.armballs.kinematics import hand_position
from sim.armballs.primitives import PrimitiveParameterError, RbfPrimitive
from sim.armballs.render import render_scene

NOT_CAUGHT = -1  # catch_step of an episode in which the ball was never caught


@dataclass
class ArmBallsState:
    """The scene at one moment.

    Attributes:
        ball: ball centre (x, y), shape (2,).
        distractor: distractor centre, shape (2,), or None without one.
        hand: the hand (x, y), shape (2,).
        caught: whether the hand holds the ball.
    """

    ball: np.ndarray
    distractor: np.ndarray | None
    hand: np.ndarray
    caught: bool = False


def initial_state(config: ArmBallsConfig | None = None) -> ArmBallsState:
    """The scene every episode starts from."""
    cfg = config or ArmBallsConfig()
    return ArmBallsState(
        ball=np.array(cfg.ball_start, dtype=float),
        distractor=np.array(cfg.distractor_start, dtype=float) if cfg.distractor else None,
        hand=hand_position(np.zeros(cfg.n_joints), np.asarray(cfg.link_lengths)),
    )


def step(
    state: ArmBallsState,
    command: np.ndarray,
    noise: np.ndarray | None = None,
    config: ArmBallsConfig | None = None,
) -> ArmBallsState:
    """One step of the rules, one scene at a time (the reference ``play_commands`` must match).

    Args:
        state: the scene before the step (not modified).
        command: joint commands of this step, shape (n_joints,), in [-1, 1].
        noise: the distractor's standard normal draw for this step, shape (2,); needed when
            the scene has a distractor, ignored otherwise.
        config: the environment's settings.

    Returns:
        the scene after the step.
    """
    cfg = config or ArmBallsConfig()
    hand = hand_position(np.asarray(command, dtype=float), np.asarray(cfg.link_lengths))
    caught = state.caught or bool(distance(hand, state.ball) < cfg.catch_radius)
    ball = hand.copy() if caught else state.ball.copy()
    distractor = None
    if state.distractor is not None:
        if noise is None:
            raise ValueError("a scene with a distractor needs the step's noise draw, shape (2,)")
        lim = cfg.distractor_limit
        distractor = np.clip(state.distractor + cfg.distractor_noise * noise, -lim, lim)
    return ArmBallsState(ball=ball, distractor=distractor, hand=hand, caught=caught)


@dataclass(frozen=True)
class EpisodePaths:
    """What N episodes did, step by step (arrays over episodes n and steps t).

    Attributes:
        hand: shape (N, T, 2).
        ball: shape (N, T, 2).
        distractor: shape (N, T, 2), or None without one.
        catch_step: first step at which the ball was caught, shape (N,) int, or ``NOT_CAUGHT``.
    """

    hand: np.ndarray
    ball: np.ndarray
    distractor: np.ndarray | None
    catch_step: np.ndarray


def play_commands(
    commands: np.ndarray, noise: np.ndarray | None, config: ArmBallsConfig | None = None
) -> EpisodePaths:
    """Play N command sequences from the initial scene, vectorised over episodes and steps.

    Args:
        commands: shape (N, T, n_joints), in [-1, 1].
        noise: the distractor's standard normal draws, shape (N, T, 2); None without one.
        config: the environment's settings.
    """
    cfg = config or ArmBallsConfig()
    commands = np.asarray(commands, dtype=float)
    if commands.ndim != 3 or commands.shape[2] != cfg.n_joints:
        raise ValueError(f"commands have shape {commands.shape}, expected (N, T, {cfg.n_joints})")
    n, t = commands.shape[:2]
    hand = hand_position(commands, np.asarray(cfg.link_lengths))  # (N, T, 2)
    start = np.asarray(cfg.ball_start, dtype=float)
    # the ball stays at its start until caught, so the catch test is against the start
    gap = hand - start
    close = np.sqrt(gap[..., 0] * gap[..., 0] + gap[..., 1] * gap[..., 1]) < cfg.catch_radius
    caught_any = close.any(axis=1)
    first = np.where(caught_any, close.argmax(axis=1), NOT_CAUGHT)
    held = np.arange(t)[None, :] >= np.where(caught_any, first, t)[:, None]  # (N, T)
    ball = np.where(held[..., None], hand, start)
    distractor = None
    if cfg.distractor:
        if noise is None or np.shape(noise) != (n, t, 2):
            raise ValueError(f"Arm-2-Balls needs noise of shape ({n}, {t}, 2)")
        distractor = _clipped_walk(
            np.asarray(cfg.distractor_start, dtype=float),
            cfg.distractor_noise * np.asarray(noise, dtype=float),
            cfg.distractor_limit,
        )
    return EpisodePaths(hand=hand, ball=ball, distractor=distractor, catch_step=first)


_SCALAR_WALKS = 4  # up to this many walks (episodes x 2 axes), plain floats beat numpy


def _clipped_walk(start: np.ndarray, steps: np.ndarray, limit: float) -> np.ndarray:
    """Positions of N walks clipped to [-limit, limit] after every step.

    Args:
        start: shape (2,).
        steps: shape (N, T, 2).
        limit: the clip bound.

    Returns:
        shape (N, T, 2): the position after each step.
    """
    n, t = steps.shape[:2]
    if n * 2 <= _SCALAR_WALKS:  # one episode at a time: 50 tiny numpy calls cost more
        out = []
        for episode in steps.tolist():
            x, y = float(start[0]), float(start[1])
            path = []
            for dx, dy in episode:
                x = min(max(x + dx, -limit), limit)
                y = min(max(y + dy, -limit), limit)
                path.append((x, y))
            out.append(path)
        return np.array(out, dtype=float).reshape(n, t, 2)
    out = np.empty((n, t, 2))
    d = np.broadcast_to(start, (n, 2)).copy()
    for k in range(t):
        np.add(d, steps[:, k], out=d)
        np.clip(d, -limit, limit, out=d)
        out[:, k] = d
    return out


@dataclass(frozen=True)
class EpisodeOutcome:
    """One episode's result: the scene after its last step.

    Attributes:
        ball: the ball's final centre, shape (2,) (what the published metric counts).
        distractor: the distractor's final centre, shape (2,), or None without one.
        hand: the hand's final position, shape (2,).
        catch_step: first step holding the ball, or ``NOT_CAUGHT``.
        image: the observed image of the final scene, (S, S, 3) uint8 RGB, or None.
        commands: the joint commands played, shape (T, n_joints).
        paths: the episode step by step (N = 1).
    """

    ball: np.ndarray
    distractor: np.ndarray | None
    hand: np.ndarray
    catch_step: int
    image: np.ndarray | None
    commands: np.ndarray
    paths: EpisodePaths

    @property
    def caught(self) -> bool:
        """Whether the arm caught (and so moved) the ball."""
        return self.catch_step != NOT_CAUGHT


class ArmBallsEnv:
    """Episodes of one environment configuration: motor parameters in, outcomes out."""

    def __init__(self, config: ArmBallsConfig | None = None) -> None:
        self.config = config or ArmBallsConfig()
        self.primitive = RbfPrimitive(self.config)

    @property
    def n_params(self) -> int:
        """Length of a motor parameter vector."""
        return self.primitive.n_params

    def _noise(self, rng: np.random.Generator, n: int) -> np.ndarray | None:
        if not self.config.distractor:
            return None
        return rng.standard_normal((n, self.config.n_steps, 2))

    def play(
        self, params: np.ndarray, rng: np.random.Generator, render: bool = True
    ) -> EpisodeOutcome:
        """Play one episode.

        Args:
            params: motor parameters, shape (n_params,), in [-1, 1].
            rng: draws the distractor's walk (unused without a distractor).
            render: whether to draw the final scene.
        """
        if np.ndim(params) != 1:
            raise PrimitiveParameterError(
                f"one episode takes parameters of shape ({self.n_params},), got {np.shape(params)}"
            )
        commands = self.primitive.commands(params)
        paths = play_commands(commands[None], self._noise(rng, 1), self.config)
        ball = paths.ball[0, -1].copy()
        distractor = None if paths.distractor is None else paths.distractor[0, -1].copy()
        image = render_scene(ball, distractor, config=self.config) if render else None
        return EpisodeOutcome(
            ball=ball,
            distractor=distractor,
            hand=paths.hand[0, -1].copy(),
            catch_step=int(paths.catch_step[0]),
            image=image,
            commands=commands,
            paths=paths,
        )

    def play_batch(self, params: np.ndarray, rng: np.random.Generator) -> EpisodePaths:
        """Play N episodes at once, without images (what RPE needs).

        Args:
            params: shape (N, n_params), in [-1, 1].
            rng: as in ``play``; the draws are those of N ``play`` calls in turn.

        Returns:
            the N episodes' paths; the outcomes are their last steps (``[:, -1]``).
        """
        if np.ndim(params) != 2:
            raise PrimitiveParameterError(
                f"a batch takes parameters of shape (N, {self.n_params}), got {np.shape(params)}"
            )
        commands = self.primitive.commands(params)
        return play_commands(commands, self._noise(rng, len(commands)), self.config)
