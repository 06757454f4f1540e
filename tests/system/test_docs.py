"""README.md and docs/*.md are a manual and results, not a lab diary.

What a page must not hold: ISO dates (how a finding was reached lives in git history), commit
hashes, issue numbers ("issue 31", "issues 27 and 31", "#31"); what it must not be: over 350
lines (the README over 150). Every relative link must point to a file of the repository.

The manual pages (the README and every docs page but the results pages, ``results*.md``) say
how things are and how to use them: no notebook text either. No finding labels ("F8", the
results pages' sections), no p-values (a results page's statistics), no "today", "used to",
"no longer", "the issue", "superseded", "git history", "the first version", and no remark on
what ran beside a measurement ("the machine was not idle", "other jobs", "shared with 3
other agents").
"""

from __future__ import annotations

import re
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[2]
PAGES = [ROOT / "README.md", *sorted((ROOT / "docs").glob("*.md"))]
# The results pages: findings with their statistics, which the manual pages link to.
RESULTS = re.compile(r"results(_\w+)?\.md")
MANUAL_PAGES = [p for p in PAGES if not RESULTS.fullmatch(p.name)]
MAX_LINES = {"README.md": 150}
MAX_LINES_DOCS = 350

ISO_DATE = re.compile(r"\b(19|20)\d\d-(0[1-9]|1[0-2])-(0[1-9]|[12]\d|3[01])\b")
ISSUE = re.compile(r"\bissues? +(#?\d+)|(?<![\w&/])#\d+\b", re.I)
# A commit-like token: 7-40 hex digits with at least one digit and one letter, standing alone
# (not part of a longer word, a 0x constant, a number with units, a path or a URL). A file's
# content hash as a command prints it ("sha256 d56a0c4dda76", "sha256 c9a7... -> d335...") is
# not a commit.
HEX_TOKEN = re.compile(r"(?<![\w./:-])(?<!sha256 )(?<!-> )[0-9a-f]{7,40}(?![\w/-])")
NOTEBOOK = [
    re.compile(r"\bF\d{1,2}\b"),  # a finding's label
    # a p-value: "p 0.008", "p = 0.16", "p < 0.01", "Welch p 0.47", "p 1e-8"
    re.compile(r"\bp ?(?:[=<>≤] ?)?(?:0?\.\d+|\d(?:\.\d+)?e-\d+)"),
    re.compile(r"\btoday\b|\bused to\b|\bno longer\b|\bthe issue\b", re.I),
    re.compile(r"\bsuperseded\b|\bgit history\b|\bthe first version\b", re.I),
    re.compile(r"\bnot idle\b|\bother (?:jobs|agents)\b|\bshared with \d+ other", re.I),
]
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


def notebook_marks(text: str) -> list[str]:
    """Every finding label, p-value, "today"-like word and remark on the machine's other work
    in a manual page's text."""
    return [m.group(0) for pattern in NOTEBOOK for m in pattern.finditer(text)]


@pytest.mark.parametrize("page", MANUAL_PAGES, ids=lambda p: str(p.relative_to(ROOT)))
def test_a_manual_page_holds_no_notebook_text(page: Path):
    marks = notebook_marks(page.read_text())
    assert not marks, f"{page.relative_to(ROOT)}: {marks[:10]}"


def test_the_manual_pages_are_every_page_but_the_results():
    names = {p.name for p in MANUAL_PAGES}
    assert {"README.md", "twin.md", "goal_exploration.md", "ecosystem.md", "viewing.md"} <= names
    assert {"canopen.md", "architecture.md"} <= names
    assert not any(n.startswith("results") for n in names)
    assert len(PAGES) - len(MANUAL_PAGES) == sum(bool(RESULTS.fullmatch(p.name)) for p in PAGES)


@pytest.mark.parametrize(
    "text",
    [
        "(results.md, F8)",
        "the runs of F1-F7",
        "density 160 ± 16 (p 0.008)",
        "RGE-SAE 1.05x (p = 0.16)",
        "Welch p 0.47",
        "not above RPE (p < 0.01)",
        "(p 1e-8)",
        "48 cells today",
        "today's defaults",
        "It used to hang forever there",
        "no longer decays",
        "guess / the issue",
        "are superseded; see the git history",
        "The first version rebuilt the tree",
        "The machine was not idle: other test suites ran beside it",
        "beside other jobs, load average 9",
        "2 CPU cores shared with 3 other agents",
    ],
)
def test_the_patterns_find_notebook_text(text: str):
    assert notebook_marks(text)


@pytest.mark.parametrize(
    "text",
    [
        "a 4096 x 4096 shadow map",
        "option `sigma` 0.05",
        "step 0.15 rad at 40 Hz",
        "the ball's polar features (r_n, cos t, sin t)",
        "the camera repeats a frame now and then",
        "the F-number of the lens",
        "a top 0.1 of the scores",
    ],
)
def test_the_notebook_patterns_leave_manual_text_alone(text: str):
    assert not notebook_marks(text)


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
