"""Facts shared by the companion (``companion``) and the SITL vehicle (``sim_vehicle``).

``sim_vehicle`` must never import ``companion``; what both need is defined here once:

- :mod:`heli_common.mavlink_ids`: ArduCopter mode numbers (from pymavlink's
  ``mavutil.mode_mapping_acm``) and MAVLink enum names (from pymavlink's generated
  ``ardupilotmega`` dialect);
- :mod:`heli_common.geometry`: the point-in-polygon test;
- :mod:`heli_common.frames`: the local NED frame about a geodetic origin (WGS-84, pymap3d);
- :mod:`heli_common.mission_item`: the ``MISSION_ITEM_INT`` record;
- :mod:`heli_common.cli_args`: the command-line parser of both (values beginning with a minus
  sign, options shared by a command's actions).

Pure numerics and data: no I/O.
"""
