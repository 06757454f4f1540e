"""The plugins' tests run in the LeRobot venv (``make test-lerobot``, Python 3.12): without
lerobot installed they are not collected. ``harness`` sets LeRobot's folders before anything
imports lerobot; the session ends with the LeRobot commands the tests ran (the CI lines).
"""

from __future__ import annotations

import importlib.util
import shutil
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]
if str(ROOT) not in sys.path:  # testkit/ and this folder, as the main suite's pythonpath
    sys.path.insert(0, str(ROOT))

from lerobot_plugins.tests import harness  # noqa: E402  (sets the environment first)

if importlib.util.find_spec("lerobot") is None:
    collect_ignore_glob = ["test_*.py"]


def pytest_terminal_summary(terminalreporter) -> None:
    if harness.RAN:
        terminalreporter.section("LeRobot commands run")
        for line in harness.RAN:
            terminalreporter.write_line(line)


def pytest_sessionfinish(session, exitstatus) -> None:
    shutil.rmtree(harness.SCRATCH, ignore_errors=True)
