"""Threats in and decisions out over the wire (DESIGN 6): the zenoh ``ThreatBus`` (``bus`` and
its inbound, outbound and client parts), the validated JSON payload (``codec``), the sources'
access rules (``access``), one received sample (``update``) and ADS-B reports as threats
(``adsb``). The I/O edge of the threat layer."""
