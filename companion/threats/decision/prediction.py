"""Predict: every threat becomes a tube in space-time (DESIGN 7.1, paper section 3.3).

A threat reported at ``received_t_s`` moves on at constant velocity. Its *tube* at time t is
the ball centred on the predicted position with radius

    r(t) = radius_m + inflation_m + min(uncertainty_max_m, uncertainty_m_s * (t - received_t_s))

where ``inflation_m`` stands for the rotor radius plus a margin and the last term grows with
the prediction time of a *moving* threat (a static pop-up stays where it was reported). The
radius never shrinks with t, so checking an interval against its later end is conservative.

A manned aircraft (``traffic == "manned"``, ADS-B) is judged by the aviation volumes, not by a
sphere about its airframe: its tube is the well-clear *cylinder*, of radius ``r(t)`` (the well
clear distance ``ThreatSettings.manned_h_m`` plus the inflation and the growth) and half-height
``manned_v_m``. Its clearance is ``max(h - r, vertical_scale (v - manned_v_m))`` for a
horizontal distance h and a vertical one v from its centre, with ``vertical_scale = manned_h_m
/ manned_v_m``: in horizontal metres, a metre of height worth eight of distance
(``spacetime.interval_clearance``). The decision looks at manned aircraft from farther away
(``manned_range_m``) and further ahead (``manned_horizon_s``: ``horizon_for``).

Pure: numpy only.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

__all__ = [
    "Tube",
    "TrajectoryTube",
    "along_samples",
    "predict_tubes",
    "tubes_for",
    "horizon_for",
    "range_for",
    "is_manned",
    "STATIC_SPEED_M_S",
]

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
    half_height_m : float
        A manned aircraft's cylinder: its half-height (m); inf: a ball (module docstring).
    vertical_scale : float
        The cylinder's horizontal metres per vertical metre of clearance.
    traffic : str
        ``drone`` or ``manned`` (``Threat.traffic``).
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
    half_height_m: float = math.inf
    vertical_scale: float = 1.0
    traffic: str = "drone"

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
    #: Another vehicle of the fleet is a ball at drone scale.
    half_height_m = math.inf
    vertical_scale = 1.0
    traffic = "drone"

    @property
    def speed_m_s(self) -> float:
        """Fastest speed between two samples (0 for a hover)."""
        if len(self.times_s) < 2:
            return 0.0
        step = np.linalg.norm(np.diff(self.ned_m, axis=0), axis=1) / np.diff(self.times_s)
        return float(step.max())


def is_manned(item) -> bool:
    """A threat or tube of manned traffic (``traffic == "manned"``; another vehicle of the fleet,
    which carries no traffic kind, is drone scale)."""
    return getattr(item, "traffic", "drone") == "manned"


def range_for(threat, settings) -> float:
    """How far (m) the decision looks for ``threat``: ``manned_range_m`` for manned traffic,
    else ``sensor_range_m`` (``ThreatSettings``)."""
    return settings.manned_range_m if is_manned(threat) else settings.sensor_range_m


def horizon_for(threats, settings) -> float:
    """The check's horizon (s) against ``threats`` (or their tubes): ``manned_horizon_s`` when
    one of them is manned traffic, else ``horizon_s``."""
    return settings.manned_horizon_s if any(map(is_manned, threats)) else settings.horizon_s


def tubes_for(threats, settings) -> list[Tube]:
    """``predict_tubes`` with the policy's inflation, growth and manned volume
    (``ThreatSettings``)."""
    return predict_tubes(
        threats,
        inflation_m=settings.inflation_m,
        uncertainty_m_s=settings.uncertainty_m_s,
        uncertainty_max_m=settings.uncertainty_max_m,
        manned_axes_m=(settings.manned_h_m, settings.manned_v_m),
    )


def predict_tubes(
    threats,
    *,
    inflation_m: float,
    uncertainty_m_s: float = 0.0,
    uncertainty_max_m: float = 0.0,
    manned_axes_m: tuple[float, float] | None = None,
) -> list[Tube]:
    """Tubes of ``threats`` (local-frame ``Threat`` records) for the space-time check.

    Parameters
    ----------
    threats : iterable of companion.threats.model.Threat
        In the local NED frame, stamped on the checking clock.
    inflation_m : float
        Rotor radius plus margin, added to every radius (m).
    uncertainty_m_s, uncertainty_max_m : float
        Growth of a moving threat's radius per second since its last update, and its cap.
    manned_axes_m : (float, float), optional
        Radius and half-height (m) of a manned aircraft's cylinder (module docstring). None:
        manned traffic is a ball of its own radius, like any threat.

    Returns
    -------
    list of Tube
        A static threat's tube lives over the whole horizon: its ``ttl_s`` says how long its
        last report stays valid, not when it goes away (a source that still sees it reports it
        again before then), and a candidate that only waits for it to expire (a retime in front
        of a pop-up) would wait for ever and be decided again and again. A mover's tube ends
        when its report expires: its constant-velocity prediction is not trusted beyond. A manned
        aircraft's lives over the whole (manned) horizon: its ttl is ADS-B's few seconds
        between reports, after which the threat table drops a target no longer heard.
    """
    out = []
    for th in threats:
        if hasattr(th, "tube"):  # another vehicle: its own shape (companion.fleet)
            out.append(th.tube(inflation_m))
            continue
        vel = np.asarray(th.velocity_ned_m_s, dtype=float)
        moving = float(np.linalg.norm(vel)) > STATIC_SPEED_M_S
        radius, half_height, ends = float(th.radius_m), math.inf, th.expires_t_s if moving else math.inf
        if manned_axes_m is not None and is_manned(th):
            radius, half_height = float(manned_axes_m[0]), float(manned_axes_m[1])
            ends = math.inf  # ADS-B's ttl drops a target not heard (the table's)
        out.append(
            Tube(
                th.uid,
                th.pos_ned_m,
                vel,
                float(th.received_t_s),
                radius + inflation_m,
                float(th.radius_m),
                uncertainty_m_s if moving else 0.0,
                uncertainty_max_m if moving else 0.0,
                ends,
                half_height,
                radius / half_height if math.isfinite(half_height) else 1.0,
                th.traffic,
            )
        )
    return out
