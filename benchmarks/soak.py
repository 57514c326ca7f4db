"""Soak (issue 11): 100,000 bad MAVLink frames and 10,000 threat payloads during one real flight.

Separate ``sim-vehicle`` and ``companion run`` processes fly ``mission_files/exclusion_zones.plan``
(``companion.sitl.vehicles.flight_processes``, as the threat storm does; in real time by default,
so that the injection fits in the flight). Once the first leg is flown, this process

- sends ``--frames`` MAVLink datagrams from its own UDP socket, paced at ``--rate`` per second,
  three quarters to the vehicle's port and one quarter to the companion's MAVLink port (its gate,
  in front of MAVSDK): random
  bytes, valid frames with a broken CRC, truncated frames, unknown message ids, and valid frames
  from a foreign system id (77) that must all be refused: SET_POSITION_TARGET_LOCAL_NED with NaN
  (yaw NaN too) or infinite fields, COMMAND_LONG with NaN or out-of-range parameters
  (takeoff, arm, mode, reposition, mission start, speed, yaw, home) or an unknown command,
  PARAM_SET with NaN or out-of-range values, and abandoned mission uploads (MISSION_COUNT, then
  an item out of order, then nothing);
- meanwhile PUTs ``--payloads`` threat payloads over zenoh (a second thread, spread over the same
  time): mostly junk (random
  bytes, random JSON, valid threats with one field broken, an id that is not the key's), one in a
  hundred a valid threat 2 km away (accepted, never in the way).

MISSION_CLEAR_ALL from the foreign system is *not* sent: without MAVLink signing a vehicle obeys
it from anyone (ArduPilot does too), so it is a command, not junk; a signed soak can add it once
``sim-vehicle --signing-key`` exists.

Reported: frames sent per kind and to whom; the vehicle's own counters (``packets_in``,
``messages_in``, ``bad_crc``, ``unknown_id``, ``bad_data``, ``truncated``, from its
``link statistics`` log line at shutdown); datagrams the kernel dropped at the vehicle's and at
the companion's socket (``/proc/net/udp``: what "lost" means for UDP); frames per second handled
by the vehicle; the mission on the vehicle downloaded before and after (unchanged?); whether the
flight completed (the companion's summary, and the vehicle itself disarmed on the ground after
its track reached the last waypoint area); and the companion's threat-bus counters from its
flight record (received, put, rejected, handler errors: none may be lost).

Usage::

    .venv/bin/python benchmarks/soak.py [--quick] [--frames N] [--payloads M] [--rate HZ]

Prints a table, writes ``out/bench/soak.json`` and ``docs/benchmarks/soak.md``.
"""

from __future__ import annotations

import argparse
import ast
import collections
import json
import logging
import math
import re
import socket
import sys
import tempfile
import threading
import time
from pathlib import Path

import numpy as np

REPO = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(REPO))
sys.path.insert(0, str(REPO / "tests"))

from flight_support import DEMO_MISSION, TrackListener, flight_processes  # noqa: E402
from pymavlink.dialects.v20 import ardupilotmega as mavlink  # noqa: E402
from support import MavlinkPeer  # noqa: E402

from companion.demo import FlightWatcher, last_json_line  # noqa: E402
from companion.record.flight_record import load_record  # noqa: E402
from companion.threats.model import Threat  # noqa: E402
from companion.threats.transport import codec  # noqa: E402
from companion.threats.transport.bus import ThreatBus  # noqa: E402

log = logging.getLogger("soak")

SPEEDUP = 1.0
"""Real time by default: 100,000 frames at 1000 per s need a flight of 100 s after the first leg."""
FOREIGN_SYSID = 77
VEHICLE_SYSID = 1
VEHICLE_SHARE = 0.75
VALID_EVERY = 100
#: Frame kinds and their shares of the mix.
FRAME_MIX = {
    "random": 0.2,
    "bad_crc": 0.2,
    "truncated": 0.15,
    "unknown_id": 0.05,
    "nan_setpoint": 0.15,
    "bad_command": 0.15,
    "bad_param": 0.05,
    "abandoned_upload": 0.05,
}
#: Kinds that may go to the companion's port (mission uploads and parameters are the vehicle's).
COMPANION_KINDS = ("random", "bad_crc", "truncated", "unknown_id", "nan_setpoint", "bad_command")
NAN, INF = math.nan, math.inf
M = mavlink
#: COMMAND_LONG (command, params) that the vehicle must refuse (DENIED or UNSUPPORTED).
BAD_COMMANDS = [
    (M.MAV_CMD_NAV_TAKEOFF, (0, 0, 0, 0, 0, 0, NAN)),
    (M.MAV_CMD_NAV_TAKEOFF, (0, 0, 0, 0, 0, 0, -50.0)),
    (M.MAV_CMD_COMPONENT_ARM_DISARM, (NAN, 0, 0, 0, 0, 0, 0)),
    (M.MAV_CMD_DO_SET_MODE, (1, NAN, 0, 0, 0, 0, 0)),
    (M.MAV_CMD_DO_SET_MODE, (1, 99, 0, 0, 0, 0, 0)),
    (M.MAV_CMD_DO_REPOSITION, (-1, 1, 0, NAN, NAN, NAN, NAN)),
    (M.MAV_CMD_MISSION_START, (1e9, 0, 0, 0, 0, 0, 0)),
    (M.MAV_CMD_DO_CHANGE_SPEED, (1, 1e6, 0, 0, 0, 0, 0)),
    (M.MAV_CMD_CONDITION_YAW, (NAN, 0, 1, 0, 0, 0, 0)),
    (M.MAV_CMD_DO_SET_HOME, (0, 0, 0, 0, NAN, NAN, NAN)),
    (31999, (0, 0, 0, 0, 0, 0, 0)),
]
FORCE_DISARM = 21196
PARAMS = [b"WPNAV_SPEED", b"GUID_TIMEOUT", b"SIM_SPEEDUP", b"POS_KP_XY"]


# ================================================================ frames
class FrameFactory:
    """Builds the junk frames of each kind (seeded)."""

    def __init__(self, seed: int) -> None:
        self.rng = np.random.default_rng(seed)
        self.mav = mavlink.MAVLink(None, FOREIGN_SYSID, 190)
        self.upload_seq = 0

    def _valid(self) -> bytes:
        """A valid frame of the foreign system (as a base to break)."""
        k = int(self.rng.integers(3))
        if k == 0:
            return self.mav.heartbeat_encode(6, 8, 0, 0, 0).pack(self.mav)
        if k == 1:
            return self.mav.command_long_encode(
                VEHICLE_SYSID, 1, M.MAV_CMD_COMPONENT_ARM_DISARM, 0, 0, FORCE_DISARM, 0, 0, 0, 0, 0
            ).pack(self.mav)
        return self.mav.set_position_target_local_ned_encode(
            0, VEHICLE_SYSID, 1, M.MAV_FRAME_LOCAL_NED, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0
        ).pack(self.mav)

    def build(self, kind: str) -> list[bytes]:
        """The datagram(s) of one frame of ``kind`` (an abandoned upload is two datagrams)."""
        rng = self.rng
        if kind == "random":
            return [rng.integers(0, 256, int(rng.integers(1, 280)), dtype=np.uint8).tobytes()]
        if kind == "bad_crc":  # would force-disarm in flight, or stop the flight, if accepted
            data = bytearray(self._valid())
            data[-1 - int(rng.integers(2))] ^= int(rng.integers(1, 256))
            return [bytes(data)]
        if kind == "truncated":
            data = self._valid()
            return [data[: int(rng.integers(1, len(data)))]]
        if kind == "unknown_id":
            msgid = int(rng.integers(20000, 0xFFFFFF))
            payload = rng.integers(0, 256, int(rng.integers(1, 40)), dtype=np.uint8).tobytes()
            header = bytes(
                [
                    0xFD,
                    len(payload),
                    0,
                    0,
                    int(rng.integers(256)),
                    FOREIGN_SYSID,
                    190,
                    msgid & 0xFF,
                    (msgid >> 8) & 0xFF,
                    msgid >> 16,
                ]
            )
            return [header + payload + rng.integers(0, 256, 2, dtype=np.uint8).tobytes()]
        if kind == "nan_setpoint":  # refused: yaw NaN (or infinite fields); never "hold here"
            bad = INF if rng.random() < 0.3 else NAN
            return [
                self.mav.set_position_target_local_ned_encode(
                    0, VEHICLE_SYSID, 1, M.MAV_FRAME_LOCAL_NED, 0, bad, bad, bad, bad, bad, bad, bad, bad, bad, NAN, NAN
                ).pack(self.mav)
            ]
        if kind == "bad_command":
            command, params = BAD_COMMANDS[int(rng.integers(len(BAD_COMMANDS)))]
            return [self.mav.command_long_encode(VEHICLE_SYSID, 1, command, 0, *params).pack(self.mav)]
        if kind == "bad_param":
            value = [NAN, 1e9, -1e9, INF][int(rng.integers(4))]
            name = PARAMS[int(rng.integers(len(PARAMS)))]
            return [self.mav.param_set_encode(VEHICLE_SYSID, 1, name, value, M.MAV_PARAM_TYPE_REAL32).pack(self.mav)]
        if kind == "abandoned_upload":  # MISSION_COUNT, then an item out of order, then nothing
            count = int(rng.integers(2, 20))
            item = self.mav.mission_item_int_encode(
                VEHICLE_SYSID, 1, count - 1, 3, 16, 0, 1, 0, 0, 0, 0, 473977420, 85455940, 10.0, 0
            )
            return [self.mav.mission_count_encode(VEHICLE_SYSID, 1, count, 0).pack(self.mav), item.pack(self.mav)]
        raise ValueError(kind)


def make_frames(n: int, seed: int) -> list[tuple[str, str, bytes]]:
    """``n`` datagrams as (kind, target, bytes); target ``vehicle`` or ``companion``."""
    factory = FrameFactory(seed)
    kinds, shares = zip(*FRAME_MIX.items())
    rng = np.random.default_rng(seed + 1)
    to_companion = (1.0 - VEHICLE_SHARE) / sum(FRAME_MIX[k] for k in COMPANION_KINDS)
    out: list[tuple[str, str, bytes]] = []
    draws = rng.choice(len(kinds), size=n, p=np.array(shares) / sum(shares))
    coins = rng.random(n)
    for k, coin in zip(draws, coins):
        if len(out) >= n:
            break
        kind = kinds[int(k)]
        target = "companion" if kind in COMPANION_KINDS and coin < to_companion else "vehicle"
        for data in factory.build(kind)[: n - len(out)]:
            out.append((kind, target, data))
    return out


def send_frames(frames, vehicle_port: int, companion_port: int, rate_hz: float, stop: threading.Event) -> dict:
    """Send the frames paced at ``rate_hz`` (absolute deadlines, in bursts); returns counts and times."""
    sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    sock.bind(("127.0.0.1", 0))
    sock.setblocking(False)
    targets = {"vehicle": ("127.0.0.1", vehicle_port), "companion": ("127.0.0.1", companion_port)}
    sent = collections.Counter()
    errors = 0
    t0 = time.monotonic()
    for i, (kind, target, data) in enumerate(frames):
        if stop.is_set():
            break
        if i % 10 == 0:
            delay = t0 + i / rate_hz - time.monotonic()
            if delay > 0:
                time.sleep(delay)
            try:  # drain what the vehicle answers (ACKs, requests, broadcasts), never read
                while True:
                    sock.recv(65535)
            except (BlockingIOError, ConnectionRefusedError):
                pass
        try:
            sock.sendto(data, targets[target])
            sent[(target, kind)] += 1
        except BlockingIOError:
            errors += 1
    duration = time.monotonic() - t0
    sock.close()
    return {"sent": sent, "send_errors": errors, "seconds": duration}


# ================================================================ threat payloads
def make_payloads(n: int, seed: int) -> list[tuple[str, bytes, bool]]:
    """``n`` (threat id, payload, valid) tuples: junk, and one in ``VALID_EVERY`` a valid far threat."""
    rng = np.random.default_rng(seed)
    out = []
    for i in range(n):
        tid = f"soak{i % 500}"
        if i % VALID_EVERY == VALID_EVERY - 1:
            threat = Threat(tid, "popup", "local_ned", (2000.0 + i % 7, 2000.0, -20.0), (0.0, 0.0, 0.0), 5.0, 5.0)
            out.append((tid, codec.encode(threat), True))
            continue
        k = i % 5
        if k == 0:
            payload = rng.integers(0, 256, int(rng.integers(0, 200)), dtype=np.uint8).tobytes()
        elif k == 1:
            payload = json.dumps([float(x) for x in rng.normal(size=int(rng.integers(0, 5)))]).encode()
        else:
            data = {
                "v": 1,
                "id": tid,
                "kind": "popup",
                "frame": "local_ned",
                "position": [2000.0, 2000.0, -20.0],
                "radius_m": 5.0,
                "ttl_s": 5.0,
            }
            broken = ["v", "id", "kind", "frame", "position", "radius_m", "ttl_s", "colour"][int(rng.integers(8))]
            data[broken] = {
                "v": 2,
                "id": "other",
                "kind": "ufo",
                "frame": "enu",
                "position": [1.0, NAN, 2.0],
                "radius_m": -1.0,
                "ttl_s": INF,
                "colour": "red",
            }[broken]
            payload = json.dumps(data, allow_nan=True).encode()
        out.append((tid, payload, False))
    return out


def send_payloads(bus: ThreatBus, payloads, rate_hz: float, stop: threading.Event, result: dict) -> None:
    """PUT the payloads at ``rate_hz`` (reliable: congestion blocks rather than drops)."""
    import zenoh

    t0 = time.monotonic()
    sent = 0
    for i, (tid, payload, _) in enumerate(payloads):
        if stop.is_set():
            break
        bus.session.put(bus.key(f"threats/{tid}"), payload, congestion_control=zenoh.CongestionControl.BLOCK)
        sent += 1
        delay = t0 + (i + 1) / rate_hz - time.monotonic()
        if delay > 0:
            time.sleep(delay)
    result.update(sent=sent, seconds=time.monotonic() - t0)


# ================================================================ measurements
def kernel_drops(port: int) -> int | None:
    """Datagrams the kernel dropped at the UDP socket bound to ``port`` (``/proc/net/udp``)."""
    try:
        lines = Path("/proc/net/udp").read_text().splitlines()[1:]
    except OSError:
        return None
    total, found = 0, False
    for line in lines:
        cols = line.split()
        if int(cols[1].split(":")[1], 16) == port:
            total += int(cols[-1])
            found = True
    return total if found else None


def vehicle_counters(log_path: Path) -> dict:
    """The ``link statistics`` the vehicle logs when it stops."""
    for line in reversed(log_path.read_text(errors="replace").splitlines()):
        match = re.search(r"link statistics: (\{.*\})", line)
        if match:
            return ast.literal_eval(match.group(1))
    return {}


def stored_lists(gcs: MavlinkPeer) -> dict:
    """The vehicle's mission and fence as downloaded, or None for a failed download."""
    out = {}
    for name, mission_type in (("mission", M.MAV_MISSION_TYPE_MISSION), ("fence", M.MAV_MISSION_TYPE_FENCE)):
        items = None
        for _ in range(3):
            items = gcs.download(mission_type)
            if items is not None:
                break
        out[name] = (
            None
            if items is None
            else [(i.seq, i.frame, i.command, i.param1, i.param2, i.param3, i.param4, i.x, i.y, i.z) for i in items]
        )
    return out


def companion_port(args: list[str]) -> int:
    url = args[args.index("--connect") + 1]
    return int(url.rsplit(":", 1)[1])


# ================================================================ the run
class _QueueSocket:
    """The vehicle's socket in-process: datagrams in from a list, answers counted and dropped."""

    def __init__(self) -> None:
        self.inbox: collections.deque = collections.deque()
        self.sent = 0

    def recvfrom(self, size: int):
        if not self.inbox:
            raise BlockingIOError
        return self.inbox.popleft()

    def sendto(self, data: bytes, address: tuple) -> int:
        self.sent += 1
        return len(data)

    def close(self) -> None:
        pass


def vehicle_cost(frames, log_dir: Path) -> dict:
    """CPU cost per frame kind of the vehicle's MAVLink input, in-process, on the vehicle's frames.

    The server of ``sim-vehicle`` (hovering on the ground, its log to a file as in the real
    process) handles each datagram through ``_receive``; the process CPU time per kind is measured.
    """
    from heli_model.model import HeliModel
    from sim_vehicle.autopilot import Autopilot
    from sim_vehicle.config import VehicleSettings, replace_path
    from sim_vehicle.mavlink import MavlinkServer

    settings = replace_path(VehicleSettings(), "link.out", ())
    vehicle = Autopilot(HeliModel.default(), settings, (47.397742, 8.545594, 488.0, 0.0), np.random.default_rng(0))
    server = MavlinkServer(vehicle, settings, VEHICLE_SYSID, 0)
    real, server.sock = server.sock, _QueueSocket()
    logger = logging.getLogger("sim_vehicle")
    handler = logging.FileHandler(log_dir / "vehicle_cost.log")
    logger.addHandler(handler)
    logger.propagate = False
    cpu = collections.defaultdict(float)
    count = collections.Counter()
    try:
        for kind, target, data in frames:
            if target != "vehicle":
                continue
            t0 = time.process_time()
            server.sock.inbox.append((data, ("127.0.0.1", 9)))
            server._receive()
            cpu[kind] += time.process_time() - t0
            count[kind] += 1
    finally:
        logger.removeHandler(handler)
        logger.propagate = True
        handler.close()
        real.close()
    total = sum(cpu.values())
    return {
        "per_kind_us": {k: round(cpu[k] / count[k] * 1e6, 1) for k in sorted(count)},
        "frames": sum(count.values()),
        "cpu_s": round(total, 3),
        "frames_per_cpu_s": round(sum(count.values()) / total, 0) if total > 0 else None,
    }


def run(
    frames_n: int, payloads_n: int, rate_hz: float, payload_rate_hz: float, speedup: float = SPEEDUP, seed: int = 11
) -> dict:
    frames = make_frames(frames_n, seed)
    payloads = make_payloads(payloads_n, seed)
    with tempfile.TemporaryDirectory(prefix="soak_") as tmp, TrackListener(rate_hz=5.0) as track:
        out = Path(tmp)
        with flight_processes(out, DEMO_MISSION, speedup=speedup, gcs_out=track.address) as flight:
            mav_port = companion_port(flight.companion.argv)
            with ThreatBus(1, listen=(), connect=(flight.endpoint,)) as bus:
                watcher = FlightWatcher(bus)
                deadline = time.monotonic() + 180
                while not (watcher.status and watcher.status.get("leg", 0) >= 1) and time.monotonic() < deadline:
                    if flight.companion.poll() is not None:
                        raise RuntimeError(f"the companion exited early; see {flight.log}")
                    time.sleep(0.05)
                with MavlinkPeer(flight.vehicle_port, VEHICLE_SYSID, source_system=251) as gcs:
                    before = stored_lists(gcs)
                drops0 = {"vehicle": kernel_drops(flight.vehicle_port), "companion": kernel_drops(mav_port)}
                stop = threading.Event()
                payload_result: dict = {}
                sender = threading.Thread(
                    target=send_payloads, args=(bus, payloads, payload_rate_hz, stop, payload_result), daemon=True
                )
                log.info(
                    "injecting %d frames at %g/s and %d payloads at %g/s",
                    len(frames),
                    rate_hz,
                    len(payloads),
                    payload_rate_hz,
                )
                sender.start()
                frame_result = send_frames(frames, flight.vehicle_port, mav_port, rate_hz, stop)
                sender.join()
                drops1 = {"vehicle": kernel_drops(flight.vehicle_port), "companion": kernel_drops(mav_port)}
                in_flight = flight.companion.poll() is None
                flight.companion.wait(600)
                time.sleep(1.0)
                with MavlinkPeer(flight.vehicle_port, VEHICLE_SYSID, source_system=251) as gcs:
                    after = stored_lists(gcs)
        summary = last_json_line(flight.log) or {}
        record = load_record(flight.record)
        bus_counts = next((e for e in record.events if e.get("name") == "threat_bus"), {})
        decisions = collections.Counter(d.get("kind") for d in record.decisions)
        jitter = next((e for e in record.events if e.get("name") == "setpoint_jitter"), {})
        counters = vehicle_counters(out / "sim_vehicle.log")
        track_t, track_pos = track.samples()
        cost = vehicle_cost(frames, out)
    sent = frame_result["sent"]
    to_vehicle = sum(v for (target, _), v in sent.items() if target == "vehicle")
    to_companion = sum(v for (target, _), v in sent.items() if target == "companion")
    lost = {k: (None if drops0[k] is None or drops1[k] is None else drops1[k] - drops0[k]) for k in drops0}
    valid_sent = sum(1 for _, _, valid in payloads[: payload_result.get("sent", 0)] if valid)
    final = track_pos[-1] if len(track_pos) else np.full(3, np.nan)
    return {
        "frames": {
            "to_vehicle": to_vehicle,
            "to_companion": to_companion,
            "by_kind": {f"{t}/{k}": v for (t, k), v in sorted(sent.items())},
            "send_errors": frame_result["send_errors"],
            "seconds": round(frame_result["seconds"], 2),
            "rate_hz": round((to_vehicle + to_companion) / frame_result["seconds"], 1),
            "vehicle_rate_hz": round(to_vehicle / frame_result["seconds"], 1),
            "still_flying_at_end": in_flight,
        },
        "kernel_drops": lost,
        "vehicle_cost": cost,
        "speedup": speedup,
        "vehicle": counters,
        "mission_unchanged": repr(before) == repr(after) and before.get("mission") is not None,  # NaN == NaN
        "lists_before": before if repr(before) != repr(after) else None,
        "lists_after": after if repr(before) != repr(after) else None,
        "mission_items": None if before.get("mission") is None else len(before["mission"]),
        "fence_items": None if before.get("fence") is None else len(before["fence"]),
        "payloads": {
            "sent": payload_result.get("sent"),
            "valid_sent": valid_sent,
            "seconds": round(payload_result.get("seconds", math.nan), 2),
            "received": bus_counts.get("received"),
            "put": bus_counts.get("put"),
            "rejected": bus_counts.get("rejected"),
            "handler_errors": bus_counts.get("handler_errors"),
            "lost": None
            if bus_counts.get("received") is None
            else payload_result.get("sent", 0) - bus_counts["received"],
        },
        "outcome": summary.get("outcome"),
        "legs": f"{summary.get('legs_reached')}/{summary.get('legs_planned')}",
        "rms_tracking_error_m": summary.get("rms_tracking_error_m"),
        "max_tracking_error_m": summary.get("max_tracking_error_m"),
        "decisions": dict(decisions),
        "setpoint_jitter_p99_ms": jitter.get("p99_ms"),
        "vehicle_disarmed_at_end": track.armed is False,
        "vehicle_final_height_m": None if not np.all(np.isfinite(final)) else round(float(-final[2]), 2),
    }


def ok(r: dict) -> bool:
    """Nothing lost, everything refused, the flight completed and the mission unchanged."""
    v = r["vehicle"]
    p = r["payloads"]
    return (
        r["outcome"] == "completed"
        and r["mission_unchanged"]
        and r["vehicle_disarmed_at_end"]
        and all(d == 0 for d in r["kernel_drops"].values() if d is not None)
        and v.get("packets_in", 0) >= r["frames"]["to_vehicle"]
        and p["lost"] == 0
        and p["put"] == p["valid_sent"]
        and p["rejected"] == p["sent"] - p["valid_sent"]
        and p["handler_errors"] == 0
    )


def table(r: dict) -> str:
    f, v, p = r["frames"], r["vehicle"], r["payloads"]
    kinds = collections.defaultdict(dict)
    for key, n in f["by_kind"].items():
        target, kind = key.split("/")
        kinds[kind][target] = n
    cost = r["vehicle_cost"]
    rows = [
        f"| {kind} | {d.get('vehicle', 0)} | {d.get('companion', 0)} | {cost['per_kind_us'].get(kind, '-')} |"
        for kind, d in kinds.items()
    ]
    drops = r["kernel_drops"]
    return "\n".join(
        [
            f"{f['to_vehicle'] + f['to_companion']} bad MAVLink frames ({f['to_vehicle']} to the vehicle, "
            f"{f['to_companion']} to the companion's MAVLink port) in {f['seconds']:g} s and {p['sent']} threat payloads "
            f"over zenoh in {p['seconds']:g} s, during one flight of `exclusion_zones.plan` (real `sim-vehicle` and "
            f"`companion run` processes, SITL at {r['speedup']:g}x, no MAVLink signing, so no MISSION_CLEAR_ALL: unsigned, "
            "a vehicle obeys it from anyone). Goals: nothing lost, every bad frame counted and refused, the flight "
            "completes, the mission on the vehicle unchanged.",
            "",
            "| frame kind | to the vehicle | to the companion | vehicle CPU per frame (us, in-process) |",
            "|---|---|---|---|",
            *rows,
            "",
            f"The vehicle's MAVLink input costs {cost['cpu_s']:g} s of CPU for these {cost['frames']} frames in-process "
            f"(its log to a file, as in the process): {cost['frames_per_cpu_s']:g} frames per CPU second. In the flight "
            "below they arrived at the rate in the first column; 'kernel drops' are the datagrams the kernel "
            "discarded because a socket's buffer was full (UDP's only way to lose one).",
            "",
            "| vehicle: frames handled per s | packets in | messages in | bad CRC | unknown id | bad data | truncated | "
            "kernel drops vehicle / companion |",
            "|---|---|---|---|---|---|---|---|",
            f"| {f['vehicle_rate_hz']:g} | {v.get('packets_in')} | {v.get('messages_in')} | {v.get('bad_crc')} | "
            f"{v.get('unknown_id')} | {v.get('bad_data')} | {v.get('truncated')} | {drops['vehicle']} / "
            f"{drops['companion']} |",
            "",
            "| threat payloads sent | valid | received by the companion | put | rejected | handler errors | lost |",
            "|---|---|---|---|---|---|---|",
            f"| {p['sent']} | {p['valid_sent']} | {p['received']} | {p['put']} | {p['rejected']} | {p['handler_errors']} "
            f"| {p['lost']} |",
            "",
            "| flight outcome | legs | still flying when the injection ended | vehicle disarmed at the end | mission / "
            "fence items unchanged | RMS / max tracking error (m) | setpoint jitter p99 (ms) |",
            "|---|---|---|---|---|---|---|",
            f"| {r['outcome']} | {r['legs']} | {f['still_flying_at_end']} | {r['vehicle_disarmed_at_end']} | "
            f"{r['mission_unchanged']} ({r['mission_items']} / {r['fence_items']}) | "
            f"{_round(r.get('rms_tracking_error_m'))} / {_round(r.get('max_tracking_error_m'))} | "
            f"{_round(r.get('setpoint_jitter_p99_ms'), 2)} |",
        ]
    )


def _round(value, digits: int = 3):
    return "-" if value is None else round(value, digits)


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--frames", type=int, default=100_000, help="MAVLink datagrams to send")
    parser.add_argument("--payloads", type=int, default=10_000, help="threat payloads to PUT")
    parser.add_argument(
        "--rate",
        type=float,
        default=2000.0,
        help="datagrams per second (the injection must end before the flight does)",
    )
    parser.add_argument(
        "--payload-rate",
        type=float,
        default=None,
        help="threat payloads per second (default: spread over the frames' injection)",
    )
    parser.add_argument("--speedup", type=float, default=SPEEDUP, help="SITL speed-up of the flight")
    parser.add_argument("--quick", action="store_true", help="10,000 frames and 1,000 payloads")
    args = parser.parse_args()
    logging.basicConfig(level=logging.INFO, format="%(asctime)s %(levelname)s %(name)s: %(message)s")
    frames_n, payloads_n = (10_000, 1_000) if args.quick else (args.frames, args.payloads)
    payload_rate = args.payload_rate or payloads_n * args.rate / max(frames_n, 1)
    result = run(frames_n, payloads_n, args.rate, payload_rate, args.speedup)
    text = table(result)
    log.info("result:\n%s", text)
    bench = REPO / "out" / "bench"
    bench.mkdir(parents=True, exist_ok=True)
    (bench / "soak.json").write_text(json.dumps(result, indent=2, default=str))
    (REPO / "docs" / "benchmarks" / "soak.md").write_text(
        "# Soak: bad MAVLink frames and threat payloads during a flight\n\n" + text + "\n"
    )
    return 0 if ok(result) else 1


if __name__ == "__main__":
    sys.exit(main())
