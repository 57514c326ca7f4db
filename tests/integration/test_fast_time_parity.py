"""One flight core in real time and in fast time (issue 22): the same seeded encounter flown
by ``sim-vehicle`` and ``companion run`` (separate processes, MAVLink and zenoh) and by the
fast-time executor on the helicopter model (``companion.flight.fast_time``) takes the same
sequence of decision kinds, and the closest approaches agree within 1 m.

The real flight flies ``mission_files/open_square.waypoints`` at 2x (open air, no fence: the plans are
the same in both) with a pop-up put on the first leg 3 s ahead of the reference; alternatives
are off (M-GART's budget is wall-clock time, so its answer would depend on the machine's load).
The pop-up, as the companion recorded it (received at its mission time), is given to the fast
flight at the same time from the leg's start; both fly the same mission legs, planned with the
same seed from the takeoff point. Judged by the vehicle's own LOCAL_POSITION_NED in real time
and the model's positions in fast time.
"""

from __future__ import annotations

import dataclasses
import logging

import numpy as np
import pytest
from flight_support import TrackListener, fly
from support import REPO_ROOT

from companion.config import load_settings
from companion.demo import DEMO_HOME, Injection
from companion.flight.fast_time import FastTimeFlight
from companion.flight.pipeline import TrajectoryPipeline
from companion.flight.plan import plan_mission
from companion.mission import load_mission_file
from companion.mission.convert import mission_to_local
from companion.record.flight_record import load_record
from companion.threats.model import Threat

pytestmark = pytest.mark.integration

log = logging.getLogger(__name__)

MISSION = REPO_ROOT / "mission_files" / "open_square.waypoints"
SPEEDUP = 2.0
POPUP = Injection("pop1", "popup", leg=0, after_s=4.0, ahead_s=3.0, radius_m=3.0)
CONFIG = "seed = 7\n[flight]\nalternatives_k = 0\n"


def first_leg_threat(record):
    """The pop-up as the companion holds it: (received mission time, position, radius)."""
    line = next(t for t in record.threats if t["id"] == POPUP.threat_id and not t.get("removed"))
    return float(line["t_s"]), np.asarray(line["position_ned_m"], dtype=float), float(line["radius_m"])


def leg_start_s(record, leg: int) -> float:
    return next(float(e["t_s"]) for e in record.events if e.get("name") == "leg_started" and e["leg"] == leg)


def planned_legs(settings):
    """The mission's legs as ``companion run`` plans them before takeoff (same seed, same start)."""
    plan = load_mission_file(MISSION)
    local = mission_to_local(plan, DEMO_HOME, settings=settings.mission, dim=3)
    alt_m = -float(local.waypoints[0].pos_ned_m[2])
    rng = np.random.default_rng(settings.seed)
    legs = plan_mission(
        local,
        np.array([0.0, 0.0, -alt_m]),
        pipeline=TrajectoryPipeline.from_settings(settings.smoothing, settings.planning, settings.feasibility),
        settings=settings.flight,
        rng=np.random.default_rng(rng.integers(2**63)),
    )
    return legs, local.world, int(rng.integers(2**31))


def closest_approach_m(t_s, pos, centre, radius_m, after_s) -> float:
    sel = t_s >= after_s
    return float(np.min(np.linalg.norm(pos[sel] - centre, axis=1)) - radius_m)


@pytest.fixture(scope="module")
def real(tmp_path_factory):
    tmp = tmp_path_factory.mktemp("parity")
    config = tmp / "companion.toml"
    config.write_text(CONFIG)
    with TrackListener(rate_hz=50.0) as track:
        summary = fly(
            tmp,
            MISSION,
            speedup=SPEEDUP,
            injections=[POPUP],
            gcs_out=track.address,
            extra_args=["--config", str(config)],
            timeout_s=400.0,
        )
        t_s, pos = track.samples()
    return summary, load_record(summary["record"]), t_s, pos, config


def test_real_and_fast_time_flights_take_the_same_decisions_and_pass_as_close(real):
    summary, record, t_real, pos_real, config = real
    assert summary["outcome"] == "completed", summary
    settings = load_settings(config)
    settings = dataclasses.replace(settings, link=dataclasses.replace(settings.link, time_scale=SPEEDUP))
    received_s, centre, radius_m = first_leg_threat(record)
    start_s = leg_start_s(record, 0)
    kinds_real = [d["kind"] for d in record.decisions if d.get("leg") == 0]
    assert kinds_real, "the pop-up asked for no decision in the real flight"

    legs, world, seed = planned_legs(settings)
    threat = Threat(
        POPUP.threat_id,
        "popup",
        "local_ned",
        tuple(centre),
        (0.0, 0.0, 0.0),
        radius_m,
        received_t_s=received_s - start_s,
    )
    flight = FastTimeFlight(
        legs[:1],
        settings,
        threats=[(received_s - start_s, threat, threat.id)],
        seed=seed,
        start_yaw_rad=float(legs[0].trajectory.yaw_rad(np.array([0.0]))[0]),
        world=world,
        job_time_scale=SPEEDUP,
    )  # a job takes SPEEDUP x its wall time of mission time
    fast = flight.run(max_s=200.0)
    kinds_fast = [d["event"] for d in fast.decisions]
    assert fast.outcome.value == "completed", fast.reason
    assert kinds_fast == kinds_real, f"fast time {kinds_fast}, real time {kinds_real}"

    leg_end_s = leg_start_s(record, 1)
    in_leg = (t_real >= start_s) & (t_real <= leg_end_s)
    cpa_real = closest_approach_m(t_real[in_leg], pos_real[in_leg], centre, radius_m, received_s)
    cpa_fast = closest_approach_m(fast.t_s + start_s, fast.pos_ned_m, centre, radius_m, received_s)
    log.info("decisions %s; closest approach real %.2f m, fast %.2f m", kinds_real, cpa_real, cpa_fast)
    assert cpa_real > 0.0 and cpa_fast > 0.0, (cpa_real, cpa_fast)
    assert abs(cpa_real - cpa_fast) <= 1.0, f"closest approach: real {cpa_real:.2f} m, fast {cpa_fast:.2f} m"
