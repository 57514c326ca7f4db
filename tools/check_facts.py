#!/usr/bin/env python3
"""Check the house rules that can be checked: each shared fact is defined once (issue 12, item 2)
and the structure of docs/DESIGN.md (sections 2 and 11) holds.

Checks, over ``companion/``, ``sim_vehicle/``, ``heli_model/``, ``heli_common/`` and
``mavlink_signing/`` (the packages that exist), and for check 13 over ``benchmarks/``:

1. ``sim_vehicle``, ``heli_model`` and ``heli_common`` never import ``companion``;
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
8. no class over 280 statement lines or 30 methods and no function or method over 45 statement
   lines (the lines on which a statement begins, its docstring left out: a measure the formatter
   does not change, where wrapping an argument list over several lines would), except the
   few named in ``SIZE_EXCEPTIONS`` (each with its reason; an entry that no longer exceeds is a
   finding, so the list only shrinks);
9. no import cycle between the project's modules (every import counts: those inside functions and
   those under ``if TYPE_CHECKING:`` too), except inside a package of ``CYCLE_EXCEPTIONS``;
10. the numerics (planning, smoothing, world, the trajectory pipeline, the threat layer's maths and
    decision step, the helicopter model and its control, the simulator's physics) import no I/O
    library (sockets, asyncio, zenoh, MAVSDK, pymavlink, subprocess ...);
11. no mixins: no class named ``*Mixin`` and no class with two or more project-defined bases
    (project exceptions and Protocols, and library bases such as ``Exception``, ``ValueError``,
    ``enum.Enum``, ``NamedTuple`` or ``Protocol``, do not count), except ``MIXIN_EXCEPTIONS``;
12. ``companion``, ``heli_model`` and ``heli_common`` never import ``sim_vehicle`` (any import,
    at any depth, also inside functions). Until ``heli_model/`` exists (the move of the model out
    of ``sim_vehicle`` is under way) the companion's imports are printed as a note, not a failure;
13. the benchmarks and the campaign fly threat encounters with the flight executor instead of
    emulating it: no module of ``benchmarks/`` or ``companion/campaign/`` says "emulat", and
    ``benchmarks/threats.py`` (and ``companion/campaign/``, when present) imports
    ``companion.flight.executor``. Skipped with a note while ``companion/flight/executor.py``
    does not exist.

Prints each finding (``path:line: name: measure``) and each note; exit status 1 if any check
fails, 0 otherwise. Reads files only.
"""

from __future__ import annotations

import ast
import re
import sys
from pathlib import Path
from typing import NamedTuple

ROOT = Path(__file__).resolve().parent.parent
PACKAGES = ("companion", "sim_vehicle", "heli_model", "heli_common", "mavlink_signing")
MODE_NAMES = (
    "STABILIZE",
    "ACRO",
    "ALT_HOLD",
    "AUTO",
    "GUIDED",
    "LOITER",
    "RTL",
    "CIRCLE",
    "LAND",
    "POSHOLD",
    "BRAKE",
    "SMART_RTL",
)
_MODES = "|".join(MODE_NAMES)
MODE_DICT_RE = re.compile(rf"""["']({_MODES})["']\s*:\s*\d+|\b\d+\s*:\s*["']({_MODES})["']""")
MODE_ASSIGN_RE = re.compile(rf"^\s*({_MODES})\s*=\s*\d+\s*(#.*)?$", re.M)
MAV_INT_RE = re.compile(
    r"^\s*(MAV_CMD_\w+|CMD_\w+|MAV_FRAME_\w+|FRAME_\w+|MAV_RESULT_\w+|MAVLINK_MSG_ID_\w+)"
    r"\s*=\s*\d+\s*(#.*)?$",
    re.M,
)
LOCAL_FRAME_CLASS_RE = re.compile(r"^class\s+(LocalFrame|\w*(Flat|Ned|NED)Frame)\b", re.M)
POINT_IN_POLYGON_RE = re.compile(r"^\s*def\s+point_in_polygon\b", re.M)
ARDUPILOT_NUMBER_RE = re.compile(r"^\s*(FORCE_DISARM_MAGIC|AUX_\w*MOTOR_INTERLOCK)\s*=\s*\d", re.M)
MAX_CLASS_LINES = 280
MAX_CLASS_METHODS = 30
MAX_FUNCTION_LINES = 45
#: ``"path::qualname"`` -> why it may exceed MAX_CLASS_LINES / MAX_CLASS_METHODS / MAX_FUNCTION_LINES
#: today. Shrink it: an entry whose file exists but which no longer exceeds is a finding; an entry
#: whose file does not exist (yet, or any more: the move to the new layout) is only a note.
SIZE_EXCEPTIONS = {
    "companion/commands/plan.py::plot_plan": "one matplotlib figure (tree, obstacles, paths, curvature panel) drawn inline; split by layer",
    "companion/service/startup.py::start_vehicle": "the start-up procedure as one awaited sequence (GUIDED, interlock, arm, run-up, takeoff, climb)",
    "companion/planning/mgart.py::mgart": "M-GART's outer loop (plan, forbid, repeat) with its long numpydoc; steps not yet named",
    "companion/smoothing/g1.py::smooth_g1": "numpydoc of 25 lines plus the halving loop of the collision repair",
    "companion/smoothing/g2.py::smooth_g2": "numpydoc of 25 lines plus the halving loop of the collision repair",
    "companion/smoothing/repair.py::corners_clear": "the vectorised certification of every corner curve at once, kept together for speed",
    "companion/threats/scenario.py::_event": "validates every key of a scenario event, naming the key",
    "companion/world/world.py::World": "427 lines: the world's exact queries (free, segment, clearance, overlay) and their numpydoc",
    "companion/world/world.py::World.segment_free": "the exact segment test per obstacle kind with its bounds handling and numpydoc",
    "sim_vehicle/cli.py::run": "builds the whole vehicle (model, autopilot, server, traffic, clock) from the arguments",
    "heli_model/control/closed_loop.py::simulate_closed_loop": "the closed-loop prediction's argument checks, state set-up and loop with a long numpydoc",
    "heli_model/control_kernel.py::law_step": "one control period (outer PID, LQI, integrators, saturation) in one numba kernel, the Python step's operations in its order (bit-identical)",
    "heli_model/control/modal.py::run_modal": "the modal recursion with its rotation correction, one numerical routine",
    "heli_model/model.py::assemble_matrices": "the hover model's A and B written entry by entry, as the paper's equations (one statement an entry)",
    "heli_model/control/closed_loop_model.py::build_closed_loop": "the closed loop's matrices assembled block by block in one place, each block one statement",
    "companion/fleet/start_gate.py::StartGate._run": "the start gate's one loop over the vehicles' states (wait, release, time out), each step one statement",
    "heli_model/dynamics.py::step_rk4": "one RK4 step written out (four stages, yaw and position kinematics) for speed",
}
#: ``"path::qualname"`` -> why this class may be or use a mixin today.
MIXIN_EXCEPTIONS = {}
#: Package -> why an import cycle wholly inside it is tolerated today (an entry of a package with
#: no cycle left is a finding; of a package that does not exist, a note).
CYCLE_EXCEPTIONS = {}
#: Base classes that never make a class a mixin (stdlib and library bases, by their last name).
LIBRARY_BASES = frozenset(
    {
        "object",
        "Exception",
        "BaseException",
        "ValueError",
        "TypeError",
        "RuntimeError",
        "KeyError",
        "LookupError",
        "OSError",
        "Warning",
        "Enum",
        "IntEnum",
        "StrEnum",
        "Flag",
        "IntFlag",
        "NamedTuple",
        "TypedDict",
        "Protocol",
        "Generic",
        "ABC",
    }
)
#: Modules (prefixes) that must compute only: numbers in, numbers out. Old and new paths of the
#: restructuring are both listed while it is under way; only existing modules are checked.
NUMERICS = (
    "companion.planning",
    "companion.smoothing",
    "companion.world",
    "companion.threats.decision",
    "companion.flight",
    "companion.view.geometry",
    "heli_model",
    "sim_vehicle.rsc",
    "sim_vehicle.autopilot",
    "heli_common.geometry",
    "heli_common.frames",
)
#: Top-level modules that do I/O (network, processes, MAVLink transports, logs on disk).
IO_LIBRARIES = (
    "socket",
    "asyncio",
    "selectors",
    "subprocess",
    "zenoh",
    "mavsdk",
    "pymavlink",
    "http",
    "urllib",
    "mcap",
    "foxglove",
    "serial",
)
MISSION_ITEM_INT_FIELDS = (
    "seq",
    "frame",
    "command",
    "current",
    "autocontinue",
    "param1",
    "param2",
    "param3",
    "param4",
    "x",
    "y",
    "z",
)
EXECUTOR = "companion.flight.executor"
#: Modules that fly the executor: itself, and its fast-time driver.
EXECUTOR_MODULES = (EXECUTOR, "companion.flight.fast_time")
#: Benchmarks that fly threat encounters and must use the flight executor, not a copy of it.
EXECUTOR_USERS = ("benchmarks/threats.py",)
EMULATION_RE = re.compile("emulat", re.I)


def sources(root: Path = ROOT) -> list[Path]:
    """The Python files of the checked packages, sorted."""
    return sorted(p for pkg in PACKAGES for p in (root / pkg).rglob("*.py"))


def imports_package(tree: ast.AST, package: str) -> list[int]:
    """Line numbers of ``import package...`` / ``from package... import`` anywhere in ``tree``."""

    def named(name: str | None) -> bool:
        return bool(name) and (name == package or name.startswith(package + "."))

    lines = []
    for node in ast.walk(tree):
        if isinstance(node, ast.Import) and any(named(a.name) for a in node.names):
            lines.append(node.lineno)
        elif isinstance(node, ast.ImportFrom) and node.level == 0 and named(node.module):
            lines.append(node.lineno)
    return lines


def mission_item_records(tree: ast.AST) -> list[tuple[str, int]]:
    """Classes whose annotated fields include all of MISSION_ITEM_INT's."""
    found = []
    for node in ast.walk(tree):
        if isinstance(node, ast.ClassDef):
            fields = {s.target.id for s in node.body if isinstance(s, ast.AnnAssign) and isinstance(s.target, ast.Name)}
            if set(MISSION_ITEM_INT_FIELDS) <= fields:
                found.append((node.name, node.lineno))
    return found


def module_name(rel: str) -> str:
    """Dotted module name of the file at ``rel`` (``a/b/__init__.py`` -> ``a.b``)."""
    parts = rel.removesuffix(".py").split("/")
    return ".".join(parts[:-1] if parts[-1] == "__init__" else parts)


def imported_modules(tree: ast.AST, module: str, is_package: bool, modules: frozenset[str] = frozenset()) -> set[str]:
    """Absolute names of the modules ``tree`` imports, at any depth (``if TYPE_CHECKING:`` too).

    ``from a import b`` imports ``a.b`` when that is one of ``modules`` (a submodule), else ``a``.
    """
    found: set[str] = set()
    package = module if is_package else module.rpartition(".")[0]

    def visit(node: ast.AST) -> None:
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


def definitions(tree: ast.AST):
    """Every class and function of ``tree``: (qualname, node), outermost first."""

    def walk(node: ast.AST, prefix: str):
        for child in ast.iter_child_nodes(node):
            if isinstance(child, (ast.ClassDef, ast.FunctionDef, ast.AsyncFunctionDef)):
                qualname = prefix + child.name
                yield qualname, child
                yield from walk(child, qualname + ".")
            else:
                yield from walk(child, prefix)

    yield from walk(tree, "")


def statement_lines(node: ast.AST) -> int:
    """Lines of ``node`` (a class or function) on which a statement begins, its ``def`` or
    ``class`` line included and its docstring left out: the formatter's wrapping changes none."""
    body = list(getattr(node, "body", []))
    if (
        body
        and isinstance(body[0], ast.Expr)
        and isinstance(body[0].value, ast.Constant)
        and isinstance(body[0].value.value, str)
    ):
        body = body[1:]
    return 1 + len({n.lineno for b in body for n in ast.walk(b) if isinstance(n, ast.stmt)})


def size_findings(rel: str, tree: ast.AST) -> dict[str, str]:
    """``"rel::qualname"`` -> finding, for each class over MAX_CLASS_LINES statement lines or
    MAX_CLASS_METHODS methods and each function or method over MAX_FUNCTION_LINES statement
    lines (``statement_lines``)."""
    found = {}
    for qualname, node in definitions(tree):
        lines = statement_lines(node)
        where = f"{rel}:{node.lineno}: {qualname}"
        if isinstance(node, ast.ClassDef):
            methods = sum(isinstance(s, (ast.FunctionDef, ast.AsyncFunctionDef)) for s in node.body)
            if lines > MAX_CLASS_LINES or methods > MAX_CLASS_METHODS:
                found[f"{rel}::{qualname}"] = (
                    f"{where}: class of {lines} statement lines, {methods} methods "
                    f"(max {MAX_CLASS_LINES} lines, {MAX_CLASS_METHODS} methods)"
                )
        elif lines > MAX_FUNCTION_LINES:
            found[f"{rel}::{qualname}"] = f"{where}: function of {lines} statement lines (max {MAX_FUNCTION_LINES})"
    return found


def exception_findings(
    found: dict[str, str], exceptions: dict[str, str], root: Path, what: str
) -> tuple[list[str], list[str]]:
    """(findings, notes): what ``found`` holds outside ``exceptions``, plus each entry of
    ``exceptions`` whose file exists but which is no longer found; entries of files that do not
    exist are notes."""
    findings = [f for key, f in sorted(found.items()) if key not in exceptions]
    notes = []
    for key in sorted(set(exceptions) - set(found)):
        rel = key.partition("::")[0]
        if (root / rel).is_file():
            findings.append(f"{key}: listed in {what} but no longer exceeds: remove the entry")
        else:
            notes.append(f"{key}: listed in {what}; no such file (yet)")
    return findings, notes


def _base_name(node: ast.expr) -> str:
    """``a.b.C`` / ``C`` / ``C[T]`` -> ``C``."""
    if isinstance(node, ast.Subscript):
        node = node.value
    if isinstance(node, ast.Attribute):
        return node.attr
    return node.id if isinstance(node, ast.Name) else ""


def class_bases(trees: dict[str, tuple[str, ast.AST]]) -> dict[str, list[tuple[str, int, list[str]]]]:
    """Class name -> [(rel, line, base names)] for every class of the project (by name)."""
    classes: dict[str, list[tuple[str, int, list[str]]]] = {}
    for rel, tree in trees.values():
        for qualname, node in definitions(tree):
            if isinstance(node, ast.ClassDef):
                bases = [_base_name(b) for b in node.bases]
                classes.setdefault(node.name, []).append((f"{rel}::{qualname}", node.lineno, bases))
    return classes


def _is_exception(name: str, classes, seen: frozenset[str] = frozenset()) -> bool:
    """True when class ``name`` is an exception: so named, or deriving from one."""
    if name.endswith(("Error", "Exception", "Warning")) or name in ("Exception", "BaseException"):
        return True
    return (
        name in classes
        and name not in seen
        and any(_is_exception(b, classes, seen | {name}) for _, _, bases in classes[name] for b in bases)
    )


def _counts_as_project_base(name: str, classes) -> bool:
    """True when base ``name`` is a project class that is neither an exception nor a Protocol."""
    if name not in classes or name in LIBRARY_BASES:
        return False
    is_protocol = any("Protocol" in bases for _, _, bases in classes[name])
    return not is_protocol and not _is_exception(name, classes)


def mixin_findings(trees: dict[str, tuple[str, ast.AST]]) -> dict[str, str]:
    """``"rel::qualname"`` -> finding for each class named ``*Mixin`` and each class with two or
    more project-defined bases that are neither exceptions nor Protocols."""
    classes = class_bases(trees)
    found = {}
    for name, defs in classes.items():
        for key, line, bases in defs:
            rel, _, qualname = key.partition("::")
            if name.endswith("Mixin"):
                found[key] = f"{rel}:{line}: {qualname}: a mixin class (compose a collaborator instead)"
                continue
            project = [b for b in bases if _counts_as_project_base(b, classes)]
            if len(project) >= 2:
                found[key] = f"{rel}:{line}: {qualname}: {len(project)} project base classes ({', '.join(project)})"
    return found


def imports_executor(tree: ast.AST) -> bool:
    """True when ``tree`` imports ``companion.flight.executor`` or its fast-time driver
    ``companion.flight.fast_time`` (at any depth, in any form)."""
    for node in ast.walk(tree):
        if isinstance(node, ast.Import) and any(_is_executor(a.name) for a in node.names):
            return True
        if isinstance(node, ast.ImportFrom) and node.level == 0 and node.module:
            if _is_executor(node.module) or any(_is_executor(f"{node.module}.{a.name}") for a in node.names):
                return True
    return False


def _is_executor(module: str) -> bool:
    return any(module == m or module.startswith(m + ".") for m in EXECUTOR_MODULES)


def executor_findings(root: Path) -> tuple[list[str], list[str]]:
    """(findings, notes) of check 13: benchmarks and the campaign use the flight executor."""
    executor = root / (EXECUTOR.replace(".", "/") + ".py")
    if not executor.is_file():
        return [], [f"skipped: {executor.relative_to(root).as_posix()} does not exist yet"]
    findings = []
    campaign = sorted((root / "companion" / "campaign").rglob("*.py"))
    for path in sorted((root / "benchmarks").glob("*.py")) + campaign:
        rel = path.relative_to(root).as_posix()
        text = path.read_text(encoding="utf-8")
        for m in EMULATION_RE.finditer(text):
            line = text.count("\n", 0, m.start()) + 1
            findings.append(f"{rel}:{line}: says 'emulat...': fly with {EXECUTOR}, do not emulate it")
    for rel in EXECUTOR_USERS:
        path = root / rel
        if path.is_file() and not imports_executor(ast.parse(path.read_text(encoding="utf-8"))):
            findings.append(f"{rel}:1: does not import {EXECUTOR}")
    if campaign and not any(imports_executor(ast.parse(p.read_text(encoding="utf-8"))) for p in campaign):
        findings.append(f"companion/campaign/: no module imports {EXECUTOR}")
    return findings, []


def in_prefixes(module: str, prefixes: tuple[str, ...]) -> bool:
    """True when ``module`` is one of ``prefixes`` or inside one of them (``a.b`` is in ``a``)."""
    return any(module == p or module.startswith(p + ".") for p in prefixes)


class Result(NamedTuple):
    """One check's outcome; ``notes`` are printed but never fail it."""

    name: str
    passed: bool
    findings: list[str]
    notes: list[str]


def cycle_findings(cycles: list[list[str]], modules) -> tuple[list[str], list[str]]:
    """(findings, notes): the cycles not wholly inside a package of CYCLE_EXCEPTIONS, plus each
    entry of an existing package with no cycle left; entries of absent packages are notes."""
    findings, excused = [], set()
    for cycle in cycles:
        package = next((p for p in CYCLE_EXCEPTIONS if all(in_prefixes(m, (p,)) for m in cycle)), None)
        if package is None:
            findings.append(" <-> ".join(cycle))
        else:
            excused.add(package)
    notes = []
    for package in sorted(set(CYCLE_EXCEPTIONS) - excused):
        if package in modules:
            findings.append(f"{package}: listed in CYCLE_EXCEPTIONS but has no cycle: remove the entry")
        else:
            notes.append(f"{package}: listed in CYCLE_EXCEPTIONS; no such package (yet)")
    return findings, notes


def _line(text: str, m: re.Match) -> int:
    return text.count("\n", 0, m.start()) + 1


def text_facts(rel: str, text: str, facts: dict[str, list]) -> None:
    """Append what the regular expressions find in ``text`` to ``facts`` (checks 2-5, 7)."""
    for m in ARDUPILOT_NUMBER_RE.finditer(text):
        fact = "MOTOR_INTERLOCK" if "INTERLOCK" in m.group(1) else m.group(1)
        facts["ardupilot_numbers"].append((fact, f"{rel}:{_line(text, m)}: {m.group(1)}"))
    for rx in (MODE_DICT_RE, MODE_ASSIGN_RE):
        facts["mode_dicts"] += [f"{rel}:{_line(text, m)}: {m.group(0).strip()}" for m in rx.finditer(text)]
    facts["pip"] += [f"{rel}:{_line(text, m)}" for m in POINT_IN_POLYGON_RE.finditer(text)]
    facts["frames"] += [f"{rel}:{_line(text, m)}: class {m.group(1)}" for m in LOCAL_FRAME_CLASS_RE.finditer(text)]
    facts["mav_ints"] += [f"{rel}:{_line(text, m)}: {m.group(0).strip()}" for m in MAV_INT_RE.finditer(text)]


def check(root: Path = ROOT) -> list[Result]:
    """Run every check; returns one Result per check, in the module docstring's order."""
    facts: dict[str, list] = {k: [] for k in ("ardupilot_numbers", "mode_dicts", "pip", "frames", "mav_ints")}
    no_import, records, io_in_numerics, sim_imports, sim_notes = [], [], [], [], []
    sizes: dict[str, str] = {}
    trees: dict[str, tuple[ast.AST, bool]] = {}
    files: dict[str, tuple[str, ast.AST]] = {}
    heli_model_exists = (root / "heli_model" / "__init__.py").is_file()
    for path in sources(root):
        rel = path.relative_to(root).as_posix()
        text = path.read_text(encoding="utf-8")
        tree = ast.parse(text, filename=rel)
        module = module_name(rel)
        trees[module] = (tree, path.name == "__init__.py")
        files[module] = (rel, tree)
        sizes.update(size_findings(rel, tree))
        text_facts(rel, text, facts)
        records += [f"{rel}:{line}: class {name}" for name, line in mission_item_records(tree)]
        if in_prefixes(module, NUMERICS):
            tops = {m.split(".")[0] for m in imported_modules(tree, module, path.name == "__init__.py")}
            io_in_numerics += [f"{rel}: imports {lib}" for lib in sorted(tops & set(IO_LIBRARIES))]
        if rel.startswith(("sim_vehicle/", "heli_model/", "heli_common/")):
            no_import += [f"{rel}:{n}: imports companion" for n in imports_package(tree, "companion")]
        if rel.startswith(("companion/", "heli_model/", "heli_common/")):
            found = [f"{rel}:{n}: imports sim_vehicle" for n in imports_package(tree, "sim_vehicle")]
            pending = rel.startswith("companion/") and not heli_model_exists
            (sim_notes if pending else sim_imports).extend(found)
    cycles, cycle_notes = cycle_findings(import_cycles(import_graph(trees)), trees)
    too_big, size_notes = exception_findings(sizes, SIZE_EXCEPTIONS, root, "SIZE_EXCEPTIONS")
    mixins, mixin_notes = exception_findings(mixin_findings(files), MIXIN_EXCEPTIONS, root, "MIXIN_EXCEPTIONS")
    if sim_notes:
        sim_notes.insert(0, f"pending until heli_model/ exists: {len(sim_notes)} companion imports of sim_vehicle")
    emulating, executor_notes = executor_findings(root)
    mode_dicts, pip, frames, mav_ints = facts["mode_dicts"], facts["pip"], facts["frames"], facts["mav_ints"]
    ardupilot_numbers = facts["ardupilot_numbers"]
    return [
        Result("sim_vehicle, heli_model and heli_common never import companion", not no_import, no_import, []),
        Result("no hand-written ArduCopter mode numbers", not mode_dicts, mode_dicts, []),
        Result("def point_in_polygon defined once", len(pip) == 1, pip, []),
        Result("local-frame class defined once", len(frames) == 1, frames, []),
        Result("no hand-written MAV_CMD/MAV_FRAME/MAV_RESULT/MSG_ID integers", not mav_ints, mav_ints, []),
        Result("MISSION_ITEM_INT record defined once", len(records) == 1, records, []),
        Result(
            "ArduPilot numbers pymavlink lacks written once",
            len(ardupilot_numbers) == len({fact for fact, _ in ardupilot_numbers}),
            [where for _, where in ardupilot_numbers],
            [],
        ),
        Result(
            f"no class over {MAX_CLASS_LINES} statement lines or {MAX_CLASS_METHODS} methods, no function "
            f"over {MAX_FUNCTION_LINES} statement lines",
            not too_big,
            too_big,
            size_notes,
        ),
        Result("no import cycle", not cycles, cycles, cycle_notes),
        Result("numerics import no I/O library", not io_in_numerics, io_in_numerics, []),
        Result("no mixins", not mixins, mixins, mixin_notes),
        Result(
            "companion, heli_model and heli_common never import sim_vehicle", not sim_imports, sim_imports, sim_notes
        ),
        Result("benchmarks and campaign fly with the flight executor", not emulating, emulating, executor_notes),
    ]


def main() -> int:
    results = check()
    for name, ok, findings, notes in results:
        print(f"{'ok  ' if ok else 'FAIL'} {name}")
        for f in findings:
            print(f"       {f}")
        for note in notes:
            print(f"       note: {note}")
    failed = sum(not r.passed for r in results)
    print(f"{len(results) - failed}/{len(results)} checks passed")
    return 1 if failed else 0


if __name__ == "__main__":
    sys.exit(main())
