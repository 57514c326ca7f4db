#!/usr/bin/env python3
"""Check that each shared fact of the project is defined once (issue 12, item 2).

Checks, over ``companion/``, ``sim_vehicle/``, ``heli_common/`` and ``mavlink_signing/``:

1. ``sim_vehicle`` and ``heli_common`` never import ``companion``;
2. ArduCopter mode numbers are written once: no dict literal pairing a mode name with a number,
   no ``GUIDED = 4``-style assignment (the numbers come from ``mavutil.mode_mapping_acm`` via
   ``heli_common.mavlink_ids``);
3. ``def point_in_polygon`` is defined exactly once (``heli_common/geometry.py``);
4. a local-frame class (``class LocalFrame``) is defined exactly once (``heli_common/frames.py``);
5. no hand-written MAV_CMD / MAV_FRAME / MAV_RESULT / MAVLINK_MSG_ID integers
   (``MAV_CMD_X = 22``, ``CMD_X = 22``, ...): use pymavlink's generated names;
6. the ``MISSION_ITEM_INT`` record is defined once (``heli_common/mission_item.py``).

Prints each finding; exit status 1 if any check fails, 0 otherwise. Reads files only.
"""

from __future__ import annotations

import ast
import re
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
PACKAGES = ("companion", "sim_vehicle", "heli_common", "mavlink_signing")
MODE_NAMES = ("STABILIZE", "ACRO", "ALT_HOLD", "AUTO", "GUIDED", "LOITER", "RTL", "CIRCLE", "LAND",
              "POSHOLD", "BRAKE", "SMART_RTL")
_MODES = "|".join(MODE_NAMES)
MODE_DICT_RE = re.compile(rf"""["']({_MODES})["']\s*:\s*\d+|\b\d+\s*:\s*["']({_MODES})["']""")
MODE_ASSIGN_RE = re.compile(rf"^\s*({_MODES})\s*=\s*\d+\s*(#.*)?$", re.M)
MAV_INT_RE = re.compile(r"^\s*(MAV_CMD_\w+|CMD_\w+|MAV_FRAME_\w+|FRAME_\w+|MAV_RESULT_\w+|MAVLINK_MSG_ID_\w+)"
                        r"\s*=\s*\d+\s*(#.*)?$", re.M)
LOCAL_FRAME_CLASS_RE = re.compile(r"^class\s+(LocalFrame|\w*(Flat|Ned|NED)Frame)\b", re.M)
POINT_IN_POLYGON_RE = re.compile(r"^\s*def\s+point_in_polygon\b", re.M)
MISSION_ITEM_INT_FIELDS = ("seq", "frame", "command", "current", "autocontinue", "param1", "param2",
                           "param3", "param4", "x", "y", "z")


def sources(root: Path = ROOT) -> list[Path]:
    """The Python files of the checked packages, sorted."""
    return sorted(p for pkg in PACKAGES for p in (root / pkg).rglob("*.py"))


def imports_companion(tree: ast.AST) -> list[int]:
    """Line numbers of ``import companion...`` / ``from companion... import`` in ``tree``."""
    lines = []
    for node in ast.walk(tree):
        if isinstance(node, ast.Import):
            if any(a.name == "companion" or a.name.startswith("companion.") for a in node.names):
                lines.append(node.lineno)
        elif isinstance(node, ast.ImportFrom) and node.level == 0 and node.module:
            if node.module == "companion" or node.module.startswith("companion."):
                lines.append(node.lineno)
    return lines


def mission_item_records(tree: ast.AST) -> list[tuple[str, int]]:
    """Classes whose annotated fields include all of MISSION_ITEM_INT's."""
    found = []
    for node in ast.walk(tree):
        if isinstance(node, ast.ClassDef):
            fields = {s.target.id for s in node.body
                      if isinstance(s, ast.AnnAssign) and isinstance(s.target, ast.Name)}
            if set(MISSION_ITEM_INT_FIELDS) <= fields:
                found.append((node.name, node.lineno))
    return found


def check(root: Path = ROOT) -> list[tuple[str, bool, list[str]]]:
    """Run every check; returns (name, passed, findings) per check."""
    no_import, mode_dicts, pip, frames, mav_ints, records = [], [], [], [], [], []
    for path in sources(root):
        rel = path.relative_to(root).as_posix()
        text = path.read_text(encoding="utf-8")
        tree = ast.parse(text, filename=rel)
        if rel.startswith(("sim_vehicle/", "heli_common/")):
            no_import += [f"{rel}:{n}: imports companion" for n in imports_companion(tree)]
        for rx in (MODE_DICT_RE, MODE_ASSIGN_RE):
            for m in rx.finditer(text):
                mode_dicts.append(f"{rel}:{text.count(chr(10), 0, m.start()) + 1}: {m.group(0).strip()}")
        for m in POINT_IN_POLYGON_RE.finditer(text):
            pip.append(f"{rel}:{text.count(chr(10), 0, m.start()) + 1}")
        for m in LOCAL_FRAME_CLASS_RE.finditer(text):
            frames.append(f"{rel}:{text.count(chr(10), 0, m.start()) + 1}: class {m.group(1)}")
        for m in MAV_INT_RE.finditer(text):
            mav_ints.append(f"{rel}:{text.count(chr(10), 0, m.start()) + 1}: {m.group(0).strip()}")
        records += [f"{rel}:{line}: class {name}" for name, line in mission_item_records(tree)]
    return [
        ("sim_vehicle and heli_common never import companion", not no_import, no_import),
        ("no hand-written ArduCopter mode numbers", not mode_dicts, mode_dicts),
        ("def point_in_polygon defined once", len(pip) == 1, pip),
        ("local-frame class defined once", len(frames) == 1, frames),
        ("no hand-written MAV_CMD/MAV_FRAME/MAV_RESULT/MSG_ID integers", not mav_ints, mav_ints),
        ("MISSION_ITEM_INT record defined once", len(records) == 1, records),
    ]


def main() -> int:
    results = check()
    for name, ok, findings in results:
        print(f"{'ok  ' if ok else 'FAIL'} {name}")
        for f in findings:
            print(f"       {f}")
    failed = sum(not ok for _, ok, _ in results)
    print(f"{len(results) - failed}/{len(results)} checks passed")
    return 1 if failed else 0


if __name__ == "__main__":
    sys.exit(main())
