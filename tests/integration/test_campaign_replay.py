"""``companion campaign replay`` (issue 23): an encounter of a campaign, flown by real
``sim-vehicle`` and ``companion run`` processes with its reports put over zenoh, judged by the
vehicle's own telemetry. A head-on encounter in open air that fast time calls a collision
without the system and a manoeuvre with it: in SITL every report is put, the companion reacts
(a decision on its zenoh events), and the vehicle's telemetry covers the encounter's window.
"""

from __future__ import annotations

import json
import subprocess
import sys

import pytest
from support import REPO_ROOT

from companion.campaign.store import CampaignStore
from companion.record.flight_record import load_record

pytestmark = [pytest.mark.integration, pytest.mark.timeout(600)]

SPEC = """name = "replay-check"
seed = 3
max_pairs = 10
min_pairs = 10
batch_pairs = 10
strata = ["head_on/open"]
"""


def flown_campaign(tmp_path, spec_text: str):
    """``companion campaign run`` of ``spec_text`` in one worker; its directory."""
    spec = tmp_path / "spec.toml"
    spec.write_text(spec_text)
    out = tmp_path / "campaign"
    run = subprocess.run(
        [
            sys.executable,
            "-m",
            "companion.cli",
            "campaign",
            "run",
            str(spec),
            "--out",
            str(out),
            "--workers",
            "1",
            "--no-progress",
        ],
        cwd=REPO_ROOT,
        capture_output=True,
        text=True,
        timeout=300,
    )
    assert run.returncode == 0, run.stderr[-3000:]
    return out


def replayed(out, encounter_id: int) -> dict:
    """``companion campaign replay`` of one encounter at speed-up 4 (real processes); its outcome."""
    replay = subprocess.run(
        [sys.executable, "-m", "companion.cli", "campaign", "replay", str(out), str(encounter_id), "--speedup", "4"],
        cwd=REPO_ROOT,
        capture_output=True,
        text=True,
        timeout=500,
    )
    assert replay.returncode == 0, replay.stderr[-3000:]
    return json.loads(replay.stdout[replay.stdout.index("{") :])


def test_replay_flies_the_encounter_in_sitl(tmp_path):
    out = flown_campaign(tmp_path, SPEC)
    rows = CampaignStore(out).table().to_pylist()
    pick = next(r for r in rows if r["u_collision"] and r["m_manoeuvred"])
    outcome = replayed(out, pick["id"])
    assert outcome["id"] == pick["id"] and outcome["puts"] > 0
    assert outcome["fast_time"]["min_sep_m"] == pytest.approx(pick["m_min_sep_m"])
    record = load_record(outcome["record"])
    assert record.decisions, "the companion made no decision in SITL"
    t = record.samples["t_s"] - outcome["leg_t0_s"]
    assert t.min() < 1.0 and t.max() > 20.0  # the telemetry covers the leg and the encounter
    assert len(outcome["hmd_m"]) == 1 and outcome["min_sep_m"] < 100.0


MANNED_SPEC = """name = "replay-manned"
seed = 5
max_pairs = 2
min_pairs = 2
batch_pairs = 2
strata = ["manned/rotorcraft"]
"""


def test_manned_traffic_reaches_the_companion_as_adsb_vehicle_through_the_vehicle(tmp_path):
    """A manned rotorcraft of the MIT LL model, replayed: its reports are ADSB_VEHICLE messages of
    an ADS-B receiver component sent to the vehicle, which routes them to the companion (--adsb);
    the companion's record holds them as threats, at the message's quantisation, 1 Hz apart."""
    out = flown_campaign(tmp_path, MANNED_SPEC)
    outcome = replayed(out, 0)
    assert outcome["puts"] > 20
    record = load_record(outcome["record"])
    heard = [t for t in record.threats if str(t["id"]).startswith("adsb-")]
    assert 20 <= len(heard) <= outcome["puts"]  # reports sent after the landing reach no one
    gaps = [b["t_s"] - a["t_s"] for a, b in zip(heard, heard[1:])]
    # 1 Hz: the gaps alternate about 0.8 and 1.2 s (the vehicle forwards at its own ticks), so
    # their median is either; their mean is the rate. On a loaded machine a report can go
    # unrecorded (a gap of 2 s, seen once in 70 with four test files flying side by side):
    # rarely, and never two in a row
    late = [g for g in gaps if g > 1.5]
    assert 0.9 < sum(gaps) / len(gaps) < 1.1 and max(gaps) < 2.5 and len(late) <= len(gaps) // 20, gaps
    # a 50 m/s intruder: a tenth of a second of timing at speed-up 4 is metres of separation
    assert outcome["fast_time"]["min_sep_m"] == pytest.approx(outcome["min_sep_m"], rel=0.02, abs=5.0)


WELL_CLEAR_SPEC = """name = "replay-manned-well-clear"
seed = 5
max_pairs = 8
min_pairs = 8
batch_pairs = 8
strata = ["manned/rotorcraft"]
"""


def test_a_manned_rotorcraft_on_a_collision_course_passes_with_no_loss_of_well_clear_in_sitl(tmp_path):
    """Issue 24: a rotorcraft track of the MIT LL model on a collision course (an NMAC without
    the system, in fast time), sent to the vehicle as ADSB_VEHICLE at 1 Hz and routed to the
    companion, passes with no loss of well clear (2000 ft / 250 ft), judged by the vehicle's own
    telemetry against the track."""
    out = flown_campaign(tmp_path, WELL_CLEAR_SPEC)
    rows = CampaignStore(out).table().to_pylist()
    pick = next(r for r in rows if r["u_nmac"] and not r["m_lowc"])
    outcome = replayed(out, pick["id"])
    assert outcome["puts"] > 20
    record = load_record(outcome["record"])
    assert any(str(d.get("threat_id", "")).startswith("adsb-") for d in record.decisions), "no decision on the traffic"
    assert not outcome["nmac"] and not outcome["lowc"], (outcome["hmd_m"], outcome["min_sep_m"])
