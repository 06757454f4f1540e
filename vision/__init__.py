"""Cameras, rectification, the ball tracker and the learned representation. Imports no other
package of the project."""

from vision.camera import Camera, CameraError, Frame

__all__ = ["Camera", "CameraError", "Frame"]
