"""The import direction of docs/architecture.md holds: robot/ imports no other package of the
project, vision/ only robot/'s CLI errors and file writes, and the wings of explore/ import
downwards only (learner < rigs < runs < campaigns < report < export < cli). Read from the
source (every import statement, inside functions too), so a lazy import cannot hide an edge."""

from __future__ import annotations

import ast
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[2]
PACKAGES = ("robot", "vision", "sim", "calibration", "explore")
# what each package may import of the project (besides itself)
ALLOWED = {
    "robot": set(),
    "vision": {"robot"},  # robot.cli_errors and robot.files only (below)
    "sim": {"robot", "vision"},
    "calibration": {"robot", "vision", "sim"},
    "explore": {"robot", "vision", "sim", "calibration"},
}
# what vision/ may import of robot/: the bottom layer's shared helpers, not the arm
VISION_FROM_ROBOT = {"robot.cli_errors", "robot.files"}
WINGS = ("learner", "rigs", "runs", "campaigns", "report", "export", "cli")


def _imports(path: Path) -> set[str]:
    """Every module name an import statement of ``path`` names (absolute imports)."""
    names = set()
    for node in ast.walk(ast.parse(path.read_text(), str(path))):
        if isinstance(node, ast.Import):
            names.update(alias.name for alias in node.names)
        elif isinstance(node, ast.ImportFrom) and node.module and node.level == 0:
            names.add(node.module)
    return names


def _modules(package: str) -> list[Path]:
    return sorted((ROOT / package).rglob("*.py"))


@pytest.mark.parametrize("package", PACKAGES)
def test_a_package_imports_only_the_packages_below_it(package):
    bad = []
    for path in _modules(package):
        for name in _imports(path):
            top = name.split(".")[0]
            if top in PACKAGES and top != package and top not in ALLOWED[package]:
                bad.append(f"{path.relative_to(ROOT)} imports {name}")
    assert bad == []


def test_vision_imports_only_the_shared_helpers_of_robot():
    bad = [
        f"{path.relative_to(ROOT)} imports {name}"
        for path in _modules("vision")
        for name in _imports(path)
        if name.split(".")[0] == "robot" and name not in VISION_FROM_ROBOT
    ]
    assert bad == []


def test_the_wings_of_explore_import_downwards_only():
    bad = []
    for path in _modules("explore"):
        parts = path.relative_to(ROOT / "explore").parts
        wing = parts[0] if len(parts) > 1 else None
        if wing not in WINGS:
            continue  # explore/__init__.py, explore/options.py: shared, import no wing
        for name in _imports(path):
            bits = name.split(".")
            into = bits[1] if bits[0] == "explore" and len(bits) > 1 else None
            if into in WINGS and WINGS.index(into) > WINGS.index(wing):
                bad.append(f"{path.relative_to(ROOT)} ({wing}) imports {name}")
    assert bad == []


def test_the_shared_modules_of_explore_import_no_wing():
    for path in (ROOT / "explore" / "options.py", ROOT / "explore" / "__init__.py"):
        wings = {n for n in _imports(path) if n.split(".")[:2][-1] in WINGS}
        assert wings == set(), path
