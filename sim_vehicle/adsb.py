"""Simulated ADS-B traffic around home, sent as ADSB_VEHICLE the way ArduPilot's SITL does.

ArduPilot's SITL (``SITL/SIM_ADSB.cpp``, parameters SIM_ADSB_COUNT, SIM_ADSB_RADIUS,
SIM_ADSB_ALT) spawns aircraft at random around the origin, flies them in straight lines and
respawns the ones that leave the area; the vehicle relays them to the ground station as
ADSB_VEHICLE (every field valid, ``flags`` 511 with SIMULATED, squawk 1200, tslc 1 s), one
aircraft per send of the ADSB stream and a new pass through the list at most once a second
(``AP_ADSB::send_adsb_vehicle``), so each aircraft is reported at about 1 Hz.

Here the airspace is a helicopter's: each aircraft *crosses* the disc of SIM_ADSB_RADIUS around
home on a straight, level track (it enters at a random bearing and heads for a random point
within half the radius of home) at 10-40 m/s, at SIM_ADSB_ALT +- 50 m above home (never below
5 m). An aircraft that has left the disc and is moving away is replaced by a new one (new
ICAO address). Positions are NED metres from home, simulated seconds; every random draw comes
from the ``rng`` given (``sim-vehicle --seed``), so traffic replays. Pure: no I/O.
"""

from __future__ import annotations

import dataclasses
import math

import numpy as np

EMITTER_TYPES = (1, 2, 7, 14)
"""ADSB_EMITTER_TYPE LIGHT, SMALL, ROTOCRAFT and UAV: what a helicopter meets at low level."""
MIN_HEIGHT_M = 5.0
"""No simulated aircraft flies lower than this above home."""


@dataclasses.dataclass(frozen=True)
class AdsbSettings:
    """Simulated traffic (ArduPilot parameter in brackets).

    Attributes
    ----------
    count : int
        Number of aircraft, 0 = none [SIM_ADSB_COUNT] (``sim-vehicle --adsb-traffic N``).
    radius_m : float
        Radius of the disc around home that the aircraft cross, m [SIM_ADSB_RADIUS].
    alt_m : float
        Mean altitude of the traffic above home, m [SIM_ADSB_ALT].
    alt_spread_m : float
        Altitudes are drawn uniformly within ``alt_m`` +- this, m.
    speed_min_m_s, speed_max_m_s : float
        Ground speeds are drawn uniformly between these, m/s.
    """

    count: int = 0
    radius_m: float = 500.0
    alt_m: float = 20.0
    alt_spread_m: float = 50.0
    speed_min_m_s: float = 10.0
    speed_max_m_s: float = 40.0

    def __post_init__(self) -> None:
        if not (isinstance(self.count, int) and 0 <= self.count <= 100):
            raise ValueError(f"count: expected an integer 0..100, got {self.count!r}")
        for name, lo, hi in (
            ("radius_m", 50.0, 100_000.0),
            ("alt_m", -100.0, 10_000.0),
            ("alt_spread_m", 0.0, 1000.0),
            ("speed_min_m_s", 0.5, 400.0),
            ("speed_max_m_s", 0.5, 400.0),
        ):
            value = getattr(self, name)
            if not (isinstance(value, (int, float)) and math.isfinite(value) and lo <= value <= hi):
                raise ValueError(f"{name}: expected {lo:g}..{hi:g}, got {value!r}")
        if self.speed_max_m_s < self.speed_min_m_s:
            raise ValueError(
                f"speed_max_m_s: expected >= speed_min_m_s ({self.speed_min_m_s:g}), got {self.speed_max_m_s!r}"
            )


@dataclasses.dataclass
class Aircraft:
    """One simulated aircraft.

    Attributes
    ----------
    icao_address : int
        24-bit ICAO address (unique among the live aircraft).
    callsign : str
        ``SIM<address>``, as ArduPilot's SITL names them.
    emitter_type : int
        ADSB_EMITTER_TYPE.
    pos_ned_m : ndarray, shape (3,)
        Position, m NED from home.
    vel_ned_m_s : ndarray, shape (3,)
        Velocity, m/s NED (level: down component 0).
    """

    icao_address: int
    callsign: str
    emitter_type: int
    pos_ned_m: np.ndarray
    vel_ned_m_s: np.ndarray

    @property
    def heading_deg(self) -> float:
        """Course over ground, degrees clockwise from north in [0, 360)."""
        return math.degrees(math.atan2(self.vel_ned_m_s[1], self.vel_ned_m_s[0])) % 360.0

    @property
    def ground_speed_m_s(self) -> float:
        """Horizontal speed, m/s."""
        return float(math.hypot(self.vel_ned_m_s[0], self.vel_ned_m_s[1]))


class TrafficModel:
    """Aircraft crossing the area around home.

    Parameters
    ----------
    settings : AdsbSettings
        Count, radius, altitude band, speeds.
    rng : numpy.random.Generator
        Source of every random draw (seeded by the caller).
    """

    def __init__(self, settings: AdsbSettings, rng: np.random.Generator) -> None:
        self.settings = settings
        self.rng = rng
        self.aircraft: list[Aircraft] = []
        self.spawned = 0
        self._resize(initial=True)

    def apply_settings(self, settings: AdsbSettings) -> None:
        """New settings (SIM_ADSB_* changed): the fleet grows or shrinks to the new count."""
        self.settings = settings
        self._resize(initial=True)

    def step(self, dt_s: float) -> None:
        """Fly every aircraft ``dt_s`` simulated seconds on; replace those that have left."""
        if dt_s <= 0.0:
            return
        radius = self.settings.radius_m
        for i, plane in enumerate(self.aircraft):
            plane.pos_ned_m = plane.pos_ned_m + plane.vel_ned_m_s * dt_s
            ne = plane.pos_ned_m[:2]
            leaving = float(np.dot(ne, plane.vel_ned_m_s[:2])) > 0.0
            if leaving and float(np.hypot(*ne)) > radius:
                self.aircraft[i] = self._spawn(on_edge=True)

    def _resize(self, initial: bool) -> None:
        count = self.settings.count
        del self.aircraft[count:]
        while len(self.aircraft) < count:
            self.aircraft.append(self._spawn(on_edge=not initial))

    def _icao(self) -> int:
        taken = {a.icao_address for a in self.aircraft}
        while True:
            address = int(self.rng.integers(1, 10_000))  # ArduPilot's SITL: rand() % 10000
            if address not in taken:
                return address

    def _spawn(self, on_edge: bool) -> Aircraft:
        """A new aircraft entering the disc (or, at start, somewhere along its crossing)."""
        s = self.settings
        bearing = float(self.rng.uniform(0.0, 2.0 * math.pi))
        entry = s.radius_m * np.array([math.cos(bearing), math.sin(bearing)])
        aim_r = 0.5 * s.radius_m * math.sqrt(float(self.rng.uniform(0.0, 1.0)))
        aim_b = float(self.rng.uniform(0.0, 2.0 * math.pi))
        aim = aim_r * np.array([math.cos(aim_b), math.sin(aim_b)])
        direction = (aim - entry) / float(np.linalg.norm(aim - entry))
        speed = float(self.rng.uniform(s.speed_min_m_s, s.speed_max_m_s))
        height = float(self.rng.uniform(s.alt_m - s.alt_spread_m, s.alt_m + s.alt_spread_m))
        height = max(height, MIN_HEIGHT_M)
        start = entry
        if not on_edge:  # traffic is already in the area when the simulation starts
            chord = 2.0 * float(np.dot(-entry, direction))  # where the track leaves the disc
            start = entry + direction * float(self.rng.uniform(0.0, max(chord, 0.0)))
        address = self._icao()
        emitter = int(self.rng.choice(EMITTER_TYPES))
        self.spawned += 1
        return Aircraft(
            icao_address=address,
            callsign=f"SIM{address}",
            emitter_type=emitter,
            pos_ned_m=np.array([start[0], start[1], -height]),
            vel_ned_m_s=np.array([direction[0] * speed, direction[1] * speed, 0.0]),
        )


class RoundRobin:
    """Which aircraft the next ADSB_VEHICLE of one link reports (``AP_ADSB::send_adsb_vehicle``).

    One aircraft per call; after the last one, a new pass starts no sooner than 1 s after the
    previous pass started.
    """

    PASS_PERIOD_S = 1.0

    def __init__(self) -> None:
        self.index = 0
        self.pass_start_s: float | None = None

    def next(self, count: int, now_s: float) -> int | None:
        """Index of the aircraft to send now, or None (nothing to send this time)."""
        if count <= 0:
            return None
        if self.pass_start_s is None:
            self.pass_start_s = now_s
        if self.index >= count:
            if now_s - self.pass_start_s < self.PASS_PERIOD_S:
                return None
            self.index = 0
            self.pass_start_s = now_s
        index = self.index
        self.index += 1
        return index


__all__ = ["AdsbSettings", "Aircraft", "TrafficModel", "RoundRobin", "EMITTER_TYPES"]
