"""Emergency threat management (paper section 3.3, DESIGN sections 6 and 7).

- ``model``: ``Threat`` (one pop-up or moving threat) and ``ThreatTable`` (PUT, DELETE, expiry,
  constant-velocity prediction).
- ``codec``: the JSON payload of ``uav/<sysid>/threats/<id>``, version 1, validated strictly.
- ``bus``: ``ThreatBus``, the zenoh session (imports zenoh; I/O edge), made of ``bus_inbound``
  (threats in), ``bus_outbound`` (status, events, path out; the threat list served) and
  ``bus_client`` (``companion threat``); ``update``: ``ThreatUpdate``, one sample as received.
- the policy, one module per step of DESIGN section 7 (all pure):
  ``prediction`` (threats -> space-time tubes), ``spacetime`` (the one check),
  ``evasion`` (escape library), ``retime`` (time warps of the active path), ``join`` (the one
  splice), ``alternatives`` (M-GART switching targets), ``candidates`` (each strategy's
  candidates), ``decision`` (the cost, ``Decision``) and ``policy`` (``ThreatManager``).
- ``reactor``: ``ThreatReactor``, the daemon's side (zenoh in, decisions out; I/O edge), made of
  ``reactor_decisions`` (decide, monitor, resume, tell) and ``reactor_legs`` (legs,
  alternatives, the published path); ``statustext``: what the ground stations are told.
- ``scenario``: scripted threat sequences (``companion threat play``).
- ``settings``: ``ThreatSettings`` and ``ZenohSettings``.

This package's ``__init__`` imports neither zenoh nor the planners.
"""

from companion.threats.codec import decode, encode
from companion.threats.model import Threat, ThreatTable

__all__ = ["Threat", "ThreatTable", "decode", "encode"]
