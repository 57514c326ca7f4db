"""The sampling of the flown references is bit-identical to its original implementation.

``Trajectory``, ``TrajectoryChain`` and ``RetimedTrajectory`` (and the Bezier and profile
maths under them) were sped up for the fast-time Monte-Carlo; a faster sampling must not move
a single bit of a single setpoint. This module keeps a frozen copy of the original sampling
code (``_Ref*``, working on the same objects' data) and asserts ``==`` equality of positions,
velocities, accelerations, yaws and yaw rates: for scalar times, 1-point and 76-point arrays
(the executor's setpoint and a 15 s horizon at 0.2 s), times outside [0, duration], chains of
1 to 3 pieces and retimes nested 1 to 4 deep.
"""

from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from companion.flight.plan import TrajectoryChain
from companion.flight.trajectory import Trajectory
from companion.smoothing import TrajectoryLimits, smooth_g1, smooth_g2, time_parameterize
from companion.smoothing.bezier_arclength import TABLE_INTERVALS, arc_derivatives, locate
from companion.smoothing.bezier_maths import bernstein
from companion.threats.decision.retime import RetimedTrajectory

# ---------------------------------------------------------------------------- frozen reference
# A verbatim copy of the sampling code before it was sped up (numerical operations in their
# original order); only the attribute access is adapted to free functions.


def _ref_bernstein(n: int, u: np.ndarray) -> np.ndarray:
    u = np.asarray(u, dtype=float).reshape(-1)
    v = 1.0 - u
    up = np.empty((u.size, n + 1))
    vp = np.empty((u.size, n + 1))
    up[:, 0] = 1.0
    vp[:, 0] = 1.0
    for i in range(1, n + 1):
        np.multiply(up[:, i - 1], u, out=up[:, i])
        np.multiply(vp[:, i - 1], v, out=vp[:, i])
    return np.array([math.comb(n, i) for i in range(n + 1)], dtype=float) * up * vp[:, ::-1]


def _ref_hermite_quintic(x, m0, m1, c0, c1):
    x2 = x * x
    x3 = x2 * x
    x4 = x3 * x
    x5 = x4 * x
    return (
        (x - 6 * x3 + 8 * x4 - 3 * x5) * m0
        + (0.5 * x2 - 1.5 * x3 + 1.5 * x4 - 0.5 * x5) * c0
        + (0.5 * x3 - x4 + 0.5 * x5) * c1
        + (-4 * x3 + 7 * x4 - 3 * x5) * m1
        + (10 * x3 - 15 * x4 + 6 * x5)
    )


def _ref_hermite_args(table, j):
    knot = j + j // TABLE_INTERVALS
    h = table.h[j]
    hh = h * (TABLE_INTERVALS * h)
    return h * table.u_s[knot], h * table.u_s[knot + 1], hh * table.u_ss[knot], hh * table.u_ss[knot + 1]


def _ref_locate(table, s_m):
    s = np.clip(s_m, 0.0, table.piece_start_s[-1])
    j = np.clip(np.searchsorted(table.s_lo, s, side="right") - 1, 0, table.s_lo.size - 1)
    x = np.clip((s - table.s_lo[j]) / np.maximum(table.h[j], 1e-300), 0.0, 1.0)
    frac = _ref_hermite_quintic(x, *_ref_hermite_args(table, j))
    piece, k = np.divmod(j, TABLE_INTERVALS)
    return piece, (k + np.clip(frac, 0.0, 1.0)) / TABLE_INTERVALS


def _ref_arc_derivatives(du):
    out = [du[0]]
    if len(du) == 1:
        return out
    a = du[1]
    sig2 = np.maximum(np.sum(a * a, axis=1, keepdims=True), 1e-300)
    sig = np.sqrt(sig2)
    out.append(a / sig)
    if len(du) == 2:
        return out
    b = du[2]
    g = np.sum(a * b, axis=1, keepdims=True)
    out.append(b / sig2 - g * a / sig2**2)
    if len(du) == 3:
        return out
    c = du[3]
    gp = np.sum(b * b, axis=1, keepdims=True) + np.sum(a * c, axis=1, keepdims=True)
    dk_du = c / sig2 - 3.0 * g * b / sig2**2 - gp * a / sig2**2 + 4.0 * g**2 * a / sig2**3
    out.append(dk_du / sig)
    return out


def _ref_piece_derivative(curve, piece, u, order):
    hod = curve._hodograph(order)
    basis = _ref_bernstein(hod.shape[1] - 1, u)
    return np.einsum("kn,knd->kd", basis, hod[piece], optimize=False)


def _ref_curve_locate(curve, s_m):
    return _ref_locate(curve._table, np.asarray(s_m, dtype=float).reshape(-1))


def _ref_curve_arc_derivatives(curve, piece, u, order):
    return _ref_arc_derivatives([_ref_piece_derivative(curve, piece, u, k) for k in range(order + 1)])


def _ref_curve_derivative(curve, s_m, order):
    s = np.asarray(s_m, dtype=float).reshape(-1)
    piece, u = _ref_curve_locate(curve, s)
    return _ref_curve_arc_derivatives(curve, piece, u, order)[order]


def _ref_profile_evaluate(p, tau_s):
    tau = p.tau_s
    k = np.clip(np.searchsorted(tau, tau_s, side="right") - 1, 0, tau.size - 2)
    h = tau_s - tau[k]
    s0, v0, a = p.s_m[k], p.v_m_s[k], p.a_m_s2[k]
    s = s0 + v0 * h + 0.5 * a * h * h
    v = v0 + a * h
    s2 = p._s2[k] + s0 * h + 0.5 * v0 * h * h + a * h**3 / 6.0
    before = tau_s < tau[0]
    if np.any(before):
        hb = tau_s[before] - tau[0]
        vs = p.start_speed_m_s
        s[before] = p.s_m[0] + vs * hb
        v[before] = vs
        s2[before] = p.s_m[0] * hb + 0.5 * vs * hb * hb
    after = tau_s > tau[-1]
    if np.any(after):
        ha = tau_s[after] - tau[-1]
        ve = p.end_speed_m_s
        s[after] = p.s_m[-1] + ve * ha
        v[after] = ve
        s2[after] = p._s2[-1] + p.s_m[-1] * ha + 0.5 * ve * ha * ha
    return s, v, s2


def _ref_profile_filtered(p, tau_s):
    half = 0.5 * p.window_s
    s_hi, v_hi, s2_hi = _ref_profile_evaluate(p, tau_s + half)
    s_lo, v_lo, s2_lo = _ref_profile_evaluate(p, tau_s - half)
    inv = 1.0 / p.window_s
    return (s2_hi - s2_lo) * inv, (s_hi - s_lo) * inv, (v_hi - v_lo) * inv


class _RefTrajectory:
    """The original ``Trajectory`` sampling of ``traj``."""

    def __init__(self, traj: Trajectory) -> None:
        self.traj = traj

    def _check_t(self, t_s):
        arr = np.asarray(t_s, dtype=float)
        assert np.all(np.isfinite(arr))
        return np.clip(arr.reshape(-1), 0.0, self.traj.duration_s), arr.ndim == 0

    def _lift(self, xy, down):
        if self.traj.down_m is None:
            return xy
        col = np.full((xy.shape[0], 1), down)
        return np.hstack([xy, col])

    def _fallback_yaw_table(self):
        tr = self.traj
        n = max(2, int(math.ceil(tr.length_m / 2.0)) + 1)
        s = np.linspace(0.0, tr.length_m, n)
        tangent = _ref_curve_derivative(tr.curve, s, 1)
        horizontal = np.linalg.norm(tangent[:, :2], axis=1) > 1e-6
        yaw = np.arctan2(tangent[:, 1], tangent[:, 0])
        if not np.any(horizontal):
            return s, np.full(n, tr.yaw_hold_rad)
        idx = np.where(horizontal, np.arange(n), -1)
        idx = np.maximum.accumulate(idx)
        first = int(np.argmax(horizontal))
        idx[idx < 0] = first
        return s, yaw[idx]

    def sample(self, t_s):
        tr = self.traj
        t, scalar = self._check_t(t_s)
        s, v, a = _ref_profile_filtered(tr.profile, t + tr._tau_start)
        s = np.clip(s, 0.0, tr.length_m)
        piece, u = _ref_curve_locate(tr.curve, s)
        r, r_s, r_ss = _ref_curve_arc_derivatives(tr.curve, piece, u, 2)
        vv = v[:, None]
        pos = self._lift(r, tr.down_m if tr.down_m is not None else 0.0)
        vel = self._lift(r_s * vv, 0.0)
        acc = self._lift(r_ss * vv * vv + r_s * a[:, None], 0.0)
        if scalar:
            return pos[0], vel[0], acc[0]
        return pos, vel, acc

    def yaw_rad(self, t_s):
        tr = self.traj
        t, scalar = self._check_t(t_s)
        if tr.yaw_mode == "hold":
            out = np.full(t.shape, tr.yaw_hold_rad)
            return out[0] if scalar else out
        s = np.clip(_ref_profile_filtered(tr.profile, t + tr._tau_start)[0], 0.0, tr.length_m)
        tangent = _ref_curve_derivative(tr.curve, s, 1)
        yaw = np.arctan2(tangent[:, 1], tangent[:, 0])
        flat = np.linalg.norm(tangent[:, :2], axis=1) <= 1e-6
        if np.any(flat):
            table_s, table_yaw = self._fallback_yaw_table()
            k = np.clip(np.searchsorted(table_s, s[flat], side="right") - 1, 0, table_yaw.size - 1)
            yaw[flat] = table_yaw[k]
        return yaw[0] if scalar else yaw

    def yaw_rate_rad_s(self, t_s):
        tr = self.traj
        t, scalar = self._check_t(t_s)
        if tr.yaw_mode == "hold":
            out = np.zeros(t.shape)
            return out[0] if scalar else out
        s, v, _ = _ref_profile_filtered(tr.profile, t + tr._tau_start)
        s = np.clip(s, 0.0, tr.length_m)
        piece, u = _ref_curve_locate(tr.curve, s)
        _, r_s, r_ss = _ref_curve_arc_derivatives(tr.curve, piece, u, 2)
        horiz2 = r_s[:, 0] ** 2 + r_s[:, 1] ** 2
        turn = r_s[:, 0] * r_ss[:, 1] - r_s[:, 1] * r_ss[:, 0]
        out = np.where(horiz2 > 1e-12, v * turn / np.maximum(horiz2, 1e-12), 0.0)
        return out[0] if scalar else out


class _RefChain:
    """The original ``TrajectoryChain`` sampling, over reference pieces."""

    def __init__(self, chain: TrajectoryChain) -> None:
        self.pieces = tuple(reference(p) for p in chain.pieces)
        durations = np.array([p.duration_s for p in chain.pieces], dtype=float)
        self.t_start_s = np.concatenate([[0.0], np.cumsum(durations)[:-1]])
        self.duration_s = float(durations.sum())

    def _split(self, t_s):
        t = np.clip(np.atleast_1d(np.asarray(t_s, dtype=float)), 0.0, self.duration_s)
        idx = np.clip(np.searchsorted(self.t_start_s, t, side="right") - 1, 0, len(self.pieces) - 1)
        return t, idx

    def sample(self, t_s):
        t, idx = self._split(t_s)
        pos = np.empty((t.size, 3))
        vel = np.empty((t.size, 3))
        acc = np.empty((t.size, 3))
        for k in np.unique(idx):
            sel = idx == k
            p, v, a = self.pieces[k].sample(t[sel] - self.t_start_s[k])
            pos[sel], vel[sel], acc[sel] = p, v, a
        return pos, vel, acc

    def _per_piece(self, name, t_s):
        t, idx = self._split(t_s)
        out = np.empty(t.size)
        for k in np.unique(idx):
            sel = idx == k
            out[sel] = getattr(self.pieces[k], name)(t[sel] - self.t_start_s[k])
        return out

    def yaw_rad(self, t_s):
        return self._per_piece("yaw_rad", t_s)

    def yaw_rate_rad_s(self, t_s):
        return self._per_piece("yaw_rate_rad_s", t_s)


class _RefRetimed:
    """The original ``RetimedTrajectory`` (duration and sampling) over a reference base."""

    def __init__(self, rt: RetimedTrajectory) -> None:
        self.base = reference(rt.base)
        self.base_duration_s = rt.base.duration_s
        self.tau0_s, self.rate, self.wait_s, self.ramp_s = rt.tau0_s, rt.rate, rt.wait_s, rt.ramp_s
        warp_end = 2.0 * self.ramp_s + self.wait_s
        remaining = self.base_duration_s - self.tau0_s
        tau_warp = self._integral(np.array([warp_end]))[0]
        if tau_warp <= remaining:
            self.duration_s = warp_end + remaining - tau_warp
        else:
            lo, hi = 0.0, warp_end
            for _ in range(50):
                mid = 0.5 * (lo + hi)
                lo, hi = (mid, hi) if self._integral(np.array([mid]))[0] < remaining else (lo, mid)
            self.duration_s = hi
        self.delay_s = self.duration_s - remaining

    def _rate(self, t):
        drop = 1.0 - self.rate
        w = math.pi / self.ramp_s
        t2 = self.ramp_s + self.wait_s
        r = np.ones_like(t)
        dr = np.zeros_like(t)
        down = t < self.ramp_s
        r[down] = 1.0 - drop * 0.5 * (1.0 - np.cos(w * t[down]))
        dr[down] = -drop * 0.5 * w * np.sin(w * t[down])
        hold = (t >= self.ramp_s) & (t < t2)
        r[hold] = self.rate
        up = (t >= t2) & (t < t2 + self.ramp_s)
        x = t[up] - t2
        r[up] = self.rate + drop * 0.5 * (1.0 - np.cos(w * x))
        dr[up] = drop * 0.5 * w * np.sin(w * x)
        return r, dr

    def _integral(self, t):
        drop = 1.0 - self.rate
        w = math.pi / self.ramp_s
        ramp_loss = lambda x: drop * 0.5 * (x - np.sin(w * x) / w)  # noqa: E731
        t1 = np.minimum(t, self.ramp_s)
        loss = ramp_loss(t1)
        t_hold = np.clip(t - self.ramp_s, 0.0, self.wait_s)
        loss = loss + drop * t_hold
        x = np.clip(t - self.ramp_s - self.wait_s, 0.0, self.ramp_s)
        loss = loss + drop * x - ramp_loss(x)
        return t - loss

    def _tau(self, t_s):
        t = np.clip(np.atleast_1d(np.asarray(t_s, dtype=float)), 0.0, self.duration_s)
        r, dr = self._rate(t)
        ended = t >= self.duration_s
        r[ended], dr[ended] = 0.0, 0.0
        return np.minimum(self.tau0_s + self._integral(t), self.base_duration_s), r, dr

    def tau_at(self, t_s):
        return self._tau(t_s)[0]

    def sample(self, t_s):
        tau, r, dr = self._tau(t_s)
        pos, vel, acc = (np.atleast_2d(v) for v in self.base.sample(tau))
        return pos, vel * r[:, None], acc * (r * r)[:, None] + vel * dr[:, None]

    def yaw_rad(self, t_s):
        return self.base.yaw_rad(self._tau(t_s)[0])

    def yaw_rate_rad_s(self, t_s):
        tau, r, _ = self._tau(t_s)
        return self.base.yaw_rate_rad_s(tau) * r


def reference(ref):
    """The frozen original implementation of ``ref``'s sampling."""
    if isinstance(ref, RetimedTrajectory):
        return _RefRetimed(ref)
    if isinstance(ref, TrajectoryChain):
        return _RefChain(ref)
    if isinstance(ref, Trajectory):
        return _RefTrajectory(ref)
    raise TypeError(f"no reference implementation for {type(ref).__name__}")


# ---------------------------------------------------------------------------- references flown
FAST = TrajectoryLimits(speed_m_s=6.0)


def _g2(path, down_m=-20.0, **kw) -> Trajectory:
    return time_parameterize(smooth_g2(np.array(path, dtype=float), 0.1), FAST, **kw).to_ned(down_m)


def _trajectories() -> dict[str, Trajectory]:
    climb = time_parameterize(
        np.array([[0.0, 0.0, -20.0], [0.0, 0.0, -35.0]]),
        TrajectoryLimits(speed_m_s=2.5, accel_m_s2=1.5, lat_accel_m_s2=1.5, jerk_m_s3=6.0),
        yaw_mode="hold",
        yaw_hold_rad=0.7,
    )
    vertical_tangent = time_parameterize(np.array([[3.0, 1.0, -20.0], [3.0, 1.0, -5.0]]), yaw_mode="tangent")
    g1_3d = time_parameterize(
        smooth_g1(np.array([[0.0, 0.0, -20.0], [30.0, 5.0, -25.0], [40.0, 40.0, -25.0], [10.0, 60.0, -30.0]]))
    )
    return {
        "g2 lifted": _g2([[0, 0], [50, 0], [90, 40], [60, 90]]),
        "g2 second": _g2([[60, 90], [20, 100], [0, 140]]),
        "g2 third": _g2([[0, 140], [30, 170], [80, 160]], down_m=-25.0),
        "g2 2d": time_parameterize(smooth_g2(np.array([[0.0, 0.0], [40.0, 0.0], [40.0, 30.0]]), 0.1)),
        "g2 moving start": _g2([[0, 0], [40, 10], [70, -20]], start_speed_m_s=4.0, end_speed_m_s=2.0),
        "g2 slowed": _g2([[0, 0], [50, 0], [90, 40]]).time_scaled(1.7),
        "g2 hold yaw": _g2([[0, 0], [20, 20], [60, 20]], yaw_mode="hold", yaw_hold_rad=-1.2),
        "g1 3d": g1_3d,
        "climb (hold yaw)": climb,
        "vertical (tangent yaw)": vertical_tangent,
        "polyline": time_parameterize(np.array([[0.0, 0.0, -10.0], [25.0, 0.0, -10.0], [25.0, 18.0, -10.0]])),
    }


TRAJ = _trajectories()
CHAINS = {
    "chain 1": TrajectoryChain([TRAJ["g2 lifted"]]),
    "chain 2": TrajectoryChain([TRAJ["climb (hold yaw)"], TRAJ["g1 3d"]]),
    "chain 3": TrajectoryChain([TRAJ["g2 lifted"], TRAJ["g2 second"], TRAJ["g2 third"]]),
}
_WARPS = [(5.0, 0.4, 3.0, 1.5), (2.0, 0.0, 2.0, 1.2), (1.0, 0.5, 4.0, 0.8), (0.0, 0.0, 6.0, 1e-3)]


def _nested(base, depth: int) -> RetimedTrajectory:
    out = base
    for tau0, rate, wait, ramp in _WARPS[:depth]:
        out = RetimedTrajectory(out, min(tau0, 0.5 * out.duration_s), rate, wait, ramp)
    return out


RETIMED = {
    f"retime {d} deep of {name}": _nested(base, d)
    for name, base in [("g2 lifted", TRAJ["g2 lifted"]), ("chain 3", CHAINS["chain 3"]), ("g1 3d", TRAJ["g1 3d"])]
    for d in (1, 2, 3, 4)
}
RETIMED["retime ending in its warp"] = RetimedTrajectory(
    TRAJ["g2 second"], TRAJ["g2 second"].duration_s - 1.0, 0.0, 5.0, 2.0
)
RETIMED["pause, ramp 1e-3"] = RetimedTrajectory(CHAINS["chain 2"], 0.0, 0.0, 4.0, 1e-3)
ALL = {**TRAJ, **CHAINS, **RETIMED}
REFS = {name: reference(ref) for name, ref in ALL.items()}


# ---------------------------------------------------------------------------- assertions
def _same(a, b, what: str) -> None:
    a, b = np.asarray(a), np.asarray(b)
    assert a.shape == b.shape and a.dtype == b.dtype, f"{what}: {a.shape} {a.dtype} != {b.shape} {b.dtype}"
    # bit for bit: == plus the sign of zeros (NaN never appears)
    assert np.array_equal(a, b) and np.array_equal(np.signbit(a), np.signbit(b)), (
        f"{what}: max difference {np.max(np.abs(a - b))}"
    )


def _assert_identical(name: str, t) -> None:
    ref, old = ALL[name], REFS[name]
    for key, new_out, old_out in zip(("pos", "vel", "acc"), ref.sample(t), old.sample(t)):
        _same(new_out, old_out, f"{name} {key} at {t!r}")
    _same(ref.yaw_rad(t), old.yaw_rad(t), f"{name} yaw at {t!r}")
    _same(ref.yaw_rate_rad_s(t), old.yaw_rate_rad_s(t), f"{name} yaw rate at {t!r}")
    if isinstance(ref, RetimedTrajectory):
        _same(ref.tau_at(t), old.tau_at(t), f"{name} tau at {t!r}")


def _times(ref) -> list:
    d = ref.duration_s
    horizon = 0.3 * d + 0.2 * np.arange(76)
    return [
        0.0,
        d,
        0.41 * d,
        -1.0,
        d + 3.0,
        np.array([0.0]),
        np.array([0.63 * d]),
        np.array([d + 0.5]),
        horizon,
        horizon[::-1].copy(),
        np.linspace(-2.0, d + 2.0, 76),
        np.linspace(0.0, d, 301),
    ]


@pytest.mark.parametrize("name", sorted(ALL))
def test_sampling_is_bit_identical_at_the_executor_s_times(name):
    for t in _times(ALL[name]):
        _assert_identical(name, t)


@pytest.mark.parametrize("name", sorted(RETIMED))
def test_retimed_durations_are_unchanged(name):
    assert ALL[name].duration_s == REFS[name].duration_s
    assert ALL[name].delay_s == REFS[name].delay_s


@pytest.mark.parametrize("name", sorted(CHAINS))
def test_chain_times_at_the_joints_are_identical(name):
    chain = ALL[name]
    joints = np.concatenate([chain.t_start_s, [chain.duration_s]])
    near = np.concatenate([joints, np.nextafter(joints, -np.inf), np.nextafter(joints, np.inf)])
    _assert_identical(name, near)
    for t in near:
        _assert_identical(name, float(t))


fraction = st.floats(-0.2, 1.2, allow_nan=False)


@settings(max_examples=60, deadline=None)
@given(
    name=st.sampled_from(sorted(ALL)),
    where=fraction,
    step=st.sampled_from([0.0, 0.05, 0.2, 1.0]),
    n=st.sampled_from([1, 2, 7, 76]),
    scalar=st.booleans(),
)
def test_sampling_is_bit_identical_anywhere(name, where, step, n, scalar):
    d = ALL[name].duration_s
    t = where * d + step * np.arange(n)
    _assert_identical(name, float(t[0]) if scalar else t)


@settings(max_examples=40, deadline=None)
@given(st.lists(fraction, min_size=1, max_size=40), st.sampled_from(sorted(ALL)))
def test_unsorted_times_are_bit_identical(fractions, name):
    _assert_identical(name, np.array(fractions) * ALL[name].duration_s)


@settings(max_examples=60, deadline=None)
@given(st.integers(0, 7), st.lists(st.floats(-0.1, 1.1, allow_nan=False), min_size=1, max_size=80))
def test_bernstein_is_bit_identical(n, u):
    _same(bernstein(n, np.array(u)), _ref_bernstein(n, np.array(u)), f"bernstein {n}")


@settings(max_examples=60, deadline=None)
@given(st.sampled_from(sorted(TRAJ)), st.lists(st.floats(-5.0, 400.0, allow_nan=False), min_size=1, max_size=80))
def test_locate_and_arc_derivatives_are_bit_identical(name, s):
    curve = TRAJ[name].curve
    s = np.array(s)
    for new, old in zip(locate(curve._table, s), _ref_locate(curve._table, s)):
        _same(new, old, f"{name} locate")
    piece, u = _ref_locate(curve._table, s)
    for order in (0, 1, 2, 3):
        _same(curve.derivative(s, order), _ref_curve_derivative(curve, s, order), f"{name} derivative {order}")
        du = [_ref_piece_derivative(curve, piece, u, k) for k in range(order + 1)]
        for new, old in zip(arc_derivatives(du), _ref_arc_derivatives(du)):
            _same(new, old, f"{name} arc derivatives {order}")
    _same(curve.evaluate(s), _ref_piece_derivative(curve, *_ref_locate(curve._table, s), 0), f"{name} evaluate")


@settings(max_examples=40, deadline=None)
@given(st.sampled_from(sorted(TRAJ)), st.lists(st.floats(-30.0, 200.0, allow_nan=False), min_size=1, max_size=80))
def test_profile_is_bit_identical(name, tau):
    profile = TRAJ[name].profile
    tau = np.array(tau)
    for new, old in zip(profile.evaluate(tau), _ref_profile_evaluate(profile, tau)):
        _same(new, old, f"{name} evaluate")
    for new, old in zip(profile.filtered(tau), _ref_profile_filtered(profile, tau)):
        _same(new, old, f"{name} filtered")


def test_the_references_cover_the_branches():
    # times before and after the raw profile, flat tangents, hold yaw, 2D, mixed degrees
    assert any(TRAJ[n].yaw_mode == "hold" for n in TRAJ)
    assert TRAJ["g2 2d"].d == 2
    assert np.any(
        np.linalg.norm(TRAJ["vertical (tangent yaw)"].curve.derivative(np.array([1.0]), 1)[:, :2], axis=1) <= 1e-6
    )
    assert RETIMED["retime ending in its warp"].duration_s < 2 * 2.0 + 5.0
    assert len(CHAINS["chain 3"].pieces) == 3


@pytest.mark.parametrize("name", sorted(CHAINS) + ["retime 2 deep of chain 3"])
def test_no_time_gives_empty_samples_as_before(name):
    empty = np.zeros(0)
    for key, new_out, old_out in zip(("pos", "vel", "acc"), ALL[name].sample(empty), REFS[name].sample(empty)):
        _same(new_out, old_out, f"{name} {key} at no time")
    _same(ALL[name].yaw_rad(empty), REFS[name].yaw_rad(empty), f"{name} yaw at no time")
