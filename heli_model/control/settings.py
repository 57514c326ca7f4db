"""Flight-controller settings, the setpoint record and the LQI weights (Bryson's rule).

Choice of Q and R (Bryson's rule)
---------------------------------
``Q = diag(1 / dx_max^2)`` and ``R = diag(1 / delta_max^2)`` with the largest acceptable
excursion of each state and input during a manoeuvre (:data:`BRYSON_STATE_MAX`,
:data:`BRYSON_INTEGRATOR_MAX`, :data:`BRYSON_INPUT_MAX`):

=========================  ==============  ==============================================
state                      max excursion   why
=========================  ==============  ==============================================
u, v, w                    0.5 m/s         velocity tracking error budget
p, q, r                    1.0 rad/s       rates are free to move, lightly weighted
phi, theta                 0.35 rad        20 degrees of bank / pitch
a, b                       0.1 rad         rotor flapping (tip-path plane) deflection
r_fb, c, d                 1.0             internal rotor / damper states, lightly weighted
psi                        0.2 rad         heading error
int(u, v, w) dt            0.3 m           integral of the velocity error (a position drift)
int(psi) dt                0.2 rad s
inputs d_lat .. d_col      0.4             40 % of full stick for a typical manoeuvre,
                                           so steps and 5 m/s turns stay clear of |delta| = 1
=========================  ==============  ==============================================
"""

from __future__ import annotations

import dataclasses
import math
from typing import Any

import numpy as np

from heli_common.typed_config import from_dict as _typed_from_dict
from heli_common.typed_config import require_numbers
from heli_model.dynamics import IDX_PSI
from heli_model.model import N_INPUTS, N_STATES

__all__ = [
    "BRYSON_INPUT_MAX",
    "BRYSON_INTEGRATOR_MAX",
    "BRYSON_STATE_MAX",
    "DEFAULT_Q_WEIGHTS",
    "DEFAULT_R_WEIGHTS",
    "N_LQI_STATES",
    "N_TRACKED",
    "TRACKED_INDICES",
    "ControlError",
    "ControllerSettings",
    "Setpoint",
    "bryson_weights",
    "check_weights",
    "setpoint_axes",
]

_FLOAT64 = np.dtype(np.float64)

N_LQI_STATES = N_STATES + 1
"""14: the hover model plus the heading."""
N_TRACKED = 4
"""Tracked outputs u, v, w, psi."""
TRACKED_INDICES = (0, 1, 2, IDX_PSI)

BRYSON_STATE_MAX: tuple[float, ...] = (
    0.5,
    0.5,
    0.5,  # u v w   (m/s)
    1.0,
    1.0,
    1.0,  # p q r   (rad/s)
    0.35,
    0.35,  # phi theta (rad)
    0.1,
    0.1,  # a b (rad)
    1.0,
    1.0,
    1.0,  # r_fb c d
    0.2,  # psi (rad)
)
BRYSON_INTEGRATOR_MAX: tuple[float, ...] = (0.3, 0.3, 0.3, 0.2)
BRYSON_INPUT_MAX: tuple[float, ...] = (0.4, 0.4, 0.4, 0.4)


def bryson_weights(state_max, integrator_max, input_max) -> tuple[tuple[float, ...], tuple[float, ...]]:
    """Diagonal Q (18) and R (4) weights from the largest acceptable excursions (Bryson's rule)."""
    q = tuple(1.0 / float(v) ** 2 for v in (*state_max, *integrator_max))
    r = tuple(1.0 / float(v) ** 2 for v in input_max)
    return q, r


DEFAULT_Q_WEIGHTS, DEFAULT_R_WEIGHTS = bryson_weights(BRYSON_STATE_MAX, BRYSON_INTEGRATOR_MAX, BRYSON_INPUT_MAX)


class ControlError(ValueError):
    """Wrong controller arguments or settings; the message names the argument or key."""


@dataclasses.dataclass(frozen=True)
class ControllerSettings:
    """Tunables of the flight controller (all have defaults; TOML tables override them).

    Attributes
    ----------
    control_dt_s : float
        Control period the LQI is designed for, s (100 Hz).
    q_weights : tuple of 18 float
        Diagonal of Q: 14 states ``[u v w p q r phi theta a b r_fb c d psi]`` then the 4
        integrators of ``u v w psi`` (Bryson defaults, see the module docstring).
    r_weights : tuple of 4 float
        Diagonal of R for ``[d_lat d_lon d_ped d_col]``.
    kp_xy_1_s, ki_xy_1_s2, kd_xy : float
        Horizontal PID position gains (velocity command per metre, per metre-second, and per
        m/s of velocity error).
    kp_z_1_s, ki_z_1_s2, kd_z : float
        Vertical PID position gains.
    pos_integral_max_m_s : float
        Clamp of each PID integrator's contribution to the velocity command, m/s.
    max_speed_xy_m_s : float
        Horizontal speed limit of the velocity command.
    max_climb_m_s, max_descent_m_s : float
        Vertical speed limits (up, down), m/s.
    max_accel_m_s2 : float
        Limit of the acceleration feed-forward magnitude, m/s^2.
    cmd_accel_xy_m_s2, cmd_accel_z_m_s2 : float
        Slew-rate limit of the velocity command (horizontal vector, vertical), m/s^2: a
        position step becomes a velocity ramp instead of a velocity step, so the rotor inputs
        do not saturate. Keep them above the trajectory's accelerations so they only act on
        steps and large errors.
    max_yaw_rate_rad_s : float
        Limit of the yaw-rate feed-forward and slew-rate limit of the heading reference,
        rad/s (a heading step is flown as a turn at this rate).
    """

    control_dt_s: float = 0.01
    q_weights: tuple[float, ...] = DEFAULT_Q_WEIGHTS
    r_weights: tuple[float, ...] = DEFAULT_R_WEIGHTS
    kp_xy_1_s: float = 1.0
    ki_xy_1_s2: float = 0.0
    kd_xy: float = 0.0
    kp_z_1_s: float = 1.0
    ki_z_1_s2: float = 0.0
    kd_z: float = 0.0
    pos_integral_max_m_s: float = 1.0
    max_speed_xy_m_s: float = 12.0
    max_climb_m_s: float = 3.0
    max_descent_m_s: float = 2.0
    max_accel_m_s2: float = 5.0
    cmd_accel_xy_m_s2: float = 3.0
    cmd_accel_z_m_s2: float = 2.0
    max_yaw_rate_rad_s: float = 1.5

    def __post_init__(self) -> None:
        positive = (
            "control_dt_s",
            "max_speed_xy_m_s",
            "max_climb_m_s",
            "max_descent_m_s",
            "max_accel_m_s2",
            "max_yaw_rate_rad_s",
            "cmd_accel_xy_m_s2",
            "cmd_accel_z_m_s2",
        )
        non_negative = ("kp_xy_1_s", "ki_xy_1_s2", "kd_xy", "kp_z_1_s", "ki_z_1_s2", "kd_z", "pos_integral_max_m_s")
        require_numbers(ControlError, "controller", self, positive=positive, non_negative=non_negative)
        check_weights(self.q_weights, N_LQI_STATES + N_TRACKED, "q_weights", allow_zero=True)
        check_weights(self.r_weights, N_INPUTS, "r_weights", allow_zero=False)

    @classmethod
    def from_dict(cls, data: Any, prefix: str = "") -> ControllerSettings:
        """Build from a (TOML) table; wrong keys or values raise :class:`ControlError` naming them."""
        return _typed_from_dict(cls, data, prefix, ControlError)


def check_weights(w: Any, n: int, name: str, *, allow_zero: bool) -> tuple[float, ...]:
    """``n`` finite weights (>= 0, or > 0 unless ``allow_zero``) as a tuple; :class:`ControlError` names the bad one."""
    try:
        values = tuple(float(v) for v in w)
    except (TypeError, ValueError):
        raise ControlError(f"{name}: expected {n} numbers, got {w!r}") from None
    if len(values) != n:
        raise ControlError(f"{name}: expected {n} weights, got {len(values)}")
    for i, v in enumerate(values):
        if not math.isfinite(v) or v < 0 or (v == 0 and not allow_zero):
            bound = ">= 0" if allow_zero else "> 0"
            raise ControlError(f"{name}[{i}]: expected a finite weight {bound}, got {v!r}")
    return values


@dataclasses.dataclass(frozen=True)
class Setpoint:
    """What the vehicle is asked to do; ``None`` = not commanded.

    A NaN entry inside a vector leaves that axis alone (MAVLink type_mask per axis). An axis
    with a position is position-controlled (the velocity and acceleration are its
    feed-forward); an axis with only a velocity is velocity-controlled (its position integrator
    is reset); an axis with neither brakes to zero velocity.

    Attributes
    ----------
    pos_ned_m : (3,) or None
    vel_ned_m_s : (3,) or None
    acc_ned_m_s2 : (3,) or None
    yaw_rad : float or None
    yaw_rate_rad_s : float or None
    """

    pos_ned_m: Any = None
    vel_ned_m_s: Any = None
    acc_ned_m_s2: Any = None
    yaw_rad: float | None = None
    yaw_rate_rad_s: float | None = None


def setpoint_axes(v: Any, name: str) -> tuple[float, float, float] | None:
    """The three axes of a setpoint vector as floats (NaN = not commanded), or None; infinities raise."""
    if v is None:
        return None
    if type(v) is np.ndarray and v.dtype is _FLOAT64 and v.shape == (3,):
        a, b, c = v.tolist()  # the fast path of the lines below (the fast-time flights' arrays)
    else:
        try:
            a, b, c = v
            a, b, c = float(a), float(b), float(c)
        except (TypeError, ValueError):
            raise ControlError(f"setpoint.{name}: expected 3 numbers, got {v!r}") from None
    if a * 0.0 + b * 0.0 + c * 0.0 != 0.0:  # an infinity or a NaN among them
        for x in (a, b, c):
            if math.isinf(x):
                raise ControlError(f"setpoint.{name}: expected finite numbers (NaN = axis not commanded), got {v!r}")
    return a, b, c
