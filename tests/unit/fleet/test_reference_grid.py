"""The published trajectory: sliced from a grid evaluated once per reference."""

import numpy as np
from hypothesis import given, settings
from hypothesis import strategies as st

from companion.fleet.link import ReferenceGrid, sample_reference
from companion.fleet.settings import FleetSettings


class Line:
    """A straight trajectory at 2 m/s along north for ``duration_s``; counts its evaluations."""

    def __init__(self, duration_s: float) -> None:
        self.duration_s = duration_s
        self.calls = 0

    def sample(self, tau):
        self.calls += 1
        tau = np.asarray(tau, float)
        pos = np.stack([2.0 * tau, np.zeros_like(tau), -10.0 * np.ones_like(tau)], axis=-1)
        return pos, None, None


class Ref:
    def __init__(self, trajectory, t0_s):
        self.trajectory, self.t0_s, self.path_id = trajectory, t0_s, "p"


@settings(max_examples=200, deadline=None)
@given(st.floats(0.1, 90.0), st.floats(-20.0, 200.0), st.floats(-50.0, 150.0))
def test_slices_are_the_trajectory_at_their_times(duration_s, t0_s, now_s):
    fleet = FleetSettings()
    ref = Ref(Line(duration_s), t0_s)
    path = sample_reference(ref, now_s, fleet)
    times = path.times_s
    assert times[0] <= now_s < times[0] + fleet.sample_step_s + 1e-9
    k = np.clip(np.round((times - t0_s) / fleet.sample_step_s), 0, np.ceil(duration_s / fleet.sample_step_s))
    on_grid = np.minimum(k * fleet.sample_step_s, duration_s)
    np.testing.assert_allclose(path.ned_m[:, 0], 2.0 * on_grid, atol=1e-9)
    # the horizon is covered unless the trajectory ends first (then its end point is the last)
    assert (
        times[-1] >= min(now_s + fleet.horizon_s - fleet.sample_step_s, t0_s + duration_s) - 1e-9
        or path.ned_m[-1, 0] == 2.0 * duration_s
    )
    assert len(path.ned_m) <= fleet.horizon_s / fleet.sample_step_s + 1


def test_the_grid_is_evaluated_once_per_reference():
    fleet, line = FleetSettings(), Line(40.0)
    grid = ReferenceGrid(fleet.sample_step_s)
    for now in np.arange(0.0, 40.0, 0.5):
        sample_reference(Ref(line, 3.0), float(now), fleet, grid=grid)
    assert line.calls == 1
    sample_reference(Ref(line, 4.0), 10.0, fleet, grid=grid)  # the same path started later
    assert line.calls == 2
