"""companion.link.frames: the home frame against the vehicle's EKF-origin frame."""

from __future__ import annotations

import numpy as np
from hypothesis import given, settings
from hypothesis import strategies as st

from companion.geo import LocalFrame
from companion.link.frames import LinkFrames

ORIGIN = (47.397742, 8.545594, 488.1)


def test_without_an_origin_the_frames_coincide():
    frames = LinkFrames.build((47.3978, 8.5456, 490.0))
    assert frames.origin_lla is None and frames.offset_m == 0.0
    assert np.array_equal(frames.to_home([1.0, 2.0, -3.0]), [1.0, 2.0, -3.0])
    assert np.array_equal(LinkFrames().to_origin([1.0, 2.0, -3.0]), [1.0, 2.0, -3.0])


def test_a_moved_home_is_a_translation_of_its_position_in_the_origin_frame():
    home = tuple(float(v) for v in LocalFrame(*ORIGIN).to_lla(10.0, -6.0, -1.5))
    frames = LinkFrames.build(home, ORIGIN)
    assert np.allclose(frames.home_in_origin_ned_m, [10.0, -6.0, -1.5], atol=1e-6)
    # the vehicle sitting on the EKF origin is 10 m south, 6 m east and 1.5 m below home
    assert np.allclose(frames.to_home([0.0, 0.0, 0.0]), [-10.0, 6.0, 1.5], atol=1e-6)
    # a setpoint at home goes to the vehicle as home's position in its own frame
    assert np.allclose(frames.to_origin([0.0, 0.0, -15.0]), [10.0, -6.0, -16.5], atol=1e-6)


@settings(max_examples=50, deadline=None)
@given(
    st.floats(-200, 200),
    st.floats(-200, 200),
    st.floats(-20, 20),
    st.lists(st.floats(-500, 500), min_size=3, max_size=3),
)
def test_to_home_and_to_origin_are_inverse(n, e, up, point):
    home = tuple(float(v) for v in LocalFrame(*ORIGIN).to_lla(n, e, -up))
    frames = LinkFrames.build(home, ORIGIN)
    p = np.array(point)
    assert np.allclose(frames.to_origin(frames.to_home(p)), p, atol=1e-9)
    batch = np.stack([p, p + 1.0])
    assert frames.to_home(batch).shape == (2, 3)


def test_positions_in_both_frames_name_the_same_place():
    """A point given in the origin frame and converted is where geodesy about home puts it."""
    home = tuple(float(v) for v in LocalFrame(*ORIGIN).to_lla(40.0, 25.0, -3.0))
    frames = LinkFrames.build(home, ORIGIN)
    lla = LocalFrame(*ORIGIN).to_lla(70.0, -10.0, -20.0)
    about_home = np.array(LocalFrame(*home).to_ned(*lla), dtype=float)
    assert np.allclose(frames.to_home([70.0, -10.0, -20.0]), about_home, atol=2e-3)
