"""The flight controller: LQI on the 14-state hover model and a PID position loop (paper section 2.2).

The package, one room per job:

* :mod:`~heli_model.control.settings`: :class:`ControllerSettings`, :class:`Setpoint`, the
  Bryson weights of Q and R;
* :mod:`~heli_model.control.lqi`: the 14-state model, its ZOH discretisation and the LQI
  design (:func:`design_lqi`, python-control's ``dlqr`` with integral action);
* :mod:`~heli_model.control.law`: the per-tick law as a pure function of the controller state
  (:class:`ControlLaw`, :class:`ControllerState`); :mod:`~heli_model.control.flight_controller`:
  :class:`FlightController`, the law with its state; :mod:`~heli_model.control.outer_loop`: the
  PID position loop, command limits and heading reference the law uses;
* :mod:`~heli_model.control.closed_loop` (with :mod:`~heli_model.control.closed_loop_model`
  and :mod:`~heli_model.control.modal`): :func:`simulate_closed_loop`, the fast prediction of
  how the loop tracks a trajectory, used by the companion's feasibility check.

With the default weights the 1 m / 2 m position steps and the 5 m/s circle of 30 m radius are
flown without saturation (``tests/unit/sim_vehicle/test_sim_control.py``,
``benchmarks/sitl_realtime.py``). Pure numerics; python-control is imported lazily (it costs
about 1.6 s).
"""

from heli_model.control.closed_loop import ClosedLoopResult, simulate_closed_loop
from heli_model.control.flight_controller import FlightController
from heli_model.control.law import ControlLaw, ControllerState, initial_controller_state
from heli_model.control.lqi import (
    LqiGains,
    control_law_matrix,
    design_lqi,
    feedforward_map,
    model_14,
    tracked_output_matrix,
    zoh,
)
from heli_model.control.outer_loop import wrap_pi
from heli_model.control.settings import (
    BRYSON_INPUT_MAX,
    BRYSON_INTEGRATOR_MAX,
    BRYSON_STATE_MAX,
    DEFAULT_Q_WEIGHTS,
    DEFAULT_R_WEIGHTS,
    N_LQI_STATES,
    N_TRACKED,
    TRACKED_INDICES,
    ControlError,
    ControllerSettings,
    Setpoint,
    bryson_weights,
)

__all__ = [
    "BRYSON_INPUT_MAX",
    "BRYSON_INTEGRATOR_MAX",
    "BRYSON_STATE_MAX",
    "DEFAULT_Q_WEIGHTS",
    "DEFAULT_R_WEIGHTS",
    "N_LQI_STATES",
    "N_TRACKED",
    "TRACKED_INDICES",
    "ClosedLoopResult",
    "ControlError",
    "ControlLaw",
    "ControllerSettings",
    "ControllerState",
    "FlightController",
    "LqiGains",
    "Setpoint",
    "bryson_weights",
    "control_law_matrix",
    "design_lqi",
    "feedforward_map",
    "initial_controller_state",
    "model_14",
    "simulate_closed_loop",
    "tracked_output_matrix",
    "wrap_pi",
    "zoh",
]
