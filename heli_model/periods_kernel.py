"""Compiled kernel of several control periods in one call: the control law, then the RK4 sub-steps.

:func:`fly_periods` runs ``periods`` updates of :class:`heli_model.vehicle_update.VehicleUpdate`
with one setpoint and no wind (a fast-time flight's tick: 50 Hz setpoints, 100 Hz control), each
one control period of :func:`heli_model.control_kernel.law_step` followed by the sub-steps of
:func:`heli_model.rk4_kernel.integrate_rk4`: the same kernels, called in the same order, so the
state is the one ``update`` gives in a loop, to the bit. What it saves is the Python between
them (the controller state's fields unpacked and packed twice a period).

Packed arguments (floats, NaN = axis not commanded):

* ``setpoint`` (13,): position (3), velocity (3), acceleration (3), has_yaw (0 or 1), yaw,
  has_rate (0 or 1), yaw rate;
* ``controller`` (11,): LQI integrators (4), position integrators (3), heading reference,
  previous velocity command (3); ``controller_out`` the same after the last period.

This module imports numba: import it lazily (``VehicleUpdate.fly``).
"""

from __future__ import annotations

import numpy as np
from numba import njit

from heli_model import control_kernel, rk4_kernel

__all__ = ["OK", "FALL_BACK", "SETPOINT_SIZE", "CONTROLLER_SIZE", "fly_periods"]

OK = 0
"""Every period ran compiled."""
FALL_BACK = 1
"""A period would not run compiled (the caller runs ``update`` in a loop instead, which says why)."""
SETPOINT_SIZE = 13
CONTROLLER_SIZE = 11


@njit(cache=True)
def fly_periods(
    P, L, M, x, setpoint, controller, law_dt, h, n_sub, periods, x_out, delta, raw, vel_cmd, controller_out
):
    """``periods`` control periods of ``law_dt``, each with ``n_sub`` RK4 sub-steps of ``h``.

    Parameters
    ----------
    P : ndarray, shape (N_PARAMS,)
        ``control_kernel.pack_settings``.
    L : ndarray, shape (4, 26)
        The control-law matrix.
    M : ndarray, shape (n_core + 12, n_core + 7)
        ``dynamics.rk4_matrices`` for ``h``.
    x : ndarray, shape (17,) or (21,)
        The state; not modified.
    setpoint : ndarray, shape (13,)
    controller : ndarray, shape (11,)
    law_dt, h : float
    n_sub, periods : int
    x_out : ndarray, same shape as ``x``
        Output: the state after the last period.
    delta, raw : ndarray, shape (4,)
        Output: the last period's rotor inputs, clipped and not.
    vel_cmd : ndarray, shape (3,)
        Output: the last period's velocity command.
    controller_out : ndarray, shape (11,)
        Output: the controller state after the last period.

    Returns
    -------
    status : int
        :data:`OK`, or :data:`FALL_BACK` (the outputs are then undefined).
    saturated : bool
        The last period's.
    """
    p0, p1, p2, v0, v1, v2, a0, a1, a2 = (
        setpoint[0],
        setpoint[1],
        setpoint[2],
        setpoint[3],
        setpoint[4],
        setpoint[5],
        setpoint[6],
        setpoint[7],
        setpoint[8],
    )
    has_yaw, yaw, has_rate, rate = setpoint[9] != 0.0, setpoint[10], setpoint[11] != 0.0, setpoint[12]
    z0, z1, z2, z3 = controller[0], controller[1], controller[2], controller[3]
    i0, i1, i2, yaw_ref = controller[4], controller[5], controller[6], controller[7]
    prev0, prev1, prev2 = controller[8], controller[9], controller[10]
    calm = np.zeros(3)
    src = x.copy()
    saturated = False
    for _ in range(periods):
        status, saturated, z, integral, yaw_ref, cmd = control_kernel.law_step(
            P,
            L,
            src,
            p0,
            p1,
            p2,
            v0,
            v1,
            v2,
            a0,
            a1,
            a2,
            has_yaw,
            yaw,
            has_rate,
            rate,
            z0,
            z1,
            z2,
            z3,
            i0,
            i1,
            i2,
            yaw_ref,
            prev0,
            prev1,
            prev2,
            law_dt,
            delta,
            raw,
            vel_cmd,
        )
        if status != control_kernel.OK:
            return FALL_BACK, False
        z0, z1, z2, z3 = z
        i0, i1, i2 = integral
        prev0, prev1, prev2 = cmd
        if rk4_kernel.integrate_rk4(M, src, delta, h, n_sub, calm, rk4_kernel.WIND_CALM, x_out) != rk4_kernel.OK:
            return FALL_BACK, False
        src[:] = x_out
    controller_out[0], controller_out[1], controller_out[2], controller_out[3] = z0, z1, z2, z3
    controller_out[4], controller_out[5], controller_out[6], controller_out[7] = i0, i1, i2, yaw_ref
    controller_out[8], controller_out[9], controller_out[10] = prev0, prev1, prev2
    return OK, saturated
