"""The hold (brake along the active path) is a full reference: yaw rate agrees with yaw."""

from __future__ import annotations

import numpy as np

from companion.smoothing import smooth_g2, time_parameterize
from companion.threats.manager import BrakeAlongPath


def test_hold_yaw_rate_is_the_derivative_of_its_yaw():
    path = np.array([[0.0, 0.0, -10.0], [40.0, 0.0, -10.0], [40.0, 40.0, -10.0]])
    active = time_parameterize(smooth_g2(path, 0.1))
    t_turn = active.time_at_s(np.array([32.0]))[0]          # braking inside the corner
    hold = BrakeAlongPath(active, 0.0, t_turn, 2.5)
    t = np.linspace(0.05, hold.duration_s - 0.05, 200)
    yaw = np.unwrap(hold.yaw_rad(t))
    numeric = np.gradient(yaw, t)
    assert np.max(np.abs(hold.yaw_rate_rad_s(t) - numeric)) < 0.02
    assert np.max(np.abs(hold.yaw_rate_rad_s(t))) > 0.05    # it does turn
    assert np.allclose(hold.sample(np.array([hold.duration_s]))[1], 0.0, atol=1e-9)
