"""Predict: every threat becomes a tube in space-time (DESIGN 7.1, paper section 3.3).

A threat reported at ``received_t_s`` moves on at constant velocity. Its *tube* at time t is
the ball centred on the predicted position with radius

    r(t) = radius_m + inflation_m + min(uncertainty_max_m, uncertainty_m_s * (t - received_t_s))

where ``inflation_m`` stands for the rotor radius plus a margin and the last term grows with
the prediction time of a *moving* threat (a static pop-up stays where it was reported). The
radius never shrinks with t, so checking an interval against its later end is conservative.

Pure: numpy only.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

__all__ = ["Tube", "TrajectoryTube", "along_samples", "predict_tubes", "STATIC_SPEED_M_S"]

#: A threat slower than this (m/s) counts as static: its tube does not grow.
STATIC_SPEED_M_S = 0.05


@dataclass(frozen=True)
class Tube:
    """One threat predicted in space-time.

    Attributes
    ----------
    threat_id : str
        The threat's ``uid`` (``<source>/<id>``, or ``id`` for a local threat).
    center_ned_m : ndarray, shape (3,)
        Position at ``t0_s``.
    vel_ned_m_s : ndarray, shape (3,)
    t0_s : float
        Time of the threat's last update (clock s).
    radius_m : float
        Inflated radius at ``t0_s`` (m).
    bare_radius_m : float
        The threat's own radius (m), for reports of a real intrusion.
    growth_m_s, growth_max_m : float
        Uncertainty growth rate (m/s) and cap (m).
    expires_t_s : float
        After this time the tube is gone (inf without ttl).
    """

    threat_id: str
    center_ned_m: np.ndarray
    vel_ned_m_s: np.ndarray
    t0_s: float
    radius_m: float
    bare_radius_m: float
    growth_m_s: float = 0.0
    growth_max_m: float = 0.0
    expires_t_s: float = math.inf

    def center_at(self, t_s: np.ndarray) -> np.ndarray:
        """Predicted centre (K, 3) at clock times ``t_s`` (K,)."""
        t = np.asarray(t_s, dtype=float).reshape(-1)
        return self.center_ned_m[None, :] + (t - self.t0_s)[:, None] * self.vel_ned_m_s[None, :]

    def radius_at(self, t_s: np.ndarray) -> np.ndarray:
        """Inflated radius (K,) at clock times ``t_s`` (K,); infinite lifetime is not assumed:
        after ``expires_t_s`` the radius is -inf (no tube)."""
        t = np.asarray(t_s, dtype=float).reshape(-1)
        grow = np.minimum(self.growth_max_m, self.growth_m_s * np.maximum(t - self.t0_s, 0.0))
        return np.where(t <= self.expires_t_s, self.radius_m + grow, -np.inf)

    @property
    def speed_m_s(self) -> float:
        return float(np.linalg.norm(self.vel_ned_m_s))


def along_samples(times_s: np.ndarray, ned_m: np.ndarray, t_s) -> np.ndarray:
    """Positions (K, 3) at times ``t_s`` (K,) on the polyline ``ned_m`` (N, 3) sampled at
    ``times_s`` (N,): linear between samples, held before the first and after the last."""
    t = np.asarray(t_s, dtype=float).reshape(-1)
    return np.stack([np.interp(t, times_s, ned_m[:, i]) for i in range(3)], axis=1)


@dataclass(frozen=True)
class TrajectoryTube:
    """Another vehicle along its shared trajectory (``companion.fleet``): a ball whose centre
    follows the samples (linearly between them; held before the first and after the last) and
    whose radius grows with the time since the message that carried them.

    Attributes
    ----------
    threat_id : str
    times_s : ndarray, shape (K,)
        Increasing sample times on the checking clock (s).
    ned_m : ndarray, shape (K, 3)
    radius_m : float
        Inflated radius at ``t0_s`` (m).
    bare_radius_m : float
    t0_s : float
        Time of the message (checking clock, s): the growth starts there.
    growth_m_s, growth_max_m : float
    expires_t_s : float
    """

    threat_id: str
    times_s: np.ndarray
    ned_m: np.ndarray
    radius_m: float
    bare_radius_m: float
    t0_s: float
    growth_m_s: float = 0.0
    growth_max_m: float = 0.0
    expires_t_s: float = math.inf

    def center_at(self, t_s: np.ndarray) -> np.ndarray:
        """Centre (K, 3) at clock times ``t_s`` (K,)."""
        return along_samples(self.times_s, self.ned_m, t_s)

    #: The same growth and end as a threat's tube (the same attributes).
    radius_at = Tube.radius_at

    @property
    def speed_m_s(self) -> float:
        """Fastest speed between two samples (0 for a hover)."""
        if len(self.times_s) < 2:
            return 0.0
        step = np.linalg.norm(np.diff(self.ned_m, axis=0), axis=1) / np.diff(self.times_s)
        return float(step.max())


def predict_tubes(threats, *, inflation_m: float, uncertainty_m_s: float = 0.0,
                  uncertainty_max_m: float = 0.0) -> list[Tube]:
    """Tubes of ``threats`` (local-frame ``Threat`` records) for the space-time check.

    Parameters
    ----------
    threats : iterable of companion.threats.model.Threat
        In the local NED frame, stamped on the checking clock.
    inflation_m : float
        Rotor radius plus margin, added to every radius (m).
    uncertainty_m_s, uncertainty_max_m : float
        Growth of a moving threat's radius per second since its last update, and its cap.

    Returns
    -------
    list of Tube
        A static threat's tube lives over the whole horizon: its ``ttl_s`` says how long its
        last report stays valid, not when it goes away (a source that still sees it reports it
        again before then), and a candidate that only waits for it to expire (a retime in front
        of a pop-up) would wait for ever and be decided again and again. A mover's tube ends
        when its report expires: its constant-velocity prediction is not trusted beyond.
    """
    out = []
    for th in threats:
        if hasattr(th, "tube"):                 # another vehicle: its own shape (companion.fleet)
            out.append(th.tube(inflation_m))
            continue
        vel = np.asarray(th.velocity_ned_m_s, dtype=float)
        moving = float(np.linalg.norm(vel)) > STATIC_SPEED_M_S
        out.append(Tube(th.uid, th.pos_ned_m, vel, float(th.received_t_s),
                        float(th.radius_m) + inflation_m, float(th.radius_m),
                        uncertainty_m_s if moving else 0.0, uncertainty_max_m if moving else 0.0,
                        th.expires_t_s if moving else math.inf))
    return out
