"""What the operator sees, as Foxglove scene entities built from the record's fields.

Everything is drawn in ``map``, east-north-up about home (``companion.view.geometry``); the
vehicle is the frame ``base_link`` (forward-left-up), placed by a ``FrameTransform`` from
``map``. Nothing here does I/O.
"""

from __future__ import annotations

import math
from collections.abc import Iterable, Sequence

import numpy as np
from foxglove.messages import (
    Color,
    CubePrimitive,
    CylinderPrimitive,
    Duration,
    FrameTransform,
    LinePrimitive,
    LinePrimitiveLineType,
    Point3,
    Pose,
    Quaternion,
    SceneEntity,
    SpherePrimitive,
    Timestamp,
    TriangleListPrimitive,
    Vector3,
)

from companion.view.geometry import enu_from_ned, flu_quaternion_enu, prism_side_triangles, threat_tube

__all__ = [
    "MAP_FRAME",
    "VEHICLE_FRAME",
    "timestamp",
    "obstacle_entities",
    "path_entity",
    "threat_entity",
    "vehicle_entity",
    "vehicle_transform",
]

MAP_FRAME = "map"
VEHICLE_FRAME = "base_link"
OBSTACLE_COLOUR = Color(r=0.85, g=0.3, b=0.25, a=0.35)
THREAT_COLOUR = (1.0, 0.15, 0.1)
UNBOUNDED_PAD_M = 5.0


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
        return {
            "cylinders": [
                CylinderPrimitive(
                    pose=_pose((east, north, 0.5 * (bottom + top))),
                    size=_vector((d, d, top - bottom)),
                    bottom_scale=1.0,
                    top_scale=1.0,
                    color=OBSTACLE_COLOUR,
                )
            ]
        }
    if kind == "box":
        lo, hi = enu_from_ned(ob["min"]), enu_from_ned(ob["max"])
        return {
            "cubes": [CubePrimitive(pose=_pose(0.5 * (lo + hi)), size=_vector(np.abs(hi - lo)), color=OBSTACLE_COLOUR)]
        }
    if kind == "prism":
        bottom, top = _up_limits_m(ob, bounds_down_m)
        walls = prism_side_triangles(ob["vertices"], bottom, top)
        return {
            "triangles": [TriangleListPrimitive(pose=_pose((0, 0, 0)), points=_points(walls), color=OBSTACLE_COLOUR)]
        }
    raise ValueError(f"obstacle type {kind!r} has no scene shape")


def obstacle_entities(world: dict, time_s: float) -> list[SceneEntity]:
    """The static world (``world_to_dict``'s mapping) as one entity per obstacle."""
    head = world.get("world", {})
    bounds_down_m = (float(head.get("bounds_min", [0, 0, -50])[-1]), float(head.get("bounds_max", [0, 0, 0])[-1]))
    return [
        SceneEntity(
            timestamp=timestamp(time_s),
            frame_id=MAP_FRAME,
            id=f"obstacle/{i}",
            **_obstacle_primitives(ob, bounds_down_m),
        )
        for i, ob in enumerate(world.get("obstacles", []))
    ]


def path_entity(
    entity_id: str, path_ned_m: Sequence, time_s: float, rgba: tuple[float, ...], thickness_px: float = 3.0
) -> SceneEntity:
    """A polyline (NED, shape (n, 3)) as a line strip, ``thickness_px`` pixels wide."""
    points = enu_from_ned(path_ned_m) if len(path_ned_m) else np.zeros((0, 3))
    line = LinePrimitive(
        type=LinePrimitiveLineType.LineStrip,
        pose=_pose((0, 0, 0)),
        thickness=thickness_px,
        scale_invariant=True,
        points=_points(points),
        color=Color(r=rgba[0], g=rgba[1], b=rgba[2], a=rgba[3]),
    )
    return SceneEntity(timestamp=timestamp(time_s), frame_id=MAP_FRAME, id=entity_id, lines=[line])


def threat_entity(
    threat_id: str,
    position_ned_m: Sequence,
    velocity_ned_m_s: Sequence,
    radius_m: float,
    age_s: float,
    time_s: float,
    horizon_s: float = 10.0,
    step_s: float = 2.5,
    uncertainty_m_s: float = 0.3,
) -> SceneEntity:
    """A threat where it is predicted now (``age_s`` after its report) and its tube ahead
    (:func:`threat_tube`): a line to ``horizon_s`` ahead and fainter, wider spheres."""
    pos = np.asarray(position_ned_m, dtype=float)
    vel = np.asarray(velocity_ned_m_s, dtype=float)
    centres, radii = threat_tube(pos, vel, radius_m, age_s, horizon_s, step_s, uncertainty_m_s)
    spheres = [
        SpherePrimitive(
            pose=_pose(enu_from_ned(c)),
            size=_vector((2 * r, 2 * r, 2 * r)),
            color=Color(r=THREAT_COLOUR[0], g=THREAT_COLOUR[1], b=THREAT_COLOUR[2], a=0.55 / (1 + k)),
        )
        for k, (c, r) in enumerate(zip(centres, radii))
    ]
    lines = []
    if len(centres) > 1:
        ends = enu_from_ned([centres[0], centres[-1]])
        lines.append(
            LinePrimitive(
                type=LinePrimitiveLineType.LineStrip,
                pose=_pose((0, 0, 0)),
                thickness=2.0,
                scale_invariant=True,
                points=_points(ends),
                color=Color(r=1.0, g=0.3, b=0.2, a=0.9),
            )
        )
    return SceneEntity(
        timestamp=timestamp(time_s), frame_id=MAP_FRAME, id=f"threat/{threat_id}", spheres=spheres, lines=lines
    )


def vehicle_entity(time_s: float, rotor_radius_m: float = 1.0) -> SceneEntity:
    """The helicopter in its own frame: a fuselage box and a translucent rotor disc."""
    body = CubePrimitive(pose=_pose((0, 0, 0)), size=_vector((1.6, 0.5, 0.5)), color=Color(r=0.2, g=0.4, b=0.9, a=1.0))
    rotor = CylinderPrimitive(
        pose=_pose((0, 0, 0.4)),
        size=_vector((2 * rotor_radius_m, 2 * rotor_radius_m, 0.05)),
        bottom_scale=1.0,
        top_scale=1.0,
        color=Color(r=0.6, g=0.7, b=1.0, a=0.4),
    )
    return SceneEntity(
        timestamp=timestamp(time_s),
        frame_id=VEHICLE_FRAME,
        id="vehicle",
        frame_locked=True,
        cubes=[body],
        cylinders=[rotor],
        lifetime=Duration(sec=0, nsec=0),
    )


def vehicle_transform(position_ned_m: Sequence, euler_rad: Sequence | None, time_s: float) -> FrameTransform:
    """``map`` -> ``base_link``: the vehicle's position and attitude (roll, pitch, yaw NED/FRD;
    level and facing north when ``euler_rad`` is None)."""
    x, y, z, w = flu_quaternion_enu(euler_rad if euler_rad is not None else (0.0, 0.0, 0.0))
    return FrameTransform(
        timestamp=timestamp(time_s),
        parent_frame_id=MAP_FRAME,
        child_frame_id=VEHICLE_FRAME,
        translation=_vector(enu_from_ned(position_ned_m)),
        rotation=Quaternion(x=float(x), y=float(y), z=float(z), w=float(w)),
    )
