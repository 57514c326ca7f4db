"""No first-call failure (issue 25, item 4): the kernels are compiled before any budget's clock.

The cold-cache test runs in a fresh process with numba's cache in an empty directory, so it
compiles for real (about 20 s on the 2-core reference machine) without touching the
suite's cache.
"""

from __future__ import annotations

import logging
import os
import subprocess
import sys
from pathlib import Path

import numpy as np
from numba.core.registry import CPUDispatcher

from companion.kernels import ensure_compiled
from companion.numba_cache import cache_is_cold, compile_once
from companion.planning import CostWeights, GartSettings, MgartSettings, gart, mgart
from companion.world import Box, Cylinder, Disc, Prism, Sphere, World, read_world_file

ROOT = Path(__file__).resolve().parents[2]

FIRST_CALL = """
import logging, sys
import numpy as np
logging.basicConfig(level=logging.INFO, stream=sys.stderr, format="%(message)s")
from companion.planning import gart
from companion.world import Disc, World
world = World([Disc((5.0, 5.0), 2.0)], np.zeros(2), np.full(2, 10.0))
r = gart(world, np.full(2, 1.0), np.full(2, 9.0), rng=np.random.default_rng(0), max_time_s=0.5,
         stop_at_first=True)
print(r.status, r.elapsed_s, 0 if r.path is None else len(r.path))
"""


def first_call(cache_dir: Path) -> tuple[list[str], str]:
    """The first GART of a fresh process whose numba cache is ``cache_dir``: (its printed
    status, elapsed, path length) and its log."""
    env = dict(os.environ, NUMBA_CACHE_DIR=str(cache_dir), PYTHONPATH=str(ROOT))
    out = subprocess.run(
        [sys.executable, "-c", FIRST_CALL], capture_output=True, text=True, env=env, cwd=ROOT, timeout=240, check=True
    )
    return out.stdout.split(), out.stderr


def test_the_first_gart_on_a_cold_cache_finds_its_path_within_budget(tmp_path):
    words, log = first_call(tmp_path)
    status, elapsed_s, points = words[0], float(words[1]), int(words[2])
    assert status == "exact" and points >= 2, log
    assert elapsed_s <= 0.5  # the compile was not in the budget
    assert "compiling the planners (once, about" in log
    words, log = first_call(tmp_path)  # the cache is warm now: loaded, not announced
    assert words[0] == "exact" and "compiling the planners" not in log


def signatures() -> set[tuple[str, str, str]]:
    """Every specialisation of the project's numba kernels loaded in this process."""
    found = set()
    for name, module in list(sys.modules.items()):
        if name.split(".")[0] not in ("companion", "heli_model", "heli_common"):
            continue
        for value in list(vars(module).values()):
            if isinstance(value, CPUDispatcher):
                found.update((value.py_func.__module__, value.py_func.__qualname__, str(s)) for s in value.signatures)
    return found


def worlds() -> list[World]:
    lo2, hi2, lo3, hi3 = np.zeros(2), np.full(2, 10.0), np.zeros(3), np.full(3, 10.0)
    square = [(3.0, 3.0), (6.0, 3.0), (6.0, 6.0), (3.0, 6.0)]
    many = [Disc((0.5 * (i % 20), 2.0 + 0.5 * (i // 20)), 0.05) for i in range(300)]
    return [
        World([Disc((5.0, 5.0), 1.5)], lo2, hi2),
        World([Box((3.0, 3.0), (6.0, 6.0))], lo2, hi2),
        World([Cylinder((5.0, 5.0), 1.5, 0.0, 10.0)], lo3, hi3),
        World([Prism(square)], lo2, hi2),
        World([Sphere((5.0, 5.0, 5.0), 1.5)], lo3, hi3),
        World(many, lo2, hi2),
    ]


def test_after_ensure_compiled_no_public_call_compiles():
    """Worlds of every kind, the shipped ones, the paper's cost terms: nothing left to compile."""
    ensure_compiled()
    before = signatures()
    rng = np.random.default_rng(1)
    cases = [(w, np.full(w.dim, 0.5), np.full(w.dim, 9.5)) for w in worlds()]
    for name in ("paper_2d.toml", "city_3d.toml"):
        wf = read_world_file(ROOT / "mission_files" / "worlds" / name)
        cases.append((wf.world, wf.start, wf.goal))
    costs = (CostWeights(), CostWeights(threat=1.0), CostWeights(tracking_m_per_rad=1.0))
    for world, start, goal in cases:
        for cost in costs:
            gs = GartSettings(cost=cost)
            gart(world, start, goal, rng=rng, max_iterations=300, settings=gs)
            mgart(world, start, goal, 3, rng=rng, max_iterations=300, settings=MgartSettings(gart=gs))
    assert signatures() - before == set()


class _Probe:
    """A stand-in for a numba dispatcher whose cache index is ``index``."""

    def __init__(self, index: dict) -> None:
        cache_file = type("CacheFile", (), {"_load_index": lambda self: index})()
        self._cache = type("Cache", (), {"_cache_file": cache_file})()


def test_a_cold_cache_is_announced_once_and_a_warm_one_is_not(caplog):
    calls = []
    with caplog.at_level(logging.INFO, logger="companion.numba_cache"):
        compile_once("the things", lambda: calls.append(1), [_Probe({}), _Probe({"sig": 1})], 12.0)
        compile_once("the things", lambda: calls.append(2), [_Probe({"sig": 1})], 12.0)
    announced = [r.getMessage() for r in caplog.records if r.getMessage().startswith("compiling")]
    assert calls == [1, 2] and announced == ["compiling the things (once, about 12 s)"]


def test_a_dispatcher_without_a_cache_is_not_cold():
    assert not cache_is_cold([object()]) and not cache_is_cold([])
