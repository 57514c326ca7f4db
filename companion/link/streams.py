"""Telemetry streams: the companion asks for every message it depends on (DESIGN 5).

ArduCopter sends only HEARTBEAT (and replies) on a link until a ground station or companion
asks for more; rates are per link and are lost when the vehicle reboots. ``StreamKeeper``
therefore requests each message the companion uses, at a rate from the settings
(``[link.streams]``, Hz of *vehicle* time: a SITL sped up X times sends X times as many per
wall-clock second, as ArduPilot's SITL and ``sim-vehicle`` both do):

1. ``MAV_CMD_SET_MESSAGE_INTERVAL`` per message (the modern way, acknowledged);
2. if the vehicle does not know that command (UNSUPPORTED) or refuses one message (DENIED,
   FAILED), ``REQUEST_DATA_STREAM`` for the message's ArduPilot stream group
   (:data:`DATA_STREAM_OF`; not acknowledged, so the arrival of the message is what counts);
3. messages with no group (HOME_POSITION, GPS_GLOBAL_ORIGIN) are asked for once with
   ``MAV_CMD_REQUEST_MESSAGE``; a message the vehicle cannot send at all is logged and left out
   (e.g. ADSB_VEHICLE without a receiver, GPS_GLOBAL_ORIGIN on a vehicle whose local frame is
   home's).

Every request is made again when the vehicle reboots (its ``time_boot_ms`` jumps back), when
the link comes back after a loss, or when a core stream (position, attitude) has been silent
for ``stale_after_s`` while heartbeats arrive. The message ids and MAV_DATA_STREAM groups are
pymavlink's constants.

Which messages, and why (``companion.daemon``, ``companion.link.watchers``):
GLOBAL_POSITION_INT (altitude above home), LOCAL_POSITION_NED (position, velocity, the vehicle
clock), ATTITUDE (heading), EXTENDED_SYS_STATE (landed / in air), HOME_POSITION and
GPS_GLOBAL_ORIGIN (the two frames), SYS_STATUS (health), SERVO_OUTPUT_RAW (the flight record),
RPM (rotor run-up, helicopters) and ADSB_VEHICLE (traffic, when ADS-B threats are on).
"""

from __future__ import annotations

import asyncio
import dataclasses
import logging
import math
import time
from collections.abc import Callable
from dataclasses import dataclass

from pymavlink.dialects.v20 import ardupilotmega as mavlink

from companion.errors import ConfigError
from companion.link.ports import CommandSender, MessageSender, VehicleTarget
from heli_common.typed_config import require_numbers

__all__ = [
    "StreamSettings",
    "StreamKeeper",
    "StreamRequest",
    "stream_requests",
    "DATA_STREAM_OF",
    "CORE_STREAMS",
    "data_stream_rates",
]

log = logging.getLogger(__name__)

#: The ArduCopter stream group (REQUEST_DATA_STREAM id) each message belongs to (ArduCopter's
#: GCS_Mavlink.cpp ``STREAM_*_msgs``; EXTENDED_SYS_STATE as ``sim-vehicle`` groups it).
DATA_STREAM_OF = {
    "SYS_STATUS": mavlink.MAV_DATA_STREAM_EXTENDED_STATUS,
    "EXTENDED_SYS_STATE": mavlink.MAV_DATA_STREAM_EXTENDED_STATUS,
    "GLOBAL_POSITION_INT": mavlink.MAV_DATA_STREAM_POSITION,
    "LOCAL_POSITION_NED": mavlink.MAV_DATA_STREAM_POSITION,
    "ATTITUDE": mavlink.MAV_DATA_STREAM_EXTRA1,
    "SERVO_OUTPUT_RAW": mavlink.MAV_DATA_STREAM_RC_CHANNELS,
    "RPM": mavlink.MAV_DATA_STREAM_EXTRA3,
}
#: Messages asked for once with REQUEST_MESSAGE when they cannot be streamed.
ONE_SHOT = frozenset({"HOME_POSITION", "GPS_GLOBAL_ORIGIN"})
#: Streams that every flying vehicle sends once asked: silence means the request was lost.
CORE_STREAMS = ("LOCAL_POSITION_NED", "ATTITUDE")

MAV_RESULT_ACCEPTED = mavlink.MAV_RESULT_ACCEPTED
MAV_RESULT_UNSUPPORTED = mavlink.MAV_RESULT_UNSUPPORTED


@dataclass(frozen=True)
class StreamSettings:
    """Telemetry rates the companion asks for (``[link.streams]``), Hz of vehicle time.

    0 leaves a message alone (not requested). ADSB_VEHICLE is asked for only when ADS-B
    threats are on (``[adsb] enabled``).

    Parameters
    ----------
    global_position_int_hz, local_position_ned_hz, attitude_hz, extended_sys_state_hz,
    home_position_hz, gps_global_origin_hz, sys_status_hz, servo_output_raw_hz, rpm_hz,
    adsb_vehicle_hz : float
        Rates. LOCAL_POSITION_NED drives the vehicle clock and the tracking error (10 Hz);
        SERVO_OUTPUT_RAW is recorded at 10 Hz at most (5 Hz); HOME_POSITION and
        GPS_GLOBAL_ORIGIN change rarely (0.5 Hz); ADSB_VEHICLE is 1 Hz per aircraft (each report
        is a threat update and a threat decision).
    stale_after_s : float
        Wall-clock seconds of silence of a core stream (LOCAL_POSITION_NED, ATTITUDE) while
        heartbeats arrive after which every request is made again (also the shortest time
        between two such rounds).
    command_timeout_s : float
        How long to wait for each COMMAND_ACK of a request (wall clock).
    """

    global_position_int_hz: float = 5.0
    local_position_ned_hz: float = 10.0
    attitude_hz: float = 10.0
    extended_sys_state_hz: float = 2.0
    home_position_hz: float = 0.5
    gps_global_origin_hz: float = 0.5
    sys_status_hz: float = 1.0
    servo_output_raw_hz: float = 5.0
    rpm_hz: float = 2.0
    adsb_vehicle_hz: float = 1.0
    stale_after_s: float = 3.0
    command_timeout_s: float = 1.5

    def __post_init__(self) -> None:
        rates = [f.name for f in dataclasses.fields(self) if f.name.endswith("_hz")]
        require_numbers(
            ConfigError,
            "link.streams",
            self,
            non_negative=tuple(rates),
            positive=("stale_after_s", "command_timeout_s"),
        )
        for name in rates:
            if getattr(self, name) > 100.0:
                raise ConfigError(f"link.streams.{name}: at most 100 Hz, got {getattr(self, name)}")

    def rate_of(self, message: str) -> float:
        """The rate (Hz) of ``message`` (e.g. ``"LOCAL_POSITION_NED"``)."""
        return float(getattr(self, f"{message.lower()}_hz"))


@dataclass(frozen=True)
class StreamRequest:
    """One message to ask for: its name, MAVLink id and rate (Hz of vehicle time)."""

    name: str
    msg_id: int
    rate_hz: float

    @property
    def interval_us(self) -> float:
        """SET_MESSAGE_INTERVAL's param2."""
        return 1e6 / self.rate_hz


def stream_requests(settings: StreamSettings, adsb: bool = False) -> list[StreamRequest]:
    """The messages to request, in order, with their pymavlink ids (rates of 0 left out)."""
    names = [
        "LOCAL_POSITION_NED",
        "ATTITUDE",
        "GLOBAL_POSITION_INT",
        "EXTENDED_SYS_STATE",
        "HOME_POSITION",
        "GPS_GLOBAL_ORIGIN",
        "SYS_STATUS",
        "SERVO_OUTPUT_RAW",
        "RPM",
    ]
    if adsb:
        names.append("ADSB_VEHICLE")
    out = []
    for name in names:
        rate = settings.rate_of(name)
        if rate > 0.0:
            out.append(StreamRequest(name, int(getattr(mavlink, f"MAVLINK_MSG_ID_{name}")), rate))
    return out


def data_stream_rates(requests) -> dict[int, int]:
    """REQUEST_DATA_STREAM group -> rate (whole Hz, at least 1): the fastest message of each
    group among ``requests`` (those with a group)."""
    out: dict[int, int] = {}
    for req in requests:
        group = DATA_STREAM_OF.get(req.name)
        if group is not None:
            out[group] = max(out.get(group, 1), int(math.ceil(req.rate_hz)))
    return out


class StreamKeeper:
    """Requests the telemetry streams and requests them again when they are lost.

    Parameters
    ----------
    settings : StreamSettings
    commands : CommandSender
        SET_MESSAGE_INTERVAL and REQUEST_MESSAGE (``command_result``).
    sender : MessageSender
        REQUEST_DATA_STREAM (``send_message``).
    target : VehicleTarget
        Who is asked (``target_system``, ``target_component``).
    connected : callable() -> bool
        Whether heartbeats arrive (nothing is asked while they do not).
    adsb : bool
        Also ask for ADSB_VEHICLE.

    Attributes
    ----------
    status : dict
        Message name -> how it is obtained: ``interval`` (SET_MESSAGE_INTERVAL accepted),
        ``data_stream`` (REQUEST_DATA_STREAM sent), ``requested`` (REQUEST_MESSAGE accepted),
        ``unavailable`` (the vehicle cannot send it) or ``pending`` (no answer yet).
    rounds : int
        How many times every stream has been requested.
    """

    def __init__(
        self,
        settings: StreamSettings,
        *,
        commands: CommandSender,
        sender: MessageSender,
        target: VehicleTarget,
        connected: Callable[[], bool],
        adsb: bool = False,
    ) -> None:
        self._commands = commands
        self._sender = sender
        self._target = target
        self._connected = connected
        self.settings = settings
        self.requests = stream_requests(settings, adsb)
        self.status: dict[str, str] = {r.name: "pending" for r in self.requests}
        self.rounds = 0
        self._seen_t: dict[str, float] = {}
        self._boot_s: float | None = None
        self._wanted = asyncio.Event()
        self._reason = "start"
        self._last_round_t = -math.inf
        self._interval_unsupported = False

    # ------------------------------------------------------------------ what the link tells
    def note(self, name: str, boot_s: float | None = None) -> None:
        """A message ``name`` arrived (called by the link's watchers); ``boot_s`` its
        ``time_boot_ms`` in seconds, when it has one: a jump back is a reboot."""
        now = time.monotonic()
        self._seen_t[name] = now
        if boot_s is None:
            return
        if self._boot_s is not None and boot_s < self._boot_s - 1.0:
            log.warning(
                "the vehicle rebooted (boot time %.1f s -> %.1f s): requesting its streams again", self._boot_s, boot_s
            )
            self.request_again("vehicle reboot")
        self._boot_s = boot_s

    def seen(self, name: str) -> bool:
        """True once ``name`` has arrived."""
        return name in self._seen_t

    def unavailable(self, name: str) -> bool:
        """True when the vehicle said it cannot send ``name``."""
        return self.status.get(name) == "unavailable"

    def request_again(self, reason: str) -> None:
        """Make every request again soon (link back, reboot ...)."""
        self._reason = reason
        self._wanted.set()

    # ------------------------------------------------------------------ the task
    async def run(self) -> None:
        """Request everything now, then again whenever needed (runs until cancelled)."""
        self._wanted.set()
        check_s = min(1.0, self.settings.stale_after_s / 2.0)
        while True:
            try:
                await asyncio.wait_for(self._wanted.wait(), check_s)
            except TimeoutError:
                self._check_stale()
                continue
            self._wanted.clear()
            if not self._connected():
                continue  # asked again when the link is back
            try:
                await self.request_all(self._reason)
            except asyncio.CancelledError:
                raise
            except Exception:  # noqa: BLE001 - streams are retried; never stop the link
                log.exception("stream requests failed; retrying")
                await asyncio.sleep(check_s)
                self._wanted.set()

    def _check_stale(self) -> None:
        now = time.monotonic()
        if not self._connected() or now - self._last_round_t < self.settings.stale_after_s:
            return
        for name in CORE_STREAMS:
            if name not in self.status or self.status[name] == "unavailable":
                continue
            seen = self._seen_t.get(name)
            if seen is None or now - seen > self.settings.stale_after_s:
                self.request_again(f"no {name} for {self.settings.stale_after_s:g} s")
                return

    async def request_all(self, reason: str = "start") -> dict[str, str]:
        """Request every stream once (SET_MESSAGE_INTERVAL, else the fallbacks); returns
        ``status``."""
        self._last_round_t = time.monotonic()
        self.rounds += 1
        log.info(
            "requesting telemetry streams (%s): %s",
            reason,
            ", ".join(f"{r.name} {r.rate_hz:g} Hz" for r in self.requests),
        )
        fallback = []
        for req in self.requests:
            if self._interval_unsupported:
                fallback.append(req)
                continue
            result = await self._commands.command_result(
                mavlink.MAV_CMD_SET_MESSAGE_INTERVAL,
                (req.msg_id, req.interval_us),
                what=f"SET_MESSAGE_INTERVAL {req.name}",
                timeout_s=self.settings.command_timeout_s,
            )
            if result == MAV_RESULT_ACCEPTED:
                self.status[req.name] = "interval"
            elif result is None:
                self.status[req.name] = "pending"
            elif result == MAV_RESULT_UNSUPPORTED:
                log.info("the vehicle does not know SET_MESSAGE_INTERVAL: REQUEST_DATA_STREAM instead")
                self._interval_unsupported = True
                fallback.append(req)
            else:
                fallback.append(req)
        await self._fall_back(fallback)
        missing = [n for n, s in self.status.items() if s == "unavailable"]
        if missing:
            log.info("the vehicle cannot send %s", ", ".join(missing))
        return dict(self.status)

    async def _fall_back(self, requests: list[StreamRequest]) -> None:
        groups = data_stream_rates(requests)
        for group, rate in sorted(groups.items()):
            self._sender.send_message(
                "REQUEST_DATA_STREAM",
                {
                    "target_system": self._target.target_system,
                    "target_component": self._target.target_component,
                    "req_stream_id": group,
                    "req_message_rate": rate,
                    "start_stop": 1,
                },
            )
        for req in requests:
            if req.name in DATA_STREAM_OF:
                self.status[req.name] = "data_stream"
                log.info("%s requested with REQUEST_DATA_STREAM %d", req.name, DATA_STREAM_OF[req.name])
                continue
            if req.name not in ONE_SHOT:
                self.status[req.name] = "unavailable"
                continue
            result = await self._commands.command_result(
                mavlink.MAV_CMD_REQUEST_MESSAGE,
                (req.msg_id,),
                what=f"REQUEST_MESSAGE {req.name}",
                timeout_s=self.settings.command_timeout_s,
            )
            if result == MAV_RESULT_ACCEPTED:
                self.status[req.name] = "requested"
            elif result is None:
                self.status[req.name] = "pending"
            else:
                self.status[req.name] = "unavailable"
