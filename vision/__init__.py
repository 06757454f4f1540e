"""Cameras, rectification, the ball tracker and the learned representation. Imports no other
package of the project. (OpenCV is imported inside functions, so importing this is cheap.)"""

import os

# OpenMP's waiting threads sleep instead of spinning (torch's CPU thread pool, for the VAE and
# the spatial autoencoder). Spinning, a 2-thread training step beside another busy process
# took 668 ms instead of 184 ms (measured 2026-12-01, load 3 on 2 cores): each thread burnt
# its time slice waiting for the other. Read when torch starts, so set on importing vision/
# (before any of its modules imports torch); a user's own setting wins.
os.environ.setdefault("OMP_WAIT_POLICY", "PASSIVE")

from vision.camera import Camera, CameraError, EndOfStream, Frame
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
    "EndOfStream",
    "FileCamera",
    "Frame",
    "HSVRange",
    "OpenCVCamera",
    "TrackerConfig",
    "pixels_to_arena",
    "polar_features",
]
