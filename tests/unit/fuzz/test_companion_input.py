"""Property-based fuzz of the companion's MAVLink input: the telemetry watchers of ``VehicleLink``.

What passes the gate (``companion.link.gate``, fuzzed in ``test_gate_input.py``) reaches the
companion's watchers as field dicts (``tapped_fields``); this fuzzes the companion's own parsing
of them: each watcher of :class:`~companion.link.watchers.TelemetryWatchers` (``VehicleLink.watchers``:
HEARTBEAT, LOCAL_POSITION_NED, ATTITUDE, GLOBAL_POSITION_INT, EXTENDED_SYS_STATE, GPS_GLOBAL_ORIGIN,
HOME_POSITION, STATUSTEXT, SYS_STATUS, RPM) runs on its own event loop, fed by a stand-in
subscription with hypothesis field dicts:
fields missing, NaN, infinite, out of range, from the vehicle or from another system.

Properties: nothing raises out of a watcher's ``apply`` (a raise would be caught by
``_guarded``, logged, and the subscription restarted after 0.5 s, losing what arrives
meanwhile); the telemetry snapshot stays finite (positions, velocities, attitude, home, origin).

The fuzz found both broken at first (NaN stored as it came; a null field raised out of
``apply``); the reproducers stay below as fixed cases. A message whose fields are null or not
finite is now dropped whole (``companion.link.telemetry.finite_fields``).
"""

from __future__ import annotations

import asyncio
import collections
import logging
import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from pymavlink.dialects.v20 import ardupilotmega as mavlink

from companion.link.session import LinkSession
from companion.link.watchers import TelemetryWatchers

VEHICLE = 1

#: MavlinkDirect watchers: message name -> the watcher coroutine's name.
DIRECT = {
    "HEARTBEAT": "_watch_heartbeat",
    "LOCAL_POSITION_NED": "_watch_local_position",
    "EXTENDED_SYS_STATE": "_watch_landed_state",
    "GPS_GLOBAL_ORIGIN": "_watch_origin",
    "HOME_POSITION": "_watch_home",
    "STATUSTEXT": "_watch_statustext",
    "SYS_STATUS": "_watch_sys_status",
    "RPM": "_watch_rpm",
    "ATTITUDE": "_watch_attitude",
    "GLOBAL_POSITION_INT": "_watch_global_position",
}


class Failures(logging.Handler):
    """Records the watchers' "subscription failed" reports."""

    def __init__(self) -> None:
        super().__init__(logging.ERROR)
        self.records: list[logging.LogRecord] = []

    def emit(self, record: logging.LogRecord) -> None:
        self.records.append(record)


class FakeSubscriptions:
    """Stands in for the link's messages in (a ``MessageSource``): one queue per subscription.

    A subscription yields its queue and then waits; ``drained`` is set when every queue is empty
    and each watcher has asked for its next value (so it has applied the previous one).
    """

    def __init__(self) -> None:
        self.queues: dict[str, collections.deque] = collections.defaultdict(collections.deque)
        self.waiting: set[str] = set()
        self.wake = asyncio.Event()

    async def _source(self, name: str):
        while True:
            queue = self.queues[name]
            if not queue:
                self.waiting.add(name)
                self.wake.clear()
                await self.wake.wait()
                continue
            self.waiting.discard(name)
            yield queue.popleft()

    def messages(self, name: str):
        return self._source(name)


async def drive(inputs: list[tuple[str, object]]) -> tuple[TelemetryWatchers, list[logging.LogRecord]]:
    """Run every watcher of fresh link watchers on ``inputs`` ((subscription, value) pairs, in order)."""
    subs = FakeSubscriptions()
    watchers = TelemetryWatchers(LinkSession(), subs, lambda: None)
    names = list(DIRECT.values())
    failures = Failures()
    logger = logging.getLogger("companion.link")  # the watchers and every other part of the link
    logger.addHandler(failures)
    tasks = [asyncio.get_running_loop().create_task(getattr(watchers, name)()) for name in names]
    try:
        for sub, value in inputs:
            subs.queues[sub].append(value)
            subs.wake.set()
            for _ in range(100):  # until every subscription is waiting again (a restart takes 0.5 s)
                await asyncio.sleep(0)
                if not any(subs.queues.values()) and len(subs.waiting) == len(DIRECT):
                    break
            else:
                await asyncio.sleep(0.6)
    finally:
        for task in tasks:
            task.cancel()
        await asyncio.gather(*tasks, return_exceptions=True)
        logger.removeHandler(failures)
    return watchers, failures.records


# ================================================================ strategies
F32 = st.one_of(st.floats(width=32), st.sampled_from([math.nan, math.inf, -math.inf, 3.4e38, -3.4e38, 0.0]))
NUMBER_OR_NAN_AS_NULL = st.one_of(F32, st.none())  # a JSON encoder may write NaN as null


def field_values(ftype: str, nullable: bool):
    if ftype == "char":
        return st.text(max_size=60)
    if ftype in ("float", "double"):
        return NUMBER_OR_NAN_AS_NULL if nullable else F32
    bits = {
        "int8_t": 8,
        "uint8_t": 8,
        "int16_t": 16,
        "uint16_t": 16,
        "int32_t": 32,
        "uint32_t": 32,
        "int64_t": 64,
        "uint64_t": 64,
    }[ftype.replace("_mavlink_version", "")]
    signed = not ftype.startswith("u")
    lo, hi = (-(2 ** (bits - 1)), 2 ** (bits - 1) - 1) if signed else (0, 2**bits - 1)
    return st.integers(lo, hi)


def fields_dicts(name: str, nullable: bool = False):
    """JSON field dicts as MavlinkDirect gives them for message ``name``: typed values (a NaN written
    as null with ``nullable``), any field possibly missing, from the vehicle (mostly) or another system."""
    cls = mavlink.mavlink_map[getattr(mavlink, f"MAVLINK_MSG_ID_{name}")]
    types = dict(zip(cls.ordered_fieldnames, cls.fieldtypes))
    values = {}
    for field in cls.fieldnames:
        ftype = types[field]
        strategy = field_values(ftype, nullable)
        if field in cls.array_lengths and ftype != "char":
            strategy = st.lists(strategy, min_size=cls.array_lengths[field], max_size=cls.array_lengths[field])
        values[field] = strategy
    header = {
        "_sysid": st.sampled_from([VEHICLE] * 4 + [2, 255]),
        "_compid": st.sampled_from([1] * 4 + [0, 190]),
        "_t_s": st.floats(0, 1e6),
    }
    return st.fixed_dictionaries(header, optional=values)


def inputs(nullable: bool = False):
    return st.lists(
        st.one_of(*[st.tuples(st.just(name), fields_dicts(name, nullable)) for name in DIRECT]), min_size=1, max_size=15
    )


def finite_telemetry(watchers: TelemetryWatchers) -> list[str]:
    """Names of the telemetry values that are not finite."""
    t = watchers.state.snapshot(0.0)
    bad = []
    for name in (
        "pos_ned_m",
        "vel_ned_m_s",
        "attitude_rad",
        "lat_deg",
        "lon_deg",
        "alt_amsl_m",
        "rel_alt_m",
        "home_lla",
        "origin_lla",
        "boot_s",
        "rotor_rpm",
    ):
        value = getattr(t, name)
        if value is not None and not np.all(np.isfinite(np.asarray(value, dtype=float))):
            bad.append(f"{name}={value!r}")
    return bad


# ================================================================ the properties
@settings(max_examples=60, deadline=None)
@given(received=inputs())
def test_watchers_never_raise_on_typed_fields(received):
    """Typed values (what MAVSDK decodes from a frame), NaN and infinities included: no watcher raises."""
    watchers, failures = asyncio.run(drive(received))
    assert not failures, [r.getMessage() for r in failures]
    assert watchers.state.values.get("mode") is None or isinstance(watchers.state.values["mode"], int)


@settings(max_examples=60, deadline=None)
@given(received=inputs())
def test_telemetry_stays_finite(received):
    watchers, _ = asyncio.run(drive(received))
    assert not finite_telemetry(watchers)


@pytest.mark.parametrize(
    "sub, value",
    [
        (
            "LOCAL_POSITION_NED",
            {
                "_sysid": VEHICLE,
                "_compid": 1,
                "x": math.nan,
                "y": 0.0,
                "z": -10.0,
                "vx": 0.0,
                "vy": 0.0,
                "vz": 0.0,
                "time_boot_ms": 1000,
            },
        ),
        (
            "LOCAL_POSITION_NED",
            {
                "_sysid": VEHICLE,
                "_compid": 1,
                "x": 0.0,
                "y": 0.0,
                "z": -10.0,
                "vx": math.inf,
                "vy": 0.0,
                "vz": 0.0,
                "time_boot_ms": 1000,
            },
        ),
        ("ATTITUDE", {"_sysid": VEHICLE, "_compid": 1, "roll": 0.0, "pitch": 0.0, "yaw": math.nan}),
        (
            "GLOBAL_POSITION_INT",
            {
                "_sysid": VEHICLE,
                "_compid": 1,
                "lat": 473977420,
                "lon": 85455940,
                "alt": math.inf,
                "relative_alt": 10000,
            },
        ),
        ("RPM", {"_sysid": VEHICLE, "_compid": 1, "rpm1": math.inf, "rpm2": 0.0}),
    ],
)
def test_reproducers_non_finite_telemetry(sub, value):
    watchers, failures = asyncio.run(drive([(sub, value)]))
    assert not failures
    assert not finite_telemetry(watchers)


@pytest.mark.parametrize(
    "sub, value",
    [
        ("EXTENDED_SYS_STATE", {"_sysid": VEHICLE, "_compid": 1, "landed_state": None, "vtol_state": 0}),
        (
            "LOCAL_POSITION_NED",
            {
                "_sysid": VEHICLE,
                "_compid": 1,
                "x": 0.0,
                "y": 0.0,
                "z": -10.0,
                "vx": 0.0,
                "vy": 0.0,
                "vz": 0.0,
                "time_boot_ms": None,
            },
        ),
        ("HEARTBEAT", {"_sysid": VEHICLE, "_compid": 1, "base_mode": None, "custom_mode": 4}),
        ("RPM", {"_sysid": VEHICLE, "_compid": 1, "rpm1": None, "rpm2": 0.0}),
    ],
)
def test_reproducers_null_fields_raise(sub, value):
    """Found by hypothesis with ``inputs(nullable=True)``; kept as fixed cases (each costs a 0.5 s restart)."""
    watchers, failures = asyncio.run(drive([(sub, value)]))
    assert not failures, [r.getMessage() for r in failures]


def test_foreign_systems_do_not_touch_the_telemetry():
    """Frames from another system id (MAVSDK passes them on) leave the vehicle's telemetry alone."""
    foreign = [
        (
            "LOCAL_POSITION_NED",
            {
                "_sysid": 42,
                "_compid": 1,
                "x": math.nan,
                "y": 1.0,
                "z": 2.0,
                "vx": 0.0,
                "vy": 0.0,
                "vz": 0.0,
                "time_boot_ms": 5,
            },
        ),
        ("HEARTBEAT", {"_sysid": 42, "_compid": 1, "base_mode": 129, "custom_mode": 9}),
        ("HOME_POSITION", {"_sysid": 42, "_compid": 1, "latitude": 10, "longitude": 10, "altitude": 0}),
        ("EXTENDED_SYS_STATE", {"_sysid": 42, "_compid": 1, "landed_state": 2}),
    ]
    watchers, failures = asyncio.run(drive(foreign))
    assert not failures
    assert watchers.state.pos_origin is None and watchers.state.values == {}
