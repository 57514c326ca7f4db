"""Make the shared test helpers (``support``, ``flight_support``) importable from every test;
choose the hypothesis profile."""

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
