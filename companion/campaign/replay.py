"""``companion campaign replay DIR ID``: one encounter of a campaign flown in SITL, for a person
to watch (Foxglove, QGroundControl) and to set against its fast-time row.

The encounter is made from the campaign's spec exactly as its row was
(``CampaignWorker.encounter``); then real processes fly it: ``sim-vehicle`` (home at the
campaign's ``HOME``) and ``companion run`` with

- the mission as a QGroundControl ``.plan``: takeoff to the leg's start altitude, the leg's
  goal, land, and the campaign world's airspace as the operator gives it (an inclusion fence on
  its horizontal bounds; its ceiling in the companion's settings, ``--config``);
- the mission's world (obstacles and fences) as a world file, when it has any (the companion
  takes a world file's obstacles, not its bounds: without the fence and the ceiling it would
  fly in 33 m about the route, up to 120 m);
- ``--foxglove PORT`` when asked.

The intruders' reports are sent at their encounter times, counted from the instant the
companion engages the leg (its ``path`` message for ``leg0``; mission time from its
``status``), as in flight:

- drone-scale ones are put over zenoh, as the local-frame payloads the campaign decodes;
- manned ones are ADSB_VEHICLE messages (the fields ``delivery.adsb_reports`` gives fast time)
  sent to the vehicle by an ADS-B receiver component (``MAV_COMP_ID_ADSB``); the vehicle routes
  them to the companion, which runs with ``--adsb``. The flight is judged by the vehicle's own telemetry in the flight
record against the intruders' true tracks, with the campaign's volumes.
"""

from __future__ import annotations

import dataclasses
import logging
import time
from pathlib import Path

import numpy as np
from pymavlink import mavutil

from companion.campaign import judge
from companion.campaign.delivery import adsb_reports, feed_updates
from companion.campaign.flying import HOME, CampaignWorker
from companion.campaign.tracks import Encounter
from companion.mission.model import FencePolygon, MissionItem, MissionPlan
from companion.mission.plan_file import write_plan_file
from companion.record.flight_record import load_record
from companion.sitl.vehicles import flight_processes
from companion.threats.transport.bus import ThreatBus
from companion.world.io import dumps_world_toml

__all__ = ["ReplayResult", "write_mission", "replay", "judged", "judge_track", "recorded_track"]

log = logging.getLogger(__name__)

ACCEPTANCE_M = 3.0


@dataclasses.dataclass(frozen=True)
class ReplayResult:
    """One encounter flown in SITL.

    Attributes
    ----------
    encounter : Encounter
    leg_t0_s : float
        The companion's mission time of the leg's start (encounter time 0; its ``leg_started``
        event).
    separation : judge.Separation
        Judged on the vehicle's telemetry.
    puts : int
        Threat reports put.
    out_dir : Path
    t_s : ndarray, shape (K,)
        Encounter times of the vehicle's telemetry samples (0: the leg's start).
    pos_ned_m : ndarray, shape (K, 3)
        The vehicle's own positions then.
    """

    encounter: Encounter
    leg_t0_s: float
    separation: judge.Separation
    puts: int
    out_dir: Path
    t_s: np.ndarray
    pos_ned_m: np.ndarray

    def outcome(self) -> dict:
        s = self.separation
        return {
            "id": self.encounter.id,
            "stratum": self.encounter.stratum,
            "collision": s.collision,
            "nmac": s.nmac,
            "lowc": s.lowc,
            "min_sep_m": s.min_sep_m,
            "hmd_m": list(s.hmd_m),
            "vmd_m": list(s.vmd_m),
            "leg_t0_s": self.leg_t0_s,
            "puts": self.puts,
            "record": str(self.out_dir / "flight.jsonl"),
        }


def write_mission(mission, path: Path) -> Path:
    """The campaign mission as a QGroundControl ``.plan`` (takeoff, the leg's goal, land; home at
    ``HOME``) whose airspace is the campaign world's, as an operator gives it: an inclusion fence
    on its horizontal bounds. Its ceiling goes in the companion's settings (``mission_settings``)."""
    start, goal = mission.legs[0].start_ned_m, mission.goal_ned_m
    lat, lon, _ = HOME.to_lla(goal[0], goal[1], goal[2])
    relative = mavutil.mavlink.MAV_FRAME_GLOBAL_RELATIVE_ALT
    items = (
        MissionItem(mavutil.mavlink.MAV_CMD_NAV_TAKEOFF, relative, alt_m=-float(start[2])),
        MissionItem(
            mavutil.mavlink.MAV_CMD_NAV_WAYPOINT,
            relative,
            param2=ACCEPTANCE_M,
            lat_deg=float(lat),
            lon_deg=float(lon),
            alt_m=-float(goal[2]),
        ),
        MissionItem(mavutil.mavlink.MAV_CMD_NAV_LAND, relative, lat_deg=float(lat), lon_deg=float(lon)),
    )
    (n0, e0), (n1, e1) = mission.world.bounds_min[:2], mission.world.bounds_max[:2]
    corners = [HOME.to_lla(n, e, 0.0)[:2] for n, e in ((n0, e0), (n1, e0), (n1, e1), (n0, e1))]
    fence = FencePolygon(tuple((float(la), float(lo)) for la, lo in corners), inclusion=True)
    write_plan_file(
        MissionPlan(items, polygons=(fence,), planned_home=(HOME.lat0_deg, HOME.lon0_deg, HOME.alt0_m)), path
    )
    return path


def mission_settings(mission, path: Path) -> Path:
    """The companion's settings for the campaign mission: its world's ceiling and margin."""
    path.write_text(
        f"[mission]\nceiling_m = {-float(mission.world.bounds_min[2]):.3f}\n"
        f"margin_m = {float(mission.world.margin_m):.3f}\n"
    )
    return path


class _LegClock:
    """The companion's mission time, from its status messages, once it has engaged leg 0."""

    def __init__(self, bus: ThreatBus, speedup: float) -> None:
        self.speedup = speedup
        self.status: tuple[float, float] | None = None  # (mission time, wall time)
        self.leg_t0_s: float | None = None
        bus.subscribe_json("status", self._on_status)
        bus.subscribe_json("path", self._on_path)

    def _on_status(self, key, msg) -> None:
        if isinstance(msg, dict) and isinstance(msg.get("t_s"), (int, float)):
            self.status = (float(msg["t_s"]), time.monotonic())

    def _on_path(self, key, msg) -> None:
        if self.leg_t0_s is None and isinstance(msg, dict) and msg.get("path_id") == "leg0":
            self.leg_t0_s = float(msg["t0_s"])

    def now_s(self) -> float | None:
        if self.status is None:
            return None
        t, wall = self.status
        return t + (time.monotonic() - wall) * self.speedup


def _play(send, clock: _LegClock, updates, done, timeout_s: float) -> int:
    """``send`` each update (time, payload, ...) at its encounter time after the leg's start;
    returns how many were sent."""
    deadline = time.monotonic() + timeout_s
    while clock.leg_t0_s is None and time.monotonic() < deadline and not done():
        time.sleep(0.02)
    puts = 0
    for t_enc, payload, *_ in updates:
        while not done() and time.monotonic() < deadline:
            now = clock.now_s()
            if now is not None and now - clock.leg_t0_s >= t_enc:
                break
            time.sleep(0.005)
        if done():
            break
        send(payload)
        puts += 1
    return puts


def _adsb_sender(vehicle_port: int):
    """(send(fields), close()) of an ADS-B receiver component talking to the vehicle."""
    conn = mavutil.mavlink_connection(
        f"udpout:127.0.0.1:{vehicle_port}", source_system=1, source_component=mavutil.mavlink.MAV_COMP_ID_ADSB
    )

    def send(fields: dict) -> None:
        args = {k: v for k, v in fields.items() if k != "mavpackettype"}
        callsign = args["callsign"]
        args["callsign"] = callsign.encode() if isinstance(callsign, str) else callsign
        conn.mav.adsb_vehicle_send(**args)

    return send, conn.close


def recorded_track(record_path: Path) -> tuple[float, np.ndarray, np.ndarray]:
    """(leg 0's start, sample times from it, positions) of a flight record: the vehicle's own
    telemetry as the companion recorded it, on the encounter's clock."""
    record = load_record(record_path)
    starts = [float(e["t_s"]) for e in record.events if e.get("name") == "leg_started" and e.get("leg") == 0]
    if not starts:
        raise RuntimeError(f"{record_path}: leg 0 never started")
    t = np.asarray(record.samples["t_s"], dtype=float)
    pos = np.asarray(record.samples["pos_ned_m"], dtype=float)
    keep = np.all(np.isfinite(pos), axis=1)
    return starts[0], t[keep] - starts[0], pos[keep]


def replay(
    worker: CampaignWorker,
    index: int,
    out_dir: Path,
    *,
    speedup: float = 2.0,
    foxglove: str | None = None,
    gcs_out: str | None = None,
    timeout_s: float = 600.0,
    mitigated: bool = True,
) -> ReplayResult:
    """Fly encounter ``index`` of ``worker``'s campaign in SITL (module docstring); with
    ``mitigated`` False no report is put (the unmitigated flight, judged all the same)."""
    out_dir = Path(out_dir)
    out_dir.mkdir(parents=True, exist_ok=True)
    enc = worker.encounter(index)
    mission = worker.mission(enc.mission)
    mission_file = write_mission(mission, out_dir / "mission.plan")
    extra = ["--seed", str(worker.spec.seed), "--config", str(mission_settings(mission, out_dir / "companion.toml"))]
    if mission.obstacles or mission.fences:
        world_file = out_dir / "world.toml"
        world_file.write_text(dumps_world_toml(mission.world, name=enc.mission))
        extra += ["--world", str(world_file)]
    if foxglove:
        extra += ["--foxglove", foxglove]
    rng = np.random.default_rng([worker.spec.seed, index, 1])
    manned = enc.traffic != "drone"
    if manned:
        extra += ["--adsb"]
        updates = adsb_reports(enc.intruders, enc.delivery, rng, home=HOME) if mitigated else []
    else:
        updates = feed_updates(enc.intruders, enc.traffic, enc.delivery, rng, home=HOME) if mitigated else []
    home_arg = f"--home={HOME.lat0_deg},{HOME.lon0_deg},{HOME.alt0_m},0"
    with flight_processes(
        out_dir, mission_file, speedup=speedup, gcs_out=gcs_out, extra_args=extra, sim_args=[home_arg]
    ) as flight:
        with ThreatBus(1, listen=(), connect=(flight.endpoint,)) as bus:
            clock = _LegClock(bus, speedup)
            done = lambda: flight.companion.poll() is not None  # noqa: E731
            send, close = _adsb_sender(flight.vehicle_port) if manned else (bus.client.put_threat, lambda: None)
            try:
                puts = _play(send, clock, updates, done, timeout_s)
            finally:
                close()
            flight.companion.wait(timeout_s)
    if clock.leg_t0_s is None:
        raise RuntimeError(f"encounter {index}: the companion never engaged leg 0; see {flight.log}")
    return judged(worker, enc, flight.record, puts)


def judged(worker: CampaignWorker, enc: Encounter, record_path: Path, puts: int = 0) -> ReplayResult:
    """A replay's flight record judged against its encounter (also to judge a record again)."""
    leg_t0, t_enc, pos = recorded_track(record_path)
    sep = judge_track(enc, t_enc, pos, worker.spec.volumes)
    log.info(
        "replay %d (%s): min separation %.2f m, collision %s, NMAC %s, LoWC %s",
        enc.id,
        enc.stratum,
        sep.min_sep_m,
        sep.collision,
        sep.nmac,
        sep.lowc,
    )
    return ReplayResult(enc, leg_t0, sep, puts, Path(record_path).parent, t_enc, pos)


def judge_track(enc: Encounter, t_s: np.ndarray, pos_ned_m: np.ndarray, volumes) -> judge.Separation:
    """A flown track (encounter times) judged against ``enc``'s intruders over its window (a flight
    that ended early holds its last position, as in fast time)."""
    dt = 0.02
    grid = np.arange(enc.first_report_t_s, enc.end_t_s + 0.5 * dt, dt)
    track = np.column_stack([np.interp(grid, t_s, pos_ned_m[:, a]) for a in range(3)])
    return judge.separation(grid, track, enc.intruders, enc.traffic != "drone", volumes)
