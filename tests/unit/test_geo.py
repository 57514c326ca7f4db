"""companion.geo: LocalFrame round trips, known offsets and validation."""

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from companion.geo import GeoError, LocalFrame, check_lat_lon

HOME = (47.397742, 8.545594, 488.0)


def test_origin_maps_to_zero():
    frame = LocalFrame(*HOME)
    n, e, d = frame.to_ned(*HOME)
    assert np.allclose([n, e, d], 0.0, atol=1e-6)


def test_altitude_above_origin_is_negative_down():
    frame = LocalFrame(*HOME)
    _, _, d = frame.to_ned(HOME[0], HOME[1], HOME[2] + 25.0)
    assert d == pytest.approx(-25.0, abs=1e-6)


def test_one_millidegree_north_is_about_111_m():
    frame = LocalFrame(*HOME)
    n, e, _ = frame.to_ned(HOME[0] + 1e-3, HOME[1], HOME[2])
    assert n == pytest.approx(111.2, abs=0.3)
    assert abs(float(e)) < 1e-3


def test_vectorised_shapes():
    frame = LocalFrame(*HOME)
    ned = np.array([[0.0, 0.0, 0.0], [10.0, -5.0, -3.0], [100.0, 100.0, -50.0]])
    lla = frame.to_lla_array(ned)
    assert lla.shape == (3, 3)
    assert np.allclose(frame.to_ned_array(lla), ned, atol=1e-6)


@settings(deadline=None, max_examples=40)
@given(st.floats(-2000, 2000), st.floats(-2000, 2000), st.floats(-500, 100), st.floats(-80, 80), st.floats(-179, 179))
def test_round_trip_ned_lla_ned(n, e, d, lat0, lon0):
    frame = LocalFrame(lat0, lon0, 100.0)
    lat, lon, alt = frame.to_lla(n, e, d)
    back = frame.to_ned(lat, lon, alt)
    assert np.allclose(back, [n, e, d], atol=1e-5)


@pytest.mark.parametrize(
    "lat, lon, word",
    [(91.0, 0.0, "latitude"), (-90.5, 0.0, "latitude"), (0.0, 181.0, "longitude"), (float("nan"), 0.0, "latitude")],
)
def test_out_of_range_is_named(lat, lon, word):
    with pytest.raises(GeoError, match=word):
        check_lat_lon(lat, lon, what="test point")
    frame = LocalFrame(*HOME)
    with pytest.raises(GeoError, match=word):
        frame.to_ned(lat, lon, 0.0)


def test_bad_origin_is_rejected():
    with pytest.raises(GeoError, match="frame origin: latitude"):
        LocalFrame(95.0, 0.0, 0.0)
    with pytest.raises(GeoError, match="alt0_m"):
        LocalFrame(0.0, 0.0, float("inf"))


def test_non_finite_ned_is_rejected():
    with pytest.raises(GeoError, match="down_m"):
        LocalFrame(*HOME).to_lla(0.0, 0.0, float("nan"))
