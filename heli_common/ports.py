"""The UDP ports vehicle instance N and its companion meet on (as PX4 SITL numbers them): one
source for ``sim-vehicle --instance N`` and ``companion run --instance N``; and a free loopback
port for the tools that start processes (``companion demo``, ``companion fleet up``)."""

import socket

#: A ground station's port (QGroundControl's default): every instance sends it telemetry.
GCS_PORT = 14550
#: The companion of instance N listens on ``COMPANION_BASE_PORT + N``.
COMPANION_BASE_PORT = 14540


def companion_port(instance: int) -> int:
    """The UDP port of the companion of vehicle ``instance``."""
    return COMPANION_BASE_PORT + int(instance)


def free_port(kind: int = socket.SOCK_DGRAM) -> int:
    """A loopback port that is free now (UDP by default)."""
    with socket.socket(socket.AF_INET, kind) as sock:
        sock.bind(("127.0.0.1", 0))
        return int(sock.getsockname()[1])
