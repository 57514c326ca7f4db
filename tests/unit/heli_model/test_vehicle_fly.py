"""``VehicleUpdate.fly``: several control periods in one call give ``update``'s loop to the bit."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from heli_model.control import Setpoint
from heli_model.model import HeliModel
from heli_model.vehicle_update import VehicleCommand, VehicleUpdate


@pytest.fixture(scope="module")
def update():
    return VehicleUpdate.build(HeliModel.default())


def _loop(update, state, command, dt_s, periods):
    for _ in range(periods):
        state = update.update(state, command, dt_s)
    return state


def _same(a, b) -> bool:
    fields = zip(a.controller, b.controller)
    return (
        np.array_equal(a.x, b.x)
        and np.array_equal(a.delta, b.delta)
        and all(np.array_equal(f, g) if isinstance(f, np.ndarray) else f == g for f, g in fields)
    )


coord = st.floats(-80.0, 80.0)
vec = st.tuples(coord, coord, coord).map(np.array)
maybe = lambda s: st.one_of(st.none(), s)  # noqa: E731


@settings(max_examples=120, deadline=None)
@given(
    start=st.tuples(coord, coord, st.floats(-40.0, -2.0)),
    warm=st.integers(0, 20),
    pos=maybe(vec),
    vel=maybe(st.tuples(*[st.floats(-8, 8)] * 3).map(np.array)),
    acc=maybe(st.tuples(*[st.floats(-3, 3)] * 3).map(np.array)),
    yaw=maybe(st.floats(-4, 4)),
    rate=maybe(st.floats(-1, 1)),
    periods=st.integers(1, 4),
)
def test_fly_is_the_loop_of_updates_to_the_bit(update, start, warm, pos, vel, acc, yaw, rate, periods):
    state = update.hover_state(start, 0.3)
    for _ in range(warm):
        state = update.update(state, VehicleCommand(Setpoint(np.array([10.0, -5.0, -20.0]))), 0.01)
    command = VehicleCommand(Setpoint(pos, vel, acc, yaw, rate))
    assert _same(update.fly(state, command, 0.01, periods), _loop(update, state, command, 0.01, periods))


@pytest.mark.parametrize(
    "command, dt_s",
    [
        (VehicleCommand(Setpoint(np.array([5.0, 0.0, -10.0])), wind_ned_m_s=np.array([3.0, 1.0, 0.0])), 0.01),
        (VehicleCommand(None), 0.01),
        (VehicleCommand(Setpoint(np.array([5.0, 0.0, -10.0]))), 0.005),
        (VehicleCommand(Setpoint([5.0, 0.0, -10.0])), 0.01),
    ],
)
def test_fly_falls_back_to_the_loop_where_the_kernel_does_not_apply(update, command, dt_s):
    state = update.hover_state((0.0, 0.0, -10.0), 0.0)
    assert _same(update.fly(state, command, dt_s, 3), _loop(update, state, command, dt_s, 3))


def test_fly_raises_as_update_does(update):
    state = update.hover_state((0.0, 0.0, -10.0), 0.0)
    command = VehicleCommand(Setpoint(np.array([5.0, 0.0, -10.0])))
    with pytest.raises(Exception, match="dt_s") as loop_error:
        update.update(state, command, 0.5)
    with pytest.raises(type(loop_error.value), match="dt_s"):
        update.fly(state, command, 0.5, 2)
