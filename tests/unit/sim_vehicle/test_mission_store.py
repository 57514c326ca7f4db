"""Mission store: atomic replacement, refused items, interrupted uploads keep the old list."""

from __future__ import annotations

import dataclasses

from sim_vehicle.mission_store import (
    MISSION_TYPE_ALL,
    MISSION_TYPE_FENCE,
    MISSION_TYPE_MISSION,
    MISSION_TYPE_RALLY,
    MissionItem,
    MissionResult,
    MissionStore,
)


def make_item(
    seq: int, mission_type: int = MISSION_TYPE_MISSION, z: float = 20.0, frame: int = 6, command: int = 16
) -> MissionItem:
    return MissionItem(
        seq=seq,
        frame=frame,
        command=command,
        current=0,
        autocontinue=1,
        param1=0.0,
        param2=2.0,
        param3=0.0,
        param4=float("nan"),
        x=473977420 + 100 * seq,
        y=85455940 + 100 * seq,
        z=z,
        mission_type=mission_type,
    )


def upload(store: MissionStore, items: list[MissionItem], now_s: float = 0.0) -> bool:
    assert store.begin_upload(items[0].mission_type, len(items), now_s) == MissionResult.ACCEPTED
    complete = False
    for item in items:
        result, complete = store.receive_item(item, now_s)
        assert result == MissionResult.ACCEPTED
    return complete


def test_complete_upload_replaces_list_exactly():
    store = MissionStore()
    items = [make_item(i) for i in range(5)]
    assert upload(store, items)
    assert store.items() == tuple(items)
    assert store.generation() == 1


def test_interrupted_upload_keeps_old_mission():
    store = MissionStore(upload_timeout_s=5.0)
    old = [make_item(i) for i in range(5)]
    upload(store, old)
    new = [make_item(i, z=50.0) for i in range(4)]
    assert store.begin_upload(MISSION_TYPE_MISSION, 4, 10.0) == MissionResult.ACCEPTED
    store.receive_item(new[0], 10.0)
    store.receive_item(new[1], 10.5)
    assert store.items() == tuple(old)  # nothing replaced mid-upload
    expired = store.expire_uploads(16.0)  # the sender went silent
    assert [u.count for u in expired] == [4]
    assert store.items() == tuple(old)
    assert store.upload_in_progress(MISSION_TYPE_MISSION) is None
    result, complete = store.receive_item(new[2], 16.1)  # a late item is refused
    assert result == MissionResult.DENIED and not complete
    assert store.items() == tuple(old)


def test_out_of_order_and_past_count_items_are_refused_without_damage():
    store = MissionStore()
    old = [make_item(i) for i in range(3)]
    upload(store, old)
    store.begin_upload(MISSION_TYPE_MISSION, 2, 0.0)
    assert store.receive_item(make_item(1), 0.0) == (MissionResult.INVALID_SEQUENCE, False)
    assert store.receive_item(make_item(0), 0.0) == (MissionResult.ACCEPTED, False)
    assert store.receive_item(make_item(5), 0.0) == (MissionResult.INVALID_SEQUENCE, False)
    assert store.items() == tuple(old)
    assert store.receive_item(make_item(1), 0.0) == (MissionResult.ACCEPTED, True)
    assert len(store.items()) == 2
    # after completion, an item past the count belongs to no upload
    assert store.receive_item(make_item(2), 0.0)[0] == MissionResult.DENIED


def test_duplicate_of_last_item_is_harmless():
    store = MissionStore()
    store.begin_upload(MISSION_TYPE_MISSION, 3, 0.0)
    store.receive_item(make_item(0), 0.0)
    assert store.receive_item(make_item(0), 0.0) == (MissionResult.ACCEPTED, False)
    store.receive_item(make_item(1), 0.0)
    assert store.receive_item(make_item(2), 0.0) == (MissionResult.ACCEPTED, True)
    assert [it.seq for it in store.items()] == [0, 1, 2]


def test_invalid_item_aborts_upload_and_keeps_old_list():
    store = MissionStore()
    old = [make_item(i) for i in range(2)]
    upload(store, old)
    store.begin_upload(MISSION_TYPE_MISSION, 2, 0.0)
    store.receive_item(make_item(0), 0.0)
    bad_frame = make_item(1, frame=99)
    assert store.receive_item(bad_frame, 0.0) == (MissionResult.UNSUPPORTED_FRAME, False)
    assert store.items() == tuple(old)
    store.begin_upload(MISSION_TYPE_MISSION, 1, 0.0)
    bad_z = make_item(0, z=float("inf"))
    assert store.receive_item(bad_z, 0.0)[0] == MissionResult.INVALID_PARAM7
    bad_lat = dataclasses.replace(make_item(0), x=950_000_000)
    store.begin_upload(MISSION_TYPE_MISSION, 1, 0.0)
    assert store.receive_item(bad_lat, 0.0)[0] == MissionResult.INVALID_PARAM5_X
    assert store.items() == tuple(old)


def test_restarted_upload_drops_partial_one():
    store = MissionStore()
    old = [make_item(i) for i in range(2)]
    upload(store, old)
    store.begin_upload(MISSION_TYPE_MISSION, 3, 0.0)
    store.receive_item(make_item(0, z=99.0), 0.0)
    new = [make_item(i, z=30.0) for i in range(2)]
    assert upload(store, new)
    assert store.items() == tuple(new)


def test_lists_are_independent_and_clear_all():
    store = MissionStore()
    mission = [make_item(i) for i in range(3)]
    fence = [make_item(i, MISSION_TYPE_FENCE, command=5001) for i in range(4)]
    rally = [make_item(i, MISSION_TYPE_RALLY, command=5100) for i in range(2)]
    for items in (mission, fence, rally):
        upload(store, items)
    assert store.items(MISSION_TYPE_FENCE) == tuple(fence)
    assert store.items(MISSION_TYPE_RALLY) == tuple(rally)
    assert store.clear(MISSION_TYPE_FENCE) == MissionResult.ACCEPTED
    assert store.items(MISSION_TYPE_FENCE) == () and store.items() == tuple(mission)
    store.clear(MISSION_TYPE_ALL)
    assert store.items() == () and store.items(MISSION_TYPE_RALLY) == ()
    assert store.begin_upload(7, 1, 0.0) == MissionResult.UNSUPPORTED


def test_count_zero_clears_and_too_many_is_no_space():
    store = MissionStore()
    upload(store, [make_item(0)])
    assert store.begin_upload(MISSION_TYPE_MISSION, 100000, 0.0) == MissionResult.NO_SPACE
    assert len(store.items()) == 1
    assert store.begin_upload(MISSION_TYPE_MISSION, 0, 0.0) == MissionResult.ACCEPTED
    assert store.items() == ()
