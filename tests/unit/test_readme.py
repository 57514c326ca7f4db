"""The README is a landing page whose figures come from the generated benchmark files."""

from __future__ import annotations

import re
from pathlib import Path

import pytest

from benchmarks import headlines

ROOT = Path(__file__).resolve().parents[2]
README = ROOT / "README.md"


def test_the_readme_is_a_landing_page_of_at_most_250_lines():
    assert len(README.read_text().splitlines()) <= 250


def test_the_readme_figures_are_what_the_generated_files_say():
    """Rebuild with `.venv/bin/python benchmarks/run_all.py --assemble-only` after a benchmark."""
    text = README.read_text()
    start, end = text.index(headlines.BEGIN), text.index(headlines.END) + len(headlines.END)
    assert text[start:end] == headlines.render()


def _anchors(path: Path) -> set[str]:
    return {_slug(line.lstrip("#").strip()) for line in path.read_text().splitlines() if line.startswith("#")}


@pytest.mark.parametrize("page", [README, *sorted((ROOT / "docs").glob("*.md"))], ids=lambda p: p.name)
def test_every_link_between_the_pages_finds_its_file_and_heading(page):
    """Links of README.md and docs/*.md to a page (and its heading) of the repository resolve."""
    prose = re.sub(r"```.*?```", "", page.read_text(), flags=re.S)  # not inside code blocks
    for target, anchor in re.findall(r"\]\(([^)#\s]*)(?:#([\w-]+))?\)", prose):
        if "://" in target or target.startswith("mailto:"):
            continue
        path = (page.parent / target).resolve() if target else page
        assert path.exists(), f"{page.name}: {target}"
        if anchor and path.suffix == ".md":
            assert anchor in _anchors(path), f"{page.name}: {target}#{anchor}"


def _slug(heading: str) -> str:
    """GitHub's anchor of a heading: lower case, punctuation dropped, spaces to hyphens."""
    return re.sub(r"[^\w\- ]", "", heading.lower()).replace(" ", "-")


def test_tables_are_parsed_with_the_heading_above_them():
    text = "# A\n\n| x | y |\n|---|---|\n| a | 1 |\n| b | 2 |\n\n## B (c)\n| x | z |\n|:-|-:|\n| a | 3 |\n"
    tables = headlines.parse_tables(text)
    assert [(t.heading, t.columns, t.rows) for t in tables] == [
        ("A", ("x", "y"), (("a", "1"), ("b", "2"))),
        ("B (c)", ("x", "z"), (("a", "3"),)),
    ]


def test_a_missing_cell_names_the_file_the_column_and_the_row(tmp_path):
    path = headlines.REPO / "docs" / "benchmarks" / "planning.md"
    source = headlines.Source(path)
    with pytest.raises(headlines.HeadlineError, match=r"planning\.md: no cell in column 'nope', row 'GART'"):
        source.cell("nope", "GART")
    with pytest.raises(headlines.HeadlineError, match="cannot read it"):
        headlines.Source(tmp_path / "missing.md")


def test_a_readme_without_the_markers_is_refused():
    with pytest.raises(headlines.HeadlineError, match="markers"):
        headlines.replace_block("# no block here\n", "x")
