"""The links of README.md and docs/*.md (and the data and checkpoint READMEs) lead where they say: every
relative link names a file of the repository, every #anchor a heading of its file (GitHub's slugs), and a
link whose text is a section of the file it points to lands on that section, not on the file's top."""

from __future__ import annotations

import re
from pathlib import Path

import pytest

REPO = Path(__file__).resolve().parents[1]
DOCS = [
    REPO / "README.md",
    *sorted((REPO / "docs").glob("*.md")),
    REPO / "data" / "README.md",
    REPO / "checkpoints" / "README.md",
]
LINK = re.compile(r"\[([^\]]+)\]\(([^)\s]+)\)")
FENCE = re.compile(r"^```.*?^```", re.S | re.M)


def _prose(path: Path) -> str:
    """The file without its code blocks, whose brackets are code, not links."""
    return FENCE.sub("", path.read_text(encoding="utf-8"))


def _slug(heading: str) -> str:
    """GitHub's anchor of a heading: lower case, code marks and punctuation dropped, spaces to hyphens."""
    text = heading.strip().lower().replace("`", "")
    return re.sub(r"[^\w\- ]", "", text).replace(" ", "-")


def _headings(path: Path) -> dict[str, str]:
    """Anchor -> heading of a Markdown file (a repeated heading's anchor gets -1, -2, ... as on GitHub)."""
    found: dict[str, str] = {}
    for match in re.finditer(r"^#{1,6}\s+(.+?)\s*$", _prose(path), re.M):
        slug, n = _slug(match.group(1)), 1
        anchor = slug
        while anchor in found:
            anchor, n = f"{slug}-{n}", n + 1
        found[anchor] = match.group(1)
    return found


def _links(path: Path) -> list[tuple[str, str, str]]:
    """(text, target file or "", anchor or "") of each relative link of ``path``."""
    out = []
    for text, target in LINK.findall(_prose(path)):
        if re.match(r"[a-z]+:", target):  # https:, mailto:
            continue
        file, _, anchor = target.partition("#")
        out.append((text, file, anchor))
    return out


@pytest.mark.parametrize("doc", DOCS, ids=lambda p: str(p.relative_to(REPO)))
def test_every_relative_link_and_anchor_resolves(doc):
    broken = []
    for text, file, anchor in _links(doc):
        target = (doc.parent / file).resolve() if file else doc
        if not target.exists():
            broken.append(f"[{text}]({file}): no such file")
        elif anchor and target.suffix == ".md" and anchor not in _headings(target):
            broken.append(f"[{text}]({file}#{anchor}): no such heading in {target.name}")
    assert broken == []


@pytest.mark.parametrize("doc", DOCS, ids=lambda p: str(p.relative_to(REPO)))
def test_a_link_named_after_a_section_lands_on_it(doc):
    """README's "twelve robots succeed within 10 points of three ([More robots, more humans](
    docs/results.md))" opened results.md at its top, 320 lines above that section."""
    unanchored = []
    for text, file, anchor in _links(doc):
        if file.endswith(".md") and not anchor and (doc.parent / file).exists():
            if _slug(text) in _headings((doc.parent / file).resolve()):
                unanchored.append(f"[{text}]({file}) -> {file}#{_slug(text)}")
    assert unanchored == []
