"""Settings of the smoothing and timing stage (paper section 3.2 and the duration adjustment).

Every default lives here and is documented; ``companion/config.py`` composes these frozen
dataclasses into the settings tree (``heli_common.typed_config.from_dict``).

Why these defaults fit the R-50-class hover model (``heli_model/profiles``, the default vehicle):

- ``speed_m_s = 8``: a third of the R-50's ~25 m/s envelope, and the speed at which the hover
  linearisation the LQI is designed on still holds (body rates and attitudes stay small).
- ``accel_m_s2 = 2`` and ``lat_accel_m_s2 = 2.5``: a steady 2.5 m/s^2 needs a bank (or pitch)
  of atan(2.5/9.81) = 14 deg, well inside the linear rotor-flapping range of the model
  (Xa = -Yb = 9.81 m/s^2 per rad of flapping), leaving stick travel for gusts.
- ``jerk_m_s3 = 3``: acceleration builds in 2/3 s. Measured on the default model and LQI
  (``feasibility.check_and_stretch``, G2 paths with K_max 0.1, yaw-rate feed-forward): the
  longitudinal cyclic peaks at about 0.19 x jerk, 0.57 of full travel at 3 m/s^3 (tracking
  error 0.22 m) but 0.9 at 5 m/s^3, above the 0.8 the check accepts.
- ``kappa_max_1_m = 0.1`` (10 m radius): at ``lat_accel_m_s2`` the tightest corner is flown at
  sqrt(2.5 * 10) = 5 m/s, the sharpest turn a 3.6 m rotor-span helicopter should be asked for
  in clutter.

The closed-loop check (``companion.smoothing.feasibility``) verifies these on the actual model
and stretches the durations when they are not trackable.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

from companion.errors import SmoothingError
from heli_common.typed_config import require_numbers

__all__ = ["TrajectoryLimits", "SmoothingSettings", "FeasibilitySettings"]


@dataclass(frozen=True)
class TrajectoryLimits:
    """Kinematic limits of a time-parameterised trajectory.

    Parameters
    ----------
    speed_m_s : float
        Maximum speed along the path (m/s). Default 8.
    accel_m_s2 : float
        Maximum longitudinal (along-track) acceleration and deceleration (m/s^2). Default 2.
    lat_accel_m_s2 : float
        Maximum lateral (centripetal) acceleration ``v^2 kappa`` (m/s^2). Default 2.5.
    jerk_m_s3 : float
        Maximum longitudinal jerk (m/s^3). Default 3.
    """

    speed_m_s: float = 8.0
    accel_m_s2: float = 2.0
    lat_accel_m_s2: float = 2.5
    jerk_m_s3: float = 3.0

    def __post_init__(self) -> None:
        require_numbers(
            SmoothingError, "limits", self, positive=("speed_m_s", "accel_m_s2", "lat_accel_m_s2", "jerk_m_s3")
        )

    def stretched(self, factor: float) -> TrajectoryLimits:
        """Limits of the same trajectory flown ``factor`` times slower (time scaled by factor).

        Speed scales by ``1/factor``, accelerations by ``1/factor**2``, jerk by
        ``1/factor**3``; the time-parameterisation of ``timing`` is exactly homogeneous under
        this scaling, so the new trajectory is the old one with every duration times ``factor``.
        """
        require_numbers(SmoothingError, "stretched", factor=factor)
        return TrajectoryLimits(
            speed_m_s=self.speed_m_s / factor,
            accel_m_s2=self.accel_m_s2 / factor**2,
            lat_accel_m_s2=self.lat_accel_m_s2 / factor**2,
            jerk_m_s3=self.jerk_m_s3 / factor**3,
        )


@dataclass(frozen=True)
class SmoothingSettings:
    """Geometry and timing settings of the smoother.

    Parameters
    ----------
    method : str
        ``"g2"`` (curvature-continuous, bounded by ``kappa_max_1_m``), ``"g1"`` (quartic
        midpoint interpolation) or ``"none"`` (the polyline, stopping at every corner).
    kappa_max_1_m : float
        K_max of the G2 smoother (1/m). Default 0.1 (10 m minimum turn radius).
    limits : TrajectoryLimits
        Speed, acceleration, lateral acceleration and jerk limits.
    grid_step_m : float
        Largest arc-length step of the speed-profile grid (m). Default 1; curved pieces are
        sampled more densely anyway (16 knots per piece and their curvature peaks).
    repair_max_halvings : int
        How many times a corner that clips an obstacle is shrunk by half before the polyline's
        own corner is kept (flown with a stop). Default 12 (corner down to 1/4096).
    """

    method: str = "g2"
    kappa_max_1_m: float = 0.1
    limits: TrajectoryLimits = TrajectoryLimits()
    grid_step_m: float = 1.0
    repair_max_halvings: int = 12

    def __post_init__(self) -> None:
        if self.method not in ("g1", "g2", "none"):
            raise SmoothingError(f"smoothing.method: expected 'g1', 'g2' or 'none', got {self.method!r}")
        require_numbers(SmoothingError, "smoothing", self, positive=("kappa_max_1_m", "grid_step_m"))
        if (
            isinstance(self.repair_max_halvings, bool)
            or not isinstance(self.repair_max_halvings, int)
            or self.repair_max_halvings < 0
        ):
            raise SmoothingError(
                f"smoothing.repair_max_halvings: expected an integer >= 0, got {self.repair_max_halvings!r}"
            )


@dataclass(frozen=True)
class FeasibilitySettings:
    """Settings of the closed-loop dynamic-feasibility check (``feasibility.check_and_stretch``).

    Parameters
    ----------
    enabled : bool
        Whether ``companion run`` checks every planned leg (and ``companion plan`` every
        smoothed path) on the closed loop and stretches its timing where it is infeasible.
        Default True. The check costs about 40 ms per minute of trajectory, after a one-off
        LQI design of about 0.4 s before the first leg.
    max_abs_delta : float
        Largest normalised actuator input accepted (|delta| <= 1 is full travel). Default 0.8,
        a 20 % reserve for gusts and model error.
    max_tracking_error_m : float
        Largest accepted distance between the simulated vehicle and the reference (m).
        Default 2.0.
    sample_rate_hz : float
        Rate at which the reference is sampled for the simulation (Hz). Default 50 (the
        companion's setpoint rate).
    stretch_step : float
        Factor by which durations grow per attempt (> 1). Default 1.25.
    max_stretch : float
        Largest total stretch factor tried before giving up (reported infeasible). Default 4.
    down_m : float
        Altitude (NED down, m) at which a 2D trajectory is flown in the simulation. Default
        -20 (the hover model does not depend on altitude).
    yaw_rate_feedforward : bool
        Whether the setpoints carry the yaw rate of the trajectory (``Trajectory.yaw_rate_rad_s``)
        besides the yaw. Default True: without it the heading loop alone drives the lateral
        cyclic into saturation in 5 m/s turns of 10 m radius on the default model.
    hold_after_s : float
        Seconds of hover at the end position simulated after the trajectory, so the settling
        error counts too. Default 2.
    """

    enabled: bool = True
    max_abs_delta: float = 0.8
    max_tracking_error_m: float = 2.0
    sample_rate_hz: float = 50.0
    stretch_step: float = 1.25
    max_stretch: float = 4.0
    down_m: float = -20.0
    yaw_rate_feedforward: bool = True
    hold_after_s: float = 2.0

    def __post_init__(self) -> None:
        require_numbers(
            SmoothingError,
            "feasibility",
            self,
            non_negative=("hold_after_s",),
            positive=("max_abs_delta", "max_tracking_error_m", "sample_rate_hz", "max_stretch", "stretch_step"),
        )
        if self.stretch_step <= 1.0:
            raise SmoothingError(f"feasibility.stretch_step: must be > 1, got {self.stretch_step!r}")
        if not isinstance(self.enabled, bool):
            raise SmoothingError(f"feasibility.enabled: expected true or false, got {self.enabled!r}")
        if not math.isfinite(self.down_m):
            raise SmoothingError(f"feasibility.down_m: must be finite, got {self.down_m!r}")
