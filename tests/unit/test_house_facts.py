"""tools/check_facts.py: each shared fact (modes, MAV_CMDs, polygon test, local frame, mission
item record) is defined once, sim_vehicle never imports companion (issue 12), and the structure
of docs/DESIGN.md holds (sizes, no mixins, no cycles, the dependency direction, the executor)."""

import subprocess
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]
sys.path.insert(0, str(ROOT / "tools"))
try:
    import check_facts
finally:
    sys.path.pop(0)


def _results(root):
    return {r.name: r for r in check_facts.check(root)}


def _write(root: Path, files: dict[str, str]) -> None:
    for rel, text in files.items():
        path = root / rel
        path.parent.mkdir(parents=True, exist_ok=True)
        path.write_text(text)


SIZE = "no class over 280 statement lines or 30 methods, no function over 45 statement lines"
CYCLE = "no import cycle"
MIXINS = "no mixins"
NO_SIM = "companion, heli_model and heli_common never import sim_vehicle"
EXECUTOR = "benchmarks and campaign fly with the flight executor"


def test_check_facts_passes():
    out = subprocess.run(
        [sys.executable, str(ROOT / "tools" / "check_facts.py")], capture_output=True, text=True, timeout=60
    )
    assert out.returncode == 0, out.stdout + out.stderr


def test_check_facts_finds_duplicates(tmp_path):
    """The checks fail on a tree with the old duplicates."""
    (tmp_path / "sim_vehicle").mkdir()
    (tmp_path / "companion").mkdir()
    (tmp_path / "sim_vehicle" / "autopilot.py").write_text(
        "from companion.geo import LocalFrame\nGUIDED = 4\nCMD_NAV_TAKEOFF = 22\n"
        "def point_in_polygon(p, q):\n    return False\n"
    )
    (tmp_path / "companion" / "vehicle.py").write_text(
        'COPTER_MODES = {"GUIDED": 4}\nMAV_CMD_NAV_LAND = 21\nMAV_FRAME_LOCAL_NED = 1\n'
        "def point_in_polygon(p, q):\n    return False\nclass LocalFrame:\n    pass\n"
    )
    results = {r.name: r.passed for r in check_facts.check(tmp_path)}
    assert not results["sim_vehicle, heli_model and heli_common never import companion"]
    assert not results["no hand-written ArduCopter mode numbers"]
    assert not results["def point_in_polygon defined once"]
    assert not results["no hand-written MAV_CMD/MAV_FRAME/MAV_RESULT/MSG_ID integers"]
    assert results["local-frame class defined once"]  # one LocalFrame in that tree


def test_check_facts_finds_cycles_and_io_in_numerics(tmp_path):
    """The structural checks fail on a tree with an import cycle, I/O in the numerics and an
    ArduPilot number written twice; and pass once those are gone."""
    planning = tmp_path / "companion" / "planning"
    planning.mkdir(parents=True)
    (tmp_path / "sim_vehicle").mkdir()
    (tmp_path / "companion" / "__init__.py").write_text("")
    (planning / "__init__.py").write_text("from companion.planning import gart\n")
    (planning / "gart.py").write_text("import socket\nfrom . import tree\nFORCE_DISARM_MAGIC = 21196\n")
    (planning / "tree.py").write_text("from companion.planning.gart import socket\n")
    (tmp_path / "sim_vehicle" / "rsc.py").write_text("FORCE_DISARM_MAGIC = 21196\n")
    results = {r.name: (r.passed, r.findings) for r in check_facts.check(tmp_path)}
    assert results["no import cycle"] == (False, ["companion.planning.gart <-> companion.planning.tree"])
    assert results["numerics import no I/O library"] == (False, ["companion/planning/gart.py: imports socket"])
    assert not results["ArduPilot numbers pymavlink lacks written once"][0]
    (planning / "tree.py").write_text("x = 1\n")
    (planning / "gart.py").write_text("import math\nfrom . import tree\n")
    results = {r.name: r.passed for r in check_facts.check(tmp_path)}
    assert results["no import cycle"]  # a package re-exporting its submodule is no cycle
    assert results["numerics import no I/O library"]
    assert results["ArduPilot numbers pymavlink lacks written once"]


def test_real_tree_passes():
    """The real tree passes every check in process (with today's exception lists). The tool's
    run time (about 1.5 s) is not asserted: timing goals are never wall-clock limits in tests."""
    assert [r.name for r in check_facts.check(ROOT) if not r.passed] == []


def test_sizes_find_long_classes_functions_and_stale_exceptions(tmp_path, monkeypatch):
    """A function of 46 statement lines, a class of 31 methods and one of 281 statement lines fail,
    naming file:line, qualname and measure; an exception entry excuses one; a stale entry is a
    finding. Statement lines, not physical ones: a call wrapped over many lines is one line, a
    docstring none."""
    many = "".join(f"    def m{i}(self):\n        return {i}\n" for i in range(31))
    wrapped = "    y = f(\n" + "        1,\n" * 30 + "    )\n"
    _write(
        tmp_path,
        {
            "companion/long.py": "def fly():\n" + "    x = 1\n" * 45,
            "companion/wide.py": "class Wide:\n" + many,
            "sim_vehicle/tall.py": "class Tall:\n    def f(self):\n        return 1\n" + "    x = 1\n" * 278,
            "heli_common/ok.py": 'def short():\n    """' + "doc\n" * 30 + '"""\n' + "    x = 1\n" * 43 + wrapped,
        },
    )
    monkeypatch.setattr(check_facts, "SIZE_EXCEPTIONS", {})
    result = _results(tmp_path)[SIZE]
    assert not result.passed
    assert "companion/long.py:1: fly: function of 46 statement lines (max 45)" in result.findings
    assert (
        "companion/wide.py:1: Wide: class of 63 statement lines, 31 methods (max 280 lines, 30 methods)"
        in result.findings
    )
    assert any(f.startswith("sim_vehicle/tall.py:1: Tall: class of 281 statement lines") for f in result.findings)
    assert len(result.findings) == 3  # the function of 45 statement lines is fine
    monkeypatch.setattr(
        check_facts,
        "SIZE_EXCEPTIONS",
        {
            "companion/long.py::fly": "why",
            "companion/wide.py::Wide": "why",
            "sim_vehicle/tall.py::Tall": "why",
            "heli_common/ok.py::short": "stale",
            "heli_model/moved.py::f": "not there yet",
        },
    )
    result = _results(tmp_path)[SIZE]
    assert result.findings == [
        "heli_common/ok.py::short: listed in SIZE_EXCEPTIONS but no longer exceeds: remove the entry"
    ]
    assert result.notes == ["heli_model/moved.py::f: listed in SIZE_EXCEPTIONS; no such file (yet)"]


def test_size_exceptions_are_explained():
    """Each exception names a file and a qualname, and says why in one line."""
    for table in (check_facts.SIZE_EXCEPTIONS, check_facts.MIXIN_EXCEPTIONS):
        for key, why in table.items():
            path, sep, qualname = key.partition("::")
            assert sep and path.endswith(".py") and qualname, key
            assert why.strip() and "\n" not in why, key


def test_mixins_are_found(tmp_path, monkeypatch):
    """A ``*Mixin`` class and a class with two project bases fail; project errors combined with
    library errors, Protocols and library bases do not."""
    monkeypatch.setattr(check_facts, "MIXIN_EXCEPTIONS", {})
    _write(
        tmp_path,
        {
            "companion/errors.py": "class CompanionError(Exception):\n    pass\n"
            "class ThreatError(CompanionError):\n    pass\n",
            "companion/parts.py": "class Watchers:\n    pass\nclass Commands:\n    pass\n"
            "class LoggingMixin:\n    pass\n",
            "companion/link.py": "from companion.parts import Watchers, Commands\n"
            "class Link(Watchers, Commands):\n    pass\n",
            "companion/fine.py": "import enum\nfrom typing import NamedTuple, Protocol\n"
            "from companion.errors import CompanionError, ThreatError\n"
            "from companion.parts import Watchers\n"
            "class Clock(Protocol):\n    def now(self): ...\n"
            "class Sink(Protocol):\n    def put(self, x): ...\n"
            "class Both(Clock, Sink):\n    pass\n"
            "class BadValue(CompanionError, ValueError):\n    pass\n"
            "class Twice(ThreatError, CompanionError):\n    pass\n"
            "class Mode(enum.Enum):\n    A = 1\n"
            "class Row(NamedTuple):\n    a: int\n"
            "class One(Watchers, enum.Enum):\n    pass\n",
        },
    )
    result = _results(tmp_path)[MIXINS]
    assert not result.passed
    assert sorted(result.findings) == [
        "companion/link.py:2: Link: 2 project base classes (Watchers, Commands)",
        "companion/parts.py:5: LoggingMixin: a mixin class (compose a collaborator instead)",
    ]
    monkeypatch.setattr(
        check_facts, "MIXIN_EXCEPTIONS", {"companion/link.py::Link": "why", "companion/parts.py::LoggingMixin": "why"}
    )
    assert _results(tmp_path)[MIXINS].passed


def test_type_checking_imports_make_cycles(tmp_path, monkeypatch):
    """An import under ``if TYPE_CHECKING:`` closes a cycle; CYCLE_EXCEPTIONS excuses a package."""
    _write(
        tmp_path,
        {
            "sim_vehicle/__init__.py": "",
            "sim_vehicle/core.py": "from sim_vehicle.mode import Mode\n",
            "sim_vehicle/mode.py": "from typing import TYPE_CHECKING\nif TYPE_CHECKING:\n"
            "    from sim_vehicle.core import Core\n",
        },
    )
    monkeypatch.setattr(check_facts, "CYCLE_EXCEPTIONS", {})
    result = _results(tmp_path)[CYCLE]
    assert (result.passed, result.findings) == (False, ["sim_vehicle.core <-> sim_vehicle.mode"])
    monkeypatch.setattr(check_facts, "CYCLE_EXCEPTIONS", {"sim_vehicle": "why"})
    assert _results(tmp_path)[CYCLE].passed
    (tmp_path / "sim_vehicle" / "mode.py").write_text("x = 1\n")
    result = _results(tmp_path)[CYCLE]  # a stale entry is a finding
    assert not result.passed and "sim_vehicle: listed in CYCLE_EXCEPTIONS" in result.findings[0]


def test_companion_never_imports_sim_vehicle(tmp_path):
    """Any import of sim_vehicle from companion fails once heli_model/ exists (a note before);
    heli_model and heli_common never may."""
    _write(
        tmp_path,
        {
            "companion/smoothing/feasibility.py": "def check():\n    from sim_vehicle.model import HeliModel\n"
            "    return HeliModel\n",
            "companion/config.py": "import sim_vehicle.typed_config as tc\n",
        },
    )
    result = _results(tmp_path)[NO_SIM]
    assert result.passed and result.findings == [] and len(result.notes) == 3
    _write(tmp_path, {"heli_model/__init__.py": "", "heli_common/typed_config.py": "from sim_vehicle import x\n"})
    result = _results(tmp_path)[NO_SIM]
    assert not result.passed
    assert sorted(result.findings) == [
        "companion/config.py:1: imports sim_vehicle",
        "companion/smoothing/feasibility.py:2: imports sim_vehicle",
        "heli_common/typed_config.py:1: imports sim_vehicle",
    ]


def test_benchmarks_fly_with_the_executor(tmp_path):
    """Skipped with a note until companion/flight/executor.py exists; then an emulating benchmark
    and a threats.py without the executor import fail, and the import makes it pass."""
    _write(
        tmp_path,
        {"benchmarks/threats.py": '"""Fly encounters; the daemon is emulated."""\n', "companion/__init__.py": ""},
    )
    result = _results(tmp_path)[EXECUTOR]
    assert result.passed and result.findings == [] and "does not exist yet" in result.notes[0]
    _write(tmp_path, {"companion/flight/executor.py": "def run():\n    pass\n"})
    result = _results(tmp_path)[EXECUTOR]
    assert not result.passed
    assert result.findings == [
        "benchmarks/threats.py:1: says 'emulat...': fly with companion.flight.executor, do not emulate it",
        "benchmarks/threats.py:1: does not import companion.flight.executor",
    ]
    _write(
        tmp_path,
        {
            "benchmarks/threats.py": '"""Fly encounters with the executor."""\nfrom companion.flight import executor\n',
            "companion/campaign/run.py": "def fly():\n    pass\n",
        },
    )
    result = _results(tmp_path)[EXECUTOR]
    assert result.findings == ["companion/campaign/: no module imports companion.flight.executor"]
    _write(tmp_path, {"companion/campaign/run.py": "def fly():\n    from companion.flight.executor import run\n"})
    assert _results(tmp_path)[EXECUTOR].passed


def test_numerics_cover_the_new_layout(tmp_path):
    """heli_model (all of it) and the flight core (executor included: it runs in fast time with no
    I/O) and the decision are numerics; the daemon's service and link are not."""
    for module in (
        "heli_model.control.lqi",
        "heli_model",
        "companion.flight.pipeline",
        "companion.flight.executor",
        "companion.flight.phases",
        "companion.flight.trajectory",
        "companion.threats.decision.step",
    ):
        assert check_facts.in_prefixes(module, check_facts.NUMERICS), module
    assert not check_facts.in_prefixes("companion.service.jobs", check_facts.NUMERICS)
    assert not check_facts.in_prefixes("companion.link.periodic", check_facts.NUMERICS)
    assert not check_facts.in_prefixes("heli_modelx", check_facts.NUMERICS)
    _write(tmp_path, {"heli_model/control/lqi.py": "import asyncio\n"})
    result = _results(tmp_path)["numerics import no I/O library"]
    assert result.findings == ["heli_model/control/lqi.py: imports asyncio"]
