"""The leg's flight-phase state machine (companion.flight.phases): every transition, no vehicle."""

import dataclasses
import math

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from companion.flight.phases import (
    RESUME_AFTER_S,
    RESUME_RETRY_S,
    ActionKind,
    LegAction,
    LegObservation,
    LegPhase,
    LegState,
    leg_step,
)

RADIUS = 2.0
MARGIN = 30.0


def obs(**changes) -> LegObservation:
    """A vehicle in GUIDED following a reference that ends at t = 100 s at the goal."""
    base = LegObservation(
        t_s=50.0,
        seq=3,
        connected=True,
        armed=True,
        guided=True,
        mode_name="GUIDED",
        relink_pending=False,
        dist_to_goal_m=40.0,
        acceptance_radius_m=RADIUS,
        ref_end_t_s=100.0,
        ref_ends_short=False,
        ref_resume=False,
        timeout_margin_s=MARGIN,
    )
    return dataclasses.replace(base, **changes)


def step(state=None, **changes):
    return leg_step(state or LegState(), obs(**changes))


# ---------------------------------------------------------------------------- following
def test_following_a_running_reference_keeps_it():
    state, action = step()
    assert state.phase is LegPhase.FOLLOWING and action.kind is ActionKind.KEEP


def test_no_reference_keeps_streaming():
    state, action = step(ref_end_t_s=None, dist_to_goal_m=0.0)
    assert state.phase is LegPhase.FOLLOWING and action.kind is ActionKind.KEEP


def test_within_the_radius_before_the_reference_ended_is_not_reached():
    state, action = step(t_s=99.9, dist_to_goal_m=0.1)
    assert state.phase is LegPhase.FOLLOWING and action.kind is ActionKind.KEEP


# ---------------------------------------------------------------------------- reached / arriving / timeout
def test_reference_ended_within_the_radius_is_reached():
    state, action = step(t_s=100.0, dist_to_goal_m=RADIUS)
    assert state.phase is LegPhase.REACHED and action == LegAction(ActionKind.REACHED)


def test_reference_ended_at_the_goal_but_vehicle_not_there_is_arriving():
    state, action = step(t_s=110.0, dist_to_goal_m=5.0)
    assert state.phase is LegPhase.ARRIVING and action.kind is ActionKind.KEEP
    state, action = step(state, t_s=111.0, dist_to_goal_m=1.0)
    assert state.phase is LegPhase.REACHED and action.kind is ActionKind.REACHED


def test_not_reached_within_the_margin_times_out_naming_the_item():
    state, action = step(t_s=100.0 + MARGIN + 0.01, dist_to_goal_m=7.25)
    assert state.phase is LegPhase.TIMED_OUT and action.kind is ActionKind.ABORT
    assert action.reason == "item 3 not reached: 7.2 m away 30 s after the reference arrived"
    state, action = step(t_s=100.0 + MARGIN, dist_to_goal_m=7.25)
    assert state.phase is LegPhase.ARRIVING


def test_unknown_position_never_counts_as_reached():
    state, action = step(t_s=101.0, dist_to_goal_m=math.inf)
    assert state.phase is LegPhase.ARRIVING and action.kind is ActionKind.KEEP


# ---------------------------------------------------------------------------- stopped short and resume
def test_a_resume_reference_is_resumed_as_soon_as_it_has_ended():
    state, action = step(t_s=99.0, ref_ends_short=True, ref_resume=True)
    assert state.phase is LegPhase.FOLLOWING and action.kind is ActionKind.KEEP
    state, action = step(state, t_s=100.0, ref_ends_short=True, ref_resume=True)
    assert state.phase is LegPhase.STOPPED_SHORT and action.kind is ActionKind.RESUME
    assert state.last_resume_t_s == 100.0 and action.reason


def test_resume_is_asked_again_no_sooner_than_the_retry_period():
    state, _ = step(t_s=100.0, ref_ends_short=True, ref_resume=True)
    state, action = step(state, t_s=100.0 + RESUME_RETRY_S - 0.01, ref_ends_short=True, ref_resume=True)
    assert state.phase is LegPhase.STOPPED_SHORT and action.kind is ActionKind.KEEP
    state, action = step(state, t_s=100.0 + RESUME_RETRY_S, ref_ends_short=True, ref_resume=True)
    assert action.kind is ActionKind.RESUME and state.last_resume_t_s == 100.0 + RESUME_RETRY_S


def test_a_reference_short_without_resume_waits_resume_after_s():
    state, action = step(t_s=100.0 + RESUME_AFTER_S - 0.01, ref_ends_short=True)
    assert state.phase is LegPhase.STOPPED_SHORT and action.kind is ActionKind.KEEP
    state, action = step(state, t_s=100.0 + RESUME_AFTER_S, ref_ends_short=True)
    assert action.kind is ActionKind.RESUME


def test_a_new_reference_after_resume_is_followed_and_keeps_the_retry_memory():
    state, _ = step(t_s=100.0, ref_ends_short=True, ref_resume=True)
    state, action = step(state, t_s=100.5, ref_end_t_s=130.0)  # the way back is engaged
    assert state.phase is LegPhase.FOLLOWING and action.kind is ActionKind.KEEP
    assert state.last_resume_t_s == 100.0
    state, action = step(state, t_s=130.0, ref_end_t_s=130.0, dist_to_goal_m=0.5)
    assert action.kind is ActionKind.REACHED


def test_stopped_short_within_the_radius_is_reached():
    state, action = step(t_s=100.0, ref_ends_short=True, ref_resume=True, dist_to_goal_m=1.0)
    assert state.phase is LegPhase.REACHED and action.kind is ActionKind.REACHED


def test_stopped_short_never_times_out():
    state, action = step(
        LegState(LegPhase.STOPPED_SHORT, last_resume_t_s=1000.0), t_s=1000.5, ref_ends_short=True, ref_resume=True
    )
    assert state.phase is LegPhase.STOPPED_SHORT and action.kind is ActionKind.KEEP


# ---------------------------------------------------------------------------- link and pilot
def test_disarmed_in_flight_aborts():
    state, action = step(armed=False)
    assert state.phase is LegPhase.ABORTED and action == LegAction(ActionKind.ABORT, "the vehicle disarmed in flight")


def test_leaving_guided_aborts_naming_the_mode():
    state, action = step(guided=False, mode_name="LOITER")
    assert state.phase is LegPhase.ABORTED and action.kind is ActionKind.ABORT
    assert "left GUIDED (now LOITER)" in action.reason


def test_unknown_armed_state_or_mode_does_not_abort():
    state, action = step(armed=None, guided=None, mode_name="UNKNOWN")
    assert state.phase is LegPhase.FOLLOWING and action.kind is ActionKind.KEEP


def test_while_the_link_is_down_stale_mode_and_arming_are_ignored():
    state, action = step(connected=False, armed=False, guided=False, relink_pending=True)
    assert state.phase is LegPhase.FOLLOWING and action.kind is ActionKind.KEEP


def test_link_back_replans_the_leg_once_connected():
    state, action = step(LegState(LegPhase.STOPPED_SHORT), relink_pending=True, ref_end_t_s=None)
    assert state.phase is LegPhase.FOLLOWING and action.kind is ActionKind.REPLAN


def test_pilot_takeover_wins_over_a_pending_replan():
    state, action = step(relink_pending=True, guided=False)
    assert action.kind is ActionKind.ABORT


# ---------------------------------------------------------------------------- terminal
@pytest.mark.parametrize(
    "phase, kind",
    [
        (LegPhase.REACHED, ActionKind.REACHED),
        (LegPhase.TIMED_OUT, ActionKind.ABORT),
        (LegPhase.ABORTED, ActionKind.ABORT),
    ],
)
def test_terminal_states_stay_and_repeat_their_action(phase, kind):
    start = LegState(phase, reason="why")
    state, action = step(start, t_s=50.0, armed=True, dist_to_goal_m=100.0)
    assert state == start and action.kind is kind
    if kind is ActionKind.ABORT:
        assert action.reason == "why"


@settings(max_examples=200, deadline=None)
@given(
    t=st.floats(0.0, 300.0),
    dist=st.floats(0.0, 100.0),
    short=st.booleans(),
    resume=st.booleans(),
    last=st.floats(-1.0, 300.0),
    connected=st.booleans(),
    relink=st.booleans(),
)
def test_invariants(t, dist, short, resume, last, connected, relink):
    """Reached only within the radius after the reference's end; resumes spaced by the retry period;
    no abort while the vehicle is in GUIDED and armed unless the goal was missed in time."""
    before = LegState(LegPhase.STOPPED_SHORT, last_resume_t_s=last)
    state, action = step(
        before,
        t_s=t,
        dist_to_goal_m=dist,
        ref_ends_short=short,
        ref_resume=resume,
        connected=connected,
        relink_pending=relink,
    )
    if action.kind is ActionKind.REACHED:
        assert dist <= RADIUS and t >= 100.0
    if action.kind is ActionKind.RESUME:
        assert short and t >= 100.0 and t >= last + RESUME_RETRY_S and state.last_resume_t_s == t
    else:
        assert state.last_resume_t_s == last
    if action.kind is ActionKind.ABORT:
        assert state.phase is LegPhase.TIMED_OUT and not short and t > 100.0 + MARGIN
    if action.kind is ActionKind.REPLAN:
        assert connected and relink
