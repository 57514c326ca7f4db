"""The vehicle link: MAVSDK 4.x (ctypes ``mavsdk.asyncio``) to an ArduPilot-like helicopter.

Implements the companion side of the MAVLink contract of DESIGN.md section 5. ``VehicleLink``
owns the connection (this module) and is made of one part per job:

- connection by MAVSDK URL (``udpin://``, ``udpout://``, ``tcpin://``, ``tcpout://``,
  ``serial://``), waiting for the first autopilot, through the signing gate
  (``companion.link.transport``); ``close`` releases MAVSDK's plugins and System before MAVSDK
  itself, and ``aclose`` first waits for the command calls still running;
- telemetry streams requested, never assumed (``companion.link.streams.StreamKeeper``: ArduCopter
  sends only HEARTBEAT until asked), and requested again after a reboot or a link loss;
- telemetry as an always-fresh snapshot (``VehicleLink.telemetry``, ``companion.link.telemetry``)
  kept up to date by background subscriptions (``companion.link.watchers``), waited on with
  ``companion.link.waits``;
- the two local frames (``companion.link.frames``): positions in and out of the link are about
  the planning home, the vehicle's LOCAL_NED messages about its EKF origin; the link converts;
- mission, fence and rally upload and download (``companion.link.mission_transfer``);
- commands checked against their COMMAND_ACK, and parameters
  (``companion.link.vehicle_commands``);
- raw messages in, GUIDED setpoints and STATUSTEXT out without blocking the event loop
  (``companion.link.direct_messages``).

MAVSDK 4.x note: ``Configuration`` is built with ``Configuration.create_with_component_type``
(its constructor takes a raw handle).
"""

from __future__ import annotations

import asyncio
import collections
import contextlib
import logging
import time
from typing import Callable

import numpy as np

from companion.errors import LinkError
from companion.link.direct_messages import DirectMessages
from companion.link.frames import LinkFrames
from companion.link.gate import SigningKey, silence_reason
from companion.link.mission_transfer import MissionTransfer
from companion.link.streams import StreamKeeper, StreamSettings
from companion.link.telemetry import HEARTBEAT_TIMEOUT_S, Telemetry, TelemetryState
from companion.link.transport import GateThread, open_gate
from companion.link.vehicle_commands import VehicleCommands
from companion.link.waits import TelemetryWaits
from companion.link.watchers import TelemetryWatchers

log = logging.getLogger(__name__)

DEFAULT_URL = "udpin://0.0.0.0:14540"
URL_SCHEMES = ("udpin://", "udpout://", "udp://", "tcpin://", "tcpout://", "tcp://", "serial://")
#: How many recent STATUSTEXTs of the vehicle are kept (``VehicleLink.statustexts``).
STATUSTEXT_KEEP = 64
#: How long ``aclose`` waits for the cancelled telemetry subscriptions to end (s).
CANCEL_WAIT_S = 5.0
#: How long ``aclose`` waits for MAVSDK command calls still running before releasing MAVSDK.
IN_FLIGHT_WAIT_S = 10.0


def check_url(url: str) -> str:
    """Raise ``LinkError`` naming ``url`` unless it is a MAVSDK connection URL."""
    if not isinstance(url, str) or not url.startswith(URL_SCHEMES):
        raise LinkError(f"--connect {url!r}: not a MAVSDK URL; use e.g. udpin://0.0.0.0:14540, "
                        f"udpout://127.0.0.1:14555, tcpout://127.0.0.1:5760 or "
                        f"serial:///dev/ttyUSB0:57600")
    return url


class VehicleLink(TelemetryWatchers, TelemetryWaits, VehicleCommands, DirectMessages,
                  MissionTransfer):
    """MAVLink link to one autopilot through MAVSDK 4.x (asyncio).

    Parameters
    ----------
    role : str
        ``"companion"`` (MAVSDK ComponentType.COMPANION_COMPUTER) or ``"gcs"``
        (GROUND_STATION, as ``companion upload/download``).
    streams : StreamSettings, optional
        The telemetry the link asks for (``companion.link.streams``). Default: the defaults
        for a companion, nothing for a ground station (mission transfers need no streams).
    adsb : bool
        Also ask for ADSB_VEHICLE (ADS-B traffic as threats).
    signing_key : SigningKey, optional
        Sign everything sent and accept only frames signed with it (``companion.link.gate``).
    tlog_path : str, optional
        Record the link's traffic, both ways, to this ``.tlog`` file (``heli_common.tlog``).
    onboard : OnboardComponent, optional
        Speak as the companion component of the vehicle's system (``companion.link.onboard``:
        its HEARTBEAT instead of MAVSDK's, commands addressed to it answered); it learns the
        vehicle's system id on ``connect``.

    Examples
    --------
    >>> link = VehicleLink()                                    # doctest: +SKIP
    >>> await link.connect("udpin://0.0.0.0:14540", timeout_s=10)
    >>> await link.wait_position(5.0); link.telemetry.pos_ned_m
    >>> await link.set_mode("GUIDED"); await link.arm(); await link.takeoff(10.0)
    >>> link.send_setpoint(pos_ned_m=[0, 0, -10], vel_ned_m_s=[0, 0, 0], yaw_rad=0.0)
    """

    def __init__(self, role: str = "companion", *, streams: StreamSettings | None = None,
                 adsb: bool = False, signing_key: SigningKey | None = None,
                 tlog_path: str | None = None, onboard=None) -> None:
        if role not in ("companion", "gcs"):
            raise LinkError(f"role must be 'companion' or 'gcs', got {role!r}")
        self.role = role
        self.url: str | None = None
        self.target_system = 1
        self.target_component = 1
        self.frames = LinkFrames()
        if streams is None and role == "companion":
            streams = StreamSettings()
        self.stream_settings = streams
        self.adsb = bool(adsb)
        self.signing_key = signing_key
        self.tlog_path = tlog_path or None
        self.onboard = onboard
        self.gate: GateThread | None = None
        self.streams: StreamKeeper | None = None
        self.statustexts: collections.deque = collections.deque(maxlen=STATUSTEXT_KEEP)
        self._mavsdk = None
        self._system = None
        self._direct_sync = None   # MavlinkDirect (commands, rare sends; telemetry and setpoints: the gate)
        self._mission = None
        self._state = TelemetryState()
        self._tasks: list[asyncio.Task] = []
        self._t0 = time.monotonic()
        self._link_listeners: list[Callable[[bool], None]] = []
        self._was_connected = False
        self._command_lock: asyncio.Lock | None = None
        self._in_flight: set[asyncio.Future] = set()      # MAVSDK command calls still running
        self._mission_lock: asyncio.Lock | None = None
        self._readers: dict[str, set[asyncio.Queue]] = {}  # message type -> the queues of messages()
        self._tap_batches: collections.deque = collections.deque()
        self._taps_streamer = None

    # ----------------------------------------------------------------- connection

    async def connect(self, url: str = DEFAULT_URL, timeout_s: float = 10.0) -> None:
        """Open ``url`` and wait up to ``timeout_s`` for an autopilot, then start telemetry.

        Raises
        ------
        LinkError
            Bad URL, the URL cannot be opened, or no autopilot within ``timeout_s``.
        """
        from mavsdk.asyncio import ComponentType, Configuration, Mavsdk, MavsdkConnectionError
        from mavsdk.asyncio.plugins.mission_raw import MissionRawAsync
        from mavsdk.plugins.mavlink_direct import MavlinkDirect

        check_url(url)
        route_mavsdk_logs()
        kind = (ComponentType.COMPANION_COMPUTER if self.role == "companion"
                else ComponentType.GROUND_STATION)
        self.gate = open_gate(url, self.signing_key, tlog_path=self.tlog_path, onboard=self.onboard)
        self.gate.on_tap = self._tap_from_gate_thread(asyncio.get_running_loop())
        self._mavsdk = Mavsdk(Configuration.create_with_component_type(kind))
        self._command_lock = asyncio.Lock()
        self._mission_lock = asyncio.Lock()
        try:
            await self._mavsdk.add_any_connection(self.gate.mavsdk_url)
        except MavsdkConnectionError as exc:
            self.close()
            raise LinkError(f"cannot open {url}: {exc}") from None
        system = await self._mavsdk.first_autopilot(timeout_s=float(timeout_s))
        if system is None:
            why = silence_reason(self.gate.inbound.counts, self.signing_key)
            self.close()
            raise LinkError(f"no autopilot heard on {url} within {timeout_s:g} s ({why})")
        self.url = url
        self._system = system
        self.target_system = await system.get_system_id()
        if self.onboard is not None:
            self.onboard.set_system(self.target_system)
        self._direct_sync = MavlinkDirect(system._system)
        self._mission = MissionRawAsync(system)
        self._state.heartbeat_t = time.monotonic()
        self._was_connected = True
        if self.stream_settings is not None:
            self.streams = StreamKeeper(self, self.stream_settings, adsb=self.adsb)
        self._start_subscriptions()
        log.info("connected to system %d on %s", self.target_system, url)

    def close(self) -> None:
        """Stop the subscriptions and release MAVSDK (idempotent)."""
        for task in self._tasks:
            task.cancel()
        self._tasks.clear()
        # MAVSDK aborts the process if it is destroyed while a plugin or a System it handed out
        # is alive: release them first, newest first
        for owned in (self._mission, self._direct_sync,
                      getattr(self._system, "_system", None)):
            if owned is not None:
                with contextlib.suppress(Exception):
                    owned.destroy()
        self._mission = self._direct_sync = self._system = None
        if self._mavsdk is not None:
            with contextlib.suppress(Exception):
                self._mavsdk.destroy()
        self._mavsdk = None
        if self.gate is not None:
            self.gate.close()
        self.gate = None

    async def aclose(self) -> None:
        """Cancel the subscriptions, let them unsubscribe, then release MAVSDK (idempotent)."""
        tasks, self._tasks = self._tasks, []
        for task in tasks:
            task.cancel()
        if tasks:                        # a subscription stuck in MAVSDK must not hold the close
            _, stuck = await asyncio.wait(tasks, timeout=CANCEL_WAIT_S)
            if stuck:
                log.warning("closing the link: %d telemetry subscriptions did not end within %g s (%s)",
                            len(stuck), CANCEL_WAIT_S, ", ".join(sorted(t.get_name() for t in stuck)))
        if self._in_flight:              # MAVSDK ends each within its own retries (a few seconds)
            await asyncio.wait(set(self._in_flight), timeout=IN_FLIGHT_WAIT_S)
        self.close()

    async def __aenter__(self) -> "VehicleLink":
        return self

    async def __aexit__(self, *exc) -> None:
        await self.aclose()

    def on_link_change(self, callback: Callable[[bool], None]) -> Callable[[], None]:
        """Call ``callback(connected)`` on the loop when the heartbeat is lost or is back;
        returns the function that stops it."""
        self._link_listeners.append(callback)
        return lambda: self._link_listeners.remove(callback) if callback in self._link_listeners else None

    @property
    def connected(self) -> bool:
        """True while heartbeats arrive (within ``HEARTBEAT_TIMEOUT_S``)."""
        return time.monotonic() - self._state.heartbeat_t < HEARTBEAT_TIMEOUT_S

    async def wait_connected(self, timeout_s: float | None = None) -> bool:
        """Wait until heartbeats arrive again (MAVSDK keeps the connection open meanwhile)."""
        deadline = None if timeout_s is None else time.monotonic() + timeout_s
        while not self.connected:
            if deadline is not None and time.monotonic() > deadline:
                return False
            await asyncio.sleep(0.05)
        return True

    # ----------------------------------------------------------------- telemetry

    @property
    def telemetry(self) -> Telemetry:
        """The latest vehicle state (a new immutable snapshot on every access)."""
        return self._state.snapshot(time.monotonic(), self.frames)

    def set_planning_home(self, home_lla) -> LinkFrames:
        """Freeze the home frame: positions in and out of the link are about ``home_lla`` from
        now on, converted with the vehicle's EKF origin if it reported one
        (``companion.link.frames``). Returns the frames."""
        origin = self._state.values.get("origin_lla")
        self.frames = LinkFrames.build(home_lla, origin)
        if origin is None:
            log.info("the vehicle reports no EKF origin (GPS_GLOBAL_ORIGIN): its local frame is "
                     "taken to be home's")
        else:
            log.info("home %.7f, %.7f, %.2f m; EKF origin %.7f, %.7f, %.2f m; home in the "
                     "vehicle's local frame: %s m", *self.frames.home_lla, *origin,
                     np.round(self.frames.home_in_origin_ned_m, 3).tolist())
        return self.frames


def route_mavsdk_logs() -> None:
    """Send MAVSDK's C++ log lines to Python logging (logger ``mavsdk``) instead of stderr."""
    from mavsdk import logging as mavsdk_logging

    mav_log = logging.getLogger("mavsdk")
    # MAVSDK info chatter (version, discovery) is debug for us; warnings and errors stay
    levels = {0: logging.DEBUG, 1: logging.DEBUG, 2: logging.WARNING, 3: logging.ERROR}

    def forward(level, message, file, line) -> bool:
        mav_log.log(levels.get(int(level), logging.INFO), "%s", message)
        return True

    mavsdk_logging.log_subscribe(forward)
