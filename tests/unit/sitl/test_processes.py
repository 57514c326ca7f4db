"""companion.sitl.processes on real child processes (``python -c`` scripts): started in their
own process group with a log file, readiness waited for, stopped with escalating signals,
nothing left behind, a failing child's exit status reported."""

from __future__ import annotations

import os
import signal
import subprocess
import sys
import textwrap
import time

import pytest

from companion.errors import ConfigError, ProcessError
from companion.sitl.processes import Escalation, ManagedProcess, ProcessGroup, python_command, spawn
from companion.sitl.procfs import descendants, process_state, start_time

pytestmark = pytest.mark.skipif(not sys.platform.startswith("linux"), reason="reads /proc")

#: Short steps: the children here either obey at once or ignore the signal altogether.
QUICK = Escalation(((signal.SIGINT, 1.0), (signal.SIGTERM, 1.0)), kill_wait_s=5.0, leftover_grace_s=1.0)
#: For a child that obeys SIGINT: a loaded machine may take seconds to unwind its interpreter, and a
#: 1 s grace then escalated to SIGTERM (seen in a full suite on 2 busy cores).
PATIENT = Escalation(((signal.SIGINT, 15.0), (signal.SIGTERM, 1.0)), kill_wait_s=5.0, leftover_grace_s=1.0)


def script(body: str) -> list[str]:
    return [sys.executable, "-c", textwrap.dedent(body)]


def running(pid: int) -> bool:
    return process_state(pid) not in ("Z", "X", None)


def wait_gone(pids, timeout_s: float = 10.0) -> list[int]:
    """The pids still running after ``timeout_s`` (they may take a moment to be reaped by init)."""
    deadline = time.monotonic() + timeout_s
    while any(map(running, pids)) and time.monotonic() < deadline:
        time.sleep(0.05)
    return [pid for pid in pids if running(pid)]


SLEEPER = """
    import time
    print("ready", flush=True)
    while True:
        time.sleep(0.05)
"""

IGNORES = """
    import signal, sys, time
    def note(sig, _):
        print("got", signal.Signals(sig).name, flush=True)
    for name in sys.argv[1:]:
        signal.signal(getattr(signal, name), note)
    print("ready", flush=True)
    while True:
        time.sleep(0.05)
"""


def test_a_child_is_started_in_its_own_group_waited_for_and_stopped_with_sigint(tmp_path):
    with spawn(script(SLEEPER), tmp_path / "sleeper.log", escalation=PATIENT) as proc:
        proc.wait_ready(proc.log_contains("ready"), 30.0, "'ready'")
        assert proc.is_running() and proc.poll() is None
        assert os.getpgid(proc.pid) == proc.pid != os.getpgid(0)
        assert proc.name == "sleeper"
    assert proc.returncode == -signal.SIGINT or "KeyboardInterrupt" in proc.log_text()
    assert proc.log_text().startswith("ready")
    assert proc.stop() == proc.returncode  # idempotent


def test_the_environment_and_working_directory_are_the_childs(tmp_path):
    proc = spawn(
        script("import os; print(os.environ['SITL_TEST'], os.getcwd())"),
        tmp_path / "env.log",
        env=dict(os.environ, SITL_TEST="hello"),
        cwd=tmp_path,
    )
    assert proc.wait(30.0) == 0
    assert proc.log_text().split() == ["hello", str(tmp_path)]


def test_a_child_that_ignores_sigint_is_ended_by_sigterm(tmp_path):
    with spawn(script(IGNORES) + ["SIGINT"], tmp_path / "stubborn.log", escalation=QUICK) as proc:
        proc.wait_ready(proc.log_contains("ready"), 30.0, "'ready'")
    assert proc.returncode == -signal.SIGTERM
    assert "got SIGINT" in proc.log_text()


def test_a_child_that_ignores_sigint_and_sigterm_is_killed(tmp_path):
    proc = spawn(script(IGNORES) + ["SIGINT", "SIGTERM"], tmp_path / "deaf.log")
    proc.wait_ready(proc.log_contains("ready"), 30.0, "'ready'")
    assert proc.stop(QUICK) == -signal.SIGKILL
    assert "got SIGINT" in proc.log_text() and "got SIGTERM" in proc.log_text()


def test_a_failing_child_reports_its_exit_status(tmp_path):
    proc = spawn(script("import sys; print('bad input', flush=True); sys.exit(3)"), tmp_path / "fails.log")
    with pytest.raises(ProcessError, match=r"fails exited with status 3 before 'ready'; see .*fails\.log"):
        proc.wait_ready(proc.log_contains("ready"), 30.0, "'ready'")
    assert proc.wait(10.0) == 3 and proc.returncode == 3
    assert proc.log_tail(1) == "bad input"


def test_readiness_that_never_comes_is_an_error_naming_the_log_and_the_child_runs_on(tmp_path):
    with spawn(script(SLEEPER), tmp_path / "slow.log", escalation=QUICK) as proc:
        with pytest.raises(ProcessError, match=r"no 'listening' within 0.3 s; see .*slow\.log"):
            proc.wait_ready(proc.log_contains("listening"), 0.3, "'listening'")
        assert proc.is_running()
        with pytest.raises(TimeoutError, match="still running after 0.1 s"):
            proc.wait(0.1)
    assert not proc.is_running()


def test_a_command_that_cannot_run_and_a_second_start_are_errors(tmp_path):
    with pytest.raises(ProcessError, match="cannot start nothing"):
        ManagedProcess([str(tmp_path / "no-such-program")], tmp_path / "nothing.log").start()
    proc = spawn(script("pass"), tmp_path / "once.log")
    with pytest.raises(ProcessError, match="started already"):
        proc.start()
    assert proc.wait(10.0) == 0
    with pytest.raises(ProcessError, match="was not started"):
        ManagedProcess(script("pass"), tmp_path / "never.log").poll()
    assert ManagedProcess(script("pass"), tmp_path / "never.log").stop() is None


FAMILY = """
    import signal, subprocess, sys, time
    # a grandchild that ignores SIGINT and SIGTERM, and one that leaves the process group
    keep = subprocess.Popen([sys.executable, "-c", "import signal, time\\n"
                             "signal.signal(signal.SIGINT, signal.SIG_IGN)\\n"
                             "signal.signal(signal.SIGTERM, signal.SIG_IGN)\\n"
                             "time.sleep(600)"])
    away = subprocess.Popen([sys.executable, "-c", "import time; time.sleep(600)"], start_new_session=True)
    print(keep.pid, away.pid, flush=True)
    def leave(*_):
        # a last one started while stopping: never seen, but in the process group
        late = subprocess.Popen([sys.executable, "-c", "import signal, time\\n"
                                 "signal.signal(signal.SIGTERM, signal.SIG_IGN)\\n"
                                 "time.sleep(600)"])
        print(late.pid, flush=True)
        sys.exit(0)
    signal.signal(signal.SIGINT, leave)
    while True:
        time.sleep(0.05)
"""


def test_descendants_are_found_and_none_is_left_running_after_stop(tmp_path):
    proc = spawn(script(FAMILY), tmp_path / "family.log", escalation=QUICK)
    proc.wait_ready(lambda: len(proc.log_text().split()) >= 2, 30.0, "the grandchildren's pids")
    keep, away = (int(pid) for pid in proc.log_text().split()[:2])
    assert {keep, away} <= set(descendants(proc.pid)) and set(proc.descendants()) == set(descendants(proc.pid))
    assert start_time(keep) is not None and running(keep) and running(away)
    proc.note_descendants()
    assert sorted(proc.leftovers()) == sorted([keep, away])
    assert proc.stop() == 0  # it left on SIGINT ...
    late = int(proc.log_text().split()[2])
    assert wait_gone([keep, away, late]) == []  # ... and nothing of it is left
    assert proc.leftovers() == [] and proc.descendants() == []


def test_a_group_stops_every_child_with_each_signal_in_turn(tmp_path):
    group = ProcessGroup(QUICK)
    with group:
        stubborn = group.start(ManagedProcess(script(IGNORES) + ["SIGINT"], tmp_path / "a.log"))
        obedient = group.add(spawn(script(SLEEPER), tmp_path / "b.log"))
        deaf = group.start(ManagedProcess(script(IGNORES) + ["SIGINT", "SIGTERM"], tmp_path / "c.log"))
        for proc in group.processes:
            proc.wait_ready(proc.log_contains("ready"), 30.0, "'ready'")
        assert group.running() == [stubborn, obedient, deaf]
    assert group.running() == []
    assert stubborn.returncode == -signal.SIGTERM and deaf.returncode == -signal.SIGKILL
    assert obedient.returncode is not None and "got SIGTERM" in deaf.log_text()
    assert "got SIGINT" in stubborn.log_text() and "got SIGINT" in deaf.log_text()


ORPHANED = """
    import os, sys
    from companion.sitl.processes import spawn
    child = spawn([sys.executable, "-c", "import time; time.sleep(600)"], sys.argv[1])
    print(child.pid, flush=True)
    os.kill(os.getpid(), 9)                      # the launcher dies without stopping its child
"""


def test_a_child_ends_with_its_launcher(tmp_path):
    launcher = subprocess.run(
        script(ORPHANED) + [str(tmp_path / "orphan.log")],
        capture_output=True,
        text=True,
        timeout=60,
        env=dict(os.environ, PYTHONPATH=os.pathsep.join(sys.path)),
    )
    assert launcher.returncode == -signal.SIGKILL, launcher.stderr
    child = int(launcher.stdout.split()[0])
    assert wait_gone([child]) == [], "the child outlived its launcher"


def test_python_command_and_bad_escalations():
    assert python_command(["sim_vehicle.cli", "--port", "1"]) == [
        sys.executable,
        "-m",
        "sim_vehicle.cli",
        "--port",
        "1",
    ]
    with pytest.raises(ConfigError, match="SIGKILL"):
        Escalation(((signal.SIGKILL, 1.0),))
    with pytest.raises(ConfigError, match="wait_s"):
        Escalation(((signal.SIGINT, -1.0),))
    with pytest.raises(ConfigError, match="kill_wait_s"):
        Escalation(kill_wait_s=float("nan"))
    with pytest.raises(ConfigError, match="command line"):
        ManagedProcess([], "x.log")
