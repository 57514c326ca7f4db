"""Docs that cannot go stale: every Python snippet of the README and docs/ runs as a script.

The snippets that need a vehicle or a zenoh subscriber run against real processes in
``tests/integration/test_docs_snippets_live.py``; the others run here, each in a fresh interpreter
from the repository's root, as a reader would paste them into a file.
"""

from __future__ import annotations

import subprocess
import sys

import pytest
from docs_blocks import NEEDS_VEHICLE, NEEDS_ZENOH, ROOT, python_snippets

SNIPPETS = python_snippets()
STANDALONE = [
    pytest.param(code, id=where) for where, code in SNIPPETS if NEEDS_VEHICLE not in code and NEEDS_ZENOH not in code
]


def test_the_docs_have_runnable_snippets():
    assert len(STANDALONE) >= 3
    assert any(NEEDS_VEHICLE in code for _, code in SNIPPETS)
    assert any(NEEDS_ZENOH in code for _, code in SNIPPETS)


@pytest.mark.parametrize("code", STANDALONE)
def test_a_python_snippet_runs_as_a_script(code, tmp_path):
    script = tmp_path / "snippet.py"
    script.write_text(code)
    out = subprocess.run([sys.executable, str(script)], cwd=ROOT, capture_output=True, text=True, timeout=240)
    assert out.returncode == 0, out.stderr[-2000:]
