"""The vehicle link: MAVSDK 4.x (ctypes ``mavsdk.asyncio``) to an ArduPilot-like helicopter.

Implements the companion side of the MAVLink contract of DESIGN.md section 5. ``VehicleLink``
owns the connection and its lifecycle, and holds one part per job as a public member; each part
is given at construction what it uses (the ``LinkSession`` of MAVSDK's handles and the gate, the
other parts through the Protocols of ``companion.link.ports``) and owns its own state:

- ``connect`` by MAVSDK URL (``udpin://``, ``udpout://``, ``tcpin://``, ``tcpout://``,
  ``serial://``), waiting for the first autopilot, through the signing gate
  (``companion.link.transport``), into ``link.session`` (``companion.link.session``);
  ``close`` releases MAVSDK's plugins and System before MAVSDK itself, and ``aclose`` first
  waits for the command calls still running; ``on_link_change`` listeners hear heartbeat loss;
- ``link.streams``: the telemetry streams requested, never assumed
  (``companion.link.streams.StreamKeeper``: ArduCopter sends only HEARTBEAT until asked), and
  requested again after a reboot or a link loss;
- ``link.telemetry``: an always-fresh snapshot (``companion.link.telemetry``) of the state kept
  up to date by the subscriptions of ``link.watchers`` (``companion.link.watchers``), waited on
  with ``link.waits`` (``companion.link.waits``);
- ``link.frames`` (``companion.link.frames``): positions in and out of the link are about the
  planning home, the vehicle's LOCAL_NED messages about its EKF origin; the link converts;
- ``link.missions``: mission, fence and rally upload and download
  (``companion.link.mission_transfer``);
- ``link.commands``: commands checked against their COMMAND_ACK, and parameters
  (``companion.link.vehicle_commands``);
- ``link.inbound``: raw messages in (``companion.link.message_tap``); ``link.direct``: GUIDED
  setpoints, STATUSTEXT and other messages out without blocking the event loop
  (``companion.link.direct_messages``).

MAVSDK 4.x note: ``Configuration`` is built with ``Configuration.create_with_component_type``
(its constructor takes a raw handle).
"""

from __future__ import annotations

import asyncio
import logging
import time
from collections.abc import Callable

import numpy as np

from companion.errors import LinkError
from companion.link.direct_messages import DirectMessages
from companion.link.frames import LinkFrames
from companion.link.gate import SigningKey, silence_reason
from companion.link.message_tap import MessageTap
from companion.link.mission_transfer import MissionTransfer
from companion.link.session import LinkSession
from companion.link.streams import StreamKeeper, StreamSettings
from companion.link.telemetry import HEARTBEAT_TIMEOUT_S, Telemetry
from companion.link.transport import GateThread, open_gate
from companion.link.vehicle_commands import VehicleCommands
from companion.link.waits import TelemetryWaits
from companion.link.watchers import TelemetryWatchers

log = logging.getLogger(__name__)

DEFAULT_URL = "udpin://0.0.0.0:14540"
URL_SCHEMES = ("udpin://", "udpout://", "udp://", "tcpin://", "tcpout://", "tcp://", "serial://")
#: How long ``aclose`` waits for the cancelled telemetry subscriptions to end (s).
CANCEL_WAIT_S = 5.0
#: How long ``aclose`` waits for MAVSDK command calls still running before releasing MAVSDK.
IN_FLIGHT_WAIT_S = 10.0
#: How often the heartbeat's loss or return is checked (s).
LINK_CHECK_PERIOD_S = 0.2


def check_url(url: str) -> str:
    """Raise ``LinkError`` naming ``url`` unless it is a MAVSDK connection URL."""
    if not isinstance(url, str) or not url.startswith(URL_SCHEMES):
        raise LinkError(
            f"--connect {url!r}: not a MAVSDK URL; use e.g. udpin://0.0.0.0:14540, "
            f"udpout://127.0.0.1:14555, tcpout://127.0.0.1:5760 or "
            f"serial:///dev/ttyUSB0:57600"
        )
    return url


class VehicleLink:
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

    Attributes
    ----------
    session : LinkSession
        MAVSDK's handles and the gate while connected (set by ``connect``, emptied by ``close``).
    streams : StreamKeeper or None
        The telemetry requests of the current connection (None: not connected, or none asked).
    frames : LinkFrames
        Home frame <-> the vehicle's EKF-origin frame (``set_planning_home``).
    inbound : MessageTap
        Messages in (``messages(name)``, ``batch_reads``).
    direct : DirectMessages
        Messages out (``send_setpoint``, ``send_statustext``, ``send_message``).
    watchers : TelemetryWatchers
        The telemetry subscriptions, their ``state`` and the vehicle's ``statustexts``.
    commands : VehicleCommands
        COMMAND_LONG (``set_mode``, ``arm``, ``takeoff`` ...) and ``read_params``.
    waits : TelemetryWaits
        ``wait_for``, ``wait_ready``, ``wait_position``, ``wait_home``, ``wait_origin``.
    missions : MissionTransfer
        ``upload_plan``, ``download_plan``, ``clear_plan``.

    Examples
    --------
    >>> link = VehicleLink()                                    # doctest: +SKIP
    >>> await link.connect("udpin://0.0.0.0:14540", timeout_s=10)
    >>> await link.waits.wait_position(5.0); link.telemetry.pos_ned_m
    >>> await link.commands.set_mode("GUIDED"); await link.commands.arm()
    >>> await link.commands.takeoff(10.0)
    >>> link.direct.send_setpoint(pos_ned_m=[0, 0, -10], vel_ned_m_s=[0, 0, 0], yaw_rad=0.0)
    """

    def __init__(
        self,
        role: str = "companion",
        *,
        streams: StreamSettings | None = None,
        adsb: bool = False,
        signing_key: SigningKey | None = None,
        tlog_path: str | None = None,
        onboard=None,
    ) -> None:
        if role not in ("companion", "gcs"):
            raise LinkError(f"role must be 'companion' or 'gcs', got {role!r}")
        self.role = role
        self.url: str | None = None
        if streams is None and role == "companion":
            streams = StreamSettings()
        self.stream_settings = streams
        self.adsb = bool(adsb)
        self.signing_key = signing_key
        self.tlog_path = tlog_path or None
        self.onboard = onboard
        self.session = LinkSession()
        self.streams: StreamKeeper | None = None
        self.frames = LinkFrames()
        self.inbound = MessageTap(self.session)
        self.direct = DirectMessages(self.session, lambda: self.frames)
        self.watchers = TelemetryWatchers(self.session, self.inbound, lambda: self.streams)
        self.commands = VehicleCommands(self.session, self.inbound, self.direct, lambda: self.telemetry, self.watchers)
        self.waits = TelemetryWaits(lambda: self.telemetry, self.commands, lambda: self.streams)
        self.missions = MissionTransfer(self.session, self.inbound)
        self._tasks: list[asyncio.Task] = []
        self._link_listeners: list[Callable[[bool], None]] = []
        self._was_connected = False

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
        kind = ComponentType.COMPANION_COMPUTER if self.role == "companion" else ComponentType.GROUND_STATION
        gate = self.session.gate = open_gate(url, self.signing_key, tlog_path=self.tlog_path, onboard=self.onboard)
        self.inbound.attach(gate, asyncio.get_running_loop())
        mavsdk = self.session.mavsdk = Mavsdk(Configuration.create_with_component_type(kind))
        try:
            await mavsdk.add_any_connection(gate.mavsdk_url)
        except MavsdkConnectionError as exc:
            self.close()
            raise LinkError(f"cannot open {url}: {exc}") from None
        system = await mavsdk.first_autopilot(timeout_s=float(timeout_s))
        if system is None:
            why = silence_reason(gate.inbound.counts, self.signing_key)
            self.close()
            raise LinkError(f"no autopilot heard on {url} within {timeout_s:g} s ({why})")
        self.url = url
        self.session.attach(
            mavsdk, system, MavlinkDirect(system._system), MissionRawAsync(system), await system.get_system_id()
        )
        if self.onboard is not None:
            self.onboard.set_system(self.target_system)
        self.watchers.heard_now()
        self._was_connected = True
        if self.stream_settings is not None:
            self.streams = StreamKeeper(
                self.stream_settings,
                commands=self.commands,
                sender=self.direct,
                target=self.session,
                connected=lambda: self.connected,
                adsb=self.adsb,
            )
        self._start_tasks()
        log.info("connected to system %d on %s", self.target_system, url)

    def _start_tasks(self) -> None:
        loop = asyncio.get_running_loop()
        coros = [*self.watchers.coroutines(), self._watch_link()]
        if self.streams is not None:
            coros.append(self.streams.run())
        self._tasks = [loop.create_task(coro, name=f"link-{coro.__name__}") for coro in coros]

    def close(self) -> None:
        """Stop the subscriptions and release MAVSDK (idempotent)."""
        for task in self._tasks:
            task.cancel()
        self._tasks.clear()
        self.session.release()

    async def aclose(self) -> None:
        """Cancel the subscriptions, let them unsubscribe, then release MAVSDK (idempotent)."""
        tasks, self._tasks = self._tasks, []
        for task in tasks:
            task.cancel()
        if tasks:  # a subscription stuck in MAVSDK must not hold the close
            _, stuck = await asyncio.wait(tasks, timeout=CANCEL_WAIT_S)
            if stuck:
                log.warning(
                    "closing the link: %d telemetry subscriptions did not end within %g s (%s)",
                    len(stuck),
                    CANCEL_WAIT_S,
                    ", ".join(sorted(t.get_name() for t in stuck)),
                )
        await self.commands.wait_in_flight(IN_FLIGHT_WAIT_S)
        self.close()

    async def __aenter__(self) -> VehicleLink:
        return self

    async def __aexit__(self, *exc) -> None:
        await self.aclose()

    @property
    def target_system(self) -> int:
        """The system id of the autopilot (learnt on ``connect``; 1 before)."""
        return self.session.target_system

    @property
    def gate(self) -> GateThread | None:
        """The signing gate of the current connection (None while not connected)."""
        return self.session.gate

    # ----------------------------------------------------------------- link state

    def on_link_change(self, callback: Callable[[bool], None]) -> Callable[[], None]:
        """Call ``callback(connected)`` on the loop when the heartbeat is lost or is back;
        returns the function that stops it."""
        self._link_listeners.append(callback)
        return lambda: self._link_listeners.remove(callback) if callback in self._link_listeners else None

    @property
    def connected(self) -> bool:
        """True while heartbeats arrive (within ``HEARTBEAT_TIMEOUT_S``)."""
        return time.monotonic() - self.watchers.state.heartbeat_t < HEARTBEAT_TIMEOUT_S

    async def wait_connected(self, timeout_s: float | None = None) -> bool:
        """Wait until heartbeats arrive again (MAVSDK keeps the connection open meanwhile)."""
        deadline = None if timeout_s is None else time.monotonic() + timeout_s
        while not self.connected:
            if deadline is not None and time.monotonic() > deadline:
                return False
            await asyncio.sleep(0.05)
        return True

    async def _watch_link(self) -> None:
        """Detect heartbeat loss and return; ask for the streams again and tell the listeners."""
        while True:
            await asyncio.sleep(LINK_CHECK_PERIOD_S)
            now_connected = self.connected
            if now_connected == self._was_connected:
                continue
            self._was_connected = now_connected
            if now_connected:
                log.warning("link to system %d is back", self.target_system)
                if self.streams is not None:
                    self.streams.request_again("link back")
            else:
                log.warning(
                    "link to system %d lost: no heartbeat for %.1f s; still listening on %s",
                    self.target_system,
                    HEARTBEAT_TIMEOUT_S,
                    self.url,
                )
            for callback in list(self._link_listeners):
                try:
                    callback(now_connected)
                except Exception:  # noqa: BLE001
                    log.exception("link listener failed")

    # ----------------------------------------------------------------- telemetry

    @property
    def telemetry(self) -> Telemetry:
        """The latest vehicle state (a new immutable snapshot on every access)."""
        return self.watchers.state.snapshot(time.monotonic(), self.frames)

    def set_planning_home(self, home_lla) -> LinkFrames:
        """Freeze the home frame: positions in and out of the link are about ``home_lla`` from
        now on, converted with the vehicle's EKF origin if it reported one
        (``companion.link.frames``). Returns the frames."""
        origin = self.telemetry.origin_lla
        self.frames = LinkFrames.build(home_lla, origin)
        if origin is None:
            log.info("the vehicle reports no EKF origin (GPS_GLOBAL_ORIGIN): its local frame is taken to be home's")
        else:
            log.info(
                "home %.7f, %.7f, %.2f m; EKF origin %.7f, %.7f, %.2f m; home in the vehicle's local frame: %s m",
                *self.frames.home_lla,
                *origin,
                np.round(self.frames.home_in_origin_ned_m, 3).tolist(),
            )
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
