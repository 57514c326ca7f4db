"""What the operator sees, as Foxglove scene entities: pure functions of the record's fields.

Frames: the record is in local NED about home (m); Foxglove's 3D panel draws a right-handed
frame with z up, so every position is turned into ``map``, east-north-up about home
(``enu_from_ned``). The vehicle is the frame ``base_link`` (forward-left-up), placed by a
``FrameTransform`` from ``map``. Nothing here does I/O.
"""

from __future__ import annotations

import math
from collections.abc import Iterable, Sequence

import numpy as np
from foxglove.messages import (Color, CubePrimitive, CylinderPrimitive, Duration, FrameTransform,
                               LinePrimitive, LinePrimitiveLineType, Point3, Pose, Quaternion,
                               SceneEntity, SpherePrimitive, Timestamp, TriangleListPrimitive,
                               Vector3)

__all__ = ["MAP_FRAME", "VEHICLE_FRAME", "enu_from_ned", "flu_quaternion_enu", "threat_tube",
           "prism_side_triangles", "timestamp", "obstacle_entities", "path_entity", "threat_entity",
           "vehicle_entity", "vehicle_transform"]

MAP_FRAME = "map"
VEHICLE_FRAME = "base_link"
#: NED -> ENU swaps north and east and flips down (its own inverse).
_ENU_FROM_NED = np.array([[0.0, 1.0, 0.0], [1.0, 0.0, 0.0], [0.0, 0.0, -1.0]])
OBSTACLE_COLOUR = Color(r=0.85, g=0.3, b=0.25, a=0.35)
THREAT_COLOUR = (1.0, 0.15, 0.1)
UNBOUNDED_PAD_M = 5.0


def enu_from_ned(points_ned_m: Sequence) -> np.ndarray:
    """Positions NED -> ENU, shape (..., 3) -> (..., 3)."""
    return np.asarray(points_ned_m, dtype=float) @ _ENU_FROM_NED.T


def timestamp(time_s: float) -> Timestamp:
    """A Foxglove timestamp of ``time_s`` seconds."""
    sec = math.floor(time_s)
    return Timestamp(sec=int(sec), nsec=int((time_s - sec) * 1e9))


def _vector(v: Iterable[float]) -> Vector3:
    x, y, z = (float(c) for c in v)
    return Vector3(x=x, y=y, z=z)


def _pose(position_enu_m: Iterable[float]) -> Pose:
    return Pose(position=_vector(position_enu_m), orientation=Quaternion(x=0.0, y=0.0, z=0.0, w=1.0))


def _points(points_enu_m: np.ndarray) -> list[Point3]:
    return [Point3(x=float(p[0]), y=float(p[1]), z=float(p[2])) for p in points_enu_m]


def _up_limits_m(ob: dict, bounds_down_m: tuple[float, float]) -> tuple[float, float]:
    """(bottom, top) heights of an obstacle bounded in *down* (unbounded: the world's)."""
    down_min = ob.get("down_min", bounds_down_m[0] - UNBOUNDED_PAD_M)
    down_max = ob.get("down_max", bounds_down_m[1])
    return -float(down_max), -float(down_min)


def prism_side_triangles(vertices_ne_m: Sequence, bottom_m: float, top_m: float) -> np.ndarray:
    """The side walls of a polygon (north-east, shape (n, 2)) extruded from ``bottom_m`` to
    ``top_m`` (up), two triangles per edge, ENU: shape (6 n, 3). Right for any simple polygon."""
    ring = np.asarray(vertices_ne_m, dtype=float)[:, ::-1]             # (east, north)
    nxt = np.roll(ring, -1, axis=0)
    lo, hi = np.full((len(ring), 1), bottom_m), np.full((len(ring), 1), top_m)
    a, b = np.hstack([ring, lo]), np.hstack([nxt, lo])
    c, d = np.hstack([nxt, hi]), np.hstack([ring, hi])
    return np.stack([a, b, c, a, c, d], axis=1).reshape(-1, 3)


def _obstacle_primitives(ob: dict, bounds_down_m: tuple[float, float]) -> dict:
    kind = ob["type"]
    if kind in ("sphere",):
        centre = enu_from_ned(ob["center"])
        d = 2.0 * ob["radius"]
        return {"spheres": [SpherePrimitive(pose=_pose(centre), size=_vector((d, d, d)), color=OBSTACLE_COLOUR)]}
    if kind in ("cylinder", "disc"):
        bottom, top = _up_limits_m(ob, bounds_down_m)
        north, east = ob["center"][:2]
        d = 2.0 * ob["radius"]
        return {"cylinders": [CylinderPrimitive(pose=_pose((east, north, 0.5 * (bottom + top))),
                                                size=_vector((d, d, top - bottom)), bottom_scale=1.0,
                                                top_scale=1.0, color=OBSTACLE_COLOUR)]}
    if kind == "box":
        lo, hi = enu_from_ned(ob["min"]), enu_from_ned(ob["max"])
        return {"cubes": [CubePrimitive(pose=_pose(0.5 * (lo + hi)), size=_vector(np.abs(hi - lo)),
                                        color=OBSTACLE_COLOUR)]}
    if kind == "prism":
        bottom, top = _up_limits_m(ob, bounds_down_m)
        walls = prism_side_triangles(ob["vertices"], bottom, top)
        return {"triangles": [TriangleListPrimitive(pose=_pose((0, 0, 0)), points=_points(walls),
                                                    color=OBSTACLE_COLOUR)]}
    raise ValueError(f"obstacle type {kind!r} has no scene shape")


def obstacle_entities(world: dict, time_s: float) -> list[SceneEntity]:
    """The static world (``world_to_dict``'s mapping) as one entity per obstacle."""
    head = world.get("world", {})
    bounds_down_m = (float(head.get("bounds_min", [0, 0, -50])[-1]), float(head.get("bounds_max", [0, 0, 0])[-1]))
    return [SceneEntity(timestamp=timestamp(time_s), frame_id=MAP_FRAME, id=f"obstacle/{i}",
                        **_obstacle_primitives(ob, bounds_down_m))
            for i, ob in enumerate(world.get("obstacles", []))]


def path_entity(entity_id: str, path_ned_m: Sequence, time_s: float, rgba: tuple[float, ...],
                thickness_px: float = 3.0) -> SceneEntity:
    """A polyline (NED, shape (n, 3)) as a line strip, ``thickness_px`` pixels wide."""
    points = enu_from_ned(path_ned_m) if len(path_ned_m) else np.zeros((0, 3))
    line = LinePrimitive(type=LinePrimitiveLineType.LineStrip, pose=_pose((0, 0, 0)),
                         thickness=thickness_px, scale_invariant=True, points=_points(points),
                         color=Color(r=rgba[0], g=rgba[1], b=rgba[2], a=rgba[3]))
    return SceneEntity(timestamp=timestamp(time_s), frame_id=MAP_FRAME, id=entity_id, lines=[line])


def threat_entity(threat_id: str, position_ned_m: Sequence, velocity_ned_m_s: Sequence, radius_m: float,
                  age_s: float, time_s: float, horizon_s: float = 10.0, step_s: float = 2.5,
                  uncertainty_m_s: float = 0.3) -> SceneEntity:
    """A threat where it is predicted now (``age_s`` after its report) and its tube ahead
    (:func:`threat_tube`): a line to ``horizon_s`` ahead and fainter, wider spheres."""
    pos = np.asarray(position_ned_m, dtype=float)
    vel = np.asarray(velocity_ned_m_s, dtype=float)
    centres, radii = threat_tube(pos, vel, radius_m, age_s, horizon_s, step_s, uncertainty_m_s)
    spheres = [SpherePrimitive(pose=_pose(enu_from_ned(c)), size=_vector((2 * r, 2 * r, 2 * r)),
                               color=Color(r=THREAT_COLOUR[0], g=THREAT_COLOUR[1], b=THREAT_COLOUR[2],
                                           a=0.55 / (1 + k)))
               for k, (c, r) in enumerate(zip(centres, radii))]
    lines = []
    if len(centres) > 1:
        ends = enu_from_ned([centres[0], centres[-1]])
        lines.append(LinePrimitive(type=LinePrimitiveLineType.LineStrip, pose=_pose((0, 0, 0)), thickness=2.0,
                                   scale_invariant=True, points=_points(ends),
                                   color=Color(r=1.0, g=0.3, b=0.2, a=0.9)))
    return SceneEntity(timestamp=timestamp(time_s), frame_id=MAP_FRAME, id=f"threat/{threat_id}",
                       spheres=spheres, lines=lines)


def threat_tube(position_ned_m: np.ndarray, velocity_ned_m_s: np.ndarray, radius_m: float, age_s: float,
                horizon_s: float, step_s: float, uncertainty_m_s: float) -> tuple[np.ndarray, np.ndarray]:
    """Centres (NED, shape (k, 3)) and radii (shape (k,)) of a threat's predicted tube.

    Constant velocity from the report, ``age_s`` ago, every ``step_s`` up to ``horizon_s`` ahead
    of now; a mover's radius grows by ``uncertainty_m_s`` per second since the report (as
    ``companion.threats.prediction`` predicts it). A threat at rest is one sphere, its own size.
    """
    if np.linalg.norm(velocity_ned_m_s) <= 1e-6:
        return position_ned_m[None, :].astype(float), np.array([float(radius_m)])
    ages = age_s + np.arange(0.0, horizon_s + 1e-9, step_s)
    centres = position_ned_m[None, :] + ages[:, None] * velocity_ned_m_s[None, :]
    return centres, radius_m + uncertainty_m_s * ages


def vehicle_entity(time_s: float, rotor_radius_m: float = 1.0) -> SceneEntity:
    """The helicopter in its own frame: a fuselage box and a translucent rotor disc."""
    body = CubePrimitive(pose=_pose((0, 0, 0)), size=_vector((1.6, 0.5, 0.5)), color=Color(r=0.2, g=0.4, b=0.9, a=1.0))
    rotor = CylinderPrimitive(pose=_pose((0, 0, 0.4)), size=_vector((2 * rotor_radius_m, 2 * rotor_radius_m, 0.05)),
                              bottom_scale=1.0, top_scale=1.0, color=Color(r=0.6, g=0.7, b=1.0, a=0.4))
    return SceneEntity(timestamp=timestamp(time_s), frame_id=VEHICLE_FRAME, id="vehicle", frame_locked=True,
                       cubes=[body], cylinders=[rotor], lifetime=Duration(sec=0, nsec=0))


def _multiply(a: tuple, b: tuple) -> tuple[float, float, float, float]:
    """Hamilton product of quaternions (x, y, z, w)."""
    ax, ay, az, aw = a
    bx, by, bz, bw = b
    return (aw * bx + ax * bw + ay * bz - az * by, aw * by - ax * bz + ay * bw + az * bx,
            aw * bz + ax * by - ay * bx + az * bw, aw * bw - ax * bx - ay * by - az * bz)


#: NED -> ENU is half a turn about (1, 1, 0); FLU -> FRD half a turn about x.
_Q_ENU_FROM_NED = (math.sqrt(0.5), math.sqrt(0.5), 0.0, 0.0)
_Q_FRD_FROM_FLU = (1.0, 0.0, 0.0, 0.0)


def flu_quaternion_enu(euler_rad: Sequence[float]) -> tuple[float, float, float, float]:
    """The attitude (roll, pitch, yaw of FRD in NED, rad; ZYX order) as the quaternion
    (x, y, z, w) of the body's forward-left-up axes in east-north-up."""
    roll, pitch, yaw = (0.5 * float(a) for a in euler_rad)
    cr, sr, cp, sp, cy, sy = math.cos(roll), math.sin(roll), math.cos(pitch), math.sin(pitch), math.cos(yaw), math.sin(yaw)
    q_ned_frd = (sr * cp * cy - cr * sp * sy, cr * sp * cy + sr * cp * sy,
                 cr * cp * sy - sr * sp * cy, cr * cp * cy + sr * sp * sy)
    return _multiply(_multiply(_Q_ENU_FROM_NED, q_ned_frd), _Q_FRD_FROM_FLU)


def vehicle_transform(position_ned_m: Sequence, euler_rad: Sequence | None, time_s: float) -> FrameTransform:
    """``map`` -> ``base_link``: the vehicle's position and attitude (roll, pitch, yaw NED/FRD;
    level and facing north when ``euler_rad`` is None)."""
    x, y, z, w = flu_quaternion_enu(euler_rad if euler_rad is not None else (0.0, 0.0, 0.0))
    return FrameTransform(timestamp=timestamp(time_s), parent_frame_id=MAP_FRAME, child_frame_id=VEHICLE_FRAME,
                          translation=_vector(enu_from_ned(position_ned_m)),
                          rotation=Quaternion(x=float(x), y=float(y), z=float(z), w=float(w)))
