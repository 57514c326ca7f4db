"""Taking over a flying vehicle after a companion crash: the pure steps (issue 11).

``companion run --resume`` (``CompanionDaemon`` with ``resume=True``) reads the vehicle's
mission and its current item (MISSION_CURRENT: the companion keeps it at the goal of the leg it
flies, with MAV_CMD_DO_SET_MISSION_CURRENT), then plans from where the vehicle hovers to that
item and on through the rest of the mission. What is decided here, without I/O:

- :func:`resume_refusal`: whether the vehicle can be resumed at all (a mission on it, flying);
- :func:`remaining_waypoints` / :func:`resume_mission`: the goals still to fly.
"""

from __future__ import annotations

from dataclasses import replace

__all__ = ["resume_refusal", "remaining_waypoints", "resume_mission"]


def resume_refusal(*, mission_items: int, airborne: bool) -> str | None:
    """Why ``--resume`` cannot take over this vehicle, or None when it can.

    Parameters
    ----------
    mission_items : int
        Number of mission items stored on the vehicle.
    airborne : bool
        The vehicle is armed and in the air (``companion.service.startup.is_airborne``).
    """
    if mission_items == 0:
        return (
            "cannot resume: the vehicle has no mission (upload one, or start a new flight "
            "with --mission FILE without --resume)"
        )
    if not airborne:
        return "cannot resume: the vehicle is not flying (disarmed or on the ground); start the flight without --resume"
    return None


def remaining_waypoints(waypoints, current_seq: int) -> tuple:
    """The goals still to fly when the vehicle's current mission item is ``current_seq``.

    Parameters
    ----------
    waypoints : sequence of LocalWaypoint
        The whole local mission, in flight order (``LocalMission.waypoints``).
    current_seq : int
        MISSION_CURRENT's ``seq``: the goal of the leg that was being flown (not reached yet).
        A command item (no goal of its own) resumes at the next goal; 0 (home) or the takeoff
        item resumes at the first goal.

    Returns
    -------
    tuple of LocalWaypoint
        Every goal with ``seq >= current_seq`` except the takeoff (the vehicle already flies);
        empty when ``current_seq`` lies after the last goal (only the mission's end is left).
    """
    return tuple(w for w in waypoints if w.kind != "takeoff" and w.seq >= int(current_seq))


def resume_mission(local_mission, current_seq: int):
    """``local_mission`` with only :func:`remaining_waypoints` left (world, end action kept)."""
    return replace(local_mission, waypoints=remaining_waypoints(local_mission.waypoints, current_seq))
