"""The flight core: from a mission's legs to the reference the vehicle tracks (DESIGN 1, 2, 7).

- ``plan``: mission legs planned before takeoff (``LegPlan``, ``plan_mission``);
- ``trajectory``: flyable references sampled by time; ``reference``: the active reference on the
  vehicle's clock;
- ``phases``: the pure phase machine of one leg (``leg_step``);
- ``resume``: taking over a flying vehicle after a companion crash (pure steps).

Numerics and pure steps only: no asyncio, no MAVLink, no zenoh.
"""
