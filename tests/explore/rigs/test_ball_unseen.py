"""A physical rig's run says loudly when the ball stays unseen: one WARNING once the tracker has
missed it in ``UNSEEN_WARNING_LOOKS`` looks at rest in a row, with the tracker's last reason,
once a spell (a ball against the wall the tracker could not see went unsaid for 180 episodes
but for one INFO line)."""

from __future__ import annotations

import logging

import numpy as np

from explore.rigs.ball import UNSEEN_WARNING_LOOKS, CameraSensor, tracker_locator
from vision.camera import Camera, Frame
from vision.rectify import ArenaModel


class StillCamera(Camera):
    """A camera that shows whatever image it is given."""

    def __init__(self) -> None:
        super().__init__()
        self.image = np.zeros((48, 64, 3), np.uint8)
        self.connect()

    def _connect(self) -> None:
        pass

    def _read(self) -> Frame:
        return Frame(self.image, 0.0)

    def _disconnect(self) -> None:
        pass


def ball_frame() -> np.ndarray:
    """A yellow-green disc of radius 8 px on black, the tracker's default colour."""
    import cv2

    image = np.zeros((48, 64, 3), np.uint8)
    cv2.circle(image, (32, 24), 8, (0, 220, 200), -1)
    return image


def flat_arena() -> ArenaModel:
    """An ideal camera straight above a 64 x 48 px arena, 1 cm a pixel, its centre in the
    frame's middle."""
    homography = np.array([[0.01, 0.0, -0.32], [0.0, -0.01, 0.24], [0.0, 0.0, 1.0]])
    return ArenaModel(np.eye(3), np.zeros(5), (64, 48), homography, np.zeros(2), 0.3, None)


def warnings_of(caplog) -> list[str]:
    return [
        r.getMessage()
        for r in caplog.records
        if r.name == "explore.rigs.ball" and r.levelno == logging.WARNING
    ]


def test_a_ball_unseen_for_ten_episodes_is_one_warning_a_spell(caplog):
    camera = StillCamera()
    sensor = CameraSensor(camera, tracker_locator(flat_arena()))
    camera.image = ball_frame()
    with caplog.at_level(logging.INFO, logger="explore.rigs.ball"):
        assert np.all(np.isfinite(sensor.locate().ball))
        camera.image = np.zeros_like(camera.image)  # the ball gone from view
        for _ in range(UNSEEN_WARNING_LOOKS - 1):
            assert np.all(np.isnan(sensor.locate().ball))
        assert warnings_of(caplog) == []
        for _ in range(3 * UNSEEN_WARNING_LOOKS):
            sensor.locate()
        (line,) = warnings_of(caplog)
        assert f"ball not seen in {UNSEEN_WARNING_LOOKS} looks at rest in a row" in line
        assert "last: no ball-coloured blob" in line and "ergo track" in line
        camera.image = ball_frame()
        sensor.locate()
        assert any("ball seen again after" in r.getMessage() for r in caplog.records)
        camera.image = np.zeros_like(camera.image)
        for _ in range(UNSEEN_WARNING_LOOKS):
            sensor.locate()
    assert len(warnings_of(caplog)) == 2  # a new spell, a new warning


def test_the_settle_checks_do_not_count_as_looks(caplog):
    """``watch`` and ``still`` read the tracker many times an episode while the ball settles:
    only looks at rest (``locate``) count towards the warning."""
    camera = StillCamera()
    sensor = CameraSensor(camera, tracker_locator(flat_arena()))
    with caplog.at_level(logging.INFO, logger="explore.rigs.ball"):
        for _ in range(UNSEEN_WARNING_LOOKS - 1):
            sensor.watch()
            for _ in range(5):
                sensor.still(0.01, 0.1)
            sensor.locate()
    assert warnings_of(caplog) == [] and sensor.unseen_looks == UNSEEN_WARNING_LOOKS - 1


def test_a_blind_sensor_does_not_warn(caplog):
    """Without an arena calibration the run is blind by design, said once by open_run."""
    sensor = CameraSensor(StillCamera(), None, "no arena calibration")
    with caplog.at_level(logging.INFO, logger="explore.rigs.ball"):
        for _ in range(2 * UNSEEN_WARNING_LOOKS):
            sensor.locate()
    assert warnings_of(caplog) == []
