"""Emergency threat management (paper section 3.3, DESIGN sections 6 and 7).

- ``model``: ``Threat`` (one pop-up or moving threat) and ``ThreatTable`` (PUT, DELETE, expiry,
  constant-velocity prediction).
- ``transport``: the wire (zenoh ``ThreatBus``, the validated JSON ``codec``, ``access`` rules,
  ``update``, ADS-B ``adsb``): the I/O edge.
- ``decision``: the policy, one module per step of DESIGN section 7 (all pure).
- ``reactor``: ``ThreatReactor``, the daemon's side (zenoh in, decisions out; I/O edge);
  ``statustext``: what the ground stations are told.
- ``snapshot``: the threats held, on disk, for ``companion run --resume``.
- ``scenario``: scripted threat sequences (``companion threat play``).
- ``settings``: ``ThreatSettings`` and ``ZenohSettings``.

This package's ``__init__`` imports neither zenoh nor the planners.
"""

from companion.threats.model import Threat, ThreatTable
from companion.threats.transport.codec import decode, encode

__all__ = ["Threat", "ThreatTable", "decode", "encode"]
