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

Speed: the RK4 sub-steps of an update, with the ground stop after each, run in one call of a
compiled kernel (:func:`heli_model.rk4_kernel.integrate_rk4`, through :func:`integrate_compiled`)
that gives, bit for bit, what :func:`integrate_numpy` (:func:`heli_model.dynamics.step_rk4` in
a loop) gives; the numpy loop runs where the compiled kernel would not be exact
(:func:`heli_model.dynamics.compiled_kernels`). The sub-step plan of each time step is kept.
:meth:`VehicleUpdate.fly` runs several control periods with one setpoint (a fast-time flight's
tick) in one call of :func:`heli_model.periods_kernel.fly_periods`: the same kernels, the same
state to the bit, without the Python between the periods.
"""

from __future__ import annotations

import dataclasses
import math
from types import ModuleType
from typing import Any, NamedTuple

import numpy as np

from heli_model import dynamics
from heli_model.control import ControlLaw, ControllerSettings, ControllerState, Setpoint
from heli_model.model import N_INPUTS, HeliModel

__all__ = [
    "PHYSICS_DT_S",
    "VehicleCommand",
    "VehicleState",
    "VehicleUpdate",
    "integrate_compiled",
    "integrate_numpy",
    "stop_on_ground",
    "substeps",
]

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
    _plans: dict = dataclasses.field(default_factory=dict, init=False, repr=False, compare=False)

    @classmethod
    def build(
        cls, model: HeliModel, controller_settings: ControllerSettings | None = None, physics_dt_s: float = PHYSICS_DT_S
    ) -> VehicleUpdate:
        """Design the controller for ``controller_settings`` (cached on the model) and keep the step.

        Also runs one update of a hover, so that the compiled kernels are loaded here (numba's
        cache; compiled the first time on a machine, a few seconds) rather than in the first
        update of a flight, which the simulator runs in its real-time loop.
        """
        update = cls(model, ControlLaw(model, controller_settings), float(physics_dt_s))
        update.update(update.hover_state(), VehicleCommand(None), update.physics_dt_s)
        return update

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
                f"dt_s: expected 0 < dt_s <= the control period {control_dt_s:g} s, got {dt_s!r}"
            )
        x, delta, controller = state
        setpoint, wind = command
        if setpoint is not None:
            controller = law.step(controller, x, setpoint, control_dt_s)
            delta = controller.delta
        plan = self._plans.get(dt_s)
        if plan is None:
            plan = self._substep_plan(dt_s)
        n, h, M = plan
        kernels = dynamics.compiled_kernels(M.shape)
        if kernels is None:
            x = integrate_numpy(self.model, x, delta, h, n, wind)
        else:
            x = integrate_compiled(kernels, self.model, M, x, delta, h, n, wind)
        return VehicleState(x, delta, controller)

    def fly(self, state: VehicleState, command: VehicleCommand, dt_s: float, periods: int) -> VehicleState:
        """``periods`` updates of ``dt_s`` with the same command: :meth:`update` in a loop.

        The state is the loop's to the bit. Where the command has a setpoint and no wind and
        ``dt_s`` is the control period (a fast-time flight's tick), the periods run in one call
        of :func:`heli_model.periods_kernel.fly_periods` (the same kernels in the same order,
        without the Python between them); elsewhere, and wherever a kernel would not run, the loop.

        Parameters
        ----------
        state : VehicleState
        command : VehicleCommand
        dt_s : float
            As in :meth:`update`.
        periods : int
            >= 1.

        Returns
        -------
        VehicleState
        """
        fused = self._fly_compiled(state, command, dt_s, periods)
        if fused is not None:
            return fused
        for _ in range(periods):
            state = self.update(state, command, dt_s)
        return state

    def _fly_compiled(
        self, state: VehicleState, command: VehicleCommand, dt_s: float, periods: int
    ) -> VehicleState | None:
        setpoint, wind = command
        law = self.law
        if setpoint is None or wind is not None or dt_s != law.settings.control_dt_s:
            return None
        plan = self._plans.get(dt_s) or self._substep_plan(dt_s)
        n, h, M = plan
        x = state.x
        if dynamics.compiled_kernels(M.shape) is None or type(x) is not np.ndarray or x.shape != (M.shape[1] - 3,):
            return None
        args = law.compiled_arguments(state.controller, x, setpoint)
        if args is None:
            return None
        kernel = _periods_kernel()
        params, L, sp, controller = args
        x_next, delta, raw, vel_cmd, out = (
            np.empty(x.shape[0]),
            np.empty(N_INPUTS),
            np.empty(N_INPUTS),
            np.empty(3),
            np.empty(kernel.CONTROLLER_SIZE),
        )
        status, saturated = kernel.fly_periods(
            params, L, M, x, sp, controller, float(dt_s), h, n, int(periods), x_next, delta, raw, vel_cmd, out
        )
        if status != kernel.OK:
            return None
        z0, z1, z2, z3, i0, i1, i2, yaw_ref, c0, c1, c2 = out.tolist()
        return VehicleState(
            x_next,
            delta,
            ControllerState((z0, z1, z2, z3), (i0, i1, i2), yaw_ref, (c0, c1, c2), delta, raw, saturated, vel_cmd),
        )

    def _substep_plan(self, dt_s: float) -> tuple[int, float, np.ndarray]:
        """``(n, h, M)`` for an update of ``dt_s``: the sub-steps, their length and RK4 matrix (kept)."""
        n = substeps(dt_s, self.physics_dt_s)
        h = dt_s / n
        plan = n, h, dynamics.rk4_matrices(self.model, h)
        if len(self._plans) >= _MAX_PLANS:  # time steps that keep changing: keep the memo small
            self._plans.clear()
        self._plans[dt_s] = plan
        return plan


_PERIODS: list = []


def _periods_kernel() -> ModuleType:
    """:mod:`heli_model.periods_kernel`, imported on the first call (it imports numba)."""
    if not _PERIODS:
        from heli_model import periods_kernel

        _PERIODS.append(periods_kernel)
    return _PERIODS[0]


_MAX_PLANS = 32
"""Time steps whose sub-step plan a :class:`VehicleUpdate` keeps."""


def substeps(dt_s: float, physics_dt_s: float) -> int:
    """Number of equal RK4 sub-steps of at most ``physics_dt_s`` in ``dt_s``."""
    return max(1, math.ceil(dt_s / physics_dt_s - 1e-9))


def integrate_numpy(model: HeliModel, x: np.ndarray, delta, h: float, n: int, wind) -> np.ndarray:
    """``n`` RK4 sub-steps of ``h`` s with :func:`heli_model.dynamics.step_rk4`, each followed by the ground stop.

    The reference implementation of the update's physics (what :func:`integrate_compiled` gives
    bit for bit), run where the compiled kernels are not exact. ``wind`` as in
    :class:`VehicleCommand`.
    """
    per_substep = wind is not None and np.ndim(wind) == 2
    step_rk4 = dynamics.step_rk4
    for i in range(n):
        x = step_rk4(model, x, delta, h, wind[i] if per_substep else wind)
        if x[16] >= 0.0:
            stop_on_ground(x)
    return x


def integrate_compiled(
    kernels: ModuleType, model: HeliModel, M: np.ndarray, x, delta, h: float, n: int, wind
) -> np.ndarray:
    """:func:`integrate_numpy` in one call of the compiled kernel (:func:`heli_model.rk4_kernel.integrate_rk4`).

    Parameters
    ----------
    kernels : module
        :mod:`heli_model.rk4_kernel` (from :func:`heli_model.dynamics.compiled_kernels`).
    model : HeliModel
    M : ndarray, shape (n_core + 12, n_core + 7)
        ``dynamics.rk4_matrices(model, h)``.
    x : ndarray, shape (17,) or (21,)
    delta : array_like, shape (4,)
    h : float
    n : int
    wind : None, array_like (3,) or (>= n, 3)

    Returns
    -------
    x_next : ndarray, same shape as ``x``
    """
    if type(x) is not np.ndarray or x.dtype is not _FLOAT64:
        x = np.asarray(x, dtype=float)
    if x.shape != (M.shape[1] - 3,):
        dynamics.check_state(model, x)
    d = delta
    if type(d) is not np.ndarray or d.dtype is not _FLOAT64 or d.shape != (N_INPUTS,):
        d = _input(delta)
    if wind is None:
        flat, mode = _CALM, kernels.WIND_CALM
    elif type(wind) is np.ndarray and wind.dtype is _FLOAT64 and wind.shape == (3,):
        flat, mode = wind, kernels.WIND_CONSTANT
    else:
        flat, mode = _wind_rows(kernels, wind, n)
    x_next = np.empty(x.shape[0])
    status = kernels.integrate_rk4(M, x, d, h, n, flat, mode, x_next)
    if status != kernels.OK:
        _raise_for(kernels, status, delta, wind, mode)
    return x_next


_CALM = np.zeros(3)
_FLOAT64 = np.dtype(np.float64)


def _input(delta) -> np.ndarray:
    """The held input as floats, (4,); DynamicsError for another shape (as :func:`heli_model.dynamics.step_rk4`)."""
    if np.ndim(delta) == 1 and len(delta) == N_INPUTS:
        return np.array([float(v) for v in delta])
    raise dynamics.DynamicsError(f"delta: expected 4 inputs [d_lat, d_lon, d_ped, d_col], got {delta!r}")


def _wind_rows(kernels: ModuleType, wind, n: int) -> tuple[np.ndarray, int]:
    """The wind of :class:`VehicleCommand` as its rows of 3 floats one after the other, and how the kernel uses them."""
    rows = np.asarray(wind, dtype=float)
    if rows.ndim == 2 and rows.shape[0] >= n and rows.shape[1] == 3:
        return rows.ravel(), kernels.WIND_PER_SUBSTEP
    if rows.shape == (3,):
        return rows, kernels.WIND_CONSTANT
    raise dynamics.DynamicsError(
        f"wind_ned_m_s: expected (3,) or one row of 3 per RK4 sub-step ({n}, 3), got shape {rows.shape}"
    )


def _raise_for(kernels: ModuleType, status: int, delta, wind, mode: int) -> None:
    """The error of :func:`heli_model.dynamics.step_rk4` for a status of the kernel."""
    if status == kernels.BAD_DELTA:
        raise dynamics.DynamicsError(f"delta: expected 4 finite inputs, got {list(delta)!r}")
    if status == kernels.BAD_ANGLE:
        raise ValueError("math domain error")  # what math.cos says of an infinite heading in step_rk4
    row = wind[status] if mode == kernels.WIND_PER_SUBSTEP else wind
    raise dynamics.DynamicsError(f"wind_ned_m_s: expected 3 finite numbers, got {list(row)!r}")


def stop_on_ground(x: np.ndarray) -> None:
    """Flat ground at ``down = 0``: put a state that went below it back on it, no longer descending (in place)."""
    if x[16] >= 0.0:
        x[16] = 0.0
        if x[2] > 0.0:
            x[2] = 0.0
