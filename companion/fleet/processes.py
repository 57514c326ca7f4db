"""The fleet's child processes: starting them in their own process groups (ended with the
launcher), finding their descendants, and stopping them."""

from __future__ import annotations

import ctypes
import logging
import os
import signal
import subprocess
import sys
from pathlib import Path

__all__ = ["spawn", "start_time", "process_state", "descendants", "send_signal", "wait_or_kill"]

log = logging.getLogger(__name__)

PR_SET_PDEATHSIG = 1


def spawn(module_args: list[str], log_path: Path, env: dict | None = None) -> subprocess.Popen:
    """``python -m <module_args>`` of this interpreter, its output to ``log_path``, in its own
    process group, getting SIGTERM if the launcher dies."""
    with open(log_path, "wb") as fh:
        return subprocess.Popen([sys.executable, "-m", *module_args], stdout=fh, stderr=subprocess.STDOUT,
                                stdin=subprocess.DEVNULL, env=env, preexec_fn=_die_with_parent)


def _die_with_parent() -> None:        # preexec_fn: runs in the child before exec
    os.setpgid(0, 0)
    try:
        ctypes.CDLL(None, use_errno=True).prctl(PR_SET_PDEATHSIG, signal.SIGTERM)
    except (OSError, AttributeError):   # not Linux: the launcher's stop() still ends them
        pass


def start_time(pid: int) -> int | None:
    """The process's start time in clock ticks since boot (identifies it beyond pid reuse)."""
    try:
        with open(f"/proc/{pid}/stat", encoding="ascii", errors="replace") as fh:
            return int(fh.read().rsplit(")", 1)[1].split()[19])
    except (OSError, ValueError, IndexError):
        return None


def process_state(pid: int) -> str | None:
    """The process's state letter (``R``, ``S``, ``Z`` ...), None when it is gone."""
    try:
        with open(f"/proc/{pid}/stat", encoding="ascii", errors="replace") as fh:
            return fh.read().rsplit(")", 1)[1].split()[0]
    except (OSError, IndexError):
        return None


def descendants(pid: int) -> list[int]:
    """Every descendant process of ``pid`` (``/proc/<pid>/task/*/children``; empty off Linux)."""
    out, todo = [], [pid]
    while todo:
        parent = todo.pop()
        try:
            tasks = os.listdir(f"/proc/{parent}/task")
        except OSError:
            continue
        for tid in tasks:
            try:
                with open(f"/proc/{parent}/task/{tid}/children", encoding="ascii") as fh:
                    kids = [int(v) for v in fh.read().split()]
            except OSError:
                continue
            out += kids
            todo += kids
    return out


def send_signal(proc: subprocess.Popen, sig: int) -> None:
    """``proc.send_signal(sig)``, ignoring a process already gone."""
    try:
        proc.send_signal(sig)
    except OSError:
        pass


def wait_or_kill(proc: subprocess.Popen, timeout_s: float) -> None:
    """Wait for ``proc`` up to ``timeout_s`` wall s, then SIGKILL it."""
    try:
        proc.wait(timeout_s)
    except subprocess.TimeoutExpired:
        log.warning("pid %d did not stop within %.0f s: SIGKILL", proc.pid, timeout_s)
        proc.kill()
        proc.wait()
