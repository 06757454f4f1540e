"""Cameras, rectification, the ball tracker and the learned representation. Imports no other
package of the project. (OpenCV is imported inside functions, so importing this is cheap.)"""

from vision.camera import Camera, CameraError, Frame
from vision.file_camera import FileCamera
from vision.opencv_camera import OpenCVCamera
from vision.rectify import ArenaModel, pixels_to_arena, polar_features
from vision.tracker import BallObservation, BallTracker, HSVRange, TrackerConfig

__all__ = [
    "ArenaModel",
    "BallObservation",
    "BallTracker",
    "Camera",
    "CameraError",
    "FileCamera",
    "Frame",
    "HSVRange",
    "OpenCVCamera",
    "TrackerConfig",
    "pixels_to_arena",
    "polar_features",
]
