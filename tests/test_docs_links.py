"""Relative links in README.md and docs/ (experiments included) lead to files that exist, and their
``#anchors`` to headings of the linked page."""

from __future__ import annotations

import re
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
PAGES = [ROOT / "README.md", *sorted((ROOT / "docs").rglob("*.md"))]
LINK = re.compile(r"\[[^\]]*\]\(([^)\s]+)\)")
#: Pages that a command writes (``python -m paz6d.benchmark.results ... --out docs/results.md``): a link to one
#: counts while the page has not been written yet.
WRITTEN_BY_A_COMMAND = {ROOT / "docs" / "results.md"}


def anchor(heading: str) -> str:
    """GitHub's anchor of a Markdown heading: lower case, punctuation dropped, spaces to hyphens."""
    text = re.sub(r"[^\w\- ]", "", heading.strip().lower())
    return text.replace(" ", "-")


def anchors(page: Path) -> set[str]:
    text = re.sub(r"```.*?```", "", page.read_text(encoding="utf-8"), flags=re.S)
    return {anchor(line.lstrip("#")) for line in text.splitlines() if re.match(r"#{1,6} ", line)}


def broken_links(page: Path) -> list[str]:
    """``"target (why)"`` for each relative link of ``page`` that leads nowhere."""
    found = []
    text = re.sub(r"```.*?```", "", page.read_text(encoding="utf-8"), flags=re.S)
    for target in LINK.findall(text):
        if re.match(r"[a-z]+:", target):
            continue
        path, _, fragment = target.partition("#")
        linked = (page.parent / path).resolve() if path else page
        if not linked.exists():
            if linked not in WRITTEN_BY_A_COMMAND:
                found.append(f"{target} (no such file)")
        elif fragment and linked.suffix == ".md" and fragment not in anchors(linked):
            found.append(f"{target} (no heading #{fragment})")
    return found


def test_anchor_follows_githubs_rule():
    assert anchor(" Symmetric objects: the orientation network") == "symmetric-objects-the-orientation-network"
    assert anchor("Measured (`paz6d demo`, quick config, 2-core CPU)") == "measured-paz6d-demo-quick-config-2-core-cpu"


def test_a_broken_link_and_a_missing_heading_are_found(tmp_path):
    page = tmp_path / "page.md"
    (tmp_path / "other.md").write_text("# Title\n\n## Out-of-distribution check\n")
    page.write_text("[a](other.md#out-of-distribution-check) [b](other.md#nothing) [c](gone.md) "
                    "[d](https://example.org/x.md) [e](#here)\n\n# Here\n")
    assert broken_links(page) == ["other.md#nothing (no heading #nothing)", "gone.md (no such file)"]


@pytest.mark.parametrize("page", PAGES, ids=lambda page: str(page.relative_to(ROOT)))
def test_every_relative_link_leads_somewhere(page):
    assert broken_links(page) == []
