"""Shared fixtures. Rendering is headless (EGL) unless a display is set."""

from __future__ import annotations

import os

if "MUJOCO_GL" not in os.environ and not os.environ.get("DISPLAY"):
    os.environ["MUJOCO_GL"] = "egl"

import pytest

from sim.twin import Twin


@pytest.fixture
def twin() -> Twin:
    t = Twin(render_size=(96, 96))
    yield t
    t.close()
