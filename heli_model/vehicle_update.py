"""The pure vehicle update: flight controller and RK4 physics, ``update(state, command, dt) -> state``.

In the style of ArduPilot's JSON physics example (``libraries/SITL/examples/JSON``): one
function maps the vehicle state, the command and a time step to the next state, with no I/O,
no clock and no randomness (the wind is part of the command). :class:`VehicleUpdate` holds only
configuration (model, designed controller, physics step); the state is a :class:`VehicleState`
value and is never modified in place.

Sampled-data timing, as on the vehicle: the flight controller runs once per control period
(``law.settings.control_dt_s``, 100 Hz) and its rotor inputs are held (zero-order hold) until it
runs again; the physics advances in RK4 sub-steps of at most ``physics_dt_s`` (400 Hz). A command
with a setpoint starts a control period; a command without one holds the rotor inputs. One
update never spans more than a control period, so

* ``update(state, VehicleCommand(setpoint), control_dt_s)`` is one full control period (tests,
  ``benchmarks/sitl_realtime.py``);
* the :class:`~sim_vehicle.autopilot.Autopilot` calls it once per physics step, with the
  setpoint on the steps that start a control period.

Flat ground at ``down = 0`` stops the vehicle (it cannot sink below, nor keep descending on it).
"""

from __future__ import annotations

import dataclasses
import math
from typing import Any, NamedTuple

import numpy as np

from heli_model import dynamics
from heli_model.control import ControllerSettings, ControllerState, ControlLaw, Setpoint
from heli_model.model import N_INPUTS, HeliModel

PHYSICS_DT_S = 1.0 / 400.0
"""Default RK4 step, s (the SITL's 400 Hz)."""


class VehicleState(NamedTuple):
    """Everything the update carries from one step to the next.

    Attributes
    ----------
    x : ndarray, shape (17,) or (21,)
        Simulation state (see :mod:`heli_model.dynamics`).
    delta : ndarray, shape (4,)
        Rotor inputs ``[d_lat, d_lon, d_ped, d_col]`` held since the last control period.
    controller : ControllerState
        Integrators, heading reference and last output of the flight controller.
    """

    x: np.ndarray
    delta: np.ndarray
    controller: ControllerState


class VehicleCommand(NamedTuple):
    """What the vehicle is given for one update.

    Attributes
    ----------
    setpoint : Setpoint or None
        A setpoint starts a control period (the controller runs once); None holds the rotor inputs.
    wind_ned_m_s : array_like, shape (3,) or (n_substeps, 3), optional
        Air velocity, m/s NED: one for the whole update or one per RK4 sub-step; None = calm.
    """

    setpoint: Setpoint | None = None
    wind_ned_m_s: Any = None


@dataclasses.dataclass(frozen=True)
class VehicleUpdate:
    """Configuration of the pure update: the model, the designed controller and the physics step.

    Parameters
    ----------
    model : HeliModel
    law : ControlLaw
        The designed flight controller; it runs over ``law.settings.control_dt_s``.
    physics_dt_s : float
        Longest RK4 sub-step, s.
    """

    model: HeliModel
    law: ControlLaw
    physics_dt_s: float = PHYSICS_DT_S

    @classmethod
    def build(cls, model: HeliModel, controller_settings: ControllerSettings | None = None,
              physics_dt_s: float = PHYSICS_DT_S) -> "VehicleUpdate":
        """Design the controller for ``controller_settings`` (cached on the model) and keep the step."""
        return cls(model, ControlLaw(model, controller_settings), float(physics_dt_s))

    def hover_state(self, pos_ned_m=(0.0, 0.0, 0.0), yaw_rad: float = 0.0) -> VehicleState:
        """Trimmed hover at rest, rotor inputs zero, controller taking over there."""
        x = dynamics.hover_state(self.model, pos_ned_m, yaw_rad)
        return VehicleState(x=x, delta=np.zeros(N_INPUTS), controller=self.law.reset(x))

    def reset_controller(self, state: VehicleState) -> VehicleState:
        """The controller taking over at ``state.x`` (integrators cleared, heading held)."""
        return state._replace(controller=self.law.reset(state.x))

    def update(self, state: VehicleState, command: VehicleCommand, dt_s: float) -> VehicleState:
        """Advance the vehicle by ``dt_s``: controller (if the command has a setpoint), then RK4.

        Parameters
        ----------
        state : VehicleState
        command : VehicleCommand
        dt_s : float
            Time step, s: ``0 < dt_s <= control_dt_s``, split into equal RK4 sub-steps of at most
            ``physics_dt_s``.

        Returns
        -------
        VehicleState
            The state ``dt_s`` later; ``state`` is not modified.
        """
        law = self.law
        control_dt_s = law.settings.control_dt_s
        if not 0.0 < dt_s <= control_dt_s * (1.0 + 1e-9):
            raise dynamics.DynamicsError(
                f"dt_s: expected 0 < dt_s <= the control period {control_dt_s:g} s, got {dt_s!r}")
        x, delta, controller = state
        setpoint, wind = command
        if setpoint is not None:
            controller = law.step(controller, x, setpoint, control_dt_s)
            delta = controller.delta
        n = substeps(dt_s, self.physics_dt_s)
        h = dt_s / n
        per_substep = wind is not None and np.ndim(wind) == 2
        model, step_rk4 = self.model, dynamics.step_rk4
        for i in range(n):
            x = step_rk4(model, x, delta, h, wind[i] if per_substep else wind)
            if x[16] >= 0.0:
                stop_on_ground(x)
        return VehicleState(x, delta, controller)


def substeps(dt_s: float, physics_dt_s: float) -> int:
    """Number of equal RK4 sub-steps of at most ``physics_dt_s`` in ``dt_s``."""
    return max(1, math.ceil(dt_s / physics_dt_s - 1e-9))


def stop_on_ground(x: np.ndarray) -> None:
    """Flat ground at ``down = 0``: put a state that went below it back on it, no longer descending (in place)."""
    if x[16] >= 0.0:
        x[16] = 0.0
        if x[2] > 0.0:
            x[2] = 0.0
