"""The airframe: the pure vehicle update, its state and the wind, with the state views the rest reads.

The vehicle itself (designed flight controller and RK4 physics) is the pure update of
:mod:`heli_model.vehicle_update`; :class:`Airframe` holds its one :class:`VehicleState`, rebuilds
the update when the settings change (a PARAM_SET of a controller weight redesigns the
controller), draws the wind gusts and advances the physics one step at a time.
"""

from __future__ import annotations

import dataclasses
import math

import numpy as np

from heli_model import dynamics
from heli_model.control import ControlLaw, Setpoint, initial_controller_state
from heli_model.model import HeliModel
from heli_model.vehicle_update import VehicleCommand, VehicleState, VehicleUpdate
from heli_model.wind import WindModel, WindSettings
from sim_vehicle.config import VehicleSettings


class Airframe:
    """The simulated helicopter: model, designed controller, physics step, state and wind.

    Parameters
    ----------
    model : HeliModel
        The vehicle model.
    settings : VehicleSettings
        The settings tree (timing, controller, wind).
    yaw_deg : float
        Initial heading; the vehicle starts at rest at the ground frame's origin.
    rng : numpy.random.Generator
        Source of the wind gusts.

    Attributes
    ----------
    model : HeliModel
    vehicle : VehicleUpdate
        The pure vehicle update (model, designed controller, physics step).
    state : VehicleState
        Its state: ``x``, ``delta`` and the flight controller's state.
    wind : WindModel
        The wind now drawn from (``wind.current()`` is the last sample).
    physics_dt_s : float
        Physics step, s.
    steps_per_control : int
        Physics steps per control period.
    """

    def __init__(self, model: HeliModel, settings: VehicleSettings, yaw_deg: float, rng: np.random.Generator) -> None:
        self.model = model
        self._rng = rng
        self.state = VehicleState(
            x=dynamics.hover_state(model, (0.0, 0.0, 0.0), math.radians(yaw_deg)),
            delta=np.zeros(4),
            controller=initial_controller_state(),
        )
        self._build(settings, None)

    def apply_settings(self, settings: VehicleSettings, old: VehicleSettings) -> None:
        """Use a new settings tree (``old`` the one in use): controller redesigned if its weights changed."""
        self._build(settings, old)

    def _build(self, settings: VehicleSettings, old: VehicleSettings | None) -> None:
        first = old is None
        self.physics_dt_s = settings.timing.physics_dt_s
        self.steps_per_control = settings.timing.physics_steps_per_control
        control_dt_s = self.physics_dt_s * self.steps_per_control
        controller_settings = dataclasses.replace(settings.controller, control_dt_s=control_dt_s)
        if first or controller_settings != self.controller.settings:
            self.vehicle = VehicleUpdate.build(self.model, controller_settings, self.physics_dt_s)
            self.state = self.vehicle.reset_controller(self.state)
        elif self.vehicle.physics_dt_s != self.physics_dt_s:
            self.vehicle = dataclasses.replace(self.vehicle, physics_dt_s=self.physics_dt_s)
        if first or settings.wind != old.wind:
            wind = settings.wind
            if wind.enabled:
                wind_settings = WindSettings(wind.steady_ned_m_s(), wind.gust_m_s, wind.gust_tau_s)
            else:
                wind_settings = self.model.wind
            self.wind = WindModel(wind_settings, self._rng)
            self._wind_calm = wind_settings.is_calm

    # ------------------------------------------------------------------ state views
    @property
    def x(self) -> np.ndarray:
        """Simulation state, (17,) or (21,) (see :mod:`heli_model.dynamics`)."""
        return self.state.x

    @property
    def delta(self) -> np.ndarray:
        """Rotor inputs held now, (4,) ``[d_lat, d_lon, d_ped, d_col]`` in [-1, 1]."""
        return self.state.delta

    @property
    def controller(self) -> ControlLaw:
        """The designed flight controller (``gains``, ``settings``); its state is in :attr:`state`."""
        return self.vehicle.law

    @property
    def pos_ned_m(self) -> np.ndarray:
        """Position, (3,) m NED in the ground frame (from the start point; ground at down 0)."""
        return dynamics.pos_ned_m(self.state.x)

    @property
    def vel_ned_m_s(self) -> np.ndarray:
        """Ground velocity, (3,) m/s NED."""
        return dynamics.vel_ned_m_s(self.state.x)

    @property
    def euler_rad(self) -> np.ndarray:
        """Roll, pitch, yaw, (3,) rad."""
        return dynamics.euler_rad(self.state.x)

    @property
    def body_rates_rad_s(self) -> np.ndarray:
        """Body rates p, q, r, (3,) rad/s."""
        return dynamics.body_rates_rad_s(self.state.x)

    @property
    def height_m(self) -> float:
        """Height above the ground (down 0 of the ground frame), m."""
        return -float(self.state.x[16])

    @property
    def healthy(self) -> bool:
        """True when every state is finite (the simulated state estimate is healthy)."""
        return bool(np.all(np.isfinite(self.state.x)))

    # ------------------------------------------------------------------ changes
    def reset_controller(self, zero_inputs: bool = False) -> None:
        """Reset the flight controller's state (and with ``zero_inputs`` the rotor inputs held)."""
        state = self.state._replace(delta=np.zeros(4)) if zero_inputs else self.state
        self.state = self.vehicle.reset_controller(state)

    def settle_on_ground(self) -> None:
        """Put the vehicle at rest on the ground below it, heading kept (a forced disarm in flight drops it)."""
        x = self.state.x
        n, e, psi = float(x[14]), float(x[15]), float(x[dynamics.IDX_PSI])
        x = dynamics.hover_state(self.model, (n, e, 0.0), psi)
        self.state = self.vehicle.reset_controller(self.state._replace(x=x, delta=np.zeros(4)))

    def restore_finite(self) -> None:
        """After an internal error: a non-finite state becomes a hover at the (finite part of the) position."""
        if not self.healthy:
            pos = np.nan_to_num(self.pos_ned_m)
            x = dynamics.hover_state(self.model, (pos[0], pos[1], min(0.0, pos[2])), 0.0)
            self.state = self.state._replace(x=x)

    def physics_step(self, setpoint: Setpoint | None) -> None:
        """One physics step of the pure update (the controller first when ``setpoint`` starts a control period)."""
        wind = None if self._wind_calm else self.wind.step(self.physics_dt_s)
        self.state = self.vehicle.update(self.state, VehicleCommand(setpoint, wind), self.physics_dt_s)
