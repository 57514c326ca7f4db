#!/usr/bin/env python3
"""Write ``docs/SETTINGS.md`` from the settings dataclasses (``--check``: only compare).

Usage: ``.venv/bin/python tools/settings_doc.py [--check]``. Exit status 1 with ``--check`` when
the file differs from what the code generates (then run it without ``--check``).
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT))

from companion.config import Settings  # noqa: E402
from companion.settings_doc import reference_markdown  # noqa: E402
from sim_vehicle.config import VehicleSettings  # noqa: E402

#: The settings trees documented, in order: (root class, section title).
SETTINGS_TREES = (
    (Settings, "The companion (`companion run --config`)"),
    (VehicleSettings, "The simulator (`sim-vehicle --config`)"),
)

TARGET = ROOT / "docs" / "SETTINGS.md"


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--check", action="store_true", help="compare only; exit 1 on a difference")
    args = parser.parse_args(argv)
    text = reference_markdown(SETTINGS_TREES)
    if args.check:
        current = TARGET.read_text(encoding="utf-8") if TARGET.exists() else ""
        if current != text:
            sys.stderr.write(f"{TARGET.relative_to(ROOT)} is out of date: run tools/settings_doc.py\n")
            return 1
        return 0
    TARGET.write_text(text, encoding="utf-8")
    return 0


if __name__ == "__main__":
    sys.exit(main())
