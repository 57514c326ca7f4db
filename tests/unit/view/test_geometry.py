"""The operator's view geometry: frames, attitude, threat tubes, prism walls (issue 14)."""

import math

import numpy as np
from hypothesis import given
from hypothesis import strategies as st
from scipy.spatial.transform import Rotation

from companion.view import geometry as scene

finite = st.floats(-1e4, 1e4, allow_nan=False)
angle = st.floats(-math.pi, math.pi, allow_nan=False)


@given(st.lists(st.tuples(finite, finite, finite), min_size=1, max_size=20))
def test_enu_is_ned_with_north_east_swapped_and_down_flipped(points):
    ned = np.array(points)
    enu = scene.enu_from_ned(ned)
    np.testing.assert_allclose(enu, np.column_stack([ned[:, 1], ned[:, 0], -ned[:, 2]]))
    np.testing.assert_allclose(np.linalg.norm(enu, axis=1), np.linalg.norm(ned, axis=1))


@given(angle, st.floats(-1.2, 1.2), angle)
def test_the_body_forward_axis_points_where_the_attitude_says(roll, pitch, yaw):
    x, y, z, w = scene.flu_quaternion_enu((roll, pitch, yaw))
    forward_enu = Rotation.from_quat([x, y, z, w]).apply([1.0, 0.0, 0.0])
    forward_ned = [math.cos(pitch) * math.cos(yaw), math.cos(pitch) * math.sin(yaw), -math.sin(pitch)]
    np.testing.assert_allclose(forward_enu, scene.enu_from_ned(forward_ned), atol=1e-9)
    up_enu = Rotation.from_quat([x, y, z, w]).apply([0.0, 0.0, 1.0])
    assert abs(float(np.dot(up_enu, forward_enu))) < 1e-9
    if abs(roll) < 1.0 and abs(pitch) < 1.0:
        assert up_enu[2] > 0  # the rotor points up when nearly level


@given(
    st.tuples(finite, finite, finite),
    st.tuples(*[st.floats(-20, 20)] * 3),
    st.floats(0.5, 10),
    st.floats(0, 30),
    st.floats(0, 1),
)
def test_a_tube_follows_the_constant_velocity_prediction(pos, vel, radius, age, growth):
    pos, vel = np.array(pos), np.array(vel)
    centres, radii = scene.threat_tube(pos, vel, radius, age, 10.0, 2.5, growth)
    if np.linalg.norm(vel) <= 1e-6:
        assert centres.shape == (1, 3) and radii.tolist() == [radius]
        return
    ages = age + np.arange(0.0, 10.0 + 1e-9, 2.5)
    np.testing.assert_allclose(centres, pos + ages[:, None] * vel, atol=1e-9)
    np.testing.assert_allclose(radii, radius + growth * ages)
    assert np.all(np.diff(radii) >= 0)


@given(st.lists(st.tuples(finite, finite), min_size=3, max_size=12), st.floats(-50, 0), st.floats(0.1, 80))
def test_prism_walls_are_two_triangles_per_edge_between_bottom_and_top(vertices, bottom, height):
    walls = scene.prism_side_triangles(vertices, bottom, bottom + height)
    assert walls.shape == (6 * len(vertices), 3)
    assert set(np.round(walls[:, 2], 9)) <= {round(bottom, 9), round(bottom + height, 9)}
    east_north = {(round(e, 6), round(n, 6)) for n, e in vertices}
    assert {(round(e, 6), round(n, 6)) for e, n in walls[:, :2]} == east_north
