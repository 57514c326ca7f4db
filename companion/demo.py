"""``companion demo``: the full show in separate processes on the embedded defaults.

The demo process starts a ``sim-vehicle`` (SITL helicopter) and a ``companion run`` (the
daemon) on free ports, and is itself the separate threat-injecting process: it watches the
companion's zenoh ``status`` and ``path`` and, while the mission is flown, puts

1. a **pop-up** threat on the reference far ahead (time to conflict well above the replanning
   budget): the companion **replans** around it;
2. a threat **moving at sqrt(2) m/s** across the path met within about 10 m (paper Fig. 8): too
   late to replan, the companion **switches** to a pre-planned M-GART alternative;
3. an invalid payload: the companion publishes a **rejected** event and flies on;

then removes the threats (DELETE) and waits for the landing. It prints every decision with its
latency (threat PUT to the first setpoint of the new trajectory), the minimum separation from
the threats and the tracking error, and renders the report (``companion report``) with a
Fig. 8-style plot.

The mission is package data (``companion/data/exclusion_zones.plan``, read through
``importlib.resources``), so the demo runs from an installed wheel anywhere. The child processes
are ``python -m sim_vehicle.cli`` and ``python -m companion.cli`` of this interpreter, in the
current directory and environment, started and stopped by ``companion.sitl.vehicles.flight_processes``.
The threat integration tests and the SITL benchmarks drive their flights with the same pieces
(through ``tests/flight_support.py``).
"""

from __future__ import annotations

import contextlib
import importlib.resources
import json
import logging
import threading
import time
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from companion.errors import CompanionError
from companion.geo import LocalFrame
from companion.sitl.vehicles import flight_processes
from companion.threats.model import Threat
from companion.threats.transport.bus import ThreatBus

log = logging.getLogger(__name__)

#: ``sim-vehicle``'s default home (lat, lon, alt AMSL): the origin of the demo's global threats.
DEMO_HOME = (47.397742, 8.545594, 488.0)
#: The demo's flight record, in its output directory: MCAP, which Foxglove opens.
DEMO_RECORD = "flight.mcap"
#: The demo's mission, package data of ``companion`` (``mission_files/`` links to it).
DEMO_MISSION_RESOURCE = "data/exclusion_zones.plan"


@contextlib.contextmanager
def demo_mission():
    """The demo mission as a file on disk (from the installed package), for the context."""
    resource = importlib.resources.files("companion").joinpath(DEMO_MISSION_RESOURCE)
    with importlib.resources.as_file(resource) as path:
        yield Path(path)


@dataclass(frozen=True)
class Injection:
    """A threat placed relative to the reference being flown.

    Parameters
    ----------
    threat_id : str
    kind : str
        ``popup`` (static) or ``moving``.
    leg : int
        Put it while this leg (0-based) is flown ...
    after_s : float
        ... once its reference has run this long (mission seconds).
    ahead_s : float
        The threat's centre is the reference position this far ahead in time ...
    lateral_m : float
        ... moved this far to the right of the path (negative: left).
    radius_m : float
    speed_m_s : float
        Moving threats move at this speed ...
    heading : str
        ... ``across`` the path (towards it, perpendicular) or ``head_on`` (straight at the
        vehicle: from the meeting point towards the reference position now, level, so that on
        a curving leg too it comes at the vehicle and a hover in its way is no escape).
    frame : str
        ``local_ned`` or ``global`` (the threat is sent as lat/lon/alt about ``DEMO_HOME``).
    ttl_s : float
    raw_payload : bytes, optional
        Put these bytes instead of a placed threat (an invalid payload, to be rejected).
    """

    threat_id: str
    kind: str
    leg: int
    after_s: float
    ahead_s: float
    radius_m: float
    lateral_m: float = 0.0
    speed_m_s: float = 0.0
    heading: str = "across"
    frame: str = "local_ned"
    ttl_s: float = 120.0
    raw_payload: bytes | None = None


#: The demo's threats on ``exclusion_zones.plan``: a threat coming head-on along leg 1 at
#: 3 m/s (an evasion: no retiming or path helps against it), a pop-up on leg 3 once its M-GART
#: alternatives are ready (a switch), an invalid payload (rejected).
DEMO_HEAD_ON = Injection(
    "mover1", "moving", leg=1, after_s=2.0, ahead_s=5.0, radius_m=3.0, speed_m_s=3.0, heading="head_on"
)
DEMO_POPUP = Injection("popup1", "popup", leg=3, after_s=4.0, ahead_s=5.0, radius_m=5.0)
DEMO_INVALID = Injection(
    "broken",
    "popup",
    leg=3,
    after_s=3.0,
    ahead_s=0.0,
    radius_m=1.0,
    raw_payload=b'{"v": 1, "id": "broken", "kind": "popup"}',
)
DEMO_INJECTIONS = (DEMO_HEAD_ON, DEMO_POPUP, DEMO_INVALID)


class FlightWatcher:
    """Follows a companion's ``status``, ``path`` and ``events`` over zenoh (thread-safe)."""

    def __init__(self, bus: ThreatBus, listener=None):
        self.bus = bus
        self.listener = listener  # on_status(msg) / on_event(msg), e.g. FlightProgress
        self._lock = threading.Lock()
        self.status: dict | None = None
        self.path: dict | None = None
        self.events: list[dict] = []
        bus.subscribe_json("status", self._on_status)
        bus.subscribe_json("path", self._on_path)
        bus.subscribe_json("events", self._on_event)

    def _on_status(self, key, msg) -> None:
        with self._lock:
            self.status = msg
        if self.listener is not None and isinstance(msg, dict):
            self.listener.on_status(msg)

    def _on_path(self, key, msg) -> None:
        with self._lock:
            self.path = msg

    def _on_event(self, key, msg) -> None:
        with self._lock:
            self.events.append(msg)
        if self.listener is not None and isinstance(msg, dict):
            self.listener.on_event(msg)

    def reference_at(self, t_s: float) -> tuple[np.ndarray, np.ndarray] | None:
        """Reference position and unit direction of travel at mission time ``t_s``."""
        with self._lock:
            path = self.path
        if not path or not path.get("reference_ned_m"):
            return None
        ref = np.asarray(path["reference_ned_m"], dtype=float)
        t = np.linspace(0.0, path["duration_s"], len(ref))
        tau = min(max(t_s - path["t0_s"], 0.0), path["duration_s"])
        pos = np.array([np.interp(tau, t, ref[:, i]) for i in range(3)])
        ahead = np.array([np.interp(min(tau + 0.5, t[-1]), t, ref[:, i]) for i in range(3)])
        back = np.array([np.interp(max(tau - 0.5, 0.0), t, ref[:, i]) for i in range(3)])
        direction = ahead - back
        norm = np.linalg.norm(direction[:2])
        return pos, (direction / norm if norm > 1e-6 else np.array([1.0, 0.0, 0.0]))

    def due(self, injection: Injection) -> bool:
        """True when ``injection``'s leg is flown on its planned reference long enough."""
        with self._lock:
            status, path = self.status, self.path
        if not status or not path or path.get("leg") != injection.leg:
            return False
        if path.get("path_id") != f"leg{injection.leg}":
            return False
        return status["t_s"] - path["t0_s"] >= injection.after_s


def place(injection: Injection, watcher: FlightWatcher) -> Threat:
    """The threat of ``injection`` on the current reference (local NED, or global)."""
    now = watcher.status["t_s"]
    pos, direction = watcher.reference_at(now + injection.ahead_s)
    right = np.array([-direction[1], direction[0], 0.0]) / max(np.linalg.norm(direction[:2]), 1e-9)
    meet = pos + injection.lateral_m * right
    velocity = np.zeros(3)
    if injection.speed_m_s > 0 and injection.heading == "head_on":
        here = watcher.reference_at(now)[0]
        towards = np.append(here[:2] - meet[:2], 0.0)
        norm = np.linalg.norm(towards)
        towards = towards / norm if norm > 1e-6 else -np.append(direction[:2], 0.0)
        velocity = injection.speed_m_s * towards
    elif injection.speed_m_s > 0:
        velocity = -np.sign(injection.lateral_m or 1.0) * injection.speed_m_s * right
    position = tuple(map(float, meet))
    if injection.frame == "global":
        lat, lon, alt = LocalFrame(*DEMO_HOME).to_lla(*meet)
        position = (float(lat), float(lon), float(alt))
    return Threat(
        injection.threat_id,
        injection.kind,
        injection.frame,
        position,
        tuple(map(float, velocity)),
        injection.radius_m,
        injection.ttl_s,
    )


def inject(watcher: FlightWatcher, injections, timeout_s: float, *, done=None) -> list[Threat]:
    """Put each injection when it is due; stop when all are in, ``done()`` or the timeout.

    Returns the threats put (raw payloads are sent as they are and not returned).
    """
    pending = list(injections)
    sent: list[Threat] = []
    deadline = time.monotonic() + timeout_s
    while pending and time.monotonic() < deadline and not (done and done()):
        time.sleep(0.02)
        for injection in [i for i in pending if watcher.due(i)]:
            pending.remove(injection)
            if injection.raw_payload is not None:
                watcher.bus.client.put_raw(injection.threat_id, injection.raw_payload)
                log.info("put a raw payload on %s", injection.threat_id)
                continue
            threat = place(injection, watcher)
            watcher.bus.client.put_threat(threat)
            sent.append(threat)
            log.info("put %s %s at %s", threat.kind, threat.id, np.round(threat.position, 1))
    return sent


def last_json_line(path: Path) -> dict | None:
    """The last line of ``path`` that starts with ``{``, parsed (None: none, or not JSON)."""
    for line in reversed(path.read_text(errors="replace").splitlines()):
        if line.startswith("{"):
            try:
                return json.loads(line)
            except json.JSONDecodeError:
                return None
    return None


def fly(
    out_dir: Path,
    mission: Path,
    *,
    speedup: float = 4.0,
    injections=(),
    timeout_s: float = 300.0,
    gcs_out: str | None = None,
    extra_args=(),
    env: dict | None = None,
    listener=None,
    record_name: str = "flight.jsonl",
) -> dict:
    """Fly ``mission`` with a fresh ``sim-vehicle`` and ``companion run`` (separate processes).

    This process watches the flight over zenoh (telling ``listener`` every status and event
    message, e.g. a ``companion.progress.FlightProgress``) and puts the ``injections`` when they
    are due, then removes them. Returns the companion's summary plus ``events`` (seen on zenoh) and
    ``record`` (the flight record's path).
    """
    with flight_processes(
        out_dir, mission, speedup=speedup, gcs_out=gcs_out, extra_args=extra_args, env=env, record_name=record_name
    ) as flight:
        with ThreatBus(1, listen=(), connect=(flight.endpoint,)) as bus:
            watcher = FlightWatcher(bus, listener)
            if injections:
                sent = inject(watcher, injections, timeout_s, done=lambda: flight.companion.poll() is not None)
                time.sleep(2.0)
                for threat in sent:
                    bus.client.delete_threat(threat.id)
            flight.companion.wait(timeout_s)
    summary = last_json_line(flight.log)
    if flight.companion.returncode != 0 or summary is None:
        raise CompanionError(
            f"the flight of {mission.name} failed (companion exit {flight.companion.returncode}); see {flight.log}"
        )
    summary["events"] = list(watcher.events)
    summary["record"] = str(flight.record)
    return summary


def run_demo(out_dir: Path, *, speedup: float = 4.0, gcs_out: str | None = "127.0.0.1:14550", listener=None) -> dict:
    """The demo flight: the demo mission (``demo_mission``) with ``DEMO_INJECTIONS``."""
    with demo_mission() as mission:
        return fly(
            out_dir,
            mission,
            speedup=speedup,
            injections=DEMO_INJECTIONS,
            gcs_out=gcs_out,
            listener=listener,
            record_name=DEMO_RECORD,
        )
