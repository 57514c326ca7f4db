"""The monitor's screen (``companion.threats.decision.screen``): a proof of clear is exact.

Whenever ``proves_clear`` says the reference stays clear, ``active_conflict`` (the check the
decision runs) must find no conflict: checked on random references (straight and curved,
retimed, before their start and past their end) and random threats (static and moving, near
and far, 2D and 3D airspace). The screen must also prove the easy cases (nothing near, a
threat behind), or it would save nothing.
"""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from companion.flight.pipeline import TrajectoryPipeline
from companion.smoothing import TrajectoryLimits, smooth_g2, time_parameterize
from companion.threats.decision.kinds import Trigger
from companion.threats.decision.retime import RetimedTrajectory
from companion.threats.decision.screen import LEAD_S, MonitorScreen, ReferenceTable, proves_clear
from companion.threats.decision.step import ActiveTrajectory, DecisionPolicy, LegContext, Observation, active_conflict
from companion.threats.model import Threat
from companion.threats.settings import ThreatSettings
from companion.world import World

LIMITS = TrajectoryLimits(speed_m_s=8.0)
WORLD3 = World([], [-100.0, -100.0, -60.0], [200.0, 100.0, -2.0])
WORLD2 = World([], [-100.0, -100.0], [200.0, 100.0])
POLICY = DecisionPolicy(ThreatSettings(), TrajectoryPipeline.for_limits(LIMITS, 0.1))


def _trajectory(bend_m: float):
    path = np.array([[0.0, 0.0, -20.0], [60.0, bend_m, -20.0], [120.0, 0.0, -25.0]])
    return time_parameterize(smooth_g2(path, 0.1, world=WORLD3), LIMITS)


TRAJECTORIES = {bend: _trajectory(bend) for bend in (0.0, 25.0)}


def _active(bend_m: float, retime: float | None, start_t_s: float) -> ActiveTrajectory:
    traj = TRAJECTORIES[bend_m]
    if retime is not None:
        traj = RetimedTrajectory(traj, 3.0, retime, 2.0, 1.5)
    return ActiveTrajectory(traj, start_t_s, "leg0")


def _threat(pos, vel, radius_m: float, received_t_s: float, ttl_s: float | None = None) -> Threat:
    return Threat(
        "x",
        "popup" if not np.any(vel) else "mover",
        "local_ned",
        tuple(pos),
        radius_m=radius_m,
        velocity_ned_m_s=tuple(vel),
        received_t_s=received_t_s,
        ttl_s=ttl_s,
    )


coord = st.floats(-80.0, 180.0)
speed = st.floats(-12.0, 12.0)


@settings(max_examples=300, deadline=None)
@given(
    bend=st.sampled_from(sorted(TRAJECTORIES)),
    retime=st.one_of(st.none(), st.floats(0.0, 0.8)),
    start=st.floats(-5.0, 5.0),
    t=st.floats(-3.0, 40.0),
    dim=st.sampled_from([2, 3]),
    threats=st.lists(
        st.tuples(
            coord,
            st.floats(-60.0, 60.0),
            st.floats(-40.0, -5.0),
            speed,
            speed,
            st.floats(-2.0, 2.0),
            st.floats(0.5, 8.0),
            st.booleans(),
            st.floats(0.0, 3.0),
        ),
        min_size=1,
        max_size=3,
    ),
)
def test_a_proof_of_clear_is_never_wrong(bend, retime, start, t, dim, threats):
    active = _active(bend, retime, start)
    observed = tuple(
        _threat((n, e, d), (vn, ve, vd) if moving else (0.0, 0.0, 0.0), r, t - age)
        for n, e, d, vn, ve, vd, r, moving, age in threats
    )
    leg = LegContext(0, WORLD2 if dim == 2 else WORLD3, np.array([120.0, 0.0, -25.0])[:dim])
    table = ReferenceTable(active, POLICY.settings.check_step_s, dim)
    proven = proves_clear(table, observed, t, POLICY.settings, POLICY.accel_bound_m_s2)
    conflict = active_conflict(Observation(t, observed, active, Trigger.MONITOR), leg, POLICY)
    if proven:
        assert conflict is None


def test_the_easy_cases_are_proven():
    active = _active(0.0, None, 0.0)
    table = ReferenceTable(active, POLICY.settings.check_step_s, 3)
    s, bound = POLICY.settings, POLICY.accel_bound_m_s2
    assert proves_clear(table, (), 4.0, s, bound)
    far = _threat((60.0, 800.0, -20.0), (0.0, 0.0, 0.0), 3.0, 4.0)
    assert proves_clear(table, (far,), 4.0, s, bound)
    behind = _threat((-30.0, 0.0, -20.0), (-10.0, 0.0, 0.0), 3.0, 4.0)
    assert proves_clear(table, (behind,), 4.0, s, bound)
    ahead = _threat((40.0, 0.0, -20.0), (0.0, 0.0, 0.0), 3.0, 4.0)
    assert not proves_clear(table, (ahead,), 4.0, s, bound)


def test_the_table_covers_any_time_and_belongs_to_one_reference():
    active = _active(25.0, 0.3, 2.0)
    table = ReferenceTable(active, 0.2, 3)
    traj = active.trajectory
    t = np.array([-4.0, 0.0, 7.3, 19.9, traj.duration_s + 1.0, traj.duration_s + 80.0]) + 2.0
    exact = np.atleast_2d(traj.sample(np.clip(t - 2.0, 0.0, traj.duration_s))[0])
    assert np.max(np.linalg.norm(table.positions_at(t) - exact, axis=1)) <= table.error_m(POLICY.accel_bound_m_s2)
    assert table.describes(active, 0.2, 3)
    assert not table.describes(ActiveTrajectory(traj, 2.5, "leg0"), 0.2, 3)
    assert not table.describes(_active(25.0, 0.3, 2.0), 0.2, 3)  # another retime object
    with pytest.raises(ValueError, match="step_s"):
        ReferenceTable(active, 0.0, 3)


def test_other_frames_are_left_to_the_check():
    active = _active(0.0, None, 0.0)
    table = ReferenceTable(active, 0.2, 3)
    glob = Threat("g", "popup", "global", (-35.0, 149.0, 600.0), radius_m=3.0, received_t_s=0.0)
    assert not proves_clear(table, (glob,), 1.0, POLICY.settings, POLICY.accel_bound_m_s2)


@settings(max_examples=300, deadline=None)
@given(
    bend=st.sampled_from(sorted(TRAJECTORIES)),
    retime=st.one_of(st.none(), st.floats(0.0, 0.8)),
    t=st.floats(0.0, 25.0),
    meet_s=st.floats(0.0, 16.0),
    vel=st.tuples(speed, speed, st.floats(-2.0, 2.0)),
    miss=st.tuples(st.floats(-1.0, 1.0), st.floats(-1.0, 1.0), st.floats(-1.0, 1.0)),
    miss_m=st.floats(0.0, 12.0),
    dim=st.sampled_from([2, 3]),
)
def test_a_proof_of_clear_is_never_wrong_at_the_edge(bend, retime, t, meet_s, vel, miss, miss_m, dim):
    """Threats aimed to pass the reference at about their tube's radius: the proof's edge."""
    active = _active(bend, retime, 0.0)
    traj = active.trajectory
    meet = np.atleast_2d(traj.sample(np.array([min(t + meet_s, traj.duration_s)]))[0])[0]
    direction = np.asarray(miss) / max(float(np.linalg.norm(miss)), 1e-9)
    pos = meet + direction * miss_m - np.asarray(vel) * meet_s
    threat = _threat(pos, vel, 3.0, t)
    leg = LegContext(0, WORLD2 if dim == 2 else WORLD3, np.array([120.0, 0.0, -25.0])[:dim])
    table = ReferenceTable(active, POLICY.settings.check_step_s, dim)
    proven = proves_clear(table, (threat,), t, POLICY.settings, POLICY.accel_bound_m_s2)
    if proven:
        assert active_conflict(Observation(t, (threat,), active, Trigger.MONITOR), leg, POLICY) is None


@settings(max_examples=400, deadline=None)
@given(
    bend=st.sampled_from(sorted(TRAJECTORIES)),
    retime=st.one_of(st.none(), st.floats(0.0, 0.8)),
    start=st.floats(-3.0, 3.0),
    t=st.floats(-2.0, 30.0),
    meet_s=st.floats(0.0, 17.0),
    vel=st.tuples(speed, speed, st.floats(-2.0, 2.0)),
    miss=st.tuples(st.floats(-1.0, 1.0), st.floats(-1.0, 1.0), st.floats(-1.0, 1.0)),
    miss_m=st.floats(0.0, 12.0),
    later=st.lists(st.floats(0.0, LEAD_S), min_size=1, max_size=4),
    dim=st.sampled_from([2, 3]),
    ttl=st.one_of(st.none(), st.floats(0.3, 6.0)),
)
def test_a_standing_proof_holds_until_it_lapses(bend, retime, start, t, meet_s, vel, miss, miss_m, later, dim, ttl):
    """A proof that stands says clear at later ticks (the same reports) only when the check agrees
    (threats that expire too: a check counts a tube on an interval that starts before it expires)."""
    active = _active(bend, retime, start)
    traj = active.trajectory
    meet = np.atleast_2d(traj.sample(np.array([min(max(t + meet_s - start, 0.0), traj.duration_s)]))[0])[0]
    direction = np.asarray(miss) / max(float(np.linalg.norm(miss)), 1e-9)
    threats = (
        _threat(
            meet + direction * miss_m - np.asarray(vel) * meet_s,
            vel,
            3.0,
            t,
            None if ttl is None else min(ttl, meet_s + 0.3),
        ),
    )
    leg = LegContext(0, WORLD2 if dim == 2 else WORLD3, np.array([120.0, 0.0, -25.0])[:dim])
    screen = MonitorScreen(POLICY.settings, POLICY.accel_bound_m_s2)
    for t_now in [t] + [t + dt for dt in sorted(later)]:
        if screen.proves_clear(active, threats, t_now, dim):
            assert active_conflict(Observation(t_now, threats, active, Trigger.MONITOR), leg, POLICY) is None


def test_a_proof_stands_for_the_same_reports_only():
    active = _active(0.0, None, 0.0)
    screen = MonitorScreen(POLICY.settings, POLICY.accel_bound_m_s2)
    far = (_threat((60.0, 300.0, -20.0), (0.0, 0.0, 0.0), 3.0, 4.0),)
    assert screen.proves_clear(active, far, 4.0, 3) and screen.proofs == 1
    assert screen.proves_clear(active, far, 4.5, 3) and screen.standing == 1
    assert screen.proves_clear(active, far, 4.0 + LEAD_S + 0.1, 3) and screen.proofs == 2  # lapsed
    again = (_threat((60.0, 300.0, -20.0), (0.0, 0.0, 0.0), 3.0, 4.0),)  # a new report, equal
    assert screen.proves_clear(active, again, 4.3 + LEAD_S, 3) and screen.proofs == 3
    ahead = (_threat((40.0, 0.0, -20.0), (0.0, 0.0, 0.0), 3.0, 4.0),)
    assert not screen.proves_clear(active, ahead, 4.4 + LEAD_S, 3)
    assert not screen.proves_clear(active, ahead, 4.5 + LEAD_S, 3)  # nothing stands for it


def test_a_standing_proof_counts_a_tube_until_a_step_after_it_expires():
    """A head-on mover whose reports expire just before it meets the reference: a check counts
    its tube on an interval that starts before it expires, so a proof made earlier must too."""
    active = _active(0.0, None, 0.0)
    traj = active.trajectory
    leg = LegContext(0, WORLD3, np.array([120.0, 0.0, -25.0]))
    vel = np.array([-12.0, 0.0, 0.0])
    wrong, proven = [], 0
    for meet_s in (8.0, 9.0):
        meet = np.atleast_2d(traj.sample(np.array([meet_s]))[0])[0]
        for t in np.arange(2.0, 3.0, 0.07):
            for after_s in np.linspace(0.0, 0.3, 13):
                threat = _threat(meet - vel * (meet_s - t), vel, 0.5, t, meet_s - after_s - t)
                screen = MonitorScreen(POLICY.settings, POLICY.accel_bound_m_s2)
                for t_now in t + np.linspace(0.0, LEAD_S, 11):
                    if screen.proves_clear(active, (threat,), t_now, 3):
                        proven += 1
                        if (
                            active_conflict(Observation(t_now, (threat,), active, Trigger.MONITOR), leg, POLICY)
                            is not None
                        ):
                            wrong.append((meet_s, t, after_s, t_now))
    assert proven and not wrong


def test_a_popup_whose_report_expires_before_the_reference_reaches_it_still_conflicts():
    """A pop-up on the path whose report expires before the vehicle gets there: a static threat's
    tube lives over the whole horizon (a ttl is how long a report stays valid, not when the
    threat goes away), so the check finds the conflict and the screen never proves it clear."""
    active = _active(0.0, None, 0.0)
    traj = active.trajectory
    leg = LegContext(0, WORLD3, np.array([120.0, 0.0, -25.0]))
    proven, missed = 0, []
    for meet_s in (6.0, 9.0):
        meet = np.atleast_2d(traj.sample(np.array([meet_s]))[0])[0]
        for t in np.arange(2.0, 3.0, 0.25):
            for ttl_s in (0.5, 1.0, 2.0):
                threat = _threat(meet, np.zeros(3), 0.5, t, ttl_s)
                screen = MonitorScreen(POLICY.settings, POLICY.accel_bound_m_s2)
                proven += screen.proves_clear(active, (threat,), t + 0.2, 3)
                if active_conflict(Observation(t + 0.2, (threat,), active, Trigger.MONITOR), leg, POLICY) is None:
                    missed.append((meet_s, t, ttl_s))
    assert proven == 0 and not missed
