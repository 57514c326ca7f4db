"""Emergency threat management (paper section 3.3, DESIGN sections 6 and 7).

- ``model``: ``Threat`` (one pop-up or moving threat) and ``ThreatTable`` (PUT, DELETE, expiry,
  constant-velocity prediction).
- ``codec``: the JSON payload of ``uav/<sysid>/threats/<id>``, version 1, validated strictly.
- ``bus``: ``ThreatBus``, the zenoh session (imports zenoh; I/O edge).
- ``manager``: ``ThreatManager``, the pure replan / switch / hold policy.
- ``scenario``: scripted threat sequences (``companion threat play``).
- ``settings``: ``ThreatSettings`` and ``ZenohSettings``.

This package's ``__init__`` imports neither zenoh nor the planners.
"""

from companion.threats.codec import decode, encode
from companion.threats.model import Threat, ThreatTable

__all__ = ["Threat", "ThreatTable", "decode", "encode"]
