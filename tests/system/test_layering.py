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


# ---- no import cycle between files ----------------------------------------------------------
def _module_name(path: Path, root: Path) -> str:
    parts = list(path.relative_to(root).with_suffix("").parts)
    return ".".join(parts[:-1] if parts[-1] == "__init__" else parts)


def import_graph(root: Path = ROOT, packages: tuple[str, ...] = PACKAGES) -> dict[str, set[str]]:
    """module -> the modules of the project it imports, read from the source: every import
    statement (module level, inside functions, under ``TYPE_CHECKING``), relative ones
    resolved; ``from a import b`` is an edge to the module ``a.b`` when it is one, else to
    ``a``. A package's ``__init__`` is a module of its own (importing ``a.b`` is no edge to
    ``a``)."""
    files = {
        _module_name(p, root): p for pkg in packages for p in sorted((root / pkg).rglob("*.py"))
    }
    graph: dict[str, set[str]] = {}
    for name, path in files.items():
        here = name.split(".") if path.name == "__init__.py" else name.split(".")[:-1]
        edges = set()
        for node in ast.walk(ast.parse(path.read_text(), str(path))):
            if isinstance(node, ast.Import):
                edges |= {a.name for a in node.names if a.name in files}
            elif isinstance(node, ast.ImportFrom):
                base = node.module or ""
                if node.level:
                    up = here[: len(here) - node.level + 1]
                    base = ".".join(up + ([node.module] if node.module else []))
                for alias in node.names:
                    sub = f"{base}.{alias.name}"
                    edges |= {sub} if sub in files else ({base} if base in files else set())
        graph[name] = edges - {name}
    return graph


def import_cycles(graph: dict[str, set[str]]) -> list[list[str]]:
    """The strongly connected components of more than one module (Tarjan's algorithm,
    iterative): each is a set of modules that import one another, directly or not."""
    index: dict[str, int] = {}
    low: dict[str, int] = {}
    stack: list[str] = []
    on_stack: set[str] = set()
    cycles = []
    for start in sorted(graph):
        if start in index:
            continue
        work = [(start, iter(sorted(graph[start])))]
        index[start] = low[start] = len(index)
        stack.append(start)
        on_stack.add(start)
        while work:
            node, children = work[-1]
            child = next(children, None)
            if child is not None:
                if child not in index:
                    index[child] = low[child] = len(index)
                    stack.append(child)
                    on_stack.add(child)
                    work.append((child, iter(sorted(graph[child]))))
                elif child in on_stack:
                    low[node] = min(low[node], index[child])
                continue
            work.pop()
            if work:
                low[work[-1][0]] = min(low[work[-1][0]], low[node])
            if low[node] == index[node]:
                component = []
                while True:
                    member = stack.pop()
                    on_stack.discard(member)
                    component.append(member)
                    if member == node:
                        break
                if len(component) > 1:
                    cycles.append(sorted(component))
    return cycles


def test_no_import_cycle_between_the_product_modules():
    assert import_cycles(import_graph()) == []


def test_the_cycle_check_sees_a_cycle(tmp_path):
    """A lazy import inside a function and a relative one make a cycle as well."""
    (tmp_path / "pkg").mkdir()
    (tmp_path / "pkg" / "__init__.py").write_text("")
    (tmp_path / "pkg" / "a.py").write_text("from pkg.b import f\n")
    (tmp_path / "pkg" / "b.py").write_text("def f():\n    from . import c\n")
    (tmp_path / "pkg" / "c.py").write_text("import pkg.a\n")
    (tmp_path / "pkg" / "d.py").write_text("from pkg import a\n")
    graph = import_graph(tmp_path, ("pkg",))
    assert graph["pkg.b"] == {"pkg.c"}
    assert import_cycles(graph) == [["pkg.a", "pkg.b", "pkg.c"]]


# ---- small modules -----------------------------------------------------------------------------
MAX_LINES = 600  # a module longer than this is split by what it does


def test_no_product_module_is_over_600_lines():
    long = {
        str(path.relative_to(ROOT)): n
        for package in PACKAGES
        for path in _modules(package)
        if (n := len(path.read_text().splitlines())) > MAX_LINES
    }
    assert long == {}
