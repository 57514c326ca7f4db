"""Every "DESIGN <n>" / "DESIGN <n>.<m>" / "DESIGN section <n>" citation resolves in docs/DESIGN.md.

A section is a heading ``## N. Title``; item ``N.M`` is the M-th entry of the top-level numbered
list (``M. ...`` at the start of a line) under section N. Citations are read from the packages,
benchmarks, tools and tests, and from README.md and docs/*.md.
"""

from __future__ import annotations

import re
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[2]
DESIGN = ROOT / "docs" / "DESIGN.md"
CITING = ("companion", "sim_vehicle", "heli_model", "heli_common", "mavlink_signing", "benchmarks", "tools", "tests")
WORD = "DES" + "IGN"  # so that this file's own bad examples are not citations
_NUMBER = r"\d+(?:\.\d+)?"
CITATION_RE = re.compile(WORD + rf"(?:\.md)?\s+(?:sections?\s+)?({_NUMBER}(?:\s*(?:,|and|to)\s*{_NUMBER})*)")
SECTION_RE = re.compile(r"^## (\d+)\. \S")
ITEM_RE = re.compile(r"^(\d+)\. \S")


def design_numbers(markdown: str) -> set[str]:
    """``{"1", ..., "7", "7.1", ...}``: the sections and their numbered items in ``markdown``.

    Items must count 1, 2, 3 ... under their section; a section must follow the previous one.
    """
    found: set[str] = set()
    section = None
    in_code = False
    for line in markdown.splitlines():
        if line.startswith("```"):
            in_code = not in_code
            continue
        if in_code:
            continue
        heading = SECTION_RE.match(line)
        if heading:
            number = int(heading.group(1))
            if number != (section or 0) + 1:
                raise ValueError(f"section {number} follows section {section}")
            section, item = number, 0
            found.add(str(number))
            continue
        entry = ITEM_RE.match(line)
        if entry and section is not None:
            if int(entry.group(1)) != item + 1:
                raise ValueError(f"section {section}: item {entry.group(1)} follows item {item}")
            item += 1
            found.add(f"{section}.{item}")
    return found


def citations(text: str) -> list[tuple[int, str]]:
    """(line, number) for every section or item number cited in ``text``."""
    out = []
    for m in CITATION_RE.finditer(text):
        line = text.count("\n", 0, m.start()) + 1
        out += [(line, n) for n in re.findall(_NUMBER, m.group(1))]
    return out


def unresolved(text: str, numbers: set[str]) -> list[str]:
    """``"line: number"`` for each citation in ``text`` that is not one of ``numbers``."""
    return [f"{line}: {WORD} {n}" for line, n in citations(text) if n not in numbers]


def citing_files() -> list[Path]:
    files = [p for d in CITING for p in sorted((ROOT / d).rglob("*.py"))]
    files += [ROOT / "README.md"] + sorted(p for p in (ROOT / "docs").glob("*.md") if p != DESIGN)
    return [p for p in files if p.is_file()]


def test_design_document_numbers_sections_1_to_10_and_the_policy_steps():
    numbers = design_numbers(DESIGN.read_text(encoding="utf-8"))
    assert {str(n) for n in range(1, 11)} <= numbers
    assert {"7.1", "7.2", "7.3", "7.4", "7.5"} <= numbers


def test_every_citation_resolves():
    numbers = design_numbers(DESIGN.read_text(encoding="utf-8"))
    bad, cited = [], 0
    for path in citing_files():
        text = path.read_text(encoding="utf-8")
        cited += len(citations(text))
        bad += [f"{path.relative_to(ROOT).as_posix()}:{where}" for where in unresolved(text, numbers)]
    assert cited > 50  # the citations are found at all
    assert bad == []


SAMPLE = """# Title

## 1. What

Text with a list that is not numbered:
- a

## 2. Policy

1. **Predict.** one
2. **Check.** two
   - a sub-item
3. **Monitor.** three

```
1. not an item: code
```
"""


def test_parser_reads_sections_and_items():
    assert design_numbers(SAMPLE) == {"1", "2", "2.1", "2.2", "2.3"}


@pytest.mark.parametrize(
    "text, expected",
    [
        (f"({WORD} 2.3)", []),
        (f"({WORD} 2.4)", ["1: " + WORD + " 2.4"]),
        (f"{WORD} section 3", ["1: " + WORD + " 3"]),
        (f"{WORD}.md sections 1 and 9", ["1: " + WORD + " 9"]),
        (f"({WORD} 1, 2, 7)", ["1: " + WORD + " 7"]),
        (f"x\n({WORD} 2.1 to 2.5)", ["2: " + WORD + " 2.5"]),
        (f"{WORD} 1.1", ["1: " + WORD + " 1.1"]),  # section 1 has no numbered list
        (f"({WORD} 2, paper section 3.3)", []),  # the paper's sections are not ours
    ],
)
def test_a_bad_citation_is_found(text, expected):
    assert unresolved(text, design_numbers(SAMPLE)) == expected


def test_a_misnumbered_document_is_refused():
    with pytest.raises(ValueError, match="section 3 follows section 1"):
        design_numbers("## 1. A\n## 3. C\n")
    with pytest.raises(ValueError, match="item 3 follows item 1"):
        design_numbers("## 1. A\n1. x\n3. y\n")
