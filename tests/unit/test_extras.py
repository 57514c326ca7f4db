"""A slim install (issue 25, item 5): flying imports no optional package, and a command that
needs a missing one exits 2 with one line naming its extra.

Each case runs in a fresh process whose ``sys.modules[name] = None`` makes the package look
absent (an import of it raises ``ModuleNotFoundError``), as on a companion computer without the
extra.
"""

from __future__ import annotations

import ast
import os
import subprocess
import sys
import tomllib
from pathlib import Path

import pytest

from companion.extras import DISTRIBUTION, EXTRA_PACKAGES, MissingExtra, require

ROOT = Path(__file__).resolve().parents[2]
OPTIONAL = ("matplotlib", "foxglove", "mcap", "cryptography", "dask", "distributed", "pyarrow", "rich")

WITHOUT = """
import sys
for name in sys.argv[1].split(","):
    sys.modules[name] = None
from companion.cli import main
sys.exit(main(sys.argv[2:]))
"""


def companion_without(modules: str, *argv: str) -> subprocess.CompletedProcess:
    env = dict(os.environ, PYTHONPATH=str(ROOT))
    return subprocess.run(
        [sys.executable, "-c", WITHOUT, modules, *argv],
        check=False,
        capture_output=True,
        text=True,
        env=env,
        cwd=ROOT,
        timeout=120,
    )


WORLD = str(ROOT / "mission_files" / "worlds" / "paper_2d.toml")
CASES = [
    ("matplotlib", "report", ["report", "out/none.jsonl", "--out", "{tmp}/report"]),
    ("matplotlib", "report", ["plan", "--world", WORLD, "--plot", "{tmp}/plan.png"]),
    ("mcap", "view", ["report", "{tmp}/flight.mcap", "--out", "{tmp}/report"]),
    ("foxglove", "view", ["run", "--record", "{tmp}/flight.mcap", "--no-zenoh", "--connect", "udpin://127.0.0.1:9"]),
    ("cryptography", "keys", ["keys", "init", "{tmp}/keys"]),
    ("pyarrow", "campaign", ["campaign", "status", "{tmp}/campaign"]),
    ("distributed", "campaign", ["campaign", "run", "mission_files/campaigns/none.toml", "--out", "{tmp}/c"]),
    ("rich", "report", ["demo", "--out", "{tmp}/demo"]),
    ("foxglove", "view", ["demo", "--out", "{tmp}/demo"]),
]


@pytest.mark.parametrize("module, extra, argv", CASES, ids=[f"{c[2][0]}-without-{c[0]}" for c in CASES])
def test_a_command_without_its_extra_exits_2_naming_it(tmp_path, module, extra, argv):
    out = companion_without(module, *[a.format(tmp=tmp_path) for a in argv])
    command = argv[0]
    line = f"companion {command}: needs the '{extra}' extra: pip install '{DISTRIBUTION}[{extra}]'"
    assert out.returncode == 2, out.stderr
    assert out.stderr.strip().splitlines()[-1] == line and "Traceback" not in out.stderr, out.stderr
    assert not (tmp_path / "keys").exists()  # refused before anything was written


def test_plan_flies_without_any_extra(tmp_path):
    """``companion plan`` (no plot) plans and smooths with every optional package absent."""
    out = companion_without(
        ",".join(OPTIONAL), "plan", "--world", WORLD, "--budget", "0.5", "--json", str(tmp_path / "plan.json")
    )
    assert out.returncode == 0, out.stderr
    assert (tmp_path / "plan.json").is_file()


IMPORTS = """
import sys
from companion.cli import build_parser
build_parser()
import companion.daemon, companion.service.serve, companion.workers, companion.threats.decision.step
import sim_vehicle.cli
from companion.kernels import ensure_compiled
ensure_compiled()
print(" ".join(sorted({m.split(".")[0] for m in sys.modules} & set(sys.argv[1:]))))
"""


def test_flying_imports_no_optional_package():
    """What ``companion run`` / ``serve`` and their planning workers load (the CLI, the daemon,
    the service, the decision step, every kernel) and ``sim-vehicle``: no optional package."""
    env = dict(os.environ, PYTHONPATH=str(ROOT))
    out = subprocess.run(
        [sys.executable, "-c", IMPORTS, *OPTIONAL, "control"],
        capture_output=True,
        text=True,
        env=env,
        cwd=ROOT,
        timeout=180,
        check=True,
    )
    assert out.stdout.split() == []


def _required_pairs() -> set[tuple[str, str]]:
    """Every ``require("extra", "module")`` call in the packages."""
    pairs = set()
    for path in (ROOT / "companion").rglob("*.py"):
        for node in ast.walk(ast.parse(path.read_text())):
            if (
                isinstance(node, ast.Call)
                and getattr(node.func, "id", None) == "require"
                and len(node.args) == 2
                and all(isinstance(a, ast.Constant) for a in node.args)
            ):
                pairs.add((node.args[0].value, node.args[1].value))
    return pairs


def test_every_extra_named_installs_the_package_asked_for():
    extras = tomllib.loads((ROOT / "pyproject.toml").read_text())["project"]["optional-dependencies"]
    pairs = _required_pairs()
    assert {extra for extra, _ in pairs} == {"view", "report", "keys", "campaign"}
    for extra, module in pairs:
        distribution = EXTRA_PACKAGES[module.split(".")[0]]
        assert any(req.split(">")[0].split("=")[0].split("<")[0].strip() == distribution for req in extras[extra]), (
            extra,
            module,
        )


def test_the_slim_dependencies_have_no_optional_package():
    deps = tomllib.loads((ROOT / "pyproject.toml").read_text())["project"]["dependencies"]
    names = {d.split(">")[0].split("=")[0].split("<")[0].strip() for d in deps}
    assert names.isdisjoint(set(EXTRA_PACKAGES.values()) | {"control", "pytest", "hypothesis", "ompl"})


def test_require_returns_the_module_or_names_the_extra():
    assert require("report", "json").dumps([1]) == "[1]"
    with pytest.raises(MissingExtra, match=r"needs the 'view' extra: pip install 'heli-companion\[view\]'"):
        require("view", "no_such_package_at_all")
