"""Every reference the companion flies follows ``FlyableReference``; trajectory and timing are
not a cycle."""

from __future__ import annotations

import subprocess
import sys

import numpy as np

from companion.flight.plan import TrajectoryChain
from companion.flight.reference import ActiveReference, VehicleClock
from companion.flight.trajectory import FlyableReference, Trajectory
from companion.smoothing import smooth_g2, time_parameterize
from companion.threats.decision.evasion import EscapeLimits, escape_library
from companion.threats.decision.retime import RetimedTrajectory


def _trajectory() -> Trajectory:
    curve = smooth_g2(np.array([[0.0, 0.0], [40.0, 0.0], [40.0, 30.0]]), 0.1)
    return time_parameterize(curve).to_ned(-20.0)


def _flown() -> dict:
    traj = _trajectory()
    escape = escape_library(
        np.array([0.0, 0.0, -20.0]), np.array([5.0, 0.0, 0.0]), EscapeLimits(), vertical=True
    ).manoeuvre(0, 0.0)
    return {
        "trajectory": traj,
        "chain": TrajectoryChain([traj, _trajectory()]),
        "retimed": RetimedTrajectory(traj, 2.0, rate=0.4, wait_s=3.0, ramp_s=1.0),
        "hold on the path": RetimedTrajectory(traj, 2.0, rate=0.0, wait_s=30.0, ramp_s=1.0),
        "escape": escape,
    }


def test_every_flown_reference_is_a_flyable_reference():
    for name, ref in _flown().items():
        assert isinstance(ref, FlyableReference), name
        t = np.linspace(0.0, ref.duration_s, 7)
        pos, vel, acc = ref.sample(t)
        assert pos.shape == vel.shape == acc.shape == (7, 3), name
        assert ref.yaw_rad(t).shape == ref.yaw_rate_rad_s(t).shape == (7,), name
        np.testing.assert_allclose(pos[-1], ref.end_pos_ned_m, atol=1e-6, err_msg=name)
        assert ref.length_m >= 0.0
        # what the setpoint stream does with it
        active = ActiveReference(ref, 0.0, VehicleClock(1.0), name)
        p, v, a, yaw, rate = active.state(ref.duration_s + 1.0)
        np.testing.assert_allclose(p, ref.end_pos_ned_m, atol=1e-6, err_msg=name)
        assert not np.any(v) and not np.any(a) and rate == 0.0


def test_a_partial_reference_is_not_flyable():
    class NoYawRate:
        duration_s = 1.0
        length_m = 0.0
        end_pos_ned_m = np.zeros(3)

        def sample(self, t_s):
            return np.zeros((1, 3)), np.zeros((1, 3)), np.zeros((1, 3))

        def yaw_rad(self, t_s):
            return np.zeros(1)

    assert not isinstance(NoYawRate(), FlyableReference)


def test_trajectory_does_not_import_the_timing():
    code = (
        "import sys, companion.flight.trajectory; "
        "assert not any(m.startswith('companion.smoothing') for m in sys.modules), "
        "sorted(m for m in sys.modules if m.startswith('companion'))"
    )
    subprocess.run([sys.executable, "-c", code], check=True)
