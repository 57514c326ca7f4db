"""What ``/proc`` says about a process: its start time (which tells it from a later process with
the same pid), its state, its descendants. Linux only: elsewhere every answer is "gone" / none."""

from __future__ import annotations

import os

__all__ = ["GONE_STATES", "descendants", "process_state", "start_time"]

#: Process states of a process that no longer runs (zombie, dead; None: no such process).
GONE_STATES = ("Z", "X", None)


def start_time(pid: int) -> int | None:
    """The process's start time in clock ticks since boot (identifies it beyond pid reuse);
    None when it is gone."""
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
