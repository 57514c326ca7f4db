"""Run a module with its asyncio loop's CPU accounted per callback (``companion_cpu.py --account``).

``python benchmarks/loop_account.py OUT.json MODULE [ARGS...]`` runs ``python -m MODULE ARGS``
with every loop callback (``asyncio.Handle._run``: a task's step is named after its coroutine)
and every wait of the selector timed in the event-loop thread's own CPU time
(``time.thread_time_ns``: CLOCK_THREAD_CPUTIME_ID, so waiting and other threads do not count).
SIGUSR1 starts the accounting (the steady state begins), SIGUSR2 writes ``OUT.json``:
``{"wall_s", "loop_thread_cpu_s", "by": {name: [percent of a core, calls per second]}}``.
cProfile inflates small calls many times; this adds two clock reads per callback.
"""

from __future__ import annotations

import asyncio
import collections
import json
import runpy
import selectors
import signal
import sys
import time

_cpu_ns: collections.Counter = collections.Counter()
_calls: collections.Counter = collections.Counter()
_started: list = []  # [(monotonic s, thread CPU ns)] once SIGUSR1 came


def callback_name(handle: asyncio.Handle) -> str:
    """``task:<coroutine>`` for a task's step, else ``cb:<callable>``."""
    callback = handle._callback
    owner = getattr(callback, "__self__", None)
    if isinstance(owner, asyncio.Task):
        return "task:" + getattr(owner.get_coro(), "__qualname__", "?")
    return "cb:" + (getattr(callback, "__qualname__", None) or type(callback).__name__)


def _timed(function, name_of):
    def timed(*args, **kwargs):
        start = time.thread_time_ns()
        try:
            return function(*args, **kwargs)
        finally:
            if _started:
                name = name_of(args)
                _cpu_ns[name] += time.thread_time_ns() - start
                _calls[name] += 1

    return timed


def install(out_path: str) -> None:
    """Time the loop's callbacks and selector waits; SIGUSR1 / SIGUSR2 start / write."""
    asyncio.events.Handle._run = _timed(asyncio.events.Handle._run, lambda args: callback_name(args[0]))
    for selector in (selectors.EpollSelector, selectors.SelectSelector):
        selector.select = _timed(selector.select, lambda args: "selector wait")

    def start(*_):
        _cpu_ns.clear()
        _calls.clear()
        _started[:] = [(time.monotonic(), time.thread_time_ns())]

    def write(*_):
        if not _started:
            return
        wall_s = time.monotonic() - _started[0][0]
        by = {
            name: [round(ns / 1e9 / wall_s * 100, 3), round(_calls[name] / wall_s, 1)]
            for name, ns in _cpu_ns.most_common()
        }
        with open(out_path, "w", encoding="utf-8") as fh:
            json.dump(
                {"wall_s": wall_s, "loop_thread_cpu_s": (time.thread_time_ns() - _started[0][1]) / 1e9, "by": by},
                fh,
                indent=1,
            )

    signal.signal(signal.SIGUSR1, start)
    signal.signal(signal.SIGUSR2, write)


if __name__ == "__main__":
    install(sys.argv[1])
    sys.argv = sys.argv[2:]
    runpy.run_module(sys.argv[0], run_name="__main__", alter_sys=True)
