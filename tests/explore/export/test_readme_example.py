"""The README's Gymnasium example runs as written (a random agent on the twin)."""

from __future__ import annotations

import re
from pathlib import Path

import pytest

README = Path(__file__).resolve().parents[3] / "README.md"


def test_the_readmes_random_agent_runs():
    pytest.importorskip("gymnasium")
    text = README.read_text()
    marker = text.index("test_readme_example.py")
    code = re.search(r"```python\n(.*?)```", text[marker:], re.S)
    assert code is not None
    namespace: dict = {}
    exec(compile(code.group(1), str(README), "exec"), namespace)  # our own README
    assert namespace["env"].unwrapped.rig.arm.is_connected is False  # closed: torque off
    assert set(namespace["obs"]) == {"observation", "image", "achieved_goal", "desired_goal"}
