"""How far the live Foxglove view lags the vehicle's own telemetry (issue 25, item 6).

Real processes, nothing of the companion's own code on the measuring side:

- ``sim-vehicle --speedup X`` sending telemetry to the companion and to a listener;
- ``companion run --foxglove PORT --mission FILE --no-zenoh`` flying the mission;
- a *listener* (a process of this script, ``listen``): a UDP socket on one of the vehicle's
  ``--out`` addresses that asks for LOCAL_POSITION_NED (SET_MESSAGE_INTERVAL, about 100 Hz of
  wall clock) and writes each one's ``time_boot_ms``, position and kernel arrival time
  (SO_TIMESTAMP, wall clock) to a JSON Lines file;
- a *viewer* (a process of this script, ``view``): a WebSocket client (the ``websockets``
  package) that speaks ``foxglove.sdk.v1`` itself: it reads the server's ``advertise``,
  subscribes to the vehicle's channels (``/vehicle/telemetry`` when the server has it, and the
  record's ``/vehicle/state``), decodes each message by its channel's encoding (JSON) and writes
  it with its wall-clock receipt time.

The lag of a viewer sample is its receipt time minus the wall-clock time at which the vehicle's
telemetry showed the same state, matched two ways:

- *by stamp*: the sample carries the vehicle's ``time_boot_ms``; the listener's
  (``time_boot_ms`` -> arrival) line, interpolated, gives when the vehicle sent that state;
- *by position*: the point of the listener's track (over the last 3 s before receipt) closest
  to the sample's position, interpolated along the track, gives the time; only samples taken
  while the vehicle moves faster than ``MOVING_M_S`` count (a hover matches anywhere).

The *position error* is the distance from the viewer's position to where the vehicle's
telemetry put the vehicle at the moment the viewer received it.

Usage::

    python benchmarks/view_lag.py [--speedups 2 8] [--mission mission_files/square.waypoints]

writes ``out/bench/view_lag.json`` and ``docs/benchmarks/view_lag.md``.
"""

from __future__ import annotations

import argparse
import asyncio
import datetime
import json
import logging
import math
import os
import socket
import struct
import subprocess
import sys
import time
from pathlib import Path

import numpy as np

REPO = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(REPO))

from heli_common.ports import free_port  # noqa: E402

log = logging.getLogger("view_lag")

SUBPROTOCOL = "foxglove.sdk.v1"
MESSAGE_DATA = 0x01
TOPICS = ("/vehicle/telemetry", "/vehicle/state")
#: The listener's LOCAL_POSITION_NED rate, Hz of wall clock (asked as Hz of vehicle time).
LISTEN_WALL_HZ = 100.0
#: Samples taken slower than this (m/s, from the listener's track) are left out of the
#: position match.
MOVING_M_S = 1.0
#: How far back (s of wall clock) the position match looks for the closest point.
MATCH_WINDOW_S = 3.0
SO_TIMESTAMP = 29
DEFAULT_MISSION = REPO / "mission_files" / "square.waypoints"
OUT_JSON = REPO / "out" / "bench" / "view_lag.json"
OUT_MD = REPO / "docs" / "benchmarks" / "view_lag.md"


# ---------------------------------------------------------------------- the listener process
def listen(port: int, vehicle_port: int, speedup: float, out_path: Path) -> None:
    """Write every LOCAL_POSITION_NED on ``port`` with its kernel arrival time (wall clock)."""
    from pymavlink.dialects.v20 import ardupilotmega as mavlink

    sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    sock.setsockopt(socket.SOL_SOCKET, SO_TIMESTAMP, 1)
    sock.bind(("127.0.0.1", port))
    sock.settimeout(0.5)
    mav = mavlink.MAVLink(None, srcSystem=254, srcComponent=190)
    mav.robust_parsing = True
    interval_us = 1e6 * speedup / LISTEN_WALL_HZ
    asked_s = -math.inf
    with open(out_path, "w") as out:
        while True:
            if time.monotonic() - asked_s > 1.0:  # ask again each second (a lost request)
                asked_s = time.monotonic()
                request = mav.command_long_encode(
                    0,
                    0,
                    mavlink.MAV_CMD_SET_MESSAGE_INTERVAL,
                    0,
                    mavlink.MAVLINK_MSG_ID_LOCAL_POSITION_NED,
                    interval_us,
                    0,
                    0,
                    0,
                    0,
                    0,
                )
                sock.sendto(request.pack(mav), ("127.0.0.1", vehicle_port))
            try:
                data, ancillary, _, _ = sock.recvmsg(65535, 64)
            except TimeoutError:
                continue
            wall_s = _kernel_time_s(ancillary)
            for msg in mav.parse_buffer(data) or []:
                if msg.get_type() == "LOCAL_POSITION_NED":
                    out.write(
                        json.dumps({"wall_s": wall_s, "boot_ms": msg.time_boot_ms, "pos": [msg.x, msg.y, msg.z]}) + "\n"
                    )
                    out.flush()


def _kernel_time_s(ancillary) -> float:
    """SO_TIMESTAMP's arrival time (struct timeval, wall clock), else now."""
    for level, kind, data in ancillary:
        if level == socket.SOL_SOCKET and kind == SO_TIMESTAMP:
            sec, usec = struct.unpack("@ll", data[: struct.calcsize("@ll")])
            return sec + usec * 1e-6
    return time.time()


# ---------------------------------------------------------------------- the viewer process
async def view(port: int, out_path: Path, seconds: float) -> None:
    """Subscribe to ``TOPICS`` over ``foxglove.sdk.v1`` and write each message with its receipt time."""
    import websockets

    ws = await _connect(f"ws://127.0.0.1:{port}", seconds)
    channels: dict[int, dict] = {}
    subscribed: dict[int, int] = {}  # subscription id -> channel id
    end = time.monotonic() + seconds
    with open(out_path, "w") as out:
        async with ws:
            while time.monotonic() < end:
                try:
                    frame = await asyncio.wait_for(ws.recv(), 0.5)
                except TimeoutError:
                    continue
                except websockets.ConnectionClosed:
                    return
                wall_s = time.time()
                if isinstance(frame, bytes):
                    _write_data(frame, wall_s, channels, subscribed, out)
                else:
                    await _control(json.loads(frame), ws, channels, subscribed)


async def _connect(url: str, within_s: float):
    import websockets

    end = time.monotonic() + within_s
    while True:
        try:
            return await websockets.connect(url, subprotocols=[SUBPROTOCOL], max_size=None)
        except OSError:
            if time.monotonic() > end:
                raise
            await asyncio.sleep(0.1)


async def _control(message: dict, ws, channels: dict, subscribed: dict) -> None:
    """``advertise``: subscribe to the channels of ``TOPICS`` (JSON encoded); ``unadvertise``: forget them."""
    if message.get("op") == "unadvertise":
        for cid in message.get("channelIds", []):
            channels.pop(cid, None)
        return
    if message.get("op") != "advertise":
        return
    wanted = []
    for channel in message["channels"]:
        channels[channel["id"]] = channel
        if channel["topic"] in TOPICS and channel["id"] not in subscribed.values():
            if channel["encoding"] != "json":
                log.warning("%s: encoding %s, not decoded", channel["topic"], channel["encoding"])
                continue
            sid = len(subscribed) + 1
            subscribed[sid] = channel["id"]
            wanted.append({"id": sid, "channelId": channel["id"]})
    if wanted:
        await ws.send(json.dumps({"op": "subscribe", "subscriptions": wanted}))


def _write_data(frame: bytes, wall_s: float, channels: dict, subscribed: dict, out) -> None:
    """A binary ``Message Data`` frame: opcode, subscription id (u32), log time (u64 ns), payload."""
    if frame[0] != MESSAGE_DATA:
        return
    sid, log_time_ns = struct.unpack_from("<IQ", frame, 1)
    channel = channels.get(subscribed.get(sid))
    if channel is None:
        return
    out.write(
        json.dumps(
            {"wall_s": wall_s, "topic": channel["topic"], "log_time_ns": log_time_ns, "data": json.loads(frame[13:])}
        )
        + "\n"
    )
    out.flush()


# ---------------------------------------------------------------------- one flight
def _spawn(args: list[str], log_path: Path) -> subprocess.Popen:
    env = {**os.environ, "PYTHONPATH": str(REPO) + os.pathsep + os.environ.get("PYTHONPATH", "")}
    return subprocess.Popen(args, stdout=open(log_path, "w"), stderr=subprocess.STDOUT, env=env, cwd=REPO)


def _stop(process: subprocess.Popen) -> None:
    if process.poll() is None:
        process.terminate()
        try:
            process.wait(10)
        except subprocess.TimeoutExpired:
            process.kill()
            process.wait()


def fly(speedup: float, mission: Path, work: Path, timeout_s: float) -> tuple[Path, Path, int]:
    """One flight at ``speedup``: (listener file, viewer file, the companion's exit code); the
    flight's record goes to ``work/flight.jsonl`` (its ``setpoint_jitter`` event: the stream's
    timing with the view on)."""
    work.mkdir(parents=True, exist_ok=True)
    companion_port, listen_port, vehicle_port = free_port(), free_port(), free_port()
    fox_port = free_port(socket.SOCK_STREAM)
    me = [sys.executable, str(Path(__file__).resolve())]
    listened, viewed = work / "listener.jsonl", work / "viewer.jsonl"
    vehicle = _spawn(
        [
            sys.executable,
            "-m",
            "sim_vehicle.cli",
            "--port",
            str(vehicle_port),
            "--out",
            f"127.0.0.1:{companion_port}",
            "--out",
            f"127.0.0.1:{listen_port}",
            "--speedup",
            str(speedup),
            "-q",
        ],
        work / "sim_vehicle.log",
    )
    listener = _spawn(
        [*me, "listen", str(listen_port), str(vehicle_port), str(speedup), str(listened)], work / "listener.log"
    )
    viewer = _spawn([*me, "view", str(fox_port), str(viewed), str(timeout_s)], work / "viewer.log")
    companion = _spawn(
        [
            sys.executable,
            "-m",
            "companion.cli",
            "run",
            "--connect",
            f"udpin://127.0.0.1:{companion_port}",
            "--no-zenoh",
            "--foxglove",
            f"127.0.0.1:{fox_port}",
            "--mission",
            str(mission),
            "--record",
            str(work / "flight.jsonl"),
        ],
        work / "companion.log",
    )
    try:
        code = companion.wait(timeout_s)
    except subprocess.TimeoutExpired:
        log.error("the flight at %gx took longer than %g s", speedup, timeout_s)
        code = -1
    finally:
        for process in (companion, viewer, listener, vehicle):
            _stop(process)
    return listened, viewed, code


# ---------------------------------------------------------------------- the figures
def _load_jsonl(path: Path) -> list[dict]:
    if not path.exists():
        return []
    lines = []
    for line in path.read_text().splitlines():
        try:
            lines.append(json.loads(line))
        except json.JSONDecodeError:  # the last line, cut by the stop
            pass
    return lines


def _track(listened: list[dict]) -> dict[str, np.ndarray]:
    """The listener's telemetry, sorted by vehicle time, one row per ``time_boot_ms``."""
    rows = sorted({r["boot_ms"]: r for r in listened}.values(), key=lambda r: r["boot_ms"])
    wall = np.array([r["wall_s"] for r in rows])
    pos = np.array([r["pos"] for r in rows])
    boot = np.array([r["boot_ms"] for r in rows], dtype=float)
    dt = np.gradient(wall) if len(wall) > 1 else np.ones(len(wall))
    speed = (
        np.linalg.norm(np.gradient(pos, axis=0), axis=1) / np.maximum(dt, 1e-6)
        if len(wall) > 1
        else np.zeros(len(wall))
    )
    return {"wall": wall, "boot": boot, "pos": pos, "speed_wall": speed}


def _position_at(track: dict, wall_s: float) -> np.ndarray:
    """Where the vehicle's telemetry put it at ``wall_s`` (interpolated)."""
    return np.array([np.interp(wall_s, track["wall"], track["pos"][:, k]) for k in range(3)])


def lag_by_stamp(track: dict, samples: list[dict]) -> tuple[list[float], list[float]]:
    """(lag s, position error m) of the samples that carry ``time_boot_ms``."""
    lags, errors = [], []
    lo, hi = track["boot"][0], track["boot"][-1]
    for s in samples:
        boot = s["data"].get("time_boot_ms")
        if boot is None or not lo <= boot <= hi or s["data"].get("pos_ned_m") is None:
            continue
        sent_s = float(np.interp(boot, track["boot"], track["wall"]))
        lags.append(s["wall_s"] - sent_s)
        errors.append(float(np.linalg.norm(np.asarray(s["data"]["pos_ned_m"]) - _position_at(track, s["wall_s"]))))
    return lags, errors


def _closest_time(track: dict, pos: np.ndarray, lo: int, hi: int) -> tuple[float, float]:
    """(wall time, distance) of the point of the track's segments ``lo..hi`` closest to ``pos``."""
    a, b = track["pos"][lo : hi - 1], track["pos"][lo + 1 : hi]
    ab = b - a
    u = np.clip(np.einsum("ij,ij->i", pos - a, ab) / np.maximum(np.einsum("ij,ij->i", ab, ab), 1e-12), 0.0, 1.0)
    d = np.linalg.norm(a + u[:, None] * ab - pos, axis=1)
    k = int(np.argmin(d))
    wall = track["wall"]
    return float(wall[lo + k] + u[k] * (wall[lo + k + 1] - wall[lo + k])), float(d[k])


def lag_by_position(track: dict, samples: list[dict]) -> tuple[list[float], list[float]]:
    """(lag s, position error m) of the samples taken while the vehicle moves (see the module docstring)."""
    lags, errors = [], []
    fast_m_s = MOVING_M_S * _speedup_of(track)  # m per wall-clock second
    for s in samples:
        pos = s["data"].get("pos_ned_m")
        if pos is None:
            continue
        w = s["wall_s"]
        lo = int(np.searchsorted(track["wall"], w - MATCH_WINDOW_S))
        hi = int(np.searchsorted(track["wall"], w + 0.02))
        if hi - lo < 3 or np.interp(w, track["wall"], track["speed_wall"]) < fast_m_s:
            continue
        t, _ = _closest_time(track, np.asarray(pos, dtype=float), lo, hi)
        lags.append(w - t)
        errors.append(float(np.linalg.norm(np.asarray(pos) - _position_at(track, w))))
    return lags, errors


def _speedup_of(track: dict) -> float:
    """Vehicle seconds per wall second over the track."""
    return float((track["boot"][-1] - track["boot"][0]) * 1e-3 / max(track["wall"][-1] - track["wall"][0], 1e-9))


def _stats(values: list[float], scale: float = 1.0, digits: int = 1) -> dict:
    if not values:
        return {"n": 0}
    v = np.asarray(values) * scale
    return {
        "n": len(v),
        "p50": round(float(np.percentile(v, 50)), digits),
        "p95": round(float(np.percentile(v, 95)), digits),
        "max": round(float(v.max()), digits),
    }


def setpoint_jitter(record: Path) -> dict:
    """The flight's setpoint stream timing (its record's ``setpoint_jitter`` event), ms."""
    for line in _load_jsonl(record):
        if line.get("type") == "event" and line.get("name") == "setpoint_jitter":
            return {k: line[k] for k in ("count", "p50_ms", "p99_ms", "max_ms", "missed") if k in line}
    return {}


def analyse(listened: Path, viewed: Path) -> dict:
    """The figures of one flight, per viewer topic and match method."""
    track = _track(_load_jsonl(listened))
    viewer = _load_jsonl(viewed)
    if len(track["wall"]) < 10:
        raise RuntimeError(f"the listener heard {len(track['wall'])} LOCAL_POSITION_NED")
    result = {"speedup_measured": round(_speedup_of(track), 3), "telemetry_samples": len(track["wall"])}
    for topic in TOPICS:
        samples = [s for s in viewer if s["topic"] == topic]
        if not samples:
            continue
        walls = np.array([s["wall_s"] for s in samples])
        entry = {"samples": len(samples), "rate_hz": round((len(walls) - 1) / max(walls[-1] - walls[0], 1e-9), 1)}
        for method, match in (("stamp", lag_by_stamp), ("position", lag_by_position)):
            lags, errors = match(track, samples)
            if lags:
                entry[method] = {"lag_ms": _stats(lags, 1e3), "position_error_m": _stats(errors, 1.0, 3)}
        result[topic] = entry
    return result


# ---------------------------------------------------------------------- the report
def _row(speedup: float, topic: str, method: str, figures: dict) -> str:
    lag, err = figures["lag_ms"], figures["position_error_m"]
    return (
        f"| {speedup:g}x | `{topic}` | {method} | {lag['n']} | {lag['p50']} | {lag['p95']} | {lag['max']} "
        f"| {err['p50']} | {err['p95']} |"
    )


def markdown(report: dict) -> str:
    """``docs/benchmarks/view_lag.md``."""
    lines = [
        "# Live view lag",
        "",
        f"Generated by `benchmarks/view_lag.py` on {report['date']} at {report['commit']}: `sim-vehicle`, "
        f"`companion run --foxglove` on `{report['mission']}` and two independent processes, a pymavlink "
        "listener of the vehicle's LOCAL_POSITION_NED (kernel arrival times) and a `foxglove.sdk.v1` "
        "WebSocket client (the `websockets` package). Lag = the viewer's receipt time minus the time the "
        "vehicle's telemetry showed the same state: *stamp* matches the `time_boot_ms` the message carries, "
        f"*position* the closest point of the track (samples while the vehicle moves faster than {MOVING_M_S:g} m/s "
        "of vehicle time). Position error: the viewer's position against the vehicle's at the moment of receipt.",
        "",
        "| speed-up | topic | match | n | lag p50 ms | lag p95 ms | lag max ms | error p50 m | error p95 m |",
        "|---|---|---|---|---|---|---|---|---|",
    ]
    for run in report["runs"]:
        for topic in TOPICS:
            entry = run.get(topic)
            for method in ("stamp", "position"):
                if entry and method in entry:
                    lines.append(_row(run["speedup"], topic, method, entry[method]))
    lines += ["", "Rates received by the viewer (Hz of wall clock):", ""]
    for run in report["runs"]:
        rates = ", ".join(f"`{t}` {run[t]['rate_hz']}" for t in TOPICS if t in run)
        jitter = run.get("setpoint_jitter_ms") or {}
        stream = (
            f"; the 50 Hz setpoint stream |period - 20 ms| p50 {jitter['p50_ms']:.3f} ms, p99 "
            f"{jitter['p99_ms']:.3f} ms, max {jitter['max_ms']:.3f} ms, {jitter['missed']} missed"
            if jitter
            else ""
        )
        lines.append(
            f"- {run['speedup']:g}x (measured {run['speedup_measured']}x): {rates}; "
            f"companion exit {run['companion_exit']}{stream}"
        )
    if report.get("note"):
        lines += ["", report["note"]]
    return "\n".join(lines) + "\n"


def _commit() -> str:
    try:
        return subprocess.run(
            ["git", "rev-parse", "--short", "HEAD"], cwd=REPO, capture_output=True, text=True, check=True
        ).stdout.strip()
    except (OSError, subprocess.CalledProcessError):
        return "unknown"


def main(argv: list[str] | None = None) -> int:
    """``view_lag.py [--speedups ...]``, or the child processes ``listen`` / ``view``."""
    argv = sys.argv[1:] if argv is None else argv
    logging.basicConfig(level=logging.INFO, format="%(asctime)s %(name)s %(message)s")
    if argv and argv[0] == "listen":
        listen(int(argv[1]), int(argv[2]), float(argv[3]), Path(argv[4]))
        return 0
    if argv and argv[0] == "view":
        asyncio.run(view(int(argv[1]), Path(argv[2]), float(argv[3])))
        return 0
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--speedups", type=float, nargs="+", default=[1.0, 2.0, 4.0, 8.0])
    parser.add_argument("--mission", type=Path, default=DEFAULT_MISSION)
    parser.add_argument("--work", type=Path, default=REPO / "out" / "bench" / "view_lag")
    parser.add_argument("--timeout-s", type=float, default=400.0)
    parser.add_argument("--json", type=Path, default=OUT_JSON)
    parser.add_argument("--md", type=Path, default=OUT_MD)
    parser.add_argument("--note", default="", help="a paragraph appended to the Markdown")
    parser.add_argument("--quick", action="store_true", help="one flight at 8x (benchmarks/run_all.py --quick)")
    args = parser.parse_args(argv)
    if args.quick:
        args.speedups = [8.0]
    report = {
        "date": datetime.date.today().isoformat(),
        "commit": _commit(),
        "mission": str(args.mission.resolve().relative_to(REPO))
        if args.mission.resolve().is_relative_to(REPO)
        else str(args.mission),
        "runs": [],
        "note": args.note,
    }
    for speedup in args.speedups:
        listened, viewed, code = fly(speedup, args.mission, args.work / f"x{speedup:g}", args.timeout_s)
        run = {
            "speedup": speedup,
            "companion_exit": code,
            **analyse(listened, viewed),
            "setpoint_jitter_ms": setpoint_jitter(listened.parent / "flight.jsonl"),
        }
        log.info("%gx: %s", speedup, json.dumps(run))
        report["runs"].append(run)
    args.json.parent.mkdir(parents=True, exist_ok=True)
    args.json.write_text(json.dumps(report, indent=2) + "\n")
    args.md.parent.mkdir(parents=True, exist_ok=True)
    args.md.write_text(markdown(report))
    log.info("wrote %s and %s", args.json, args.md)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
