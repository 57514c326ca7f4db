"""Make the shared test helpers (``support``, ``flight_support``) importable from every test;
choose the hypothesis profile; compile the planners' numba kernels once before any test."""

import os
import sys
from pathlib import Path

from hypothesis import settings

sys.path.insert(0, str(Path(__file__).resolve().parent))

# `make test` (and CI) replays the same examples every run, so a result never depends on the
# day's luck; HYPOTHESIS_PROFILE=explore draws new ones (see docs/DEVELOPING.md).
settings.register_profile("repeatable", derandomize=True)
settings.register_profile("explore", derandomize=False)
settings.load_profile(os.environ.get("HYPOTHESIS_PROFILE", "repeatable"))


def pytest_sessionstart(session):
    """The planners' numba kernels, compiled (about 20 s of CPU on a fresh clone) or loaded from
    numba's cache (under a second) before any test: the companions the integration tests start
    then load them from the cache instead of each compiling them under a test's timeout."""
    from companion.workers import warm_up

    warm_up()
