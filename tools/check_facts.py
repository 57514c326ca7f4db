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
6. the ``MISSION_ITEM_INT`` record is defined once (``heli_common/mission_item.py``);
7. the ArduPilot numbers pymavlink lacks (force-disarm magic, aux function MOTOR_INTERLOCK) are
   written once (``heli_common/ardupilot_ids.py``);
8. no file in ``companion/`` or ``sim_vehicle/`` is over 500 lines;
9. no import cycle between the project's modules (every import counts, also those inside
   functions, except under ``if TYPE_CHECKING:``);
10. the numerics (planning, smoothing, world, the threat layer's maths, the simulator's physics and
    control) import no I/O library (sockets, asyncio, zenoh, MAVSDK, pymavlink, subprocess ...).

Prints each finding; exit status 1 if any check fails, 0 otherwise. Reads files only.
"""

from __future__ import annotations

import ast
import re
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
PACKAGES = ("companion", "sim_vehicle", "heli_model", "heli_common", "mavlink_signing")
MODE_NAMES = ("STABILIZE", "ACRO", "ALT_HOLD", "AUTO", "GUIDED", "LOITER", "RTL", "CIRCLE", "LAND",
              "POSHOLD", "BRAKE", "SMART_RTL")
_MODES = "|".join(MODE_NAMES)
MODE_DICT_RE = re.compile(rf"""["']({_MODES})["']\s*:\s*\d+|\b\d+\s*:\s*["']({_MODES})["']""")
MODE_ASSIGN_RE = re.compile(rf"^\s*({_MODES})\s*=\s*\d+\s*(#.*)?$", re.M)
MAV_INT_RE = re.compile(r"^\s*(MAV_CMD_\w+|CMD_\w+|MAV_FRAME_\w+|FRAME_\w+|MAV_RESULT_\w+|MAVLINK_MSG_ID_\w+)"
                        r"\s*=\s*\d+\s*(#.*)?$", re.M)
LOCAL_FRAME_CLASS_RE = re.compile(r"^class\s+(LocalFrame|\w*(Flat|Ned|NED)Frame)\b", re.M)
POINT_IN_POLYGON_RE = re.compile(r"^\s*def\s+point_in_polygon\b", re.M)
ARDUPILOT_NUMBER_RE = re.compile(r"^\s*(FORCE_DISARM_MAGIC|AUX_\w*MOTOR_INTERLOCK)\s*=\s*\d", re.M)
MAX_LINES = 500
SIZE_CHECKED = ("companion/", "sim_vehicle/")
#: Modules (prefixes) that must compute only: numbers in, numbers out.
NUMERICS = ("companion.planning", "companion.smoothing", "companion.world", "companion.threats.decision.prediction",
            "companion.threats.decision.spacetime", "companion.threats.decision.evasion", "companion.threats.decision.retime",
            "companion.threats.decision.join", "companion.threats.decision.alternatives", "companion.threats.decision.candidates",
            "companion.threats.decision.choice", "companion.threats.decision.kinds",
            "companion.threats.decision.estimate", "companion.threats.decision.worlds",
            "companion.threats.decision.step", "companion.threats.decision.values",
            "companion.flight.trajectory", "companion.flight.phases",
            "companion.view.geometry", "heli_model.dynamics", "heli_model.model", "heli_model.control",
            "heli_model.wind", "sim_vehicle.rsc", "sim_vehicle.autopilot", "heli_model.vehicle_update",
            "heli_common.geometry", "heli_common.frames")
#: Top-level modules that do I/O (network, processes, MAVLink transports, logs on disk).
IO_LIBRARIES = ("socket", "asyncio", "selectors", "subprocess", "zenoh", "mavsdk", "pymavlink",
                "http", "urllib", "mcap", "foxglove", "serial")
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


def module_name(rel: str) -> str:
    """Dotted module name of the file at ``rel`` (``a/b/__init__.py`` -> ``a.b``)."""
    parts = rel.removesuffix(".py").split("/")
    return ".".join(parts[:-1] if parts[-1] == "__init__" else parts)


def _type_checking_only(node: ast.AST) -> bool:
    test = getattr(node, "test", None)
    return isinstance(node, ast.If) and ("TYPE_CHECKING" in ast.unparse(test))


def imported_modules(tree: ast.AST, module: str, is_package: bool,
                     modules: frozenset[str] = frozenset()) -> set[str]:
    """Absolute names of the modules ``tree`` imports, skipping ``if TYPE_CHECKING:`` blocks.

    ``from a import b`` imports ``a.b`` when that is one of ``modules`` (a submodule), else ``a``.
    """
    found: set[str] = set()
    package = module if is_package else module.rpartition(".")[0]

    def visit(node: ast.AST) -> None:
        if _type_checking_only(node):
            return
        if isinstance(node, ast.Import):
            found.update(a.name for a in node.names)
        elif isinstance(node, ast.ImportFrom):
            base = node.module or ""
            if node.level:
                anchor = package.split(".")[: len(package.split(".")) - node.level + 1]
                base = ".".join(anchor + ([node.module] if node.module else []))
            for alias in node.names:
                sub = f"{base}.{alias.name}"
                found.add(sub if sub in modules else base)
        for child in ast.iter_child_nodes(node):
            visit(child)

    visit(tree)
    return found


def import_cycles(graph: dict[str, set[str]]) -> list[list[str]]:
    """Strongly connected components of more than one module (or a self-import): Tarjan's."""
    index: dict[str, int] = {}
    low: dict[str, int] = {}
    stack: list[str] = []
    on_stack: set[str] = set()
    cycles: list[list[str]] = []

    def strongconnect(v: str) -> None:
        index[v] = low[v] = len(index)
        stack.append(v)
        on_stack.add(v)
        for w in sorted(graph[v]):
            if w not in index:
                strongconnect(w)
                low[v] = min(low[v], low[w])
            elif w in on_stack:
                low[v] = min(low[v], index[w])
        if low[v] == index[v]:
            component = []
            while True:
                w = stack.pop()
                on_stack.discard(w)
                component.append(w)
                if w == v:
                    break
            if len(component) > 1 or v in graph[v]:
                cycles.append(sorted(component))

    sys.setrecursionlimit(max(sys.getrecursionlimit(), 10_000))
    for v in sorted(graph):
        if v not in index:
            strongconnect(v)
    return cycles


def import_graph(trees: dict[str, tuple[ast.AST, bool]]) -> dict[str, set[str]]:
    """Module -> the project modules it imports. A package's ``__init__`` re-exporting its own
    submodules is not an edge back from those submodules."""
    graph = {}
    modules = frozenset(trees)
    for module, (tree, is_package) in trees.items():
        targets = imported_modules(tree, module, is_package, modules) & modules
        graph[module] = {t for t in targets if t != module}
    return graph


def check(root: Path = ROOT) -> list[tuple[str, bool, list[str]]]:
    """Run every check; returns (name, passed, findings) per check."""
    no_import, mode_dicts, pip, frames, mav_ints, records = [], [], [], [], [], []
    ardupilot_numbers, too_long, io_in_numerics = [], [], []
    trees: dict[str, tuple[ast.AST, bool]] = {}
    for path in sources(root):
        rel = path.relative_to(root).as_posix()
        text = path.read_text(encoding="utf-8")
        tree = ast.parse(text, filename=rel)
        module = module_name(rel)
        trees[module] = (tree, path.name == "__init__.py")
        lines = text.count("\n") + (not text.endswith("\n") and bool(text))
        if rel.startswith(SIZE_CHECKED) and lines > MAX_LINES:
            too_long.append(f"{rel}: {lines} lines")
        if module.startswith(NUMERICS):
            tops = {m.split(".")[0] for m in imported_modules(tree, module, path.name == "__init__.py")}
            io_in_numerics += [f"{rel}: imports {lib}" for lib in sorted(tops & set(IO_LIBRARIES))]
        for m in ARDUPILOT_NUMBER_RE.finditer(text):
            fact = "MOTOR_INTERLOCK" if "INTERLOCK" in m.group(1) else m.group(1)
            ardupilot_numbers.append((fact, f"{rel}:{text.count(chr(10), 0, m.start()) + 1}: {m.group(1)}"))
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
    cycles = import_cycles(import_graph(trees))
    return [
        ("sim_vehicle and heli_common never import companion", not no_import, no_import),
        ("no hand-written ArduCopter mode numbers", not mode_dicts, mode_dicts),
        ("def point_in_polygon defined once", len(pip) == 1, pip),
        ("local-frame class defined once", len(frames) == 1, frames),
        ("no hand-written MAV_CMD/MAV_FRAME/MAV_RESULT/MSG_ID integers", not mav_ints, mav_ints),
        ("MISSION_ITEM_INT record defined once", len(records) == 1, records),
        ("ArduPilot numbers pymavlink lacks written once",
         len(ardupilot_numbers) == len({fact for fact, _ in ardupilot_numbers}),
         [where for _, where in ardupilot_numbers]),
        (f"no file over {MAX_LINES} lines in companion/ and sim_vehicle/", not too_long, too_long),
        ("no import cycle", not cycles, [" <-> ".join(c) for c in cycles]),
        ("numerics import no I/O library", not io_in_numerics, io_in_numerics),
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
