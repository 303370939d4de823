"""Every relative link in README.md and docs/*.md resolves: the file exists, and a #section is one of its headings."""

from __future__ import annotations

import re
from pathlib import Path

from conftest import REPO

LINK = re.compile(r"\[[^\]]*\]\(([^)\s]+)\)")
FENCE = re.compile(r"^```.*?^```", re.S | re.M)
CODE_SPAN = re.compile(r"`[^`\n]*`")


def pages() -> list[Path]:
    return [REPO / "README.md", *sorted((REPO / "docs").glob("*.md"))]


def prose(path: Path) -> str:
    """The page without its code blocks and code spans (a `[a](b)` there is code, not a link)."""
    return CODE_SPAN.sub("", FENCE.sub("", path.read_text(encoding="utf-8")))


def anchors(path: Path) -> set[str]:
    """GitHub's heading anchors: lower case, punctuation dropped, spaces as '-', a repeated heading numbered."""
    found: set[str] = set()
    counts: dict[str, int] = {}
    for line in FENCE.sub("", path.read_text(encoding="utf-8")).splitlines():
        if m := re.match(r"#{1,6}\s+(.*?)\s*#*\s*$", line):
            slug = re.sub(r"[^\w\- ]", "", m.group(1).strip().lower()).replace(" ", "-")
            n = counts.get(slug, 0)
            counts[slug] = n + 1
            found.add(slug if n == 0 else f"{slug}-{n}")
    return found


def broken_links(path: Path) -> list[str]:
    bad = []
    for target in LINK.findall(prose(path)):
        if re.match(r"[a-z][a-z0-9+.-]*:", target):  # http:, https:, mailto:
            continue
        file_part, _, anchor = target.partition("#")
        dest = (path.parent / file_part).resolve() if file_part else path
        if not dest.exists():
            bad.append(f"{target}: no such file")
        elif anchor and dest.suffix == ".md" and anchor not in anchors(dest):
            bad.append(f"{target}: no heading #{anchor} in {dest.name}")
    return bad


def test_every_relative_link_in_the_docs_resolves():
    found = pages()
    assert len(found) > 3  # README.md and the docs/ pages
    bad = {p.relative_to(REPO).as_posix(): b for p in found if (b := broken_links(p))}
    assert not bad, f"broken links: {bad}"


def test_every_docs_page_is_linked_from_the_readme():
    readme = set(LINK.findall(prose(REPO / "README.md")))
    missing = [p.name for p in (REPO / "docs").glob("*.md") if f"docs/{p.name}" not in readme]
    assert not missing, f"docs pages the README's list does not link: {missing}"


def test_the_link_check_sees_a_broken_link_and_a_missing_heading(tmp_path):
    (tmp_path / "a.md").write_text("# Title\n\n## Rates other than 200 Hz\n\n[x](a.md#rates-other-than-200-hz)\n")
    (tmp_path / "b.md").write_text("[x](gone.md) [y](a.md#nothing) `[z](code.md)` [w](https://example.org)\n")
    assert broken_links(tmp_path / "a.md") == []
    assert [b.split(":")[0] for b in broken_links(tmp_path / "b.md")] == ["gone.md", "a.md#nothing"]
