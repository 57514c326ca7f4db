"""The vehicle's MAVLink side, as rooms with one job each (after ArduPilot's GCS_MAVLink).

- :mod:`~sim_vehicle.mavlink.endpoint`: the UDP socket, peers, sending, receiving, routing,
  signing verdicts and the link's counters (:class:`LinkStats`);
- :mod:`~sim_vehicle.mavlink.stream_sender`: HEARTBEAT and the telemetry streams of each link;
- :mod:`~sim_vehicle.mavlink.commands`: COMMAND_LONG / COMMAND_INT through one MAV_CMD table;
- :mod:`~sim_vehicle.mavlink.mission_protocol`: the mission protocol, one class per list
  (waypoints, fence, rally) on a shared base; :mod:`~sim_vehicle.mavlink.missions` routes the
  mission messages to them; :mod:`~sim_vehicle.mavlink.mission_wire` converts items;
- :mod:`~sim_vehicle.mavlink.param_protocol`: PARAM_REQUEST_LIST / READ / SET;
- :mod:`~sim_vehicle.mavlink.guided`: SET_POSITION_TARGET_* to GUIDED setpoints;
- :mod:`~sim_vehicle.mavlink.server`: :class:`MavlinkServer` composes them and dispatches messages.

The real-time loop that drives the server is :mod:`sim_vehicle.realtime`.
"""

from sim_vehicle.mavlink.endpoint import LinkStats
from sim_vehicle.mavlink.server import MavlinkServer

__all__ = ["LinkStats", "MavlinkServer"]
