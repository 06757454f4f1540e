"""The import direction of docs/architecture.md holds: plumbing/ (the domain-free helpers)
imports no other package of the project, robot/ only plumbing/, vision/ only plumbing/, and the
wings of explore/ import downwards only (learner < rigs < runs < campaigns < report < export <
cli); the learner imports no rig package (robot, sim, calibration). Read from the source (every
import statement, inside functions too), so a lazy import cannot hide an edge."""

from __future__ import annotations

import ast
import tomllib
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[2]
PACKAGES = ("plumbing", "robot", "vision", "sim", "calibration", "explore")
# what each package may import of the project (besides itself)
ALLOWED = {
    "plumbing": set(),
    "robot": {"plumbing"},
    "vision": {"plumbing"},
    "sim": {"plumbing", "robot", "vision"},
    "calibration": {"plumbing", "robot", "vision", "sim"},
    "explore": {"plumbing", "robot", "vision", "sim", "calibration"},
}
# the packages that know a rig (an arm, its simulator, its calibration): the learner imports none
RIG_PACKAGES = ("robot", "sim", "calibration")
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


# The episode's seam (explore/rigs: the Rig, the episode player, the ball sensors) and the
# exploration loop (explore/runs) know no simulator: a twin is one rig among others, behind its
# BallSensor. Only the rigs that are simulators build one (and arena.py, the twin arena's Scene,
# reads the twin's dimensions).
SIMULATED_RIGS = ("sim.py", "sim_dataset.py", "armballs.py", "arena.py")


def test_the_episode_seam_and_the_loop_import_no_simulator():
    bad = []
    for wing, exempt in (("rigs", SIMULATED_RIGS), ("runs", ())):
        for path in sorted((ROOT / "explore" / wing).glob("*.py")):
            if path.name in exempt:
                continue
            bad += [f"{path.relative_to(ROOT)} imports {n}" for n in _imports(path)
                    if n.split(".")[0] == "sim"]  # fmt: skip
    assert bad == []


# testkit/ holds what tests, bench/ and experiments/ share (the scripted owner, the stand-in's
# truth, the fault soak, synthetic views, untrained models, the inverse-model diagnosis): no
# product module imports it, and it is not installed.
TESTKIT = "testkit"


def test_no_product_module_imports_the_testkit():
    bad = [
        f"{path.relative_to(ROOT)} imports {name}"
        for package in PACKAGES
        for path in _modules(package)
        for name in _imports(path)
        if name.split(".")[0] == TESTKIT
    ]
    assert bad == []


def test_the_testkit_is_not_installed():
    config = tomllib.loads((ROOT / "pyproject.toml").read_text())
    include = config["tool"]["setuptools"]["packages"]["find"]["include"]
    assert not [p for p in include if p.split("*")[0].split(".")[0] == TESTKIT]
    assert {p.rstrip("*") for p in include} >= set(PACKAGES)


def test_the_shared_modules_of_explore_import_no_wing():
    for path in (ROOT / "explore" / "options.py", ROOT / "explore" / "__init__.py"):
        wings = {n for n in _imports(path) if n.split(".")[:2][-1] in WINGS}
        assert wings == set(), path


# What the learner may import of the project besides itself: ``explore.options`` (shared),
# ``vision`` (representations: the VAE, the spatial code) and ``plumbing`` (the name tables, the
# field checker). No rig package (``RIG_PACKAGES``: neither the joint specs nor the arm's reach
# of ``robot``, nor ``sim``, nor ``calibration``); a rig's facts reach the learner through its
# ``Scene`` and its motor primitive, as arguments.
LEARNER_MAY_IMPORT = ("explore.learner", "explore.options", "vision", "plumbing")


def _within(name: str, prefixes: tuple[str, ...]) -> bool:
    return any(name == p or name.startswith(p + ".") for p in prefixes)


def test_the_learner_knows_no_rig():
    bad = []
    for path in _modules("explore/learner"):
        for name in _imports(path):
            if name.split(".")[0] in PACKAGES and not _within(name, LEARNER_MAY_IMPORT):
                bad.append(f"{path.relative_to(ROOT)} imports {name}")
    assert bad == []


def test_the_learner_imports_no_rig_package():
    bad = [
        f"{path.relative_to(ROOT)} imports {name}"
        for path in _modules("explore/learner")
        for name in _imports(path)
        if name.split(".")[0] in RIG_PACKAGES
    ]
    assert bad == []


def test_the_learner_check_sees_a_rig_import(tmp_path):
    """The check above fails on what it must refuse (the learner's imports before it held)."""
    bad = tmp_path / "bad.py"
    bad.write_text(
        "from robot.spec import ERGO_JR_REACH_M\nimport sim.models.make_scene\n"
        "from explore.rigs.arena import TWIN_ARENA\nfrom plumbing.registry import LazyTable\n"
    )
    refused = {n for n in _imports(bad) if not _within(n, LEARNER_MAY_IMPORT)}
    assert refused == {"robot.spec", "sim.models.make_scene", "explore.rigs.arena"}
