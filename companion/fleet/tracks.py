"""The flown tracks of a fleet, from each simulator's own tlog, and the separation they kept.

The judge of a fleet flight is the vehicles, not the companions: each ``sim-vehicle --tlog``
records everything it sent, GLOBAL_POSITION_INT included (the companions ask for it), stamped
with the wall clock of the write (pymavlink's ``msg._timestamp``). All the simulators of a fleet
run on one machine, so their wall clocks are one clock: the tracks are put on a common
wall-clock grid (linear interpolation) in one local NED frame, and the separation of every pair
of vehicles is measured on it.

- ``read_tlog_track(path, sysid)``: a ``Track`` (wall s, lat/lon/alt rows) of the vehicle's own
  GLOBAL_POSITION_INT (source system ``sysid``, component 1).
- ``separation(tracks_t, tracks_ned)``: the minimum 3D distance of each pair over their common
  time, the pair and the time of the closest approach (``Separation``).
- ``path_length_m(ned)``: the flown length of a track;
- ``achieved_speedup(track)``: the simulator's clock against the wall clock (did it keep its
  ``--speedup``?).

The numerics (``common_grid``, ``resample``, ``separation``, ``path_length_m``) take plain arrays
and are unit-tested on synthetic tracks.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np

from companion.errors import ConfigError

__all__ = [
    "Track",
    "Separation",
    "read_tlog_track",
    "tracks_in_frame",
    "common_grid",
    "resample",
    "separation",
    "path_length_m",
    "achieved_speedup",
    "fleet_separation",
]

#: Spacing of the common grid (wall s) added to the samples' own times.
GRID_STEP_S = 0.05


@dataclass(frozen=True)
class Track:
    """One vehicle's track.

    Parameters
    ----------
    sysid : int
    t_s : ndarray, shape (K,)
        Wall-clock time of each sample (s since the epoch), increasing.
    lla : ndarray, shape (K, 3)
        Latitude deg, longitude deg, altitude m AMSL.
    boot_s : ndarray, shape (K,), optional
        The vehicle's own clock at each sample (``time_boot_ms`` / 1000: simulated s).
    """

    sysid: int
    t_s: np.ndarray
    lla: np.ndarray
    boot_s: np.ndarray | None = None

    def __len__(self) -> int:
        return len(self.t_s)


@dataclass(frozen=True)
class Separation:
    """The separation kept by a set of tracks over their common time.

    Parameters
    ----------
    min_m : float
        Minimum distance between any two vehicles (inf with fewer than two tracks).
    pair : (int, int) or None
        Indices of the two tracks at the minimum.
    t_s : float
        Time of the minimum (on the tracks' clock).
    pair_min_m : dict
        ``(i, j)`` (i < j) -> that pair's minimum distance.
    common_s : float
        Length of the common time (s; 0 when the tracks do not overlap).
    """

    min_m: float
    pair: tuple[int, int] | None
    t_s: float
    pair_min_m: dict
    common_s: float

    def losses(self, required_m: float) -> int:
        """How many pairs came closer than ``required_m``."""
        return sum(1 for d in self.pair_min_m.values() if d < required_m)


def read_tlog_track(path: str | Path, sysid: int | None = None, *, component: int = 1) -> Track:
    """GLOBAL_POSITION_INT of vehicle ``sysid`` (default: the first system heard sending it) in a
    tlog, with the tlog's wall-clock stamps.

    Raises
    ------
    ConfigError
        No such file, or no GLOBAL_POSITION_INT of that vehicle in it.
    """
    from pymavlink import mavutil

    path = Path(path)
    if not path.is_file():
        raise ConfigError(f"tlog {path} does not exist")
    conn = mavutil.mavlink_connection(str(path), dialect="ardupilotmega")
    rows = []
    try:
        while True:
            msg = conn.recv_match(type="GLOBAL_POSITION_INT")
            if msg is None:
                break
            if msg.get_srcComponent() != component:
                continue
            if sysid is None:
                sysid = msg.get_srcSystem()
            if msg.get_srcSystem() != sysid:
                continue
            rows.append(
                (float(msg._timestamp), msg.lat * 1e-7, msg.lon * 1e-7, msg.alt * 1e-3, msg.time_boot_ms * 1e-3)
            )
    finally:
        conn.close()
    if not rows:
        raise ConfigError(f"tlog {path}: no GLOBAL_POSITION_INT from system {sysid} component {component}")
    arr = np.asarray(rows, dtype=np.float64)
    order = np.argsort(arr[:, 0], kind="stable")
    arr = arr[order]
    keep = np.concatenate([[True], np.diff(arr[:, 0]) > 0.0])  # one sample per stamp
    arr = arr[keep]
    return Track(int(sysid), arr[:, 0], arr[:, 1:4], arr[:, 4])


def tracks_in_frame(tracks, frame=None) -> tuple[list[np.ndarray], list[np.ndarray], object]:
    """The tracks' times and NED positions in one local frame (default: at the first track's
    first sample, on the ground). Returns ``(times, positions, frame)``."""
    from heli_common.frames import LocalFrame

    tracks = list(tracks)
    if frame is None:
        if not tracks:
            raise ConfigError("tracks: none given")
        frame = LocalFrame(*tracks[0].lla[0])
    return [t.t_s for t in tracks], [frame.to_ned_array(t.lla) for t in tracks], frame


def common_grid(times, step_s: float = GRID_STEP_S) -> np.ndarray:
    """The common time of several tracks: every sample time of any of them inside the overlap
    ``[max of starts, min of ends]`` plus a regular grid of ``step_s`` there (sorted, unique).
    Empty when they do not overlap.

    Parameters
    ----------
    times : sequence of ndarray (K_i,)
        Each track's increasing sample times.
    """
    if step_s <= 0:
        raise ConfigError(f"step_s: expected > 0, got {step_s}")
    times = [np.asarray(t, dtype=np.float64) for t in times]
    if not times or any(len(t) == 0 for t in times):
        return np.empty(0)
    start = max(float(t[0]) for t in times)
    end = min(float(t[-1]) for t in times)
    if end < start:
        return np.empty(0)
    regular = start + step_s * np.arange(int(np.floor((end - start) / step_s)) + 1)
    own = np.concatenate([t[(t >= start) & (t <= end)] for t in times])
    return np.unique(np.concatenate([regular, own, [start, end]]))


def resample(t_s, pos, grid) -> np.ndarray:
    """Positions ``pos`` (K, d) at times ``t_s`` (K,), linearly interpolated at ``grid`` (G,)
    (held at the ends). Returns (G, d)."""
    t = np.asarray(t_s, dtype=np.float64)
    p = np.asarray(pos, dtype=np.float64).reshape(len(t), -1)
    g = np.asarray(grid, dtype=np.float64)
    return (
        np.column_stack([np.interp(g, t, p[:, k]) for k in range(p.shape[1])]) if len(g) else np.empty((0, p.shape[1]))
    )


def separation(times, positions, step_s: float = GRID_STEP_S) -> Separation:
    """Minimum pairwise 3D distance of several tracks over their common time.

    Parameters
    ----------
    times : sequence of ndarray (K_i,)
        Each track's increasing sample times (one clock).
    positions : sequence of ndarray (K_i, 3)
        Each track's positions in one frame (m).
    step_s : float
        Spacing of the regular part of the common grid (``common_grid``).

    Returns
    -------
    Separation
        Every pair's minimum is taken over the common grid of all the tracks, which holds each
        track's own samples: it is never larger than the distance of two tracks at a time
        where both have a sample.
    """
    times, positions = list(times), list(positions)
    if len(times) != len(positions):
        raise ConfigError(f"separation: {len(times)} time arrays for {len(positions)} position arrays")
    grid = common_grid(times, step_s)
    if len(times) < 2 or len(grid) == 0:
        return Separation(float("inf"), None, float("nan"), {}, 0.0)
    on_grid = [resample(t, p, grid) for t, p in zip(times, positions)]
    best, pair, at = float("inf"), None, float("nan")
    pair_min = {}
    for i in range(len(on_grid)):
        for j in range(i + 1, len(on_grid)):
            dist = np.linalg.norm(on_grid[i] - on_grid[j], axis=1)
            k = int(np.argmin(dist))
            pair_min[(i, j)] = float(dist[k])
            if dist[k] < best:
                best, pair, at = float(dist[k]), (i, j), float(grid[k])
    return Separation(best, pair, at, pair_min, float(grid[-1] - grid[0]))


def path_length_m(pos) -> float:
    """Length of a polyline (K, d) in metres."""
    p = np.asarray(pos, dtype=np.float64)
    if len(p) < 2:
        return 0.0
    return float(np.sum(np.linalg.norm(np.diff(p, axis=0), axis=1)))


def achieved_speedup(track: Track) -> dict:
    """How fast the vehicle's clock ran against the wall clock: ``speedup`` (simulated s per
    wall s over the whole track) and ``max_lag_s`` (the largest wall-clock lag of a sample behind
    the straight line through the first sample at that speed-up ... a stall of the simulator)."""
    if track.boot_s is None or len(track) < 2 or track.t_s[-1] <= track.t_s[0]:
        return {"speedup": float("nan"), "max_lag_s": float("nan")}
    wall = track.t_s - track.t_s[0]
    sim = track.boot_s - track.boot_s[0]
    speedup = float(sim[-1] / wall[-1])
    lag = wall - sim / speedup if speedup > 0 else np.zeros_like(wall)
    return {"speedup": speedup, "max_lag_s": float(np.max(lag) - np.min(lag))}


def fleet_separation(tlogs, sysids=None, step_s: float = GRID_STEP_S) -> dict:
    """The fleet's numbers from its simulators' tlogs: minimum pairwise separation (and the
    pair by system id, the time), every pair's minimum, each vehicle's flown length (the whole
    track: takeoff and landing included) and the tracks' sample counts.

    Parameters
    ----------
    tlogs : sequence of path
    sysids : sequence of int, optional
        The vehicle of each tlog (default: the first system sending GLOBAL_POSITION_INT in it).
    """
    tlogs = list(tlogs)
    sysids = list(sysids) if sysids is not None else [None] * len(tlogs)
    tracks = [read_tlog_track(p, s) for p, s in zip(tlogs, sysids)]
    times, ned, _ = tracks_in_frame(tracks)
    sep = separation(times, ned, step_s)
    ids = [t.sysid for t in tracks]
    lengths = {tr.sysid: path_length_m(p) for tr, p in zip(tracks, ned)}
    speed = {tr.sysid: achieved_speedup(tr) for tr in tracks}
    return {
        "min_separation_m": sep.min_m,
        "closest_pair": None if sep.pair is None else [ids[sep.pair[0]], ids[sep.pair[1]]],
        "closest_t_s": sep.t_s,
        "common_s": sep.common_s,
        "pair_min_m": {f"{ids[i]}-{ids[j]}": d for (i, j), d in sep.pair_min_m.items()},
        "path_length_m": lengths,
        "samples": {t.sysid: len(t) for t in tracks},
        "speedup": {k: v["speedup"] for k, v in speed.items()},
        "max_lag_s": {k: v["max_lag_s"] for k, v in speed.items()},
        "separation": sep,
    }
