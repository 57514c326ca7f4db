"""The fleet's start gate: the vehicles' pre-arm checks held failing until every companion waits
to arm, then cleared on all at once."""

from __future__ import annotations

import logging
import socket
import threading
import time

from pymavlink.dialects.v20 import ardupilotmega as mavlink

from heli_common.mavlink_ids import COPTER_MODES

__all__ = ["StartGate", "HOLD_CONFIG", "HOLD_FRACTION"]

log = logging.getLogger(__name__)

#: The start gate releases the vehicles after this fraction of a companion's pre-arm wait
#: (``StartupSettings.prearm_timeout_s``, vehicle s) even if not every companion waits yet.
HOLD_FRACTION = 0.5
#: The simulators' settings while the start is held: pre-arm checks failing.
HOLD_CONFIG = (
    "# written by companion fleet up: pre-arm checks fail until the start gate opens\n[flight]\nprearm_fail = 1\n"
)
#: The gate speaks MAVLink as a ground station: system 255 (a GCS's usual id), Mission Planner's component.
GCS_SYSTEM_ID = 255
GCS_COMPONENT_ID = mavlink.MAV_COMP_ID_MISSIONPLANNER
#: The simulators' autopilot component: the one whose messages count and to which the gate writes.
AUTOPILOT_COMPONENT_ID = mavlink.MAV_COMP_ID_AUTOPILOT1


class StartGate:
    """Holds the fleet's start until every companion waits to arm, then releases all at once.

    A fleet's companions get ready at different times (each plans its mission with its own
    workers while the others do: seconds apart on a shared machine), and vehicles meant to meet
    at a crossing would then miss each other. As a ground operator holds a fleet's take-off until
    every crew is ready, the launcher (``Fleet(sync_start=True)``, the default) holds every
    vehicle's pre-arm checks failing (``SIM_PREARM_FAIL = 1`` from the simulator's start, its
    ``--config``: ``HOLD_CONFIG``) until every companion waits to arm (its vehicle in GUIDED,
    disarmed), then the gate clears them on all at once (PARAM_SET over MAVLink, as a ground
    station). How long a companion waits for its vehicle's pre-arm checks depends on the vehicle:

    - one that reports them in SYS_STATUS (``MAV_SYS_STATUS_PREARM_CHECK``, as ArduPilot does) is
      waited for up to ``startup.prearm_timeout_s`` (30 vehicle s; ``wait_prearm``), and the
      companions then arm within a SYS_STATUS period of each other;
    - one that does not (``sim-vehicle`` today) is armed at once, and a refusal is retried
      ``startup.arm_attempts`` times ``retry_interval_s`` apart: the gate then holds at most
      ``HOLD_FRACTION`` of those retries, and the companions arm within one retry interval of each
      other (2 vehicle s).

    The gate reads the vehicles' SYS_STATUS to tell which, and never holds a companion past its
    budget: one that is not ready by then starts late, as without the gate.

    A thread speaking MAVLink to each simulator's port as a ground station (system 255,
    component 190).

    Parameters
    ----------
    vehicles : sequence of (sysid, sim port, still_running: callable () -> bool)
    speedup : float
        Vehicle seconds per wall second (the hold's limit is in vehicle seconds).
    """

    GUIDED = COPTER_MODES["GUIDED"]
    ARMED_FLAG = mavlink.MAV_MODE_FLAG_SAFETY_ARMED

    def __init__(self, vehicles, speedup: float) -> None:
        from companion.service.startup import StartupSettings

        startup = StartupSettings()
        self.vehicles = list(vehicles)
        #: wall s a companion waits while its vehicle reports pre-arm checks failing ...
        self.prearm_hold_s = HOLD_FRACTION * startup.prearm_timeout_s / speedup
        #: ... and while its arming is refused by one that does not report them (0.3 s after
        #: each refusal, then the retry interval in vehicle s)
        self.retry_hold_s = HOLD_FRACTION * (startup.arm_attempts - 1) * (0.3 + startup.retry_interval_s / speedup)
        self.reports_prearm: dict[int, bool] = {}  # sysid -> SYS_STATUS has the pre-arm bit
        self.state: dict[int, tuple[int, bool]] = {}  # sysid -> (custom mode, armed)
        self.confirmed: set[int] = set()
        self.released_wall_s: float | None = None
        self.first_waiting_s: float | None = None
        self.waiting_at_release: list[int] = []
        self.held_s: float | None = None
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._run, name="fleet-start-gate", daemon=True)

    def start(self) -> StartGate:
        self._thread.start()
        return self

    def stop(self) -> None:
        self._stop.set()
        if self._thread.is_alive():
            self._thread.join(5.0)

    def waiting(self) -> list[int]:
        """System ids whose vehicle is in GUIDED and disarmed: its companion waits to arm."""
        return [sysid for sysid, (mode, armed) in self.state.items() if mode == self.GUIDED and not armed]

    @property
    def max_hold_s(self) -> float:
        """How long the gate may hold (wall s): the shorter budget unless every vehicle is known
        to report its pre-arm checks."""
        known = [self.reports_prearm.get(sysid) for sysid, _, _ in self.vehicles]
        return self.prearm_hold_s if known and all(known) else self.retry_hold_s

    def describe(self) -> dict:
        return {
            "released": self.released_wall_s is not None,
            "held_s": self.held_s,
            "waiting_at_release": self.waiting_at_release,
            "confirmed": sorted(self.confirmed),
            "max_hold_s": round(self.max_hold_s, 1),
            "vehicles_report_prearm": self.reports_prearm,
        }

    def _run(self) -> None:
        sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        sock.bind(("127.0.0.1", 0))
        sock.settimeout(0.05)
        mav = mavlink.MAVLink(None, srcSystem=GCS_SYSTEM_ID, srcComponent=GCS_COMPONENT_ID)
        mav.robust_parsing = True
        ports = {sysid: port for sysid, port, _ in self.vehicles}
        last_beat = last_set = 0.0
        try:
            while not self._stop.is_set():
                now = time.monotonic()
                if now - last_beat >= 1.0:  # a peer the simulators answer (heard in 10 s)
                    beat = mav.heartbeat_encode(mavlink.MAV_TYPE_GCS, mavlink.MAV_AUTOPILOT_INVALID, 0, 0, 0)
                    for sysid, port in ports.items():
                        _send(sock, beat.pack(mav), port)
                        if sysid not in self.reports_prearm:  # SYS_STATUS on this link, 2 Hz
                            ask = mav.command_long_encode(
                                sysid,
                                AUTOPILOT_COMPONENT_ID,
                                mavlink.MAV_CMD_SET_MESSAGE_INTERVAL,
                                0,
                                mavlink.MAVLINK_MSG_ID_SYS_STATUS,
                                500000,
                                0,
                                0,
                                0,
                                0,
                                0,
                            )
                            _send(sock, ask.pack(mav), port)
                    last_beat = now
                self._read(sock, mav)
                live = [sysid for sysid, _, running in self.vehicles if running()]
                if self.released_wall_s is None:
                    waiting = self.waiting()
                    if waiting and self.first_waiting_s is None:
                        self.first_waiting_s = now
                    everyone = bool(live) and all(sysid in waiting for sysid in live)
                    too_long = self.first_waiting_s is not None and now - self.first_waiting_s > self.max_hold_s
                    if everyone or too_long:
                        self.released_wall_s = now
                        self.held_s = round(now - self.first_waiting_s, 2)
                        self.waiting_at_release = sorted(waiting)
                        log.info(
                            "start gate: releasing %s after %.1f s (waiting: %s)",
                            sorted(ports),
                            self.held_s,
                            sorted(waiting),
                        )
                if self.released_wall_s is not None:
                    pending = [s for s in ports if s not in self.confirmed]
                    if not pending or now - self.released_wall_s > 10.0:
                        if pending:
                            log.warning("start gate: no PARAM_VALUE SIM_PREARM_FAIL = 0 from %s", pending)
                        return
                    if now - last_set >= 0.3:
                        for sysid in pending:
                            msg = mav.param_set_encode(
                                sysid, AUTOPILOT_COMPONENT_ID, b"SIM_PREARM_FAIL", 0.0, mavlink.MAV_PARAM_TYPE_INT8
                            )
                            _send(sock, msg.pack(mav), ports[sysid])
                        last_set = now
                if not live:
                    return
        finally:
            sock.close()

    def _read(self, sock, mav) -> None:
        try:
            data, _ = sock.recvfrom(65535)
        except (TimeoutError, OSError):
            return
        for msg in mav.parse_buffer(data) or []:
            kind = msg.get_type()
            if msg.get_srcComponent() != AUTOPILOT_COMPONENT_ID:
                continue
            if kind == "HEARTBEAT":
                self.state[msg.get_srcSystem()] = (msg.custom_mode, bool(msg.base_mode & self.ARMED_FLAG))
            elif kind == "SYS_STATUS":
                self.reports_prearm[msg.get_srcSystem()] = bool(
                    msg.onboard_control_sensors_present & mavlink.MAV_SYS_STATUS_PREARM_CHECK
                )
            elif kind == "PARAM_VALUE" and self.released_wall_s is not None:
                name = msg.param_id.decode() if isinstance(msg.param_id, bytes) else msg.param_id
                if name.rstrip("\x00") == "SIM_PREARM_FAIL" and msg.param_value == 0.0:
                    self.confirmed.add(msg.get_srcSystem())


def _send(sock, data: bytes, port: int) -> None:
    try:
        sock.sendto(data, ("127.0.0.1", port))
    except OSError:
        pass
