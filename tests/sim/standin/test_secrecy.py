"""The stand-in's hidden parameters stay hidden: no module of the project outside
``sim/standin/`` reads them or imports their reader. Read from the source (every import
statement, inside functions too, and every string constant), as tests/system/test_layering.py
reads the import direction.

The rules:
- ``testkit.standin_truth`` (the reader of the hidden file) is imported by tests/, bench/,
  experiments/ and testkit/ only;
- outside ``sim/standin/``, tests/, bench/, experiments/ and testkit/, only the two bus
  servers import the stand-in, and only its serving side, ``sim.standin.served`` (which hands a
  bus emulator the joints' mounting and the twin, nothing else);
- no module outside those names the hidden file (its suffix ``-hidden.json``).
"""

from __future__ import annotations

import ast
from pathlib import Path

import pytest

from sim.standin.hidden import HIDDEN_SUFFIX

ROOT = Path(__file__).resolve().parents[3]
PACKAGES = ("robot", "vision", "sim", "calibration", "explore")
# may compare against the truth (testkit/: their shared harnesses, not installed)
FREE = ("tests", "bench", "experiments", "testkit")
SERVERS = {"sim/dynamixel/server.py", "sim/canopen/server.py"}
SERVED = "sim.standin.served"
READER = "testkit.standin_truth"


def _imported(tree: ast.AST) -> set[str]:
    """Every module an import statement names, ``from a import b`` as both ``a`` and
    ``a.b`` (b may be a module)."""
    names = set()
    for node in ast.walk(tree):
        if isinstance(node, ast.Import):
            names.update(alias.name for alias in node.names)
        elif isinstance(node, ast.ImportFrom) and node.module and node.level == 0:
            names.add(node.module)
            names.update(f"{node.module}.{alias.name}" for alias in node.names)
    return names


def _strings(tree: ast.AST) -> list[str]:
    return [
        n.value for n in ast.walk(tree) if isinstance(n, ast.Constant) and isinstance(n.value, str)
    ]


def violations(rel: str, source: str) -> list[str]:
    """What breaks the rules in one file (``rel``: its path from the repository's root)."""
    tree = ast.parse(source, rel)
    top = rel.split("/")[0]
    if top in FREE:
        return []
    own = rel.startswith("sim/standin/")
    bad = []
    for name in sorted(_imported(tree)):
        if name.startswith(READER):
            bad.append(f"{rel} imports {name}, the hidden file's reader")
        elif name != "sim.standin" and not name.startswith("sim.standin."):
            continue
        elif not own and not (rel in SERVERS and name.startswith(SERVED)):
            bad.append(f"{rel} imports {name}")
    if not own:
        bad += [
            f"{rel} names the hidden file ({s!r})" for s in _strings(tree) if HIDDEN_SUFFIX in s
        ]
    return bad


def _sources() -> list[Path]:
    out = []
    for package in (*PACKAGES, *FREE):
        out += sorted((ROOT / package).rglob("*.py"))
    return out


def test_no_module_outside_the_stand_in_reads_its_truth():
    bad = []
    for path in _sources():
        bad += violations(path.relative_to(ROOT).as_posix(), path.read_text())
    assert bad == []


def test_the_two_bus_servers_are_the_stand_ins_only_users():
    users = set()
    for path in _sources():
        rel = path.relative_to(ROOT).as_posix()
        if rel.split("/")[0] in FREE or rel.startswith("sim/standin/"):
            continue
        source = path.read_text()
        # parse only the candidates: an import of the stand-in names it
        if "standin" in source and any(
            n.startswith("sim.standin") for n in _imported(ast.parse(source))
        ):
            users.add(rel)
    assert users == SERVERS


@pytest.mark.parametrize(
    ("rel", "source"),
    [
        ("calibration/joints.py", "from testkit.standin_truth import read_hidden\n"),
        ("calibration/joints.py", "def f():\n    import testkit.standin_truth\n"),
        ("calibration/joints.py", "from sim.standin import truth\n"),
        ("calibration/joints.py", "from sim.standin.hidden import draw_hidden\n"),
        ("explore/cli/main.py", "from sim.standin.served import open_served_rig\n"),
        ("sim/dynamixel/server.py", "from sim.standin.hidden import draw_hidden\n"),
        ("sim/standin/served.py", "from testkit.standin_truth import read_hidden\n"),
        ("calibration/cli.py", "PATH = '/tmp/ergo-standin-3-hidden.json'\n"),
    ],
)
def test_the_check_catches(rel, source):
    assert violations(rel, source) != []


@pytest.mark.parametrize(
    ("rel", "source"),
    [
        ("tests/system/test_guide.py", "from testkit.standin_truth import read_hidden\n"),
        ("bench/bench_guide.py", "from testkit.standin_truth import read_hidden\n"),
        ("experiments/standin_dynamics.py", "from testkit.standin_truth import read_hidden\n"),
        ("sim/canopen/server.py", "from sim.standin.served import open_served_rig\n"),
        ("sim/standin/served.py", "from sim.standin.hidden import draw_hidden\n"),
    ],
)
def test_the_check_allows(rel, source):
    assert violations(rel, source) == []
