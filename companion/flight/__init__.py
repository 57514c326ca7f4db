"""The flight core: from a mission's legs to the reference the vehicle tracks (DESIGN 1, 2, 7, 12).

- ``pipeline``: the one trajectory pipeline (``TrajectoryPipeline``: plan -> smooth -> time ->
  check, its stages in ``stages`` and ``checker``), built from the settings in one place;
  mission legs, joins, replans and alternatives are its inputs;
- ``plan``: mission legs planned before takeoff through the pipeline (``LegPlan``, ``plan_mission``);
- ``trajectory``: flyable references sampled by time; ``reference``: the active reference on the
  vehicle's clock;
- ``phases``: the pure phase machine of one leg (``leg_step``);
- ``executor``: the flight executor (``FlightExecutor``), its ``schedule`` of named tasks at
  declared rates, the one owner of the active reference (``active``), the legs (``legs``), the
  threat decisions (``avoidance``), the ports it is built with (``ports``) and its fast-time
  driver against the helicopter model (``fast_time``); ``setpoint``: the setpoint value;
- ``resume``: taking over a flying vehicle after a companion crash (pure steps).

Numerics and pure steps only: no asyncio, no MAVLink, no zenoh.
"""
