"""The flight core: from a mission's legs to the reference the vehicle tracks (DESIGN 1, 2, 7).

- ``pipeline``: the one trajectory pipeline (``TrajectoryPipeline``: plan -> smooth -> time ->
  check, its stages in ``stages`` and ``checker``), built from the settings in one place;
  mission legs, joins, replans and alternatives are its inputs;
- ``plan``: mission legs planned before takeoff through the pipeline (``LegPlan``, ``plan_mission``);
- ``trajectory``: flyable references sampled by time; ``reference``: the active reference on the
  vehicle's clock;
- ``phases``: the pure phase machine of one leg (``leg_step``);
- ``resume``: taking over a flying vehicle after a companion crash (pure steps).

Numerics and pure steps only: no asyncio, no MAVLink, no zenoh.
"""
