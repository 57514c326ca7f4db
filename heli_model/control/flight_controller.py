"""The vehicle's flight controller: the pure per-tick law (:mod:`heli_model.control.law`) with its state."""

from __future__ import annotations

import numpy as np

from heli_model.control.law import ControlLaw, ControllerState, initial_controller_state
from heli_model.control.settings import ControllerSettings, Setpoint
from heli_model.model import HeliModel


class FlightController:
    """The vehicle's flight controller: PID position loop around the LQI (paper section 2.2).

    Parameters
    ----------
    model : HeliModel
    settings : ControllerSettings, optional

    Notes
    -----
    Call :meth:`reset` with the current state when the controller takes over (arming, mode
    change), then :meth:`update` once per control period. The LQI is designed for
    ``settings.control_dt_s``; :meth:`update` integrates with the ``dt_s`` it is given. The
    design uses the paper's 14-state model; a profile's servo lag is not part of it (the
    vehicle flies with it all the same, see the tests).

    Attributes
    ----------
    law : ControlLaw
        The design (gains, control-law matrix, settings); :meth:`ControlLaw.step` is pure.
    state : ControllerState
        Integrators, heading reference, last command and output.
    settings : ControllerSettings
    gains : LqiGains
    """

    def __init__(self, model: HeliModel, settings: ControllerSettings | None = None) -> None:
        self.model = model
        self.law = ControlLaw(model, settings)
        self.settings = self.law.settings
        self.gains = self.law.gains
        self.state: ControllerState = initial_controller_state()

    def reset(self, x: np.ndarray) -> None:
        """Clear the integrators and hold the current heading (call when taking over)."""
        self.state = self.law.reset(x)

    def update(self, x: np.ndarray, setpoint: Setpoint, dt_s: float) -> np.ndarray:
        """One control period: setpoint and state in, rotor inputs out.

        Parameters
        ----------
        x : ndarray, shape (17,) or (21,)
            Simulation state (see :mod:`heli_model.dynamics`).
        setpoint : Setpoint
        dt_s : float
            Time since the previous update, s.

        Returns
        -------
        delta : ndarray, shape (4,)
            ``[d_lat, d_lon, d_ped, d_col]`` in [-1, 1]. ``self.saturated`` tells whether it
            was clipped.
        """
        self.state = self.law.step(self.state, x, setpoint, dt_s)
        return self.state.delta

    @property
    def delta(self) -> np.ndarray:
        """Last output, (4,), clipped to [-1, 1]."""
        return self.state.delta

    @property
    def delta_unclipped(self) -> np.ndarray:
        """Last output before clipping, (4,) (``|.| > 1`` where the rotor saturated)."""
        return self.state.delta_unclipped

    @property
    def saturated(self) -> bool:
        """Whether the last output was clipped."""
        return self.state.saturated

    @property
    def vel_cmd_ned_m_s(self) -> np.ndarray:
        """Last velocity command of the position loop (after its limits), (3,) m/s NED."""
        return self.state.vel_cmd_ned_m_s

    @property
    def yaw_ref_rad(self) -> float:
        """Heading reference the LQI tracks, rad."""
        return self.state.yaw_ref_rad

    @property
    def z(self) -> np.ndarray:
        """LQI integrators of the u, v, w, psi errors, (4,)."""
        return np.array(self.state.z)

    @property
    def pos_integral_m(self) -> list:
        """PID position integrators, NED (3 floats)."""
        return list(self.state.pos_integral_m)
