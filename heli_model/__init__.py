"""The helicopter model shared by the companion and the simulator (owned by neither).

- :mod:`heli_model.model`: ``HeliModel``, the linear hover model (A 13x13, B 13x4) from a profile
  TOML (``profiles/default.toml``: the R-50-class reference);
- :mod:`heli_model.dynamics`: pure RK4 integration of the model with yaw and NED kinematics;
- :mod:`heli_model.wind`: the wind and gust model;
- :mod:`heli_model.control`: the flight controller (LQI, PID position loop) and the fast
  closed-loop prediction the companion uses for feasibility;
- :mod:`heli_model.vehicle_update`: ``VehicleUpdate.update(state, command, dt) -> state``, the
  vehicle (controller and physics) as one pure step: what ``sim-vehicle`` flies over MAVLink and
  what the companion's fast-time flights fly in process.

Numerics only: no I/O, no asyncio, no MAVLink.
"""
