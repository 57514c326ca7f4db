"""The flight as Foxglove channels: to an MCAP file, to a live WebSocket server, or both.

``FlightView`` takes the flight record's lines (``write(line_type, **fields)``, the interface of
``companion.record.flight_record.FlightRecorder``), logs their content on typed JSON channels and draws the
scene: the static world, the active path, the planned legs and the M-GART alternatives, the
threats as spheres moving along their predicted tubes, the helicopter, and a map fix. Both sinks
share one ``foxglove.Context``, so a live client and the MCAP file see the same messages.
Logging costs a few microseconds in the caller's thread (foxglove-sdk's writer is native).

On a live server whose vehicle is fed from the telemetry (``live``: a
``companion.view.live.LiveServer`` with a ``VehicleFeed``), the helicopter (``/tf``, the map's
fix, its shape) is the feed's, drawn as each state arrives; the record's samples then only
fill the JSON channels (``/vehicle/state`` ... , what ``companion report`` reads back). Without
one, the samples place the helicopter too.
"""

from __future__ import annotations

import logging
import threading
import time
from collections.abc import Callable
from pathlib import Path

import foxglove
import numpy as np
from foxglove.channels import FrameTransformChannel, LocationFixChannel, LogChannel, SceneUpdateChannel
from foxglove.mcap import MCAPWriteOptions
from foxglove.messages import LocationFix, Log, LogLevel, SceneEntityDeletion, SceneEntityDeletionType, SceneUpdate

from companion.record.flight_record import jsonable
from companion.view import channels as ch
from companion.view import scene
from companion.view.live import FIX_PERIOD_S, REPUBLISH_PERIOD_S, LiveServer
from heli_common.frames import LocalFrame

__all__ = ["FlightView"]

log = logging.getLogger(__name__)

ACTIVE_PATH_RGBA = (0.1, 0.85, 0.3, 1.0)
PLANNED_RGBA = (0.6, 0.6, 0.6, 0.6)
ALTERNATIVE_RGBA = (0.3, 0.55, 1.0, 0.7)
#: MCAP chunk size: a companion killed mid-flight loses at most the chunk being filled.
CHUNK_BYTES = 64 * 1024


class FlightView:
    """Publishes the flight record's lines as Foxglove channels.

    Parameters
    ----------
    mcap_path : str or Path, optional
        Write every channel to this MCAP file (overwritten).
    server : tuple of (str, int), optional
        Serve the channels live over the Foxglove WebSocket protocol on (host, port); port 0
        picks a free one (``port``). Stopped by ``close``.
    live : LiveServer, optional
        Log into this live server instead (it outlives the view: ``close`` leaves it up), whose
        ``VehicleFeed`` draws the helicopter.
    horizon_s, uncertainty_m_s : float
        How far ahead a threat's tube is drawn (s) and how its radius grows with age (m/s), as
        the threat settings say.
    clock_ns : callable
        Wall clock in nanoseconds (log times; kept increasing).
    """

    def __init__(
        self,
        mcap_path: str | Path | None = None,
        server: tuple[str, int] | None = None,
        horizon_s: float = 10.0,
        uncertainty_m_s: float = 0.3,
        clock_ns: Callable[[], int] = time.time_ns,
        live: LiveServer | None = None,
    ) -> None:
        self._server = LiveServer(*server) if server and live is None else None  # owned
        self._draws_vehicle = live is None
        live = live or self._server
        self.context = live.context if live is not None else foxglove.Context()
        self._mcap = (
            foxglove.open_mcap(
                Path(mcap_path),
                allow_overwrite=True,
                context=self.context,
                writer_options=MCAPWriteOptions(chunk_size=CHUNK_BYTES),
            )
            if mcap_path
            else None
        )
        self.port = live.port if live is not None else None
        self._clock_ns, self._last_ns = clock_ns, 0
        self._lock = threading.Lock()
        self._json = {
            topic: foxglove.Channel(topic, schema=ch.json_schema(topic, props), context=self.context)
            for topic, props in [*ch.RECORD_TOPICS.values(), *ch.SAMPLE_TOPICS.items()]
        }
        self._scene = {
            t: SceneUpdateChannel(t, context=self.context)
            for t in (ch.SCENE_WORLD, ch.SCENE_PATHS, ch.SCENE_THREATS, ch.SCENE_VEHICLE)
        }
        self._tf = FrameTransformChannel(ch.TRANSFORMS, context=self.context)
        self._fix = LocationFixChannel(ch.LOCATION, context=self.context)
        self._log = LogChannel(ch.LOG, context=self.context)
        self._tube = (horizon_s, uncertainty_m_s)
        self._home: LocalFrame | None = None
        self._world: dict | None = None
        self._paths: dict[str, list] = {}  # path_id -> NED polyline (plans, decisions)
        self._planned: list[str] = []  # the mission's legs, in order
        self._alternatives: list = []
        self._active: str | None = None
        self._threats: dict[str, dict] = {}
        self._republished_s = -np.inf
        self._fix_t_s = -np.inf

    # -- the record interface -------------------------------------------------------------
    def write(self, line_type: str, /, **fields) -> None:
        """Publish one record line (see ``companion.record.flight_record``)."""
        fields = jsonable(fields)
        with self._lock:
            now_ns = self._now_ns()
            if line_type == "sample":
                self._sample(fields, now_ns)
                return
            topic = ch.RECORD_TOPICS.get(line_type, (None,))[0]
            if topic is not None:
                self._json[topic].log(fields, log_time=now_ns)
            handler = getattr(self, f"_on_{line_type}", None)
            if handler is not None:
                handler(fields, now_ns)

    def close(self) -> None:
        """Finish the MCAP file and stop the server it started (idempotent; a ``live`` server stays up)."""
        with self._lock:
            if self._mcap is not None:
                self._mcap.close()
                self._mcap = None
            if self._server is not None:
                self._server.close()
                self._server = None

    # -- per line type --------------------------------------------------------------------
    def _on_header(self, fields: dict, now_ns: int) -> None:
        if fields.get("home_lla"):
            self._home = LocalFrame(*fields["home_lla"][:3])

    def _on_world(self, fields: dict, now_ns: int) -> None:
        self._world = fields
        self._publish_world(now_ns)

    def _on_plan(self, fields: dict, now_ns: int) -> None:
        self._paths[fields["path_id"]] = fields["path_ned_m"]
        if fields["path_id"] not in self._planned:
            self._planned.append(fields["path_id"])
        self._publish_paths(now_ns)

    def _on_alternatives(self, fields: dict, now_ns: int) -> None:
        self._alternatives = fields.get("paths") or []
        self._publish_paths(now_ns)

    def _on_decision(self, fields: dict, now_ns: int) -> None:
        if fields.get("path_id") and fields.get("path_ned_m"):
            self._paths[fields["path_id"]] = fields["path_ned_m"]
        level = LogLevel.Warning if fields.get("kind") in ("rejected", "hold", "evade") else LogLevel.Info
        self._text(level, f"decision {fields.get('kind')}: {fields.get('reason', '')}", now_ns)

    def _on_event(self, fields: dict, now_ns: int) -> None:
        if fields.get("name") == "frames" and fields.get("home_lla"):
            self._home = LocalFrame(*fields["home_lla"][:3])
        details = ", ".join(f"{k}={v}" for k, v in fields.items() if k not in ("name", "t_s"))
        self._text(LogLevel.Info, f"{fields.get('name')}" + (f": {details}" if details else ""), now_ns)

    def _on_threat(self, fields: dict, now_ns: int) -> None:
        if fields.get("removed"):
            self._threats.pop(fields.get("id"), None)
        elif fields.get("position_ned_m") is not None:
            self._threats[fields["id"]] = fields
        self._publish_threats(fields.get("t_s", 0.0), now_ns)

    def _sample(self, fields: dict, now_ns: int) -> None:
        for topic, props in ch.SAMPLE_TOPICS.items():
            self._json[topic].log({k: fields.get(k) for k in props if k in fields}, log_time=now_ns)
        t_s, pos = fields["t_s"], fields.get("pos_ned_m")
        if pos is None:
            return
        if self._draws_vehicle:
            self._draw_vehicle(t_s, pos, fields.get("euler_rad"), now_ns)
        path_changed = bool(fields.get("path_id")) and fields["path_id"] != self._active
        self._active = fields.get("path_id") or self._active
        if self._threats:
            self._publish_threats(t_s, now_ns)
        wall_s = now_ns * 1e-9
        republish = wall_s - self._republished_s >= REPUBLISH_PERIOD_S  # for clients that join late
        if republish:
            self._republished_s = wall_s
            if self._draws_vehicle:
                self._scene[ch.SCENE_VEHICLE].log(SceneUpdate(entities=[scene.vehicle_entity(t_s)]), log_time=now_ns)
            self._publish_world(now_ns)
        if republish or path_changed:
            self._publish_paths(now_ns)

    def _draw_vehicle(self, t_s: float, pos: list, euler_rad: list | None, now_ns: int) -> None:
        """The helicopter from a sample (no live feed): ``/tf`` and the map's fix."""
        self._tf.log(scene.vehicle_transform(pos, euler_rad, t_s), log_time=now_ns)
        if self._home is not None and t_s - self._fix_t_s >= FIX_PERIOD_S:
            self._fix_t_s = t_s
            lat, lon, alt = (float(np.asarray(v).ravel()[0]) for v in self._home.to_lla(*pos))
            self._fix.log(
                LocationFix(
                    timestamp=scene.timestamp(t_s), frame_id=scene.MAP_FRAME, latitude=lat, longitude=lon, altitude=alt
                ),
                log_time=now_ns,
            )

    # -- scene ----------------------------------------------------------------------------
    def _publish_world(self, now_ns: int) -> None:
        if self._world is not None:
            entities = scene.obstacle_entities(self._world, now_ns * 1e-9)
            self._scene[ch.SCENE_WORLD].log(SceneUpdate(entities=entities), log_time=now_ns)

    def _publish_paths(self, now_ns: int) -> None:
        t = now_ns * 1e-9
        entities = [
            scene.path_entity(f"planned/{pid}", self._paths[pid], t, PLANNED_RGBA, 1.5)
            for pid in self._planned
            if pid != self._active
        ]
        entities += [
            scene.path_entity(f"alternative/{i}", p, t, ALTERNATIVE_RGBA, 1.5) for i, p in enumerate(self._alternatives)
        ]
        if self._active in self._paths:
            entities.append(scene.path_entity("active", self._paths[self._active], t, ACTIVE_PATH_RGBA, 4.0))
        self._scene[ch.SCENE_PATHS].log(_replace_all(entities), log_time=now_ns)

    def _publish_threats(self, t_s: float, now_ns: int) -> None:
        horizon_s, uncertainty_m_s = self._tube
        entities = [
            scene.threat_entity(
                tid,
                th["position_ned_m"],
                th.get("velocity_ned_m_s") or (0, 0, 0),
                th.get("radius_m", 1.0),
                max(0.0, t_s - th.get("t_s", t_s)),
                t_s,
                horizon_s=horizon_s,
                uncertainty_m_s=uncertainty_m_s,
            )
            for tid, th in self._threats.items()
        ]
        self._scene[ch.SCENE_THREATS].log(_replace_all(entities), log_time=now_ns)

    def _text(self, level: LogLevel, message: str, now_ns: int) -> None:
        self._log.log(
            Log(timestamp=scene.timestamp(now_ns * 1e-9), level=level, message=message, name="companion"),
            log_time=now_ns,
        )

    def _now_ns(self) -> int:
        self._last_ns = max(self._last_ns + 1, self._clock_ns())
        return self._last_ns


def _replace_all(entities: list) -> SceneUpdate:
    """An update that clears the topic's entities and draws ``entities`` instead."""
    return SceneUpdate(deletions=[SceneEntityDeletion(type=SceneEntityDeletionType.All)], entities=entities)
