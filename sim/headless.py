"""Pick an offscreen OpenGL backend before MuJoCo is imported when no display is set."""

from __future__ import annotations

import os


def ensure_headless_gl() -> None:
    """Set ``MUJOCO_GL=egl`` unless the user chose a backend or a display exists."""
    if "MUJOCO_GL" not in os.environ and not os.environ.get("DISPLAY"):
        os.environ["MUJOCO_GL"] = "egl"
        os.environ.setdefault("PYOPENGL_PLATFORM", "egl")
