"""Dynamic feasibility: the trajectory flown by the vehicle model in closed loop (paper 3.2).

The paper treats the vehicle's dynamics as a constraint on the smoothed path and "adjusts the
duration" until the helicopter can follow it. Here the check is done on the same model and
flight controller that ``sim-vehicle`` flies: the trajectory is sampled at the setpoint rate
(position, velocity, acceleration, yaw and, by default, yaw rate, as the companion streams
them) and ``heli_model.control.simulate_closed_loop`` predicts the vehicle's response with
the LQI of paper section 2.2 (eqs. 5-7) on the 13-state hover model.

A trajectory is *feasible* when no rotor input would clip (|delta| <= 1), the largest input
stays below ``max_abs_delta`` (a reserve for gusts and model error) and the tracking error
below ``max_tracking_error_m``. Otherwise every duration is stretched by ``stretch_step``
(``Trajectory.time_scaled``: speeds / k, accelerations / k^2, jerk / k^3, exact) until it is,
up to ``max_stretch``. The report gives the margin of the result.
"""

from __future__ import annotations

import functools
import logging
import math
import time
from dataclasses import dataclass

import numpy as np

from companion.errors import SmoothingError
from companion.flight.trajectory import Trajectory
from companion.numba_cache import compile_once
from companion.smoothing.settings import FeasibilitySettings

__all__ = ["CHANNELS", "FeasibilityReport", "FeasibilityChecker", "check", "check_and_stretch"]

logger = logging.getLogger(__name__)


@dataclass(frozen=True)
class FeasibilityReport:
    """Outcome of the closed-loop check.

    Attributes
    ----------
    feasible : bool
        The returned trajectory passes every criterion.
    trajectory : Trajectory
        The trajectory to fly: the input, or the input stretched by ``stretch``.
    stretch : float
        Factor applied to every duration (1: unchanged).
    max_abs_delta : float
        Largest normalised rotor input of the returned trajectory (1 is full travel).
    max_tracking_error_m : float
        Largest predicted distance from the reference (m).
    saturated : bool
        Some input would clip (|delta| > 1).
    delta_margin : float
        ``max_abs_delta`` setting minus the largest input (>= 0 when feasible).
    error_margin_m : float
        ``max_tracking_error_m`` setting minus the largest error.
    attempts : int
        Closed-loop simulations run.
    initial_max_abs_delta, initial_max_tracking_error_m : float
        The same figures for the input trajectory.
    reason : str
        Why the last simulated trajectory failed ('' when feasible).
    elapsed_s : float
        Wall-clock time of the whole check.
    peak_abs_delta : tuple of 4 floats
        Largest |delta| of each rotor input of the returned trajectory, in ``CHANNELS`` order
        (lateral cyclic, longitudinal cyclic, pedal, collective).
    rms_tracking_error_m : float
        Root mean square of the predicted tracking error of the returned trajectory (m).
    initial_saturated : bool
        The input trajectory would have clipped some rotor input.
    """

    feasible: bool
    trajectory: Trajectory
    stretch: float
    max_abs_delta: float
    max_tracking_error_m: float
    saturated: bool
    delta_margin: float
    error_margin_m: float
    attempts: int
    initial_max_abs_delta: float
    initial_max_tracking_error_m: float
    reason: str
    elapsed_s: float
    peak_abs_delta: tuple = (math.nan,) * 4
    rms_tracking_error_m: float = math.nan
    initial_saturated: bool = False

    def summary(self) -> dict:
        """The figures as plain data (flight record, ``companion plan --json``), without the
        trajectory."""
        return {
            "feasible": bool(self.feasible),
            "stretch": float(self.stretch),
            "max_abs_delta": float(self.max_abs_delta),
            "peak_abs_delta": {name: float(v) for name, v in zip(CHANNELS, self.peak_abs_delta)},
            "saturated": bool(self.saturated),
            "max_tracking_error_m": float(self.max_tracking_error_m),
            "rms_tracking_error_m": float(self.rms_tracking_error_m),
            "initial_max_abs_delta": float(self.initial_max_abs_delta),
            "initial_max_tracking_error_m": float(self.initial_max_tracking_error_m),
            "initial_saturated": bool(self.initial_saturated),
            "attempts": int(self.attempts),
            "reason": self.reason,
            "duration_s": float(self.trajectory.duration_s),
            "check_s": float(self.elapsed_s),
        }


#: Rotor inputs of the model, in the order of ``ClosedLoopResult.delta`` columns.
CHANNELS = ("lateral_cyclic", "longitudinal_cyclic", "pedal", "collective")


def describe(summary: dict) -> str:
    """One line of closed-loop figures from ``FeasibilityReport.summary()`` (or a recorded
    leg's), as ``companion plan`` and ``companion report`` print them."""
    f = summary
    peaks = " ".join(f"{name.split('_')[0][:3]} {v:.2f}" for name, v in f["peak_abs_delta"].items())
    text = (
        f"{'feasible' if f['feasible'] else 'INFEASIBLE'}, stretch x{f['stretch']:.3g} "
        f"({f['duration_s']:.1f} s); predicted max |delta| {f['max_abs_delta']:.2f} ({peaks}), "
        f"tracking error max {f['max_tracking_error_m']:.2f} m RMS {f['rms_tracking_error_m']:.2f} m; "
        f"check {1e3 * f['check_s']:.0f} ms"
    )
    if f["stretch"] > 1.0:
        text += (
            f"; first timing max |delta| {f['initial_max_abs_delta']:.2f}"
            f"{' (saturates)' if f['initial_saturated'] else ''}"
        )
    if f.get("reason"):
        text += f"; {f['reason']}"
    return text


#: The helicopter model's kernels compiled on a cold numba cache, reference machine (s).
MODEL_COMPILE_S = 4.0


def _model_first_calls() -> None:
    """The model's kernels called once: a vehicle update (RK4 sub-steps and the control law)
    and a two-sample closed-loop prediction, on the default model."""
    from heli_model.model import HeliModel
    from heli_model.vehicle_update import VehicleUpdate

    VehicleUpdate.build(HeliModel.default())
    FeasibilityChecker().warm_up()


@functools.cache
def warm_model() -> float:
    """Compile the helicopter model's kernels, or load them from numba's cache, once per process
    (before a check's clock: ``FeasibilityChecker`` calls it first). Logs ``compiling the
    helicopter model (once, about N s)`` when the cache is cold.

    Returns
    -------
    float
        The seconds the first call took in this process.
    """
    return compile_once("the helicopter model", _model_first_calls, model_probes(), MODEL_COMPILE_S)


def model_probes() -> tuple:
    """The kernels whose cache says whether the model's cache is cold: the control law, RK4."""
    from heli_model import control_kernel, rk4_kernel

    return control_kernel.law_step, rk4_kernel.integrate_rk4


@dataclass(frozen=True)
class _Outcome:
    max_abs_delta: float
    max_tracking_error_m: float
    saturated: bool
    peak_abs_delta: tuple = (math.nan,) * 4
    rms_tracking_error_m: float = math.nan


class FeasibilityChecker:
    """Closed-loop checker bound to one vehicle model (its LQI design is cached on the model).

    Parameters
    ----------
    model : heli_model.model.HeliModel, optional
        Default: ``HeliModel.default()`` (the R-50-class hover model).
    settings : FeasibilitySettings, optional
    controller_settings : heli_model.control.ControllerSettings, optional
        The flight controller's settings (default: the vehicle's defaults).
    """

    def __init__(self, model=None, settings: FeasibilitySettings | None = None, controller_settings=None) -> None:
        if model is None:
            from heli_model.model import HeliModel

            model = HeliModel.default()
        self.model = model
        self.settings = settings if settings is not None else FeasibilitySettings()
        if not isinstance(self.settings, FeasibilitySettings):
            raise SmoothingError(f"settings: expected a FeasibilitySettings, got {type(self.settings).__name__}")
        self.controller_settings = controller_settings

    def warm_up(self) -> float:
        """Design the LQI and build the closed loop now (about 0.4 s once per model) rather
        than in the first check; returns the seconds taken."""
        from heli_model.control import simulate_closed_loop

        start = time.perf_counter()
        t = np.array([0.0, 1.0 / self.settings.sample_rate_hz])
        zero = np.zeros((2, 3))
        simulate_closed_loop(
            self.model,
            t,
            zero,
            zero,
            zero,
            np.zeros(2),
            self.controller_settings,
            yaw_rate_rad_s=np.zeros(2) if self.settings.yaw_rate_feedforward else None,
        )
        return time.perf_counter() - start

    def reference(self, trajectory: Trajectory) -> tuple[np.ndarray, ...]:
        """Setpoint stream of ``trajectory`` at the setpoint rate, then a hover at its end.

        Returns
        -------
        t_s (K,), pos_ned_m (K, 3), vel_ned_m_s (K, 3), acc_ned_m_s2 (K, 3), yaw_rad (K,),
        yaw_rate_rad_s (K,)
        """
        traj = trajectory
        if traj.d == 2:
            traj = traj.to_ned(self.settings.down_m)
        if traj.d != 3:
            raise SmoothingError(f"trajectory: expected a 2D or 3D trajectory, got {traj.d}D")
        dt = 1.0 / self.settings.sample_rate_hz
        n = max(2, int(math.ceil(traj.duration_s / dt)) + 1)
        t_traj = np.minimum(np.arange(n) * dt, traj.duration_s)
        t_traj[-1] = traj.duration_s
        pos, vel, acc = traj.sample(t_traj)
        yaw = traj.yaw_rad(t_traj)
        rate = traj.yaw_rate_rad_s(t_traj)
        n_hold = int(math.ceil(self.settings.hold_after_s / dt))
        if n_hold:
            t_hold = traj.duration_s + dt * np.arange(1, n_hold + 1)
            t_traj = np.concatenate([t_traj, t_hold])
            pos = np.vstack([pos, np.repeat(pos[-1:], n_hold, axis=0)])
            vel = np.vstack([vel, np.zeros((n_hold, 3))])
            acc = np.vstack([acc, np.zeros((n_hold, 3))])
            yaw = np.concatenate([yaw, np.full(n_hold, yaw[-1])])
            rate = np.concatenate([rate, np.zeros(n_hold)])
        keep = np.concatenate([[True], np.diff(t_traj) > 1e-9])
        return t_traj[keep], pos[keep], vel[keep], acc[keep], yaw[keep], rate[keep]

    def simulate(self, trajectory: Trajectory):
        """Closed-loop prediction of ``trajectory``: a ``heli_model.control.ClosedLoopResult``."""
        from heli_model.control import simulate_closed_loop

        t, pos, vel, acc, yaw, rate = self.reference(trajectory)
        return simulate_closed_loop(
            self.model,
            t,
            pos,
            vel,
            acc,
            yaw,
            self.controller_settings,
            yaw_rate_rad_s=rate if self.settings.yaw_rate_feedforward else None,
        )

    def _outcome(self, trajectory: Trajectory) -> _Outcome:
        result = self.simulate(trajectory)
        peak = tuple(float(v) for v in np.max(np.abs(np.asarray(result.delta, dtype=float)), axis=0))
        return _Outcome(
            float(result.max_abs_delta),
            float(np.max(result.tracking_error_m)),
            bool(result.saturated),
            peak,
            float(result.rms_tracking_error_m),
        )

    def _failure(self, out: _Outcome) -> str:
        s = self.settings
        reasons = []
        if out.saturated:
            reasons.append(f"rotor inputs saturate (max |delta| {out.max_abs_delta:.3f})")
        elif out.max_abs_delta > s.max_abs_delta:
            reasons.append(f"max |delta| {out.max_abs_delta:.3f} > {s.max_abs_delta}")
        if out.max_tracking_error_m > s.max_tracking_error_m:
            reasons.append(f"tracking error {out.max_tracking_error_m:.3f} m > {s.max_tracking_error_m} m")
        return "; ".join(reasons)

    def check(self, trajectory: Trajectory) -> FeasibilityReport:
        """Closed-loop check of ``trajectory`` without stretching it."""
        return self._run(trajectory, stretch_allowed=False)

    def check_and_stretch(self, trajectory: Trajectory) -> FeasibilityReport:
        """Check ``trajectory`` and stretch its durations until it is feasible (or give up)."""
        return self._run(trajectory, stretch_allowed=True)

    def _run(self, trajectory: Trajectory, stretch_allowed: bool) -> FeasibilityReport:
        if not isinstance(trajectory, Trajectory):
            raise SmoothingError(f"trajectory: expected a Trajectory, got {type(trajectory).__name__}")
        warm_model()  # numba's compile before the clock (once per process)
        start = time.perf_counter()
        s = self.settings
        first = self._outcome(trajectory)
        out, reason, factor, candidate, attempts = first, self._failure(first), 1.0, trajectory, 1
        while reason and stretch_allowed and factor * s.stretch_step <= s.max_stretch * (1 + 1e-9):
            factor *= s.stretch_step
            candidate = trajectory.time_scaled(factor)
            out = self._outcome(candidate)
            reason = self._failure(out)
            attempts += 1
        if reason and stretch_allowed:
            logger.warning("feasibility: still infeasible after stretching x%.3g: %s", factor, reason)
        elif factor > 1.0:
            logger.info(
                "feasibility: stretched durations x%.3g (%.1f s -> %.1f s)",
                factor,
                trajectory.duration_s,
                candidate.duration_s,
            )
        return FeasibilityReport(
            feasible=not reason,
            trajectory=candidate,
            stretch=factor,
            max_abs_delta=out.max_abs_delta,
            max_tracking_error_m=out.max_tracking_error_m,
            saturated=out.saturated,
            delta_margin=s.max_abs_delta - out.max_abs_delta,
            error_margin_m=s.max_tracking_error_m - out.max_tracking_error_m,
            attempts=attempts,
            initial_max_abs_delta=first.max_abs_delta,
            initial_max_tracking_error_m=first.max_tracking_error_m,
            reason=reason,
            elapsed_s=time.perf_counter() - start,
            peak_abs_delta=out.peak_abs_delta,
            rms_tracking_error_m=out.rms_tracking_error_m,
            initial_saturated=first.saturated,
        )


def check(trajectory: Trajectory, model=None, settings: FeasibilitySettings | None = None) -> FeasibilityReport:
    """Closed-loop check of ``trajectory`` on ``model`` (default: the R-50-class model), no stretch."""
    return FeasibilityChecker(model, settings).check(trajectory)


def check_and_stretch(
    trajectory: Trajectory, model=None, settings: FeasibilitySettings | None = None
) -> FeasibilityReport:
    """Closed-loop check of ``trajectory``, stretching its durations until it is feasible.

    Parameters
    ----------
    trajectory : Trajectory
        2D (flown at ``settings.down_m``) or 3D NED.
    model : heli_model.model.HeliModel, optional
        Pass the same model object on every call: its LQI design is cached on it (the first
        design costs about a second).
    settings : FeasibilitySettings, optional

    Returns
    -------
    FeasibilityReport
    """
    return FeasibilityChecker(model, settings).check_and_stretch(trajectory)
