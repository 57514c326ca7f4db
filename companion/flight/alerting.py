"""The traffic alerts of one flight: the one owner of what the ground station was told about
each threat (DESIGN 7.5; ArduPilot's ``AP_Avoidance::handle_threat_gcs_notify``).

``TrafficAlerts.check`` (the executor's ``alerts`` task at ``alerts.rate_hz``, and at once when
the monitor finds a conflict) predicts every known threat against the reference being flown
(``companion.threats.alerts.closest_approach``):

- a threat *first predicted to lose well clear*, or whose level rises (LOW -> HIGH), is alerted
  at once: a STATUSTEXT and a ``COLLISION``;
- while it stays predicted inside its volume, ``COLLISION`` again at most ``rate_hz``;
- once it no longer is (or is gone), a STATUSTEXT "clear" and ``COLLISION`` with threat level
  NONE for ``cleared_report_s``, then nothing.

``decided`` tells the decision that followed: a ``COLLISION`` with its ``MAV_COLLISION_ACTION``
(an evasion, a hold, a retime, a switch or a replan), at once; a decision about a threat not
alerted yet (its inflated tube was entered, not its well-clear volume) alerts it at LOW. Each
alert is a ``TrafficAlert`` handed to the ``FlightSink`` (``alert``): the daemon sends it to the
ground stations, records it and publishes it; a fast-time flight keeps it.

No asyncio and no I/O.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Callable

import numpy as np

from companion.flight.ports import FlightSink
from companion.threats.alerts import (
    LEVEL_NAMES,
    LOW,
    NONE,
    REPORT,
    AlertSettings,
    Approach,
    alert_statustext,
    closest_approach,
    collision_action,
    collision_fields,
)
from companion.threats.decision.spacetime import STATIC_ID

__all__ = ["TrafficAlert", "TrafficAlerts"]


@dataclasses.dataclass(frozen=True)
class TrafficAlert:
    """One alert about one threat, as it goes to the ground station.

    Attributes
    ----------
    t_s : float
        Mission time.
    threat_id : str
        The threat's id (its uid in the table for a non-local source).
    traffic : str
        ``drone`` or ``manned``.
    approach : Approach
        The predicted closest approach and the threat level.
    action : int
        ``MAV_COLLISION_ACTION`` being taken (REPORT before any decision).
    collision : dict
        The ``COLLISION`` message's fields.
    statustext : (str, str) or None
        Text and severity name, when this alert is told in words too (first, raised, cleared).
    """

    t_s: float
    threat_id: str
    traffic: str
    approach: Approach
    action: int
    collision: dict
    statustext: tuple[str, str] | None = None

    def as_record(self) -> dict:
        """The flight record's ``alert`` line (and the zenoh event)."""
        a = self.approach
        return {
            "t_s": self.t_s,
            "threat_id": self.threat_id,
            "traffic": self.traffic,
            "level": LEVEL_NAMES.get(a.level, str(a.level)),
            "action": int(self.action),
            "time_to_cpa_s": round(a.time_to_cpa_s, 3),
            "horizontal_m": round(a.horizontal_m, 3),
            "vertical_m": round(a.vertical_m, 3),
            "time_to_lowc_s": None if a.time_to_lowc_s is None else round(a.time_to_lowc_s, 3),
            "text": None if self.statustext is None else self.statustext[0],
        }


@dataclasses.dataclass
class _Told:
    """What was last told about one threat."""

    level: int
    action: int
    traffic: str
    approach: Approach
    sent_t_s: float
    cleared_t_s: float | None = None


class TrafficAlerts:
    """Alerts the ground stations about the traffic (see the module docstring).

    Parameters
    ----------
    settings : AlertSettings
    threats : callable (t_s) -> tuple of threats
        Every threat known at mission time ``t_s`` (local NED; ``ThreatSource.threats_at``).
    reference : callable () -> ActiveReference or None
        The reference being flown.
    own_down_m : callable () -> float or None
        The vehicle's down coordinate, for a reference of a 2D world (None: 0).
    now_s : callable () -> float
        Mission time.
    sink : FlightSink
    """

    def __init__(
        self,
        settings: AlertSettings,
        *,
        threats: Callable,
        reference: Callable,
        own_down_m: Callable[[], float | None],
        now_s: Callable[[], float],
        sink: FlightSink,
    ) -> None:
        self.settings = settings
        self.threats = threats
        self.reference = reference
        self.own_down_m = own_down_m
        self.now_s = now_s
        self.sink = sink
        self.told: dict[str, _Told] = {}
        self.alerts = 0
        n = int(round(settings.horizon_s / settings.step_s)) + 1
        self._tau_s = np.arange(n) * settings.step_s

    # ------------------------------------------------------------------ prediction
    def _own_track(self, t_s: float) -> np.ndarray | None:
        ref = self.reference()
        if ref is None:
            return None
        traj = ref.trajectory
        tau = np.clip(t_s + self._tau_s - ref.t0_s, 0.0, traj.duration_s)
        pos = np.atleast_2d(traj.sample(tau)[0])
        if pos.shape[1] == 3:
            return pos
        down = self.own_down_m()
        return np.column_stack([pos[:, :2], np.full(len(tau), 0.0 if down is None else float(down))])

    def _approach(self, own: np.ndarray, threat, t_s: float) -> Approach:
        centre = np.atleast_2d(threat.position_at(t_s + self._tau_s))
        return closest_approach(
            own, centre, float(threat.radius_m), _traffic(threat) == "manned", self.settings, self.settings.step_s
        )

    # ------------------------------------------------------------------ the task
    def check(self, now_mono_s: float | None = None) -> None:
        """Predict every known threat and tell what changed (the schedule's task)."""
        t = self.now_s()
        own = self._own_track(t)
        seen = set()
        if own is not None:
            for threat in self.threats(t):
                uid = _uid(threat)
                seen.add(uid)
                self._update(uid, _traffic(threat), self._approach(own, threat, t), t)
        for uid in [u for u in self.told if u not in seen]:
            told = self.told[uid]
            self._update(uid, told.traffic, dataclasses.replace(told.approach, level=NONE, time_to_lowc_s=None), t)

    def _update(self, uid: str, traffic: str, approach: Approach, t_s: float) -> None:
        told = self.told.get(uid)
        period = 1.0 / self.settings.rate_hz
        if approach.level != NONE:
            if told is None or told.cleared_t_s is not None or approach.level > told.level:
                action = REPORT if told is None else told.action
                self.told[uid] = _Told(approach.level, action, traffic, approach, t_s)
                self._tell(uid, traffic, approach, action, t_s, alert_statustext(uid, approach))
            else:
                told.level, told.approach = approach.level, approach
                if t_s - told.sent_t_s >= period - 1e-9:
                    told.sent_t_s = t_s
                    self._tell(uid, traffic, approach, told.action, t_s, None)
            return
        if told is None:
            return
        told.approach = approach
        if told.cleared_t_s is None:
            told.cleared_t_s, told.sent_t_s, told.level = t_s, t_s, NONE
            self._tell(uid, traffic, approach, told.action, t_s, alert_statustext(uid, approach))
        elif t_s - told.cleared_t_s > self.settings.cleared_report_s:
            del self.told[uid]
        elif t_s - told.sent_t_s >= period - 1e-9:
            told.sent_t_s = t_s
            self._tell(uid, traffic, approach, told.action, t_s, None)

    # ------------------------------------------------------------------ decisions
    def decided(self, decision) -> None:
        """Tell the decision that followed an alert: ``COLLISION`` with its action, at once."""
        conflict = getattr(decision, "conflict", None)
        if conflict is None or conflict.threat_id == STATIC_ID:  # the static world is not traffic
            return
        uid = conflict.threat_id
        action = collision_action(decision.kind, decision.label or "")
        t = self.now_s()
        told = self.told.get(uid)
        if told is None or told.cleared_t_s is not None:
            threat = next((th for th in self.threats(t) if _uid(th) == uid), None)
            traffic = "drone" if threat is None else _traffic(threat)
            approach = self._decision_approach(threat, t)
            self.told[uid] = told = _Told(approach.level, action, traffic, approach, t)
            text = alert_statustext(uid, approach)
        else:
            told.action, told.sent_t_s, text = action, t, None
        self._tell(uid, told.traffic, told.approach, action, t, text)

    def _decision_approach(self, threat, t_s: float) -> Approach:
        """The approach of a decision's threat not alerted yet (None: no longer held): as
        predicted now, at LOW at least (the companion's own protected volume was predicted to be
        entered)."""
        own = self._own_track(t_s)
        if own is None or threat is None:
            return Approach(0.0, float("nan"), float("nan"), None, LOW)
        approach = self._approach(own, threat, t_s)
        return approach if approach.level != NONE else dataclasses.replace(approach, level=LOW)

    def _tell(self, uid: str, traffic: str, approach: Approach, action: int, t_s: float, text) -> None:
        self.alerts += 1
        self.sink.alert(
            TrafficAlert(
                t_s, uid, traffic, approach, action, collision_fields(uid.rsplit("/", 1)[-1], approach, action), text
            )
        )


def _uid(threat) -> str:
    return getattr(threat, "uid", threat.id)


def _traffic(threat) -> str:
    return getattr(threat, "traffic", "drone")
