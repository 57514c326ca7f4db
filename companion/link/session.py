"""What one MAVSDK connection hands out: the signing gate, MAVSDK and its System, the
MavlinkDirect and MissionRaw plugins, and the system the link talks to.

``VehicleLink`` owns the ``LinkSession``: its ``connect`` fills it (``attach``) and its ``close``
empties it (``release``). The link's parts (``companion.link.vehicle``) are given the session at
construction and read from it what they send through; none of them sets it.
"""

from __future__ import annotations

import contextlib
import time

from companion.errors import LinkError
from companion.link.transport import GateThread


class LinkSession:
    """The handles of the current connection (None while not connected).

    Attributes
    ----------
    gate : GateThread or None
        The signing gate between the vehicle and MAVSDK (``companion.link.transport``).
    system : mavsdk System or None
        The autopilot MAVSDK found.
    direct : MavlinkDirect or None
        MAVSDK's synchronous MavlinkDirect plugin (commands, rare sends).
    mission : MissionRawAsync or None
        MAVSDK's MissionRaw plugin (mission, fence and rally transfers).
    target_system, target_component : int
        Who the link talks to (the system id is the autopilot's, learnt on ``connect``).
    t0 : float
        Monotonic time the session was made (``time_boot_ms`` of what the link sends).
    """

    def __init__(self) -> None:
        self.gate: GateThread | None = None
        self.mavsdk = None
        self.system = None
        self.direct = None
        self.mission = None
        self.target_system = 1
        self.target_component = 1
        self.t0 = time.monotonic()

    def attach(self, mavsdk, system, direct, mission, target_system: int) -> None:
        """The connection is up: keep MAVSDK's handles and the autopilot's system id."""
        self.mavsdk, self.system, self.direct, self.mission = mavsdk, system, direct, mission
        self.target_system = int(target_system)

    def require_connected(self) -> None:
        """Raise ``LinkError`` unless connected."""
        if self.system is None or self.mavsdk is None:
            raise LinkError("the link is not connected (call connect() first)")

    def from_vehicle(self, fields: dict) -> bool:
        """True when a received message (a field dict) comes from the vehicle's system."""
        return fields.get("_sysid") == self.target_system

    def release(self) -> None:
        """Release MAVSDK and close the gate (idempotent).

        MAVSDK aborts the process if it is destroyed while a plugin or a System it handed out
        is alive: they are released first, newest first.
        """
        for owned in (self.mission, self.direct, getattr(self.system, "_system", None)):
            if owned is not None:
                with contextlib.suppress(Exception):
                    owned.destroy()
        self.mission = self.direct = self.system = None
        if self.mavsdk is not None:
            with contextlib.suppress(Exception):
                self.mavsdk.destroy()
        self.mavsdk = None
        if self.gate is not None:
            self.gate.close()
        self.gate = None
