"""``SimCamera``: the ``vision.Camera`` interface on the twin's overhead camera."""

from __future__ import annotations

from sim.twin import Twin
from vision.camera import Camera, Frame


class SimCamera(Camera):
    """Renders the twin's named camera. ``size`` is (height, width) in pixels."""

    def __init__(self, twin: Twin, camera: str = "overhead", size: tuple[int, int] | None = None):
        super().__init__()
        self.twin = twin
        self.camera = camera
        self.size = size or twin.render_size

    def _connect(self) -> None:
        pass

    def _disconnect(self) -> None:
        pass

    def _read(self) -> Frame:
        return Frame(self.twin.render(self.camera, self.size), self.twin.time)
