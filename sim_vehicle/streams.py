"""Telemetry streams of ``sim-vehicle``, per link, scheduled the way ArduCopter schedules them.

What the reference firmware (ArduCopter heli, ``../shared/ardupilot``) does and this module
copies:

* A link gets **nothing but HEARTBEAT** (and replies) until it asks. Event messages (COMMAND_ACK,
  STATUSTEXT, MISSION_ITEM_REACHED, GPS_GLOBAL_ORIGIN and HOME_POSITION when they are set) are
  not streams and are sent by the caller.
* **MAV_CMD_SET_MESSAGE_INTERVAL** (511) sets one message of the requesting link: interval in
  us, -1 stops it, 0 restores its default (the rate of the stream group that holds it, so
  usually off). Unknown messages are DENIED with STATUSTEXT "No ap_message for mavlink id (N)";
  intervals below -1 are DENIED; intervals shorter than the 400 Hz main loop allows (< 3 ms) are
  DENIED with "Requested rate for message ID N too fast. Increase SCHED_LOOP_RATE".
* **REQUEST_DATA_STREAM** sets a stream group of the requesting link to a rate in Hz
  (``start_stop`` 0 or rate 0 stops it) and every message of the group with it.
  MAV_DATA_STREAM_ALL sets every group but PARAMS (ADSB included). The rate is written into the
  link's ``MAVn_<group>`` parameter, as ArduPilot does.
* The **MAVn_<group>** parameters (ArduPilot 4.7 names; 4.6 and older called them SRn-1_...)
  hold the group rates a numbered link starts with. ArduPilot reads them at boot only
  (RebootRequired), so a PARAM_SET changes what the *next* start streams, not the current one.
  Defaults are 0: nothing streamed unasked.

A *link* here is one UDP address: each ``--out`` address (numbered 1, 2, 3 in order, with the
MAV1_/MAV2_/MAV3_ parameters) and each other peer (unnumbered, every group 0 at first). A request
changes the link it came from and no other, as a request on one ArduPilot serial port changes
that port only.

The group lists are ArduCopter's (``GCS_MAVLink_Copter.cpp``, the rows marked "observed" were
checked on the reference firmware), restricted to the messages the simulation produces.
Messages in no group (EXTENDED_SYS_STATE, HOME_POSITION, GPS_GLOBAL_ORIGIN) stream only when
set one by one. Times are simulated seconds. No sockets here.
"""

from __future__ import annotations

import logging
import math
from collections.abc import Mapping, Sequence
from typing import Any

from pymavlink.dialects.v20 import ardupilotmega as mavlink

log = logging.getLogger(__name__)

GROUPS: dict[str, tuple[str, ...]] = {
    "RAW_SENS": (),  # RAW_IMU, SCALED_* (not simulated)
    "EXT_STAT": ("SYS_STATUS", "MISSION_CURRENT", "GPS_RAW_INT"),  # observed (+ POWER_STATUS, MEMINFO, ...)
    "RC_CHAN": ("SERVO_OUTPUT_RAW", "RC_CHANNELS"),  # observed
    "RAW_CTRL": (),  # unused in Copter (observed: nothing)
    "POSITION": ("GLOBAL_POSITION_INT", "LOCAL_POSITION_NED"),  # observed
    "EXTRA1": ("ATTITUDE", "RPM"),  # observed (+ AHRS2, SIMSTATE, ESC_TELEMETRY)
    "EXTRA2": ("VFR_HUD",),  # observed
    "EXTRA3": ("SYSTEM_TIME",),  # observed (+ AHRS, WIND, EKF_STATUS_REPORT, ...)
    "PARAMS": (),  # parameter streaming, not a telemetry rate
    "ADSB": ("ADSB_VEHICLE",),  # observed with SIM_ADSB_COUNT
}
"""Stream group (``MAVn_`` parameter suffix, in ArduPilot's order) -> messages of the group."""
GROUP_NAMES = tuple(GROUPS)

DATA_STREAM_GROUPS: dict[int, str] = {
    mavlink.MAV_DATA_STREAM_RAW_SENSORS: "RAW_SENS",
    mavlink.MAV_DATA_STREAM_EXTENDED_STATUS: "EXT_STAT",
    mavlink.MAV_DATA_STREAM_RC_CHANNELS: "RC_CHAN",
    mavlink.MAV_DATA_STREAM_RAW_CONTROLLER: "RAW_CTRL",
    mavlink.MAV_DATA_STREAM_POSITION: "POSITION",
    mavlink.MAV_DATA_STREAM_EXTRA1: "EXTRA1",
    mavlink.MAV_DATA_STREAM_EXTRA2: "EXTRA2",
    mavlink.MAV_DATA_STREAM_EXTRA3: "EXTRA3",
}
"""REQUEST_DATA_STREAM ``req_stream_id`` -> group (MAV_DATA_STREAM_ALL: every group but PARAMS)."""

UNGROUPED = ("EXTENDED_SYS_STATE", "HOME_POSITION", "GPS_GLOBAL_ORIGIN")
"""Messages that stream only when set one by one with SET_MESSAGE_INTERVAL."""

MESSAGE_IDS: dict[str, int] = {
    name: getattr(mavlink, f"MAVLINK_MSG_ID_{name}")
    for name in [m for g in GROUPS.values() for m in g] + list(UNGROUPED)
}
"""Every message a link can stream -> its MAVLink id."""
NAMES_BY_ID: dict[int, str] = {v: k for k, v in MESSAGE_IDS.items()}
GROUP_OF: dict[str, str] = {m: g for g, messages in GROUPS.items() for m in messages}

LOOP_RATE_HZ = 400.0
"""ArduCopter's main loop rate (SCHED_LOOP_RATE): no message faster than one per loop."""
MAX_INTERVAL_S = 60.0
"""Longer intervals are clamped to this (ArduPilot: 60000 ms)."""

Address = tuple[str, int]


class LinkStreams:
    """The streams of one link: group rates and the interval of each message.

    Parameters
    ----------
    group_hz : mapping of str to int, optional
        Starting group rates in Hz (the ``MAVn_`` parameters of a numbered link); missing = 0.
    now_s : float
        Simulated time now.
    """

    def __init__(self, group_hz: Mapping[str, int] | None = None, now_s: float = 0.0) -> None:
        self.group_hz: dict[str, int] = {g: 0 for g in GROUP_NAMES}
        self.interval_s: dict[str, float] = {}
        self.next_s: dict[str, float] = {}
        self.extra: dict[str, Any] = {}
        for group, hz in (group_hz or {}).items():
            self.set_group(group, int(hz), now_s)

    def set_group(self, group: str, hz: int, now_s: float) -> None:
        """Group ``group`` (and each of its messages) at ``hz`` Hz; 0 stops them."""
        self.group_hz[group] = max(0, int(hz))
        for name in GROUPS[group]:
            self.set_interval(name, 1.0 / hz if hz > 0 else None, now_s)

    def set_interval(self, name: str, interval_s: float | None, now_s: float) -> None:
        """Message ``name`` every ``interval_s`` simulated seconds; None stops it."""
        if interval_s is None:
            self.interval_s.pop(name, None)
            self.next_s.pop(name, None)
            return
        self.interval_s[name] = min(float(interval_s), MAX_INTERVAL_S)
        self.next_s[name] = now_s  # the first one goes out at once

    def default_interval_s(self, name: str) -> float | None:
        """Interval a message falls back to (SET_MESSAGE_INTERVAL 0): its group's rate, or off."""
        group = GROUP_OF.get(name)
        hz = self.group_hz.get(group, 0) if group else 0
        return 1.0 / hz if hz > 0 else None

    def interval_us(self, name: str) -> int:
        """MESSAGE_INTERVAL ``interval_us`` of ``name`` on this link: -1 when not streamed."""
        interval = self.interval_s.get(name)
        return -1 if interval is None else int(round(interval * 1e6))

    def due(self, now_s: float, min_period_s: float = 0.0) -> list[str]:
        """Messages due now; each one's next time is advanced (never sooner than ``min_period_s``)."""
        out = []
        for name, interval in self.interval_s.items():
            next_s = self.next_s.get(name, now_s)
            if now_s < next_s:
                continue
            period = max(interval, min_period_s)
            self.next_s[name] = next_s + period if now_s - next_s < period else now_s + period
            out.append(name)
        return out

    @property
    def active(self) -> list[str]:
        """Messages streamed on this link."""
        return list(self.interval_s)


def decode_interval(msg_id: float, interval_us: float) -> tuple[int, str, str | None, float | None | str]:
    """Check a SET_MESSAGE_INTERVAL request as ArduPilot does.

    Returns
    -------
    result : int
        MAV_RESULT.
    text : str
        STATUSTEXT ArduPilot sends with the result ("" for none).
    name : str or None
        The message, if known.
    interval : float, None or "default"
        Seconds, None (stop) or ``"default"`` (the group rate).
    """
    if not (math.isfinite(msg_id) and math.isfinite(interval_us)):
        return mavlink.MAV_RESULT_DENIED, "", None, None
    name = NAMES_BY_ID.get(int(msg_id))
    if name is None:
        return mavlink.MAV_RESULT_DENIED, f"No ap_message for mavlink id ({int(msg_id)})", None, None
    if interval_us == 0:
        return mavlink.MAV_RESULT_ACCEPTED, "", name, "default"
    if interval_us == -1:
        return mavlink.MAV_RESULT_ACCEPTED, "", name, None
    if interval_us < -1:
        return mavlink.MAV_RESULT_DENIED, "", name, None
    interval_ms = max(1, int(interval_us // 1000))
    if interval_ms * LOOP_RATE_HZ < 1000.0:
        return (
            mavlink.MAV_RESULT_DENIED,
            f"Requested rate for message ID {int(msg_id)} too fast. Increase SCHED_LOOP_RATE",
            name,
            None,
        )
    return mavlink.MAV_RESULT_ACCEPTED, "", name, min(interval_ms / 1000.0, MAX_INTERVAL_S)


class StreamTable:
    """Every link's streams, keyed by UDP address.

    Parameters
    ----------
    numbered : sequence of Address
        The ``--out`` addresses in order: link 1, 2, ... (``MAVn_`` parameters for n <= 3).
    group_rates : sequence of mapping
        Starting group rates of links 1, 2, ... (the ``MAVn_`` parameters).
    """

    MAX_LINKS = 64
    """Unnumbered links beyond this forget the oldest one (a flood of new peers stays bounded)."""

    def __init__(self, numbered: Sequence[Address], group_rates: Sequence[Mapping[str, int]] = ()) -> None:
        self.numbered: list[Address] = list(numbered)
        self._rates = list(group_rates)
        self.links: dict[Address, LinkStreams] = {}

    def number(self, address: Address) -> int | None:
        """1-based link number of a ``--out`` address, None for other peers."""
        try:
            return self.numbered.index(address) + 1
        except ValueError:
            return None

    def link(self, address: Address, now_s: float) -> LinkStreams:
        """The streams of ``address`` (created on first use)."""
        link = self.links.get(address)
        if link is None:
            n = self.number(address)
            rates = self._rates[n - 1] if n is not None and n <= len(self._rates) else None
            if n is None and len(self.links) >= self.MAX_LINKS:
                oldest = next(a for a in self.links if self.number(a) is None)
                del self.links[oldest]
            link = self.links[address] = LinkStreams(rates, now_s)
            if rates and any(rates.values()):
                log.info(
                    "link %s:%d (MAV%d) starts with streams %s", *address, n, {g: hz for g, hz in rates.items() if hz}
                )
        return link

    def set_message_interval(
        self, address: Address, msg_id: float, interval_us: float, now_s: float
    ) -> tuple[int, str]:
        """SET_MESSAGE_INTERVAL from ``address``; returns (MAV_RESULT, STATUSTEXT or "")."""
        result, text, name, interval = decode_interval(msg_id, interval_us)
        if result != mavlink.MAV_RESULT_ACCEPTED:
            return result, text
        link = self.link(address, now_s)
        if interval == "default":
            interval = link.default_interval_s(name)
        link.set_interval(name, interval, now_s)
        log.info(
            "%s:%d: %s %s (SET_MESSAGE_INTERVAL)",
            *address,
            name,
            "off" if interval is None else f"every {interval:g} s",
        )
        return result, ""

    def request_data_stream(
        self, address: Address, stream_id: int, rate_hz: int, start_stop: int, now_s: float
    ) -> list[tuple[str, int]]:
        """REQUEST_DATA_STREAM from ``address``; returns the (group, Hz) pairs it set."""
        if start_stop not in (0, 1):
            return []
        hz = int(rate_hz) if start_stop == 1 else 0
        if stream_id == mavlink.MAV_DATA_STREAM_ALL:
            groups = [g for g in GROUP_NAMES if g != "PARAMS"]
        elif stream_id in DATA_STREAM_GROUPS:
            groups = [DATA_STREAM_GROUPS[stream_id]]
        else:
            log.info("%s:%d: REQUEST_DATA_STREAM %d: no such stream; ignored", *address, stream_id)
            return []
        link = self.link(address, now_s)
        for group in groups:
            link.set_group(group, hz, now_s)
        log.info(
            "%s:%d: stream group%s %s at %d Hz (REQUEST_DATA_STREAM)",
            *address,
            "s" if len(groups) > 1 else "",
            ",".join(groups),
            hz,
        )
        return [(g, hz) for g in groups]


__all__ = [
    "GROUPS",
    "GROUP_NAMES",
    "DATA_STREAM_GROUPS",
    "UNGROUPED",
    "MESSAGE_IDS",
    "NAMES_BY_ID",
    "LinkStreams",
    "StreamTable",
    "decode_interval",
]
