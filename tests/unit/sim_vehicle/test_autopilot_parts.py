"""The Autopilot's collaborators alone, each built with stand-ins for the Protocols it is given."""

from __future__ import annotations

import dataclasses

import numpy as np

from sim_vehicle import autopilot as ap
from sim_vehicle.autopilot import Geofence, GroundContact, Mission, Navigation, Stage
from sim_vehicle.config import VehicleSettings, replace_path
from sim_vehicle.frames import Frames
from sim_vehicle.mission_store import MissionItem

START = (47.397742, 8.545594, 488.0)


@dataclasses.dataclass
class Vehicle:
    """Stands in for the Autopilot as a host: mode, arming, ground contact, position, clock."""

    mode: int = ap.GUIDED
    armed: bool = True
    landed: bool = False
    pos_ned_m: np.ndarray = dataclasses.field(default_factory=lambda: np.array([0.0, 0.0, -10.0]))
    time_s: float = 0.0
    refused: tuple = ()

    @property
    def height_above_home_m(self) -> float:
        return -float(self.pos_ned_m[2])

    def set_mode(self, mode: int) -> tuple[bool, str]:
        if mode in self.refused:
            return False, "refused"
        self.mode = mode
        return True, ""

    def disarm(self, force: bool = False, reason: str = "commanded") -> tuple[bool, str]:
        self.armed = False
        return True, reason


@dataclasses.dataclass
class Body:
    """Stands in for the Airframe: position, velocity, height; settling on the ground."""

    pos_ned_m: np.ndarray
    vel_ned_m_s: np.ndarray = dataclasses.field(default_factory=lambda: np.zeros(3))
    settled: int = 0

    @property
    def height_m(self) -> float:
        return -float(self.pos_ned_m[2])

    def settle_on_ground(self) -> None:
        self.settled += 1
        self.pos_ned_m = np.array([self.pos_ned_m[0], self.pos_ned_m[1], 0.0])

    def reset_controller(self, zero_inputs: bool = False) -> None:
        pass


@dataclasses.dataclass
class Arming:
    """Stands in for the Arming: armed, and no rotor state (the touchdown does not read it)."""

    armed: bool = True
    rotor: object = None


def item(seq: int, command: int, z: float = 0.0, p1: float = 0.0, p2: float = 0.0) -> MissionItem:
    return MissionItem(seq, 3, command, 0, 1, p1, p2, 0.0, 0.0, 0, 0, z)


def test_geofence_breach_falls_back_to_land_when_rtl_is_refused():
    settings = replace_path(replace_path(VehicleSettings(), "flight.fence_enable", 1), "flight.fence_action", 1)
    host = Vehicle(refused=(ap.RTL,))
    events: list[tuple] = []
    square = [np.array([n, e, 0.0]) for n, e in ((-5, -5), (-5, 5), (5, 5), (5, -5))]
    targets = iter(square)
    fence = Geofence(host, Frames(START), lambda _: next(targets), lambda: settings, events.append)
    fence.set_items([item(i, ap.CMD_FENCE_POLYGON_INCLUSION, p1=4.0) for i in range(4)])
    assert len(fence.area.inclusion_polygons) == 1
    fence.check()
    assert fence.breached is None and host.mode == ap.GUIDED
    host.pos_ned_m = np.array([8.0, 0.0, -10.0])
    fence.check()
    assert fence.breached == "outside an inclusion polygon" and host.mode == ap.LAND
    assert events == [("text", 2, "Fence breach: outside an inclusion polygon")]


def test_mission_sequencer_flies_items_on_the_navigation_it_is_given():
    host = Vehicle(mode=ap.AUTO)
    events: list[tuple] = []
    frames = Frames(START)
    settings = VehicleSettings()
    nav = Navigation(Body(host.pos_ned_m), frames, lambda: settings, events.append, 0.0)
    mission = Mission(host, nav, frames, lambda: settings, events.append)
    mission.set_items(
        [
            item(0, ap.CMD_NAV_WAYPOINT),
            item(1, ap.CMD_DO_CHANGE_SPEED, p2=7.0),
            item(2, ap.CMD_NAV_LOITER_TIME, z=12.0, p1=3.0),
        ]
    )
    assert mission.has_mission and events == [("mission_current", 1)]
    mission.advance(0.0)
    assert nav.speed_m_s == 7.0 and mission.current == 2
    assert nav.current_stage.kind == "leg" and nav.current_stage.target[2] == -12.0
    nav.set_stages([])  # the navigation has flown them
    mission.item_flown()
    assert events[-2:] == [("mission_item_reached", 2), ("text", 6, "Mission complete")] and mission.finished
    assert nav.current_stage is not None and nav.current_stage.kind == "hold"  # still flying: hold there


def test_ground_contact_touchdown_ends_the_land_stage_and_disarms():
    host = Vehicle(mode=ap.LAND, time_s=12.5)
    body = Body(np.array([3.0, 4.0, -0.02]))
    settings = VehicleSettings()
    nav = Navigation(body, Frames(START), lambda: settings, lambda _: None, 0.0)
    land = Stage("land")
    nav.set_stages([land])
    done = []
    ground = GroundContact(body, nav, Arming(), host, lambda: settings, lambda: done.append(True))
    ground.landed = False
    ground.after_physics_step()
    assert ground.landed and body.settled == 1 and land.arrived_s == 12.5
    assert done == [True] and not host.armed and nav.current_stage is None
