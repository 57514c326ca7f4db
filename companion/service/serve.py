"""``companion serve``: the long-running companion-computer process (issue 14).

One ``CompanionService`` per vehicle, for the life of the companion computer:

1. **wait for the vehicle**: connect (``link.connect``), retrying every
   ``link.connect_timeout_s`` until an autopilot answers; the link then survives the vehicle's
   reboots (it asks for its streams again, ``companion.link.streams``);
2. **presence**: the companion is a component of the vehicle's MAVLink system (its system id,
   191, HEARTBEAT of type ONBOARD_CONTROLLER: STANDBY when ready, ACTIVE while it flies;
   ``companion.link.onboard``) and, with zenoh, a liveliness token ``uav/<sysid>/companion`` and
   a status on ``uav/<sysid>/status`` every second between flights;
3. **ready**: a STATUSTEXT ``companion ready ...`` when it is (and again after each flight and
   when the vehicle comes back after a loss; ``companion: service stopped`` when it exits);
4. **start**: MAV_CMD_MISSION_START addressed to component 191 (from any ground station; the
   vehicle routes it, as ArduPilot does) or ``{"command": "mission_start"}`` on
   ``uav/<sysid>/command`` (refused by a zenoh configuration whose access control is on: no rule
   lets anyone put there) flies the vehicle's stored mission: a ``CompanionDaemon`` on the same
   link and zenoh session, exactly as ``companion run`` without ``--mission`` flies it;
5. **stop**: the flight ends as ``companion run``'s does, including the moment a pilot changes
   the mode away from GUIDED (the companion stops commanding); then back to 3.

With ``view.foxglove`` (``--foxglove``) the live Foxglove view is up for the service's whole
life, from before the vehicle answers: the vehicle's state from its telemetry
(``companion.view.live``) between flights as during them, and each flight's scene, plan and
decisions on the same server while it flies (the last flight's stay shown until the next).

With ``resume`` (``--resume``, the systemd unit's), a service that finds the vehicle hovering in
GUIDED when it starts (its predecessor crashed or was killed mid-flight) takes it over first and
flies on from the vehicle's current item (``companion run --resume``).

A command while a flight runs is answered TEMPORARILY_REJECTED; MISSION_START with a first or
last item (params 1 and 2 other than 0) is DENIED: the service flies whole missions.
"""

from __future__ import annotations

import asyncio
import dataclasses
import datetime
import json
import logging
import threading
from pathlib import Path

from pymavlink.dialects.v20 import ardupilotmega as mavlink

from companion.config import Settings
from companion.daemon import CompanionDaemon, companion_link
from companion.errors import CompanionError, FlightAborted, LinkError, MissionError, VehicleRefused
from companion.link.onboard import OnboardCommand, OnboardComponent
from companion.link.setpoints import raise_stream_priority
from companion.link.vehicle import check_url
from companion.service.mission import GUIDED
from companion.service.startup import is_airborne
from companion.threats.settings import DEFAULT_SYSID

log = logging.getLogger(__name__)

__all__ = ["CompanionService", "FlightRequest", "READY_TEXT"]

READY_TEXT = "companion ready: MISSION_START to comp 191"
#: The STATUSTEXT word for how a flight ended, by the error that ended it.
OUTCOME_WORDS = {
    FlightAborted: "aborted",
    VehicleRefused: "refused by the vehicle",
    MissionError: "not flown (mission)",
    LinkError: "ended: link",
}
#: How often (wall clock, s) the presence status is published between flights.
PRESENCE_PERIOD_S = 1.0


@dataclasses.dataclass(frozen=True)
class FlightRequest:
    """A request to fly the stored mission, and who sent it (``MAVLink 255/190``, ``zenoh``);
    ``resume``: fly on from the vehicle's current item (``CompanionDaemon``'s ``resume``)."""

    source: str
    resume: bool = False


class CompanionService:
    """``companion serve`` for one vehicle (see the module docstring).

    Parameters
    ----------
    settings : Settings
    world_path : path, optional
        A world file whose obstacles are added to every mission's.
    record_dir : path, optional
        Each flight's record goes here (``flight-<n>-<UTC time>.mcap``).
    max_flights : int, optional
        Return after this many flights (default: serve until stopped).
    resume : bool
        On start, take over a vehicle that hovers in GUIDED (a companion that stopped, e.g. a
        crash that systemd restarted): fly on from its current mission item with the threats
        of the ``state.dir`` snapshot, as ``companion run --resume`` does.
    workers : str
        ``CompanionDaemon``'s ``workers``.
    """

    def __init__(
        self,
        settings: Settings,
        *,
        world_path=None,
        record_dir=None,
        max_flights: int | None = None,
        workers: str = "process",
        resume: bool = False,
    ) -> None:
        # the session opens before any vehicle answers: its prefix cannot wait for the vehicle's id
        self.settings = dataclasses.replace(settings, zenoh=settings.zenoh.for_vehicle(DEFAULT_SYSID))
        self.world_path = world_path
        self.record_dir = Path(record_dir) if record_dir else None
        self.max_flights = max_flights
        self.resume = resume
        self.workers = workers
        self.onboard = OnboardComponent(None, self._on_command)
        self.link = companion_link(settings, onboard=self.onboard)
        self.bus = None
        self.state = "waiting for the vehicle"
        self.flights = 0
        self.last_outcome: str | None = None
        self.daemon: CompanionDaemon | None = None
        self.live = None  # companion.view.live.LiveView, with view.foxglove
        self._busy = False
        self._lock = threading.Lock()
        self._loop: asyncio.AbstractEventLoop | None = None
        self._requests: asyncio.Queue[FlightRequest] | None = None
        self._token = None

    # ------------------------------------------------------------------ the service
    async def run(self) -> None:
        """Serve until ``max_flights`` flights have flown, or until cancelled (SIGTERM)."""
        self._loop = asyncio.get_running_loop()
        self._requests = asyncio.Queue()
        check_url(self.settings.link.connect)
        presence = None
        try:
            if self.settings.zenoh.enabled:  # before the priority: zenoh's threads stay normal
                self._open_presence()
                presence = self._loop.create_task(self._publish_presence(), name="presence")
            self._open_live_view()  # before the priority too: the server's threads
            raise_stream_priority()  # before connect: MAVSDK's threads inherit it
            await self._wait_for_vehicle()
            self.link.on_link_change(self._on_link_change)
            if self.resume and await self._left_hovering():
                with self._lock:
                    self._busy = True
                await self._fly(FlightRequest("resumed after a restart", resume=True))
            while self.max_flights is None or self.flights < self.max_flights:
                self._ready()
                await self._fly(await self._requests.get())
        finally:
            self._set_state("stopped")
            self._say(mavlink.MAV_SEVERITY_NOTICE, "companion: service stopped")
            if presence is not None:
                presence.cancel()
            await self._close()

    async def _wait_for_vehicle(self) -> None:
        link = self.settings.link
        while True:
            try:
                await self.link.connect(link.connect, link.connect_timeout_s)
                return
            except CompanionError as exc:
                log.warning("%s; waiting for the vehicle", exc)

    async def _left_hovering(self) -> bool:
        """Does the vehicle hover in GUIDED, as a companion that stopped mid-flight leaves it?"""
        try:
            await self.link.waits.wait_ready(self.settings.link.connect_timeout_s)
        except CompanionError as exc:
            log.warning("--resume: %s; not taking over", exc)
            return False
        tele = self.link.telemetry
        hovering = tele.mode == GUIDED and is_airborne(tele, self.settings.startup.join_min_height_m)
        log.info(
            "--resume: the vehicle is %s",
            "hovering in GUIDED: taking it over"
            if hovering
            else f"not hovering in GUIDED ({tele.mode_name}): nothing to resume",
        )
        return hovering

    async def _fly(self, request: FlightRequest) -> None:
        """One flight of the stored mission, then ready again."""
        self.flights += 1
        self._set_state("flying")
        self.onboard.active = True
        self._say(mavlink.MAV_SEVERITY_INFO, f"companion: flight {self.flights} ({request.source})")
        self.daemon = CompanionDaemon(
            self.settings,
            world_path=self.world_path,
            record_path=self._record_path(),
            resume=request.resume,
            workers=self.workers,
            link=self.link,
            bus=self.bus,
            live=self.live,
        )
        verdict, reason = "completed", ""
        try:
            await self.daemon.run()
        except CompanionError as exc:  # refused, aborted (a pilot took over), no mission ...
            verdict, reason = OUTCOME_WORDS.get(type(exc), "not flown"), str(exc)
            log.error("flight %d %s: %s", self.flights, verdict, reason)
        except Exception as exc:  # a bug: the service stays up for the next flight
            verdict, reason = "failed", f"{type(exc).__name__}: {exc}"
            log.exception("flight %d failed", self.flights)
        finally:
            print(json.dumps({"flight": self.flights, **self.daemon.summary.as_dict()}), flush=True)
            self.onboard.active = False
        self.last_outcome = f"{verdict}: {reason}" if reason else verdict
        severity = mavlink.MAV_SEVERITY_INFO if not reason else mavlink.MAV_SEVERITY_WARNING
        self._say(severity, f"companion: flight {self.flights} {verdict}")
        if reason:
            self._say(severity, reason)

    def _record_path(self) -> Path | None:
        if self.record_dir is None:
            return None
        self.record_dir.mkdir(parents=True, exist_ok=True)
        stamp = datetime.datetime.now(datetime.UTC).strftime("%Y%m%dT%H%M%SZ")
        return self.record_dir / f"flight-{self.flights}-{stamp}.mcap"

    def _open_live_view(self) -> None:
        """The live Foxglove view for the service's life (``view.foxglove``), fed from the link."""
        if not self.settings.view.foxglove:
            return
        from companion.extras import require

        require("view", "foxglove")
        from companion.view.live import LiveView  # foxglove-sdk only when used
        from companion.view.sinks import parse_foxglove_address

        self.live = LiveView(self.link, *parse_foxglove_address(self.settings.view.foxglove, "view.foxglove"))

    async def _close(self) -> None:
        if self.live is not None:
            self.live.close()
        if self._token is not None:
            self._token.undeclare()
        if self.bus is not None:
            self.bus.close()
        await self.link.aclose()

    # ------------------------------------------------------------------ state and presence
    def _ready(self) -> None:
        with self._lock:
            self._busy = False
        self._announce_ready()

    def _announce_ready(self) -> None:
        self._set_state("ready")
        self._say(mavlink.MAV_SEVERITY_INFO, READY_TEXT)

    def _set_state(self, state: str) -> None:
        self.state = state
        log.info("companion serve: %s (flights %d, last %s)", state, self.flights, self.last_outcome)

    def _say(self, severity: int, text: str) -> None:
        """A STATUSTEXT from the companion component (while the link is up)."""
        if self.link.gate is not None and self.link.connected:
            self.link.gate.post_own(self.onboard.statustext(severity, text))

    def _on_link_change(self, connected: bool) -> None:
        if connected and self.state == "ready":  # the vehicle is back (a reboot): tell its ground stations
            self._announce_ready()  # (a start already queued stays queued)

    def _open_presence(self) -> None:
        from companion.threats.transport.bus import ThreatBus

        self.bus = ThreatBus.from_settings(self.settings.zenoh).open()
        self._token = self.bus.session.liveliness().declare_token(self.bus.key("companion"))
        self.bus.subscribe_json("command", self._on_zenoh_command)

    def presence(self) -> dict:
        """The status published between flights."""
        return {
            "service": self.state,
            "flights": self.flights,
            "last_outcome": self.last_outcome,
            "link": self.link.connected,
            "mode": self.link.telemetry.mode_name,
        }

    async def _publish_presence(self) -> None:
        while True:
            if self.state != "flying":  # while flying, the flight publishes its status
                self.bus.outbound.publish_status(self.presence())
            await asyncio.sleep(PRESENCE_PERIOD_S)

    # ------------------------------------------------------------------ commands (other threads)
    def _on_command(self, command: OnboardCommand) -> int:
        """A MAVLink command to component 191 (the gate's thread): the MAV_RESULT."""
        if command.command != mavlink.MAV_CMD_MISSION_START:
            return mavlink.MAV_RESULT_UNSUPPORTED
        if any(command.params[:2]):
            log.warning(
                "MISSION_START items %g..%g refused: the service flies whole missions (0, 0)", *command.params[:2]
            )
            return mavlink.MAV_RESULT_DENIED
        source = f"MAVLink {command.sender_system}/{command.sender_component}"
        return mavlink.MAV_RESULT_ACCEPTED if self._request(source) else mavlink.MAV_RESULT_TEMPORARILY_REJECTED

    def _on_zenoh_command(self, key: str, message: dict | None) -> None:
        """``uav/<sysid>/command`` (a zenoh thread): answered on ``uav/<sysid>/events``."""
        command = message.get("command") if isinstance(message, dict) else None
        if command != "mission_start":
            result = f'unsupported: expected {{"command": "mission_start"}}, got {message!r}'[:200]
        else:
            result = "accepted" if self._request("zenoh") else f"busy: {self.state}"
        log.info("zenoh command %r: %s", command, result)
        self.bus.outbound.publish_event({"event": "command", "command": command, "result": result})

    def _request(self, source: str) -> bool:
        """Queue a flight unless one is queued or flying, or the vehicle is not there."""
        with self._lock:
            if self._busy or self.state != "ready" or self._loop is None:
                return False
            self._busy = True
        self._loop.call_soon_threadsafe(self._requests.put_nowait, FlightRequest(source))
        return True
