"""A companion killed with SIGKILL leaves no planning worker (nor forkserver) behind
(``companion.workers.exit_with_parent``)."""

from __future__ import annotations

import os
import signal
import subprocess
import sys
import time

import pytest
from support import REPO_ROOT

STARTS_WORKERS = """
import asyncio
from companion.workers import PlanningWorkers

async def main():
    workers = PlanningWorkers("process")
    await workers.start()
    print(" ".join(str(pid) for pid in workers.executor._processes), flush=True)
    await asyncio.sleep(120)

if __name__ == "__main__":
    asyncio.run(main())
"""


def parent_of(pid: int) -> int:
    with open(f"/proc/{pid}/stat") as fh:
        return int(fh.read().rsplit(")", 1)[1].split()[1])


def running(pid: int) -> bool:
    try:
        with open(f"/proc/{pid}/stat") as fh:
            return fh.read().rsplit(")", 1)[1].split()[0] != "Z"
    except FileNotFoundError:
        return False


@pytest.mark.skipif(not sys.platform.startswith("linux"), reason="reads /proc")
def test_the_workers_end_when_the_companion_is_killed():
    env = dict(os.environ, PYTHONPATH=str(REPO_ROOT))
    proc = subprocess.Popen([sys.executable, "-c", STARTS_WORKERS], stdout=subprocess.PIPE, text=True, env=env)
    try:
        pids = [int(pid) for pid in proc.stdout.readline().split()]
        assert len(pids) == 2 and all(map(running, pids))
        pids.append(parent_of(pids[0]))  # the forkserver
    finally:
        proc.send_signal(signal.SIGKILL)
        proc.wait()
    deadline = time.monotonic() + 10.0
    while any(map(running, pids)) and time.monotonic() < deadline:
        time.sleep(0.05)
    assert not any(map(running, pids)), f"planning workers and forkserver {pids} outlived their companion"
