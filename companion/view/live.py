"""The live view's server and the vehicle's state on it, as the vehicle's telemetry arrives.

``LiveView`` is both on one link (``companion run --foxglove``, ``companion serve``).
``LiveServer`` is a Foxglove WebSocket server (``foxglove.sdk.v1``) and the ``foxglove.Context``
its channels live in; it can outlive a flight (``companion serve`` keeps one up between
flights) while each flight's ``FlightView`` logs the record's channels into the same context.

``VehicleFeed`` listens to the link (``VehicleLink.inbound.listen``: on the gate's thread, as
each frame is read) and publishes, with the vehicle's own ``time_boot_ms``:

- ``/vehicle/telemetry``: each LOCAL_POSITION_NED, as position and velocity about the planning
  home (the vehicle's local frame before a flight has set one), with the last ATTITUDE;
- ``/tf``: ``map`` -> ``base_link`` from the same message (the helicopter in the 3D panel);
- ``/vehicle/location``: GLOBAL_POSITION_INT as a map fix, at most every ``FIX_PERIOD_S`` of
  vehicle time;
- ``/scene/vehicle``: the helicopter's shape, every ``REPUBLISH_PERIOD_S`` (clients that join late).

Nothing of it waits for the event loop, the flight's schedule or the record: the viewer sees a
state as soon as the companion has read it. Logging a message costs the gate's thread some tens
of microseconds (foxglove-sdk's channels are native and thread-safe).
"""

from __future__ import annotations

import logging
import time
from collections.abc import Callable

import foxglove
from foxglove.channels import FrameTransformChannel, LocationFixChannel, SceneUpdateChannel
from foxglove.messages import LocationFix, SceneUpdate

from companion.link.telemetry import finite_fields
from companion.view import channels as ch
from companion.view import scene

__all__ = ["LiveServer", "LiveView", "VehicleFeed", "FIX_PERIOD_S", "REPUBLISH_PERIOD_S"]

log = logging.getLogger(__name__)

#: The map's fix is sent at most this often (s of vehicle time): a map panel needs no more.
FIX_PERIOD_S = 0.5
#: The helicopter's shape is sent again this often (s of wall clock), for clients that join late.
REPUBLISH_PERIOD_S = 2.0
#: The messages the feed listens to.
LISTENED = ("LOCAL_POSITION_NED", "ATTITUDE", "GLOBAL_POSITION_INT")


class LiveServer:
    """A Foxglove WebSocket server on (host, port) and the context of its channels.

    Parameters
    ----------
    host : str
    port : int
        0 picks a free one (``port`` after start).
    """

    def __init__(self, host: str, port: int) -> None:
        self.context = foxglove.Context()
        self.host = host
        self._server = foxglove.start_server(name="companion", host=host, port=port, context=self.context)
        self.port = self._server.port

    @property
    def url(self) -> str:
        return f"ws://{self.host}:{self.port}"

    def close(self) -> None:
        """Stop the server (idempotent)."""
        if self._server is not None:
            self._server.stop()
            self._server = None


class VehicleFeed:
    """The vehicle's state on a live view, from the link's telemetry (see the module docstring).

    Parameters
    ----------
    context : foxglove.Context
        The live server's (``LiveServer.context``).
    frames : callable () -> LinkFrames
        The link's frames now (``VehicleLink.frames``): positions go about the planning home.
    sysid : callable () -> int or None
        The vehicle's system id (``VehicleLink.target_system``; None: not known yet, nothing is
        published): other systems' telemetry on the same link is left out.
    clock_ns : callable
        Wall clock in nanoseconds (log times).
    """

    def __init__(
        self,
        context: foxglove.Context,
        frames: Callable,
        sysid: Callable[[], int | None],
        clock_ns: Callable[[], int] = time.time_ns,
    ) -> None:
        self._frames, self._sysid, self._clock_ns = frames, sysid, clock_ns
        self._state = foxglove.Channel(
            ch.TELEMETRY, schema=ch.json_schema(ch.TELEMETRY, ch.TELEMETRY_PROPERTIES), context=context
        )
        self._tf = FrameTransformChannel(ch.TRANSFORMS, context=context)
        self._fix = LocationFixChannel(ch.LOCATION, context=context)
        self._shape = SceneUpdateChannel(ch.SCENE_VEHICLE, context=context)
        self._euler: list[float] | None = None
        self._seq = 0
        self._fix_due_ms = 0
        self._shape_due_ns = 0
        self._stops: list[Callable[[], None]] = []

    @property
    def published(self) -> int:
        """How many states ``/vehicle/telemetry`` has carried."""
        return self._seq

    def attach(self, inbound) -> None:
        """Listen to ``inbound`` (``VehicleLink.inbound``) until ``detach``."""
        handlers = (self.on_local_position, self.on_attitude, self.on_global_position)
        self._stops += [inbound.listen(name, handler) for name, handler in zip(LISTENED, handlers)]

    def detach(self) -> None:
        """Stop listening (idempotent)."""
        while self._stops:
            self._stops.pop()()

    def _own(self, fields: dict) -> bool:
        sysid = self._sysid()
        return sysid is not None and fields.get("_sysid") == sysid

    # -- on the gate's thread ---------------------------------------------------------------
    def on_attitude(self, fields: dict) -> None:
        """ATTITUDE: the attitude the next state carries."""
        if self._own(fields):
            euler = finite_fields(fields, "roll", "pitch", "yaw")
            self._euler = euler if euler is not None else self._euler

    def on_local_position(self, fields: dict) -> None:
        """LOCAL_POSITION_NED: one state on ``/vehicle/telemetry`` and ``/tf``."""
        values = finite_fields(fields, "x", "y", "z", "vx", "vy", "vz", "time_boot_ms")
        if values is None or not self._own(fields):
            return
        frames = self._frames()
        boot_ms = int(values[6])
        now_ns = self._clock_ns()
        pos = frames.to_home_floats(values[:3])
        self._seq += 1
        self._state.log(
            {
                "time_boot_ms": boot_ms,
                "t_s": boot_ms * 1e-3,
                "seq": self._seq,
                "pos_ned_m": pos,
                "vel_ned_m_s": values[3:6],
                "euler_rad": self._euler,
                "frame": "home" if frames.home_lla is not None else "vehicle_local",
            },
            log_time=now_ns,
        )
        self._tf.log(scene.vehicle_transform(pos, self._euler, boot_ms * 1e-3), log_time=now_ns)
        if now_ns >= self._shape_due_ns:
            self._shape_due_ns = now_ns + int(REPUBLISH_PERIOD_S * 1e9)
            self._shape.log(SceneUpdate(entities=[scene.vehicle_entity(boot_ms * 1e-3)]), log_time=now_ns)

    def on_global_position(self, fields: dict) -> None:
        """GLOBAL_POSITION_INT: the map's fix (at most every ``FIX_PERIOD_S`` of vehicle time)."""
        values = finite_fields(fields, "lat", "lon", "alt", "time_boot_ms")
        if values is None or not self._own(fields):
            return
        period_ms = FIX_PERIOD_S * 1e3
        if self._fix_due_ms - period_ms <= values[3] < self._fix_due_ms:  # earlier: the vehicle rebooted
            return
        self._fix_due_ms = values[3] + period_ms
        self._fix.log(
            LocationFix(
                timestamp=scene.timestamp(values[3] * 1e-3),
                frame_id=scene.MAP_FRAME,
                latitude=values[0] * 1e-7,
                longitude=values[1] * 1e-7,
                altitude=values[2] * 1e-3,
            ),
            log_time=self._clock_ns(),
        )


class LiveView:
    """A live server with the vehicle of ``link`` on it (``LiveServer`` and ``VehicleFeed``).

    Parameters
    ----------
    link : companion.link.vehicle.VehicleLink
        Connected or not: the feed hears every connection from now on.
    host : str
    port : int
        0 picks a free one.
    """

    def __init__(self, link, host: str, port: int) -> None:
        self.server = LiveServer(host, port)
        self.feed = VehicleFeed(self.server.context, frames=lambda: link.frames, sysid=lambda: link.target_system)
        self.feed.attach(link.inbound)
        log.info("Foxglove live view: %s (Foxglove: open connection, Foxglove WebSocket)", self.server.url)

    @property
    def port(self) -> int:
        return self.server.port

    def close(self) -> None:
        """Stop feeding and stop the server (idempotent)."""
        self.feed.detach()
        self.server.close()
