"""LICENSE and CITATION.cff agree with pyproject.toml (issue 25)."""

from __future__ import annotations

import tomllib

import yaml
from support import REPO_ROOT

PAPER = "UAV Path Planning Framework Under Kinodynamic Constraints in Cluttered Environments"


def project() -> dict:
    return tomllib.loads((REPO_ROOT / "pyproject.toml").read_text())["project"]


def test_the_license_file_is_the_mit_license_pyproject_declares():
    text = (REPO_ROOT / "LICENSE").read_text()
    assert project()["license"] == {"text": "MIT"}
    assert text.startswith("MIT License\n") and "Copyright (c) 2026 the heli-companion authors" in text
    assert 'THE SOFTWARE IS PROVIDED "AS IS", WITHOUT WARRANTY OF ANY KIND' in text


def test_the_citation_file_cites_the_software_and_the_paper():
    cff = yaml.safe_load((REPO_ROOT / "CITATION.cff").read_text())
    assert cff["cff-version"] == "1.2.0" and cff["type"] == "software" and cff["message"]
    assert cff["version"] == project()["version"] and cff["license"] == "MIT"
    assert cff["authors"] and all("name" in a or "family-names" in a for a in cff["authors"])
    assert PAPER in " ".join(cff["message"].split())  # named, not given invented authors
