"""The oracle's labels of a campaign's events (``companion.campaign.labels``): the oracle flies
against true tracks, a pop-up too close to stop for is unavoidable and one farther off is not,
and a campaign's mitigated drone-scale events are labelled once each (a second pass labels
nothing again), manned ones never.
"""

from __future__ import annotations

import numpy as np
import pyarrow as pa
import pytest

from companion.campaign import labels as labels_module
from companion.campaign.flying import CampaignWorker
from companion.campaign.labels import LABEL_SCHEMA, label_campaign, read_labels
from companion.campaign.oracle import label_encounter
from companion.campaign.spec import CampaignSpec
from companion.campaign.store import SCHEMA
from companion.campaign.tracks import straight_track
from companion.config import Settings
from companion.threats.model import Threat
from companion.world import World

OPEN = World([], [-100.0, -100.0, -60.0], [300.0, 100.0, -2.0], margin_m=0.0)


def test_a_track_knows_its_fastest_segment():
    track = straight_track(
        "t", 0.0, 10.0, [0.0, 0.0, -20.0], [3.0, 4.0, 0.0], 2.0, turn_t_s=4.0, v_after_ned_m_s=[0.0, -12.0, 0.0]
    )
    assert track.max_speed_m_s == pytest.approx(12.0)


@pytest.mark.parametrize("ahead_m, avoidable", [(3.5, False), (40.0, True)])
def test_a_pop_up_too_close_to_stop_for_is_unavoidable(ahead_m, avoidable):
    popup = straight_track("p", 0.0, 30.0, [ahead_m + 3.0, 0.0, -20.0], [0.0, 0.0, 0.0], 3.0, popup=True)
    result = label_encounter([0.0, 0.0, -20.0], [6.0, 0.0, 0.0], [popup], 0.0, OPEN)
    assert result.avoidable is avoidable


def test_the_oracle_flies_against_the_true_track_not_its_first_report():
    """An intruder heading away at its first report turns onto the hovering vehicle a tenth of a
    second later, 12 m/s from 10 m off: its first report's constant velocity misses by far, its
    true track leaves no escape."""
    turning = straight_track(
        "t", 0.0, 30.0, [0.0, 10.0, -20.0], [0.0, 12.0, 0.0], 2.0, turn_t_s=0.1, v_after_ned_m_s=[0.0, -12.0, 0.0]
    )
    first_report = Threat("t", "moving", "local_ned", (0.0, 10.0, -20.0), (0.0, 12.0, 0.0), radius_m=2.0)
    assert label_encounter([0.0, 0.0, -20.0], [0.0, 0.0, 0.0], [first_report], 0.0, OPEN).avoidable
    assert not label_encounter([0.0, 0.0, -20.0], [0.0, 0.0, 0.0], [turning], 0.0, OPEN).avoidable


def _rows(worker, ids):
    return pa.Table.from_pylist([worker.row(i) for i in ids], schema=SCHEMA)


def test_a_campaign_s_events_are_labelled_once(tmp_path, monkeypatch):
    worker = CampaignWorker(CampaignSpec(strata=("popup_near/open",)), Settings(), "h")
    table = _rows(worker, range(5))  # encounter 0: an NMAC, 3: a collision and an NMAC
    labels = label_campaign(worker, table, tmp_path).to_pylist()
    rows = table.to_pylist()
    expected = sorted((r["id"], e) for r in rows for e in ("collision", "nmac") if r[f"m_{e}"])
    assert len(expected) >= 2
    assert sorted((lab["id"], lab["event"]) for lab in labels) == expected
    assert all(lab["horizon_s"] >= 12.0 and np.isfinite(lab["best_margin_m"]) for lab in labels)
    assert read_labels(tmp_path).num_rows == len(labels)

    def fail(*args, **kwargs):
        raise AssertionError("labelled twice")

    monkeypatch.setattr(labels_module, "label_event", fail)
    assert label_campaign(worker, table, tmp_path).num_rows == len(labels)


def test_manned_rows_are_not_labelled(tmp_path):
    row = {name: None for name in SCHEMA.names}
    row.update({"id": 0, "traffic": "rotorcraft", "m_collision": True, "m_nmac": True})
    table = pa.Table.from_pylist([row], schema=SCHEMA)
    assert label_campaign(None, table, tmp_path).num_rows == 0
    assert read_labels(tmp_path).schema == LABEL_SCHEMA
