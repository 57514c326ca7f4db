"""Scripted threat sequences for ``companion threat play`` (DESIGN section 6, paper Fig. 8).

A scenario is a TOML file of events, each at a time after the start of the playback::

    description = "a pop-up far ahead, then a moving threat met close by"

    [[event]]
    at_s = 5.0
    action = "add"            # add | move | remove
    id = "p1"
    kind = "popup"            # popup | moving (default: moving if vel is non-zero)
    pos = [120.0, 0.0, -20.0] # local NED metres ... or lat = .., lon = .., alt_m = ..
    radius_m = 6.0
    ttl_s = 120.0             # optional (default: until removed)

    [[event]]
    at_s = 20.0
    action = "move"           # a new position and/or velocity; the rest as last sent (without
                              # pos: where the threat has moved to since, at constant velocity)
    id = "p1"
    pos = [120.0, 10.0, -20.0]
    vel = [0.0, -1.0, 0.0]

    [[event]]
    at_s = 40.0
    action = "remove"
    id = "p1"

Errors name the file, the event and the key. Pure: no zenoh here.
"""

from __future__ import annotations

import math
import tomllib
from dataclasses import dataclass, replace
from pathlib import Path

from companion.errors import ThreatPayloadError
from companion.threats.model import Threat
from companion.threats.transport import codec

__all__ = ["ScenarioEvent", "Scenario", "load_scenario", "scenario_from_dict", "ScenarioError"]

ACTIONS = ("add", "move", "remove")
EVENT_KEYS = {"at_s", "action", "id", "kind", "pos", "lat", "lon", "alt_m", "vel", "radius_m", "ttl_s"}


class ScenarioError(ThreatPayloadError):
    """A scenario file is invalid (the message names the file, event and key)."""


@dataclass(frozen=True)
class ScenarioEvent:
    """One scripted step.

    Attributes
    ----------
    at_s : float
        Time after the start of the playback (s).
    action : str
        ``add`` or ``move`` (PUT ``threat``) or ``remove`` (DELETE ``threat_id``).
    threat_id : str
    threat : Threat or None
        The full threat sent by ``add`` / ``move`` (None for ``remove``).
    """

    at_s: float
    action: str
    threat_id: str
    threat: Threat | None


@dataclass(frozen=True)
class Scenario:
    """A validated scenario: events sorted by time."""

    description: str
    events: tuple[ScenarioEvent, ...]

    @property
    def duration_s(self) -> float:
        return self.events[-1].at_s if self.events else 0.0


def _number(value, where: str) -> float:
    if isinstance(value, bool) or not isinstance(value, (int, float)) or not math.isfinite(value):
        raise ScenarioError(f"{where}: expected a finite number, got {value!r}")
    return float(value)


def _vector(value, where: str) -> tuple:
    if not isinstance(value, list) or len(value) != 3:
        raise ScenarioError(f"{where}: expected a list of 3 numbers, got {value!r}")
    return tuple(_number(v, f"{where}[{i}]") for i, v in enumerate(value))


def _position(event: dict, where: str, required: bool) -> tuple[str, tuple] | None:
    has_local = "pos" in event
    has_global = any(k in event for k in ("lat", "lon", "alt_m"))
    if has_local and has_global:
        raise ScenarioError(f"{where}.pos: give either pos (local NED) or lat/lon/alt_m, not both")
    if has_local:
        return "local_ned", _vector(event["pos"], f"{where}.pos")
    if has_global:
        for key in ("lat", "lon", "alt_m"):
            if key not in event:
                raise ScenarioError(f"{where}.{key}: missing (lat, lon and alt_m go together)")
        return "global", tuple(_number(event[k], f"{where}.{k}") for k in ("lat", "lon", "alt_m"))
    if required:
        raise ScenarioError(f"{where}.pos: missing (pos = [N, E, D] or lat/lon/alt_m)")
    return None


def _event(raw, index: int, known: dict[str, tuple[Threat, float]], name: str) -> ScenarioEvent:
    where = f"{name}: event[{index}]"
    if not isinstance(raw, dict):
        raise ScenarioError(f"{where}: expected a table")
    unknown = sorted(set(raw) - EVENT_KEYS)
    if unknown:
        raise ScenarioError(f"{where}.{unknown[0]}: unknown key (known: {', '.join(sorted(EVENT_KEYS))})")
    for key in ("at_s", "action", "id"):
        if key not in raw:
            raise ScenarioError(f"{where}.{key}: missing")
    at_s = _number(raw["at_s"], f"{where}.at_s")
    if at_s < 0:
        raise ScenarioError(f"{where}.at_s: must be >= 0, got {at_s}")
    action = raw["action"]
    if action not in ACTIONS:
        raise ScenarioError(f"{where}.action: expected one of {', '.join(ACTIONS)}, got {action!r}")
    try:
        threat_id = codec.check_id(raw["id"])
    except ThreatPayloadError as exc:
        raise ScenarioError(f"{where}.{exc}") from None
    if action == "remove":
        extra = sorted(set(raw) - {"at_s", "action", "id"})
        if extra:
            raise ScenarioError(f"{where}.{extra[0]}: not used by 'remove'")
        known.pop(threat_id, None)
        return ScenarioEvent(at_s, action, threat_id, None)
    previous, previous_at_s = known.get(threat_id, (None, 0.0))
    if action == "move" and previous is None:
        raise ScenarioError(f"{where}.id: 'move' of {threat_id!r}, which no earlier 'add' created")
    position = _position(raw, where, required=action == "add")
    vel = _vector(raw["vel"], f"{where}.vel") if "vel" in raw else None
    if action == "add":
        if "radius_m" not in raw:
            raise ScenarioError(f"{where}.radius_m: missing")
        vel = vel or (0.0, 0.0, 0.0)
        kind = raw.get("kind", "moving" if any(vel) else "popup")
        ttl = _number(raw["ttl_s"], f"{where}.ttl_s") if "ttl_s" in raw else None
        threat = Threat(
            threat_id, kind, position[0], position[1], vel, _number(raw["radius_m"], f"{where}.radius_m"), ttl, 0.0
        )
    else:
        threat = previous
        if position is not None:
            threat = replace(threat, frame=position[0], position=position[1])
        elif threat.frame == "local_ned":
            # where the threat is by now (constant velocity since it was last sent)
            moved = threat.position_at(threat.received_t_s + at_s - previous_at_s)
            threat = replace(threat, position=tuple(float(x) for x in moved))
        if vel is not None:
            threat = replace(threat, velocity_ned_m_s=vel)
        if "kind" in raw:
            threat = replace(threat, kind=raw["kind"])
        if "radius_m" in raw:
            threat = replace(threat, radius_m=_number(raw["radius_m"], f"{where}.radius_m"))
        if "ttl_s" in raw:
            threat = replace(threat, ttl_s=_number(raw["ttl_s"], f"{where}.ttl_s"))
        if threat.kind == "popup" and any(threat.velocity_ned_m_s):
            threat = replace(threat, kind="moving")
    try:
        codec.encode(threat)  # the same validation as the receiver's
    except ThreatPayloadError as exc:
        raise ScenarioError(f"{where}: {exc}") from None
    known[threat_id] = (threat, at_s)
    return ScenarioEvent(at_s, action, threat_id, threat)


def scenario_from_dict(data: dict, name: str = "scenario") -> Scenario:
    """Validate a parsed scenario (see the module docstring)."""
    if not isinstance(data, dict):
        raise ScenarioError(f"{name}: expected a table")
    unknown = sorted(set(data) - {"description", "event"})
    if unknown:
        raise ScenarioError(f"{name}: {unknown[0]}: unknown key (known: description, event)")
    raw_events = data.get("event", [])
    if not isinstance(raw_events, list) or not raw_events:
        raise ScenarioError(f"{name}: event: expected at least one [[event]] table")
    order = sorted(
        range(len(raw_events)),
        key=lambda i: (
            _number(
                raw_events[i].get("at_s", 0.0) if isinstance(raw_events[i], dict) else 0.0, f"{name}: event[{i}].at_s"
            ),
            i,
        ),
    )
    known: dict[str, tuple[Threat, float]] = {}
    events = tuple(_event(raw_events[i], i, known, name) for i in order)
    description = data.get("description", "")
    if not isinstance(description, str):
        raise ScenarioError(f"{name}: description: expected a string")
    return Scenario(description, events)


def load_scenario(path) -> Scenario:
    """Read and validate a scenario TOML file."""
    path = Path(path)
    try:
        with open(path, "rb") as fh:
            data = tomllib.load(fh)
    except FileNotFoundError:
        raise ScenarioError(f"{path}: no such file") from None
    except tomllib.TOMLDecodeError as exc:
        raise ScenarioError(f"{path}: {exc}") from None
    return scenario_from_dict(data, str(path))
