"""The fenced code blocks of README.md and docs/*.md (the docs-as-tests suites read them)."""

from __future__ import annotations

import re
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
DOCS = [ROOT / "README.md", *sorted((ROOT / "docs").glob("*.md"))]
#: Text that makes a Python snippet need a running process: a vehicle, or a zenoh subscriber.
NEEDS_VEHICLE, NEEDS_ZENOH = "udpout://127.0.0.1:14555", "tcp/127.0.0.1:7448"


def blocks(text: str):
    """(language, first line number, lines) of every fenced block of a markdown text."""
    lang, start, lines = None, 0, []
    for number, line in enumerate(text.splitlines(), 1):
        fence = re.match(r"^\s*```(\w*)\s*$", line)
        if fence and lang is None:
            lang, start, lines = fence.group(1), number + 1, []
        elif fence:
            yield lang, start, lines
            lang = None
        elif lang is not None:
            lines.append(line)


def python_snippets() -> list[tuple[str, str]]:
    """(``file:line``, code) of every ```python block of the docs."""
    return [
        (f"{path.relative_to(ROOT)}:{start}", "\n".join(lines) + "\n")
        for path in DOCS
        for lang, start, lines in blocks(path.read_text())
        if lang == "python"
    ]
