"""Where the ball is, for an episode: the rig's ``BallSensor``, and the ball locators it uses.

Every rig with an arm has a ball sensor (``Rig.sensor``), the one place that decides where the
ball (and the distractor, and the tool tip) are, whether the ball is still, the observation
image, and the scene's state a resumed run restores:

- ``TwinSensor``: the MuJoCo twin in-process: its ground truth (or the tracker on its frames,
  as on a real rig, with the rig option ``ball=tracker``), its state, the scene's changes
  between episodes (the ball put back, the distractor's walk);
- ``CameraSensor``: a physical rig: the tracker on the camera's frames with the rig's arena
  calibration; without one it reports the ball unknown (NaN), never guessed, and says why
  (``blind``). Nothing of a real arena can be snapshot or restored: those are no-ops. Its
  observation image is the twin's: the frame mapped through the arena calibration onto the
  twin's overhead view (``TWIN_VIEW``, ``vision.observation.ArenaObservation``), so that a
  model trained on the twin's renders sees the same picture; without an arena calibration, the
  frame's centre square (goal strategies are refused then: ``explore.runs.open_run``).

A ball locator maps a BGR frame (H, W, 3) uint8 to the ball's centre (x, y) on the arena,
metres, shape (2,), NaN when the tracker did not see it (hidden by the arm, ambiguous).
Positions in metres (arena frame: origin at the arm's base, z up), speeds in m/s, durations in
seconds.
"""

from __future__ import annotations

import logging
from collections.abc import Callable
from typing import Any, Protocol

import numpy as np

from explore.learner.experience import Observation
from explore.rigs.arena import TWIN_VIEW
from plumbing.fixed_order import distance
from vision.camera import Camera
from vision.observation import ArenaObservation, square_observation

log = logging.getLogger(__name__)

BallLocator = Callable[[np.ndarray], np.ndarray]
#: a camera frame (H, W, 3) BGR uint8 and a side -> the observation image (side, side, 3)
Observer = Callable[[np.ndarray, int], np.ndarray]
UNKNOWN = np.full(2, np.nan)  # a position not seen, (2,)
# Looks at rest (an episode's context and its outcome: two an episode) in a row without the
# ball after which a physical rig's run says so as a warning, once a spell: ten episodes
# (chosen: a moment's miss, the ball under the arm while it settles, stays an INFO line; a
# ball off the arena or a tracker that cannot see it is said before a run is lost to it).
UNSEEN_WARNING_LOOKS = 20
NO_STATE = np.zeros(0)  # the state of a scene nothing can restore


class BallSensor(Protocol):
    """Where the ball is, for the episode player (``explore.rigs.arm_episodes``).

    Attributes:
        blind: why the sensor cannot locate the ball (a physical rig's missing arena
            calibration), or None when it can.
    """

    blind: str | None

    def locate(self, image_side: int | None = None) -> Observation:
        """The ball and the distractor now, (2,) m each, NaN where unknown; with
        ``image_side``, also the square observation (side, side, 3) BGR uint8 (and the full
        frame it was cut from, when one was taken), from the same view."""
        ...

    def watch(self) -> None:
        """Take the reference that the next ``still`` compares with (a settle begins)."""
        ...

    def still(self, speed: float, interval_s: float) -> bool:
        """Whether the ball moves slower than ``speed`` m/s, judged over the last
        ``interval_s`` s (since ``watch`` or the previous ``still``)."""
        ...

    def tool_tip(self) -> np.ndarray:
        """The arm's tool tip now, (3,) m; NaN where the rig cannot know it."""
        ...

    def prepare(self, scene_rng: np.random.Generator) -> None:
        """The scene's changes before an episode, drawn from the episode's own stream."""
        ...

    def snapshot(self) -> np.ndarray:
        """The scene's state after an episode, (k,) (empty: nothing to restore)."""
        ...

    def restore(self, state: np.ndarray) -> None:
        """Put the scene back in a ``snapshot``'s state (a resumed run)."""
        ...


class TrackerLocator:
    """A ``BallLocator`` backed by ``vision.tracker.BallTracker`` with an ``ArenaModel``. Why
    the tracker did not see the ball is logged (INFO, logger ``explore.rigs.ball``) each time
    the reason changes (its words, not its figures): a run's log says why its ball positions
    are unknown, once per spell.

    Attributes:
        reason: why the last frame's ball was not seen, in the tracker's words; None when it
            was.
    """

    def __init__(self, arena: Any, tracker_config: Any = None) -> None:
        from vision.tracker import BallTracker

        self.tracker = BallTracker(tracker_config, arena)
        self.reason: str | None = None
        self._kind: str | None = None  # the words of the last reason, None: seen

    def __call__(self, frame: np.ndarray) -> np.ndarray:
        obs = self.tracker.track(frame)
        reason = None if obs.seen and obs.xy is not None else obs.reason or "not on the arena"
        kind = None if reason is None else reason.split("(")[0].strip()
        if kind is not None and kind != self._kind:
            blobs = ", ".join(
                f"{b.area:.0f} px circularity {b.circularity:.2f}" for b in obs.blobs[:2]
            )
            log.info("ball not seen: %s%s", reason, f" (blobs: {blobs})" if blobs else "")
        self._kind, self.reason = kind, reason
        if reason is not None:
            return np.full(2, np.nan)
        return np.asarray(obs.xy, dtype=float)


def tracker_locator(arena: Any, tracker_config: Any = None) -> TrackerLocator:
    """The tracker's locator (``TrackerLocator``) on ``arena`` with ``tracker_config``."""
    return TrackerLocator(arena, tracker_config)


def locator_from_calibration(data: dict[str, Any]) -> BallLocator:
    """The tracker from an ``arena`` calibration's data (its model and ball colour ranges)."""
    from vision.rectify import ArenaModel
    from vision.tracker import tracker_config_from_arena

    return tracker_locator(ArenaModel.from_dict(data), tracker_config_from_arena(data))


def observer_from_calibration(data: dict[str, Any]) -> ArenaObservation:
    """The twin's view (``TWIN_VIEW``) of a physical camera's frames from an ``arena``
    calibration's data, mapped through the plane of the ball's centre (its radius above the
    floor: the tracker's ``ball_radius_m``)."""
    from vision.rectify import ArenaModel
    from vision.tracker import tracker_config_from_arena

    height = tracker_config_from_arena(data).ball_radius_m
    return ArenaObservation(ArenaModel.from_dict(data), TWIN_VIEW, plane_height=height)


def camera_sensor(config: Any, camera: Camera) -> CameraSensor:
    """The ball sensor of a physical rig (``config``, a ``RigConfig``) on ``camera``: the
    tracker and the twin's view from its arena calibration (``RigConfig.resolved``: found by
    ``rig_id``, or the file named by the rig option ``arena_calibration``). Without one, ball
    positions are recorded as unknown (NaN), never guessed, and ``open_run`` warns once, or
    refuses a run whose strategy needs the ball (``CameraSensor.blind``); a damaged or foreign
    file is a ``RigError``."""
    data, why = rig_arena_data(config)
    if data is None:
        return CameraSensor(camera, None, why)
    return CameraSensor(
        camera, locator_from_calibration(data), observe=observer_from_calibration(data)
    )


def rig_arena_data(config: Any) -> tuple[dict[str, Any] | None, str | None]:
    """A physical rig's arena calibration data and None, or (None, why) without one."""
    from calibration.store import CalibrationError, CalibrationMissing, load_arena_file
    from explore.rigs.errors import RigError

    try:
        return load_arena_file(config.resolved().calibration.arena), None
    except (CalibrationMissing, FileNotFoundError) as exc:
        return None, str(exc)
    except CalibrationError as exc:  # a file that is there but wrong: never run without it
        raise RigError(f"{exc} (a damaged or foreign arena calibration is not ignored)") from exc


class TwinSensor:
    """The twin in-process: ground truth, or the tracker on its frames (``locator``).

    Args:
        twin: the ``sim.twin.Twin``.
        camera: its ``sim.camera.SimCamera`` (the overhead view).
        locator: the tracker on the camera's frames, or None: the twin's ground truth.
        prepare: the scene's changes before each episode (the ball put back, the
            distractor's walk), or None.
    """

    blind: str | None = None

    def __init__(
        self,
        twin: Any,
        camera: Any,
        locator: BallLocator | None = None,
        prepare: Callable[[np.random.Generator], None] | None = None,
    ) -> None:
        self.twin = twin
        self.camera = camera
        self.locator = locator
        self._prepare = prepare

    def locate(self, image_side: int | None = None) -> Observation:
        distractor = self.twin.distractor_position()[:2]
        if self.locator is None and image_side is None:
            return Observation(ball=self._true_ball(), distractor=distractor)
        if self.locator is None:
            # only the observation is used: rendered at its own size, no full frame
            image = self.camera.read_square(image_side).image
            return Observation(ball=self._true_ball(), image=image, distractor=distractor)
        frame = self.camera.read().image  # the tracker's view
        ball = self.locator(frame)
        if image_side is None:
            return Observation(ball=ball, distractor=distractor)
        image = square_observation(frame, image_side)
        return Observation(ball=ball, image=image, frame=frame, distractor=distractor)

    def _true_ball(self) -> np.ndarray:
        return self.twin.ball_position()[:2]

    def watch(self) -> None:
        """Nothing to take: the twin knows the ball's speed."""

    def still(self, speed: float, interval_s: float) -> bool:
        """The ball's true speed now (also with the tracker: the twin knows it)."""
        return bool(self.twin.ball_speed() < speed)

    def tool_tip(self) -> np.ndarray:
        return self.twin.end_effector_position()

    def prepare(self, scene_rng: np.random.Generator) -> None:
        if self._prepare is not None:
            self._prepare(scene_rng)

    def snapshot(self) -> np.ndarray:
        return self.twin.get_state()

    def restore(self, state: np.ndarray) -> None:
        self.twin.set_state(state)


class CameraSensor:
    """A physical rig's camera and tracker (``locator``, from its arena calibration), or no
    tracker (``blind`` says why): the ball unknown (NaN) then, and always still. ``observe``
    makes the observation image from a frame (default: its centre square).

    When the tracker misses the ball in ``UNSEEN_WARNING_LOOKS`` looks at rest in a row
    (``locate``: an episode's context and outcome), one WARNING says so (logger
    ``explore.rigs.ball``, with the tracker's last reason), once a spell; an INFO line says
    when it is seen again."""

    def __init__(
        self,
        camera: Camera,
        locator: BallLocator | None,
        blind: str | None = None,
        observe: Observer = square_observation,
    ) -> None:
        self.camera = camera
        self.locator = locator
        self.blind = None if locator is not None else (blind or "no ball locator")
        self.observe = observe
        self._previous = UNKNOWN
        self.unseen_looks = 0  # looks at rest in a row without the ball

    def _count_unseen(self, ball: np.ndarray) -> None:
        if self.locator is None:
            return  # blind: said once by open_run
        if np.all(np.isfinite(ball)):
            if self.unseen_looks >= UNSEEN_WARNING_LOOKS:
                log.info("ball seen again after %d looks at rest without it", self.unseen_looks)
            self.unseen_looks = 0
            return
        self.unseen_looks += 1
        if self.unseen_looks == UNSEEN_WARNING_LOOKS:
            reason = getattr(self.locator, "reason", None)
            log.warning(
                "ball not seen in %d looks at rest in a row (%d episodes)%s: the episodes' "
                "outcomes are unknown until it is seen again; is it off the arena or hidden? "
                "`ergo track --camera SOURCE --arena FILE` shows what the tracker sees",
                self.unseen_looks,
                self.unseen_looks // 2,
                f", last: {reason}" if reason else "",
            )

    def _ball(self, frame: np.ndarray) -> np.ndarray:
        return UNKNOWN.copy() if self.locator is None else self.locator(frame)

    def locate(self, image_side: int | None = None) -> Observation:
        frame = self.camera.read().image
        ball = self._ball(frame)
        self._count_unseen(ball)
        if image_side is None:
            return Observation(ball=ball)
        return Observation(ball=ball, image=self.observe(frame, image_side), frame=frame)

    def watch(self) -> None:
        if self.locator is not None:
            self._previous = self._ball(self.camera.read().image)

    def still(self, speed: float, interval_s: float) -> bool:
        """The tracked position against the previous one ``interval_s`` earlier; a ball not
        seen in both counts as still moving (the settle then waits up to its cap)."""
        if self.locator is None:
            return True
        here = self._ball(self.camera.read().image)
        step = distance(here, self._previous)  # NaN if either is unseen
        self._previous = here
        return step / interval_s < speed

    def tool_tip(self) -> np.ndarray:
        return np.full(3, np.nan)

    def prepare(self, scene_rng: np.random.Generator) -> None:
        """Nothing: a real arena changes only by the arm."""

    def snapshot(self) -> np.ndarray:
        return NO_STATE

    def restore(self, state: np.ndarray) -> None:
        """Nothing to restore: the arena is where the arm left it."""
