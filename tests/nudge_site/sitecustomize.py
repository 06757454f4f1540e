"""Imported by every Python process started with this folder on PYTHONPATH: with
``ERGO_TEST_NUDGE_ULP=1`` its twins are nudged too (tests/nudge_twin.py)."""

import importlib.util
import os

if os.environ.get("ERGO_TEST_NUDGE_ULP") == "1":
    _tests = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
    _path = os.path.join(_tests, "nudge_twin.py")
    _spec = importlib.util.spec_from_file_location("ergo_nudge_twin", _path)
    _module = importlib.util.module_from_spec(_spec)
    _spec.loader.exec_module(_module)
    _module.nudge_if_asked()
