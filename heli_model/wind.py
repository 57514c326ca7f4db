"""Seeded wind for the SITL helicopter: a steady wind plus first-order Gauss-Markov gusts.

The gust on each NED axis is an Ornstein-Uhlenbeck (first-order Gauss-Markov) process with
standard deviation ``gust_std_m_s`` and correlation time ``gust_tau_s``, the simplest member of
the Dryden family (MIL-F-8785C models each gust component as coloured noise; one pole is the
first-order approximation). It is sampled *exactly* at the physics step,

    g[k+1] = exp(-dt/T) g[k] + sigma * sqrt(1 - exp(-2 dt/T)) * n[k],   n ~ N(0, I),

so the statistics do not depend on the step size. The wind enters the dynamics as an airspeed
difference (see :mod:`heli_model.dynamics`): the aerodynamic derivatives act on the body
velocity relative to the air.

Pure numerics: no I/O. Randomness only through the ``numpy.random.Generator`` passed in.
"""

from __future__ import annotations

import dataclasses
import math

import numpy as np


class WindError(ValueError):
    """A wind setting is out of range; the message names the key."""


@dataclasses.dataclass(frozen=True)
class WindSettings:
    """Wind of a profile or of the ``--wind`` options.

    Attributes
    ----------
    steady_ned_m_s : tuple of 3 float
        Mean wind velocity in NED, m/s (the velocity of the air, e.g. ``(5, 0, 0)`` is a wind
        blowing *towards* north).
    gust_std_m_s : float
        Standard deviation of the gust on each axis, m/s (0 = no gusts).
    gust_tau_s : float
        Correlation time of the gusts, s (> 0).
    """

    steady_ned_m_s: tuple[float, float, float] = (0.0, 0.0, 0.0)
    gust_std_m_s: float = 0.0
    gust_tau_s: float = 2.0

    def __post_init__(self) -> None:
        if len(self.steady_ned_m_s) != 3 or not all(math.isfinite(float(v)) for v in self.steady_ned_m_s):
            raise WindError(f"steady_ned_m_s: expected 3 finite numbers, got {self.steady_ned_m_s!r}")
        if not (math.isfinite(self.gust_std_m_s) and self.gust_std_m_s >= 0.0):
            raise WindError(f"gust_std_m_s: expected a number >= 0, got {self.gust_std_m_s!r}")
        if not (math.isfinite(self.gust_tau_s) and self.gust_tau_s > 0.0):
            raise WindError(f"gust_tau_s: expected a number > 0, got {self.gust_tau_s!r}")

    @property
    def is_calm(self) -> bool:
        """True when there is neither steady wind nor gusts."""
        return self.gust_std_m_s == 0.0 and not any(self.steady_ned_m_s)


class WindModel:
    """Stateful, seeded wind generator: steady wind plus Gauss-Markov gusts.

    Parameters
    ----------
    settings : WindSettings
        Steady wind and gust statistics.
    rng : numpy.random.Generator
        Source of the gust noise (seed it for replayable flights).

    Examples
    --------
    >>> wind = WindModel(WindSettings((3.0, 0.0, 0.0), 1.0, 2.0), np.random.default_rng(1))
    >>> w = wind.step(0.0025)        # (3,) NED wind, m/s, for the next physics step
    """

    _BLOCK = 1024
    """Gust noise is drawn from ``rng`` in blocks of this many samples (3 axes each)."""

    def __init__(self, settings: WindSettings, rng: np.random.Generator) -> None:
        self.settings = settings
        self._rng = rng
        self._steady = tuple(float(v) for v in settings.steady_ned_m_s)
        # start in the stationary distribution so there is no transient
        if settings.gust_std_m_s > 0:
            self._gust = [float(v) for v in rng.normal(0.0, settings.gust_std_m_s, 3)]
        else:
            self._gust = [0.0, 0.0, 0.0]
        self._noise: list = []
        self._next = 0
        self._cached_dt = -1.0
        self._decay = 1.0
        self._drive = 0.0

    def current(self) -> np.ndarray:
        """Wind velocity now, (3,) NED m/s, without advancing the process."""
        s, g = self._steady, self._gust
        return np.array([s[0] + g[0], s[1] + g[1], s[2] + g[2]])

    def step(self, dt_s: float) -> np.ndarray:
        """Advance the gust process by ``dt_s`` and return the wind, (3,) NED m/s."""
        if not (dt_s > 0.0):
            raise WindError(f"dt_s: expected a step > 0, got {dt_s!r}")
        sigma = self.settings.gust_std_m_s
        if sigma > 0.0:
            if dt_s != self._cached_dt:
                self._decay = math.exp(-dt_s / self.settings.gust_tau_s)
                self._drive = sigma * math.sqrt(1.0 - self._decay * self._decay)
                self._cached_dt = dt_s
            if self._next >= len(self._noise):
                self._noise = self._rng.standard_normal((self._BLOCK, 3)).tolist()
                self._next = 0
            n = self._noise[self._next]
            self._next += 1
            k, d, g = self._decay, self._drive, self._gust
            g[0] = k * g[0] + d * n[0]
            g[1] = k * g[1] + d * n[1]
            g[2] = k * g[2] + d * n[2]
        return self.current()
