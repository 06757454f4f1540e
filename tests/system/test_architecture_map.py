"""docs/architecture.md's map holds: every path its tables and its newcomer's lookup list name
exists, and every name the lookup list gives beside a module is defined in one of its row's
modules (a move that leaves the map behind fails here)."""

from __future__ import annotations

import re
from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]
DOC = ROOT / "docs" / "architecture.md"
PATH = re.compile(
    r"`((?:plumbing|robot|vision|sim|calibration|explore|testkit|tests|bench|experiments|docs)/[\w./-]*)`"
)
NAME = re.compile(r"`([A-Z_][A-Z0-9_]+|[A-Z][A-Za-z]+|[a-z_]+_[a-z_]+)`")


def _section(title: str) -> str:
    text = DOC.read_text()
    start = text.index(f"## {title}")
    end = text.find("\n## ", start + 1)
    return text[start : end if end != -1 else None]


def test_every_path_the_map_names_exists():
    missing = [p for p in PATH.findall(DOC.read_text()) if not (ROOT / p.split(" ")[0]).exists()]
    assert missing == []


def test_the_lookup_list_points_at_modules_that_define_what_it_names():
    rows = [r for r in _section("Where a newcomer looks first").splitlines() if r.startswith("| ")]
    rows = rows[1:]  # the header (its rule starts with "|-")
    assert len(rows) == 7
    for row in rows:
        answer = row.split("|")[2]
        files = [ROOT / p for p in PATH.findall(answer) if p.endswith(".py")]
        assert files, row
        source = "\n".join(f.read_text() for f in files)
        for name in NAME.findall(answer):
            assert re.search(rf"\b{re.escape(name)}\b", source), f"{name} not in {files}"
