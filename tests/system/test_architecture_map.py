"""docs/architecture.md's map holds: every path its tables and its newcomer's lookup list name
exists, and the lookup list answers in one guess: each row's first file defines at least one
name the row gives, and every name a row gives (``Class``, ``function``, ``CONSTANT``,
``Class.method``) is defined in one of the row's files (a move or a rename that leaves the map
behind fails here)."""

from __future__ import annotations

import re
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[2]
DOC = ROOT / "docs" / "architecture.md"
PATH = re.compile(
    r"`((?:plumbing|robot|vision|sim|calibration|explore|testkit|tests|bench|experiments|docs)/[\w./-]*)`"
)
# A Python name in backticks, or a dotted one (``Arm.command``); paths, options (``key=value``)
# and XML (``<visual>``) are not names.
NAME = re.compile(r"`([A-Za-z_]\w*(?:\.[A-Za-z_]\w*)*)`")
# Behaviours the lookup list must answer (a newcomer's questions): each has its row.
ASKED = (
    "the clamp to the joint limits",
    "torque off on Ctrl-C",
    "the watchdog",
    "the Dynamixel packet codec",
    "the CiA 402 state walk",
    "the camera fit",
    "the arena's markers",
    "the joint calibration",
    "the servo fit",
    "the ball tracker",
    "the 64 px observation",
    "the VAE's training",
    "the spatial autoencoder's training",
    "the DMP",
    "the nearest-neighbour inverse model",
    "goal sampling",
    "interests, learning progress",
    "the episode loop",
    "the replay of the history on resume",
    "the run store's crash safety",
    "`ergo runs check`",
    "the 30 x 30 metric",
    "the report's figures",
    "rerun logging",
    "the LeRobot export",
    "the Gymnasium environments",
    "campaigns, locally and on Ray",
    "a stand-in's hidden parameters",
    "the emulated Dynamixel bus",
    "the emulated CANopen drives",
    "the twin's MJCF",
)


def _section(title: str) -> str:
    text = DOC.read_text()
    start = text.index(f"## {title}")
    end = text.find("\n## ", start + 1)
    return text[start : end if end != -1 else None]


def _lookup_rows() -> list[tuple[str, str]]:
    """(question, answer) of every row of the lookup list, but the group headings (rows with
    an empty answer)."""
    rows = []
    for line in _section("Where a newcomer looks first").splitlines():
        cells = [c.strip() for c in line.split("|")[1:-1]]
        header = cells == ["looking for", "it lives in"] or set("".join(cells)) <= {"-"}
        if len(cells) == 2 and cells[1] and not header:
            rows.append((cells[0], cells[1]))
    return rows


def defines(source: str, name: str) -> bool:
    """Whether ``source`` defines ``name``: a ``def`` or ``class``, or an assignment (a module
    constant, a class attribute, a dataclass field) at the start of a line."""
    n = re.escape(name)
    pattern = rf"^\s*(?:async\s+)?(?:def|class)\s+{n}\b|^\s*{n}\s*(?::[^=\n]*)?="
    return re.search(pattern, source, re.M) is not None


def test_every_path_the_map_names_exists():
    missing = [p for p in PATH.findall(DOC.read_text()) if not (ROOT / p.split(" ")[0]).exists()]
    assert missing == []


def test_the_lookup_list_answers_every_behaviour_a_newcomer_asked_for():
    rows = _lookup_rows()
    assert len(rows) >= 40
    questions = [q for q, _ in rows]
    unanswered = [a for a in ASKED if not any(q.startswith(a) for q in questions)]
    assert unanswered == []
    assert len(set(questions)) == len(questions)  # one row per question


@pytest.mark.parametrize("question, answer", _lookup_rows(), ids=lambda x: x[:40])
def test_each_lookup_row_names_a_module_that_defines_what_it_names(question, answer):
    files = [ROOT / p for p in PATH.findall(answer) if p.endswith(".py")]
    assert files, f"{question}: no module named"
    assert all(f.is_file() for f in files), files
    sources = {f: f.read_text() for f in files}
    names = [n for n in NAME.findall(answer) if "/" not in n]
    assert names, f"{question}: no name given beside its module"
    for dotted in names:
        for part in dotted.split("."):
            assert any(defines(src, part) for src in sources.values()), (
                f"{question}: {part!r} ({dotted}) is defined in none of {[str(f) for f in files]}"
            )
    first = sources[files[0]]
    assert any(defines(first, part) for n in names for part in n.split(".")), (
        f"{question}: the first file, {files[0]}, defines none of {names}"
    )


def test_defines_tells_a_definition_from_a_mention():
    source = (
        "MAX = 3\nclass Arm:\n    limit: float = 1.0\n    def command(self):\n        MAX + x\n"
    )
    assert defines(source, "MAX") and defines(source, "Arm") and defines(source, "command")
    assert defines(source, "limit")
    assert not defines(source, "x") and not defines(source, "comm")
