"""The LQI design without python-control gives python-control's gains bit for bit (issue 25,
item 5: python-control, and the matplotlib it requires, are not installed on a companion)."""

import numpy as np
import pytest

from heli_model.control import ControllerSettings
from heli_model.control.lqi import dlqr_integral, model_14, tracked_output_matrix, zoh
from heli_model.model import HeliModel

control = pytest.importorskip("control")  # the test extra has it: the reference implementation


@pytest.mark.parametrize("dt_s", [0.01, 0.02])
def test_dlqr_integral_is_python_controls_dlqr(dt_s):
    model = HeliModel.default()
    settings = ControllerSettings()
    q, r = np.diag(settings.q_weights), np.diag(settings.r_weights)
    Ad, Bd = zoh(*model_14(model), dt_s)
    C = tracked_output_matrix()
    sysd = control.ss(Ad, Bd, C, np.zeros((C.shape[0], Bd.shape[1])), dt_s)
    K_ref, _, E_ref = control.dlqr(sysd, q, r, integral_action=C * dt_s)
    K, E = dlqr_integral(Ad, Bd, C * dt_s, q.astype(float), r.astype(float))
    assert np.array_equal(K, np.asarray(K_ref)) and np.array_equal(E, np.asarray(E_ref))
