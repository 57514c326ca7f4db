"""Child processes started and stopped one way (``companion demo``, ``companion fleet up``, the
integration tests).

A ``ManagedProcess`` is one child: its command line, its log file (stdout and stderr), its
environment and working directory. Started (``start`` or ``spawn``), it runs

- in a process group of its own (``setpgid``), so that a Ctrl-C in the terminal reaches the
  launcher only, which then stops its children in the order it chooses;
- optionally with ``exit_with_parent``: the kernel sends it SIGTERM when the thread that started
  it ends (``PR_SET_PDEATHSIG``; Linux only), so a launcher killed with SIGKILL leaves no child.

``wait_ready(condition, timeout_s, what)`` waits for a readiness condition (``log_contains(text)``,
a heartbeat probe ...) and fails with a ``ProcessError`` naming the process and its log if the
child exits first or the time runs out.

``stop()`` escalates as its ``Escalation`` says (by default SIGINT, then SIGTERM, then SIGKILL,
each after a timeout), then ends what the child left behind: the descendants seen while it ran
(``note_descendants``; identified by their start time beyond pid reuse) get a grace period to
exit on their own, then SIGKILL, and so does anything still in its process group. A
``ProcessGroup`` stops several children at once (each signal sent to all, one deadline for all).

Everything here is blocking and thread-free; the descendants are read from ``/proc``
(``companion.sitl.procfs``; none are found off Linux).
"""

from __future__ import annotations

import ctypes
import logging
import math
import os
import signal
import subprocess
import sys
import time
from collections.abc import Callable, Iterable, Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path

from companion.errors import ConfigError, ProcessError
from companion.sitl.procfs import GONE_STATES, descendants, process_state, start_time

__all__ = [
    "Escalation",
    "ManagedProcess",
    "ProcessGroup",
    "python_command",
    "spawn",
    "stop_together",
    "DEFAULT_ESCALATION",
]

log = logging.getLogger(__name__)

PR_SET_PDEATHSIG = 1


def _libc_prctl():
    """libc's ``prctl``, looked up here (not in the child between fork and exec); None off Linux."""
    if not sys.platform.startswith("linux"):
        return None
    try:
        return ctypes.CDLL(None, use_errno=True).prctl
    except (OSError, AttributeError):
        return None


_PRCTL = _libc_prctl()


def python_command(module_args: Sequence[str]) -> list[str]:
    """``python -m <module_args>`` with this interpreter."""
    return [sys.executable, "-m", *module_args]


# ------------------------------------------------------------------------------------ stopping
@dataclass(frozen=True)
class Escalation:
    """How a child is stopped.

    Parameters
    ----------
    steps : sequence of (signal, wait_s)
        Each signal in turn, to the child only (not its process group), each followed by a wait
        of up to ``wait_s`` wall seconds for it to exit; SIGKILL follows the last.
    kill_wait_s : float
        How long to wait for the child after SIGKILL (wall s).
    leftover_grace_s : float
        How long its descendants may take to exit on their own once it has (wall s), before
        they get SIGKILL.
    """

    steps: tuple[tuple[int, float], ...] = ((signal.SIGINT, 15.0), (signal.SIGTERM, 5.0))
    kill_wait_s: float = 5.0
    leftover_grace_s: float = 5.0

    def __post_init__(self) -> None:
        for sig, wait_s in self.steps:
            if not isinstance(sig, int) or sig <= 0 or sig == signal.SIGKILL:
                raise ConfigError(f"Escalation.steps: expected signals other than SIGKILL, got {sig!r}")
            _check_seconds("Escalation.steps wait_s", wait_s)
        _check_seconds("Escalation.kill_wait_s", self.kill_wait_s)
        _check_seconds("Escalation.leftover_grace_s", self.leftover_grace_s)


def _check_seconds(name: str, value: float) -> None:
    if not (isinstance(value, (int, float)) and math.isfinite(value) and value >= 0):
        raise ConfigError(f"{name}: expected a number of seconds >= 0, got {value!r}")


#: SIGINT (15 s), SIGTERM (5 s), SIGKILL.
DEFAULT_ESCALATION = Escalation()


def stop_together(processes: Iterable[ManagedProcess], escalation: Escalation = DEFAULT_ESCALATION) -> None:
    """Stop ``processes`` at once: each step's signal to every one still running, one deadline
    for all; SIGKILL to those still running after the last step; then their leftovers
    (``ManagedProcess.end_leftovers``)."""
    started = [p for p in processes if p.started]
    for proc in started:
        proc.note_descendants()
    for sig, wait_s in escalation.steps:
        live = [p for p in started if p.poll() is None]
        if not live:
            break
        for proc in live:
            log.debug("stopping %s (pid %d): %s", proc.name, proc.pid, signal.Signals(sig).name)
            proc.send_signal(sig)
        _wait_all(live, wait_s)
    live = [p for p in started if p.poll() is None]
    for proc in live:
        log.warning("%s (pid %d) did not stop: SIGKILL", proc.name, proc.pid)
        proc.kill()
    _wait_all(live, escalation.kill_wait_s)
    for proc in live:
        if proc.poll() is None:
            log.error("%s (pid %d) is still there %.0f s after SIGKILL", proc.name, proc.pid, escalation.kill_wait_s)
    _end_leftovers(started, escalation.leftover_grace_s)


def _wait_all(processes: Sequence[ManagedProcess], timeout_s: float) -> None:
    deadline = time.monotonic() + timeout_s
    for proc in processes:
        try:
            proc.wait(max(deadline - time.monotonic(), 0.0))
        except TimeoutError:
            pass


def _end_leftovers(processes: Sequence[ManagedProcess], grace_s: float) -> None:
    deadline = time.monotonic() + grace_s
    while any(p.leftovers() for p in processes) and time.monotonic() < deadline:
        time.sleep(0.05)
    for proc in processes:
        proc.end_leftovers()


# ------------------------------------------------------------------------------------ one child
class ManagedProcess:
    """One child process with its log file (see the module docstring).

    Parameters
    ----------
    argv : sequence of str
        The command line (``python_command(module_args)`` for ``python -m``).
    log_path : path
        Its stdout and stderr (the file is truncated at the start; its directory must exist).
    name : str, optional
        For messages and logs (default: the log file's stem).
    env : mapping, optional
        Its environment (default: this process's).
    cwd : path, optional
        Its working directory (default: this process's).
    exit_with_parent : bool
        SIGTERM to the child when the thread that starts it ends (Linux ``PR_SET_PDEATHSIG``).
    escalation : Escalation
        How ``stop()`` stops it unless told otherwise.
    """

    def __init__(
        self,
        argv: Sequence[str],
        log_path,
        *,
        name: str | None = None,
        env: Mapping[str, str] | None = None,
        cwd=None,
        exit_with_parent: bool = True,
        escalation: Escalation = DEFAULT_ESCALATION,
    ) -> None:
        self.argv = [str(a) for a in argv]
        if not self.argv:
            raise ConfigError("ManagedProcess: expected a command line, got an empty one")
        self.log_path = Path(log_path)
        self.name = name or self.log_path.stem
        self.env = dict(env) if env is not None else None
        self.cwd = None if cwd is None else str(cwd)
        self.exit_with_parent = bool(exit_with_parent)
        self.escalation = escalation
        self._popen: subprocess.Popen | None = None
        self._seen: dict[int, int] = {}  # descendant pid -> its start time

    # -------------------------------------------------------------------------- start
    def start(self) -> ManagedProcess:
        """Start the child (once); returns self.

        Raises
        ------
        ProcessError
            Started already, or the command cannot be run (no such file, no permission).
        """
        if self._popen is not None:
            raise ProcessError(f"{self.name} was started already (pid {self._popen.pid})")
        preexec = _exit_with_parent_hook(os.getpid()) if self.exit_with_parent and _PRCTL else None
        try:
            with open(self.log_path, "wb") as fh:
                self._popen = subprocess.Popen(
                    self.argv,
                    stdout=fh,
                    stderr=subprocess.STDOUT,
                    stdin=subprocess.DEVNULL,
                    env=self.env,
                    cwd=self.cwd,
                    process_group=0,
                    preexec_fn=preexec,
                )
        except OSError as exc:
            raise ProcessError(f"cannot start {self.name} ({self.argv[0]}): {exc.strerror or exc}") from None
        log.debug("%s started: pid %d, log %s", self.name, self._popen.pid, self.log_path)
        return self

    @property
    def started(self) -> bool:
        return self._popen is not None

    @property
    def pid(self) -> int:
        return self._started().pid

    @property
    def returncode(self) -> int | None:
        """Its exit status once known (negative: the signal that ended it), else None."""
        return None if self._popen is None else self._popen.returncode

    def _started(self) -> subprocess.Popen:
        if self._popen is None:
            raise ProcessError(f"{self.name} was not started")
        return self._popen

    # -------------------------------------------------------------------------- run
    def poll(self) -> int | None:
        """Its exit status if it has exited, else None."""
        return self._started().poll()

    def is_running(self) -> bool:
        return self._popen is not None and self._popen.poll() is None

    def wait(self, timeout_s: float | None = None) -> int:
        """Wait until it exits; its exit status.

        Raises
        ------
        TimeoutError
            Still running after ``timeout_s`` wall seconds (it is not stopped).
        """
        try:
            return self._started().wait(timeout_s)
        except subprocess.TimeoutExpired:
            raise TimeoutError(f"{self.name} (pid {self.pid}) still running after {timeout_s:g} s") from None

    def send_signal(self, sig: int) -> None:
        """Send ``sig`` to the child (nothing once it has exited)."""
        proc = self._started()
        if proc.poll() is None:
            try:
                proc.send_signal(sig)
            except ProcessLookupError:
                pass

    def kill(self) -> None:
        """SIGKILL to the child (nothing once it has exited)."""
        self.send_signal(signal.SIGKILL)

    def wait_ready(self, ready: Callable[[], bool], timeout_s: float, what: str, poll_s: float = 0.1) -> None:
        """Call ``ready()`` every ``poll_s`` until it is true.

        Raises
        ------
        ProcessError
            The child exited first, or ``ready()`` stayed false for ``timeout_s`` wall seconds
            (the child is left running: stop it).
        """
        deadline = time.monotonic() + timeout_s
        while not ready():
            code = self.poll()
            if code is not None:
                raise ProcessError(f"{self.name} exited with status {code} before {what}; see {self.log_path}")
            if time.monotonic() > deadline:
                raise ProcessError(
                    f"{self.name} (pid {self.pid}): no {what} within {timeout_s:g} s; see {self.log_path}"
                )
            time.sleep(poll_s)

    def log_contains(self, text: str) -> Callable[[], bool]:
        """A readiness condition: ``text`` is in the log."""
        return lambda: text in self.log_text()

    def log_text(self) -> str:
        """The log so far ("" when it cannot be read)."""
        try:
            return self.log_path.read_text(errors="replace")
        except OSError:
            return ""

    def log_tail(self, lines: int = 60) -> str:
        """The last ``lines`` lines of the log."""
        return "\n".join(self.log_text().splitlines()[-lines:])

    # -------------------------------------------------------------------------- descendants
    def descendants(self) -> list[int]:
        """Its descendants now (empty once it has exited: they belong to init then)."""
        return descendants(self.pid) if self.is_running() else []

    def note_descendants(self) -> None:
        """Remember its descendants now, to end whatever of them outlives it (``end_leftovers``)."""
        for pid in self.descendants():
            if pid not in self._seen:
                started = start_time(pid)
                if started is not None:
                    self._seen[pid] = started

    def leftovers(self) -> list[int]:
        """The descendants seen (``note_descendants``) that still run."""
        return [
            pid
            for pid, started in self._seen.items()
            if start_time(pid) == started and process_state(pid) not in GONE_STATES
        ]

    def end_leftovers(self) -> list[int]:
        """Once it has exited: SIGKILL to the descendants seen that still run, and to its
        process group; returns the pids of the former."""
        if self._popen is None or self._popen.poll() is None:
            return []
        left = self.leftovers()
        for pid in left:
            log.warning("killing a process left behind by %s: pid %d", self.name, pid)
            _kill(pid)
        try:
            os.killpg(self._popen.pid, signal.SIGKILL)
        except (ProcessLookupError, PermissionError):
            pass
        return left

    # -------------------------------------------------------------------------- stop
    def stop(self, escalation: Escalation | None = None) -> int | None:
        """Stop it (``stop_together``) and what it left behind; its exit status (None if it was
        never started). Idempotent."""
        if self._popen is None:
            return None
        stop_together([self], escalation or self.escalation)
        return self._popen.returncode

    def __enter__(self) -> ManagedProcess:
        if self._popen is None:
            self.start()
        return self

    def __exit__(self, *exc) -> None:
        self.stop()

    def __repr__(self) -> str:
        state = (
            "not started"
            if self._popen is None
            else f"pid {self._popen.pid}, "
            + ("running" if self._popen.returncode is None else f"exit {self._popen.returncode}")
        )
        return f"ManagedProcess({self.name}: {state})"


def _kill(pid: int) -> None:
    try:
        os.kill(pid, signal.SIGKILL)
    except (ProcessLookupError, PermissionError):
        pass


def _exit_with_parent_hook(parent_pid: int):
    """A ``preexec_fn``: SIGTERM when the parent's thread ends, and at once if it already has."""

    def hook() -> None:
        _PRCTL(PR_SET_PDEATHSIG, signal.SIGTERM)
        if os.getppid() != parent_pid:  # the parent died before the prctl
            os.kill(os.getpid(), signal.SIGTERM)

    return hook


def spawn(argv: Sequence[str], log_path, **options) -> ManagedProcess:
    """``ManagedProcess(argv, log_path, **options).start()``."""
    return ManagedProcess(argv, log_path, **options).start()


# ------------------------------------------------------------------------------------ several
class ProcessGroup:
    """Children stopped together (``stop_together``); a context manager that stops them on exit.

    Not a POSIX process group: each child has its own.

    Parameters
    ----------
    escalation : Escalation
        How ``stop()`` stops them unless told otherwise.
    """

    def __init__(self, escalation: Escalation = DEFAULT_ESCALATION) -> None:
        self.escalation = escalation
        self.processes: list[ManagedProcess] = []

    def start(self, process: ManagedProcess) -> ManagedProcess:
        """Start ``process`` and add it; returns it."""
        self.processes.append(process)
        return process.start()

    def add(self, process: ManagedProcess) -> ManagedProcess:
        """Add a (started) process; returns it."""
        self.processes.append(process)
        return process

    def running(self) -> list[ManagedProcess]:
        return [p for p in self.processes if p.is_running()]

    def note_descendants(self) -> None:
        """``ManagedProcess.note_descendants`` of each."""
        for proc in self.processes:
            if proc.started:
                proc.note_descendants()

    def stop(self, escalation: Escalation | None = None) -> None:
        """Stop them all at once, and what they left behind. Idempotent."""
        stop_together(self.processes, escalation or self.escalation)

    def __enter__(self) -> ProcessGroup:
        return self

    def __exit__(self, *exc) -> None:
        self.stop()
