"""README.md and docs/*.md are a manual and results, not a lab diary.

What a page must not hold: ISO dates (how a finding was reached lives in git history), commit
hashes, issue numbers ("issue 31", "issues 27 and 31", "#31"); what it must not be: over 350
lines (the README over 150). Every relative link must point to a file of the repository.
"""

from __future__ import annotations

import re
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[2]
PAGES = [ROOT / "README.md", *sorted((ROOT / "docs").glob("*.md"))]
MAX_LINES = {"README.md": 150}
MAX_LINES_DOCS = 350

ISO_DATE = re.compile(r"\b(19|20)\d\d-(0[1-9]|1[0-2])-(0[1-9]|[12]\d|3[01])\b")
ISSUE = re.compile(r"\bissues? +(#?\d+)|(?<![\w&/])#\d+\b", re.I)
# A commit-like token: 7-40 hex digits with at least one digit and one letter, standing alone
# (not part of a longer word, a 0x constant, a number with units, a path or a URL). A file's
# content hash as a command prints it ("sha256 d56a0c4dda76", "sha256 c9a7... -> d335...") is
# not a commit.
HEX_TOKEN = re.compile(r"(?<![\w./:-])(?<!sha256 )(?<!-> )[0-9a-f]{7,40}(?![\w/-])")
LINK = re.compile(r"\]\(([^)\s]+)(?:\s+\"[^\"]*\")?\)")


def _is_commit_like(token: str) -> bool:
    return bool(re.search(r"\d", token)) and bool(re.search(r"[a-f]", token))


def diary_marks(text: str) -> list[str]:
    """Every ISO date, commit-like hex token and issue number in a page's text."""
    marks = [m.group(0) for m in ISO_DATE.finditer(text)]
    marks += [m.group(0) for m in ISSUE.finditer(text)]
    marks += [m.group(0) for m in HEX_TOKEN.finditer(text) if _is_commit_like(m.group(0))]
    return marks


@pytest.mark.parametrize("page", PAGES, ids=lambda p: str(p.relative_to(ROOT)))
def test_a_page_holds_no_date_commit_or_issue_number(page: Path):
    marks = diary_marks(page.read_text())
    assert not marks, f"{page.relative_to(ROOT)}: {marks[:10]}"


@pytest.mark.parametrize("page", PAGES, ids=lambda p: str(p.relative_to(ROOT)))
def test_a_page_is_short_enough_to_read(page: Path):
    limit = MAX_LINES.get(page.name if page.parent == ROOT else "", MAX_LINES_DOCS)
    lines = len(page.read_text().splitlines())
    assert lines <= limit, f"{page.relative_to(ROOT)}: {lines} lines, over {limit}"


@pytest.mark.parametrize("page", PAGES, ids=lambda p: str(p.relative_to(ROOT)))
def test_every_relative_link_points_to_a_file(page: Path):
    missing = []
    for target in LINK.findall(page.read_text()):
        if re.match(r"[a-z][a-z0-9+.-]*:", target) or target.startswith("#"):
            continue  # a URL (http:, mailto:) or an anchor on the same page
        path = target.split("#", 1)[0]
        if not (page.parent / path).exists():
            missing.append(target)
    assert not missing, f"{page.relative_to(ROOT)}: links to no file: {missing}"


@pytest.mark.parametrize(
    "text",
    [
        "run on 2026-12-03",
        "as issue 31 asked",
        "issues 27 and 31",
        "fixed in #46",
        "commit `4d27a81`",
        "main 4d27a81 today",
        "at e7bbf75c0ffee1234",
    ],
)
def test_the_patterns_find_a_diary_mark(text: str):
    assert diary_marks(text)


@pytest.mark.parametrize(
    "text",
    [
        "object 0x6041, the statusword",
        "CAN id 0x581 answers",
        "a frame t1800000 on the bus",
        "1000000 baud; 12345678 bytes",
        "the decoder's deadbeef word",
        "a torch build 2.13.0 and `## 1. Power`",
        "seed 3000, dataset seeds 3000-3001",
        "[link](docs/real_arm.md#8-a-check-run)",
        "ids 1-6, a colour #ff0000",
        "made just now, sha256 64b3ca25e769",
        "[a report](https://github.com/huggingface/lerobot/issues/3586)",
    ],
)
def test_the_patterns_leave_ordinary_text_alone(text: str):
    assert not diary_marks(text)
