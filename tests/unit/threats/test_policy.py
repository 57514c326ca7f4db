"""The threat policy (DESIGN 7): keep, retime, switch, replan, evade, hold, judged by one check.

The chosen reference is re-checked here independently: sampled every 10 ms against the threat's
true constant-velocity track (not through the policy's own check).
"""

from __future__ import annotations

import numpy as np
import pytest

from companion.smoothing import TrajectoryLimits, smooth_g2, time_parameterize
from companion.threats.model import Threat
from companion.threats.decision.policy import ThreatManager, ThreatManagerError
from companion.threats.settings import ThreatSettings
from companion.world import World

LIMITS = TrajectoryLimits(speed_m_s=6.0)
WORLD = World([], [-60.0, -60.0, -40.0], [160.0, 60.0, -5.0])
GOAL = np.array([120.0, 0.0, -20.0])


@pytest.fixture(scope="module")
def nominal():
    path = np.array([[0.0, 0.0, -20.0], GOAL])
    return time_parameterize(smooth_g2(path, 0.1, world=WORLD), LIMITS)


def manager(nominal, mode="hybrid", world=WORLD, goal=GOAL, settings=None):
    m = ThreatManager(world, goal, settings=settings or ThreatSettings(), limits=LIMITS, mode=mode,
                      rng=np.random.default_rng(3))
    m.set_active(nominal, 0.0, "leg0")
    return m


def true_separation_m(decision, threat: Threat, t_s: float, span_s: float = 20.0) -> float:
    """Smallest distance (m) from the decision's reference to the threat's centre, every 10 ms."""
    t = np.arange(t_s, t_s + span_s, 0.01)
    pos = np.atleast_2d(decision.trajectory.sample(np.clip(t - decision.start_t_s, 0.0, None))[0])
    return float(np.min(np.linalg.norm(pos[:, :3] - threat.position_at(t), axis=1)))


def ahead(m, t_s, seconds):
    ref = m.reference_state(t_s)
    return ref, ref.pos_ned_m + ref.vel_ned_m_s * seconds


def test_a_clear_reference_is_kept(nominal):
    m = manager(nominal)
    far = Threat("far", "popup", "local_ned", (60.0, 40.0, -20.0), (0, 0, 0), 3.0, None, 0.0)
    d = m.on_threats([far], 5.0)
    assert d.kind == "none" and d.trajectory is None
    assert m.active_path_id == "leg0"


def test_head_on_mover_is_evaded_in_space_time_and_not_decided_twice(nominal):
    m = manager(nominal)
    t = 6.0
    ref, _ = ahead(m, t, 0.0)
    threat = Threat("h", "moving", "local_ned", tuple(ref.pos_ned_m + [35.0, 0.0, 0.0]), (-4.0, 0.0, 0.0),
                    3.0, None, t)
    d = m.on_threats([threat], t)
    assert d.kind in ("evade", "switch", "replan", "retime")
    assert d.min_clearance_m >= 0.0
    assert true_separation_m(d, threat, t) >= threat.radius_m + 2.0 - 0.05   # inflated radius kept
    again = m.on_threats([threat], t + 0.1)
    assert again.kind == "none"


def test_close_popup_is_not_flown_into(nominal):
    m = manager(nominal)
    t = 8.0
    ref, spot = ahead(m, t, 2.0)
    threat = Threat("p", "popup", "local_ned", tuple(spot), (0, 0, 0), 4.0, None, t)
    d = m.on_threats([threat], t)
    assert d.kind in ("evade", "hold", "switch")
    assert true_separation_m(d, threat, t) >= threat.radius_m


def test_crossing_mover_is_avoided_by_retiming_when_that_is_cheapest(nominal):
    m = manager(nominal)
    t = 4.0
    ref, meet = ahead(m, t, 5.0)
    # crosses the path at right angles and reaches the meeting point in 5 s
    threat = Threat("x", "moving", "local_ned", tuple(meet + [0.0, -15.0, 0.0]), (0.0, 3.0, 0.0), 2.5, None, t)
    d = m.on_threats([threat], t)
    assert d.kind == "retime", d.reason
    assert true_separation_m(d, threat, t, 30.0) >= threat.radius_m + 2.0 - 0.05
    np.testing.assert_allclose(d.trajectory.end_pos_ned_m, GOAL, atol=1e-6)    # still to the goal


def test_after_an_evasion_the_way_back_is_planned_without_a_long_detour(nominal):
    m = manager(nominal, mode="evade")
    t = 6.0
    ref, _ = ahead(m, t, 0.0)
    threat = Threat("h", "moving", "local_ned", tuple(ref.pos_ned_m + [35.0, 0.0, 0.0]), (-4.0, 0.0, 0.0),
                    3.0, None, t)
    d = m.on_threats([threat], t)
    assert d.kind == "evade" and d.resume
    t_end = d.start_t_s + d.trajectory.duration_s
    back = m.resume([threat], t_end)
    if back.kind == "none":              # the mover is still in the way: later
        back = m.resume([threat], t_end + 5.0)
        t_end += 5.0
    assert back.kind in ("replan", "switch")
    assert not back.resume
    hover = d.trajectory.end_pos_ned_m
    direct = float(np.linalg.norm(GOAL - hover[:3]))
    assert back.trajectory.length_m <= 2.0 * direct
    assert true_separation_m(back, threat, t_end, 40.0) >= threat.radius_m


@pytest.mark.parametrize("mode,kinds", [("hold", {"hold", "none"}), ("retime", {"retime", "none"}),
                                        ("evade", {"evade", "hold", "none"}), ("switch", {"switch", "none"}),
                                        ("replan", {"replan", "none"})])
def test_single_strategies_only_use_their_own_candidates(nominal, mode, kinds):
    m = manager(nominal, mode=mode)
    t = 6.0
    ref, spot = ahead(m, t, 3.0)
    threat = Threat("p", "popup", "local_ned", tuple(spot), (0, 0, 0), 3.0, None, t)
    d = m.on_threats([threat], t)
    assert d.kind in kinds
    assert set(d.candidates) <= kinds


def test_bad_arguments_name_themselves(nominal):
    with pytest.raises(ThreatManagerError, match="mode"):
        ThreatManager(WORLD, GOAL, mode="pray")
    with pytest.raises(ThreatManagerError, match="goal_ned_m"):
        ThreatManager(WORLD, [1.0, 2.0])
    m = manager(nominal)
    glob = Threat("g", "popup", "global", (47.0, 8.0, 500.0), (0, 0, 0), 3.0)
    with pytest.raises(ThreatManagerError, match="global"):
        m.on_threats([glob], 1.0)


def test_alternatives_exist_on_a_climbing_leg():
    """The leg's slab is thinner than the climb: the alternatives' airspace includes the start."""
    slab = World([], [-60.0, -60.0, -22.0], [160.0, 60.0, -18.0])
    m = ThreatManager(slab, GOAL, limits=LIMITS, rng=np.random.default_rng(0))
    alts = m.compute_alternatives([], 0.0, 3, rng=np.random.default_rng(1), max_time_s=0.5,
                                  start_ned_m=[10.0, 0.0, -15.4])
    assert alts
    assert all(a.path_ned_m[0, 2] == pytest.approx(-15.4) for a in alts)


def test_alternatives_include_above_and_below(nominal):
    m = manager(nominal)
    alts = m.compute_alternatives([], 2.0, 2, rng=np.random.default_rng(1), max_time_s=0.5)
    assert min(float(a.path_ned_m[:, 2].min()) for a in alts) <= -26.0 + 1e-6   # 6 m above
    assert max(float(a.path_ned_m[:, 2].max()) for a in alts) >= -14.0 - 1e-6   # 6 m below
