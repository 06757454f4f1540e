"""The settings of ArmBalls / Arm-2-Balls, with the published campaign's values as defaults.

Every default is the value the published campaign ran with (Laversanne-Finot, Péré, Oudeyer,
CoRL 2018; code and data in github.com/flowersteam/Curiosity_Driven_Goal_Exploration, called
"the original" below). Where it comes from is written beside it: a file of the original, or a
config column of its dataset ``results/armballs_dataset.pkl`` (one row per run and checkpoint,
the run's ``config.json`` spread into columns). docs/armballs.md gives the full account.

Lengths are in units of the arm's reach (the links sum to 1), on the square [-1, 1]^2 with the
arm's base at the origin; time is counted in steps (one joint command each).
"""

from __future__ import annotations

from dataclasses import dataclass

# Link lengths, base to hand: ArmBalls' default ``arm_lengths`` in
# latentgoalexplo/environments/armballs.py, passed unchanged by mge_efr.py and
# mge_representation.py. The original asserts they sum to 1 (the arm's reach).
LINK_LENGTHS: tuple[float, ...] = (0.3, 0.2, 0.2, 0.1, 0.1, 0.05, 0.05)


@dataclass(frozen=True)
class ArmBallsConfig:
    """One environment's settings (the defaults are Arm-2-Balls as published).

    Attributes:
        link_lengths: the 7 links, base to hand (sum 1).
        catch_radius: the ball is caught when the hand comes closer than this to its centre
            (strictly). Dataset column ``object_size`` = 0.1 in every run (the original's
            argparse default, 0.17, and ArmBalls' own default, 0.2, were overridden).
        ball_start: where the ball is at the start of every episode. ArmBalls'
            ``object_initial_pose`` default (0.6, 0.6); the campaign never set it and ran
            with ``stochastic=False``, so the ball is put back there at every reset.
        distractor: whether the scene has the distractor (Arm-2-Balls) or not (ArmBalls). The
            original always simulates one; every run of the published dataset has it.
        distractor_start: the distractor's position at the start of every episode: ArmBalls'
            ``distract_initial_pose`` default (0.7, -0.45), restored at every reset.
        distractor_noise: standard deviation of the distractor's Gaussian step, per step and
            per axis. Dataset column ``distract_noise`` = 0.1 (all learning runs; the RPE runs
            also used 0.5, which the ball's metric cannot see).
        distractor_limit: the distractor is clipped to [-limit, limit] on each axis after each
            step: 0.95 in ArmBalls.act (a literal).
        n_steps: joint commands per episode: ``n_timesteps`` = 50, written as a literal in
            rpe.py, mge_efr.py and mge_representation.py (the class defaults, 150, were not
            used).
        n_rbf: radial basis functions per joint: dataset column ``n_rbf`` = 7.
        rbf_sdev: the bases' Gaussian standard deviation, steps: dataset column ``sdev`` = 10.
        image_size: side of the observed square image, pixels: ``width``/``height`` = 64 in
            mge_representation.py's env_config.
        ball_draw_radius: the ball's radius in the image, in world units: 0.17, a literal in
            MyArmBallsObserved's observer (it does not follow ``catch_radius``: the pretrained
            representations were trained on that size).
        distractor_draw_radius: the distractor's radius in the image: 0.15 (same place; also
            the dataset column ``distract_size``, which the dynamics never use).
    """

    link_lengths: tuple[float, ...] = LINK_LENGTHS
    catch_radius: float = 0.1
    ball_start: tuple[float, float] = (0.6, 0.6)
    distractor: bool = True
    distractor_start: tuple[float, float] = (0.7, -0.45)
    distractor_noise: float = 0.1
    distractor_limit: float = 0.95
    n_steps: int = 50
    n_rbf: int = 7
    rbf_sdev: float = 10.0
    image_size: int = 64
    ball_draw_radius: float = 0.17
    distractor_draw_radius: float = 0.15

    def __post_init__(self) -> None:
        if len(self.link_lengths) < 1 or any(v <= 0 for v in self.link_lengths):
            raise ValueError(f"link_lengths must be positive, got {self.link_lengths}")
        if abs(sum(self.link_lengths) - 1.0) > 1e-9:
            raise ValueError(
                f"link_lengths must sum to 1 (the reach), got {sum(self.link_lengths)}"
            )
        if self.catch_radius <= 0:
            raise ValueError(f"catch_radius must be positive, got {self.catch_radius}")
        if self.n_steps < 1 or self.n_rbf < 1 or self.n_steps < self.n_rbf:
            raise ValueError(
                f"need n_steps >= n_rbf >= 1, got n_steps={self.n_steps}, n_rbf={self.n_rbf}"
            )
        if self.rbf_sdev <= 0:
            raise ValueError(f"rbf_sdev must be positive, got {self.rbf_sdev}")
        if self.distractor_noise < 0 or self.distractor_limit <= 0:
            raise ValueError("distractor_noise must be >= 0 and distractor_limit > 0")
        if self.image_size < 8:
            raise ValueError(f"image_size must be at least 8 pixels, got {self.image_size}")

    @property
    def n_joints(self) -> int:
        """Number of joints (one per link)."""
        return len(self.link_lengths)

    @property
    def n_params(self) -> int:
        """Motor parameters per episode: one weight per joint and basis (49 as published)."""
        return self.n_joints * self.n_rbf


#: Arm-2-Balls as published: the ball and the random-walking distractor.
ARM_2_BALLS = ArmBallsConfig()
#: ArmBalls: the same arm and ball, no distractor.
ARM_BALLS = ArmBallsConfig(distractor=False)
