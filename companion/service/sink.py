"""What the daemon's flight tells, and where (the executor's ``FlightSink`` in real time).

``DaemonSink`` writes every event and decision to the flight record (``--record``: MCAP or
JSON Lines, and the live Foxglove view), logs the events and publishes the status with each,
and hands decisions and paths to the threat reactor: ``uav/<sysid>/events``, ``path`` and a
STATUSTEXT to the ground stations (``companion.threats.reactor``). Traffic alerts
(``companion.flight.alerting``) go to the ground stations as ArduPilot's AP_Avoidance sends them
(``COLLISION``, and a STATUSTEXT when first alerted, raised or cleared) and to the record
(``alert`` lines, ``/flight/alert`` in Foxglove).
"""

from __future__ import annotations

import logging

__all__ = ["DaemonSink"]

log = logging.getLogger(__name__)


class DaemonSink:
    """The daemon's ``FlightSink`` (see the module docstring).

    Parameters
    ----------
    daemon : CompanionDaemon
        Read for its ``recorder``, ``threats``, ``clock`` and ``status()`` when something is
        told (each is set up during the flight's start).
    """

    def __init__(self, daemon) -> None:
        self.daemon = daemon

    def record(self, line_type: str, /, **fields) -> None:
        recorder = self.daemon.recorder
        if recorder is not None:
            recorder.write(line_type, **fields)

    def event(self, name: str, **fields) -> None:
        """Log and record one event (leg reached, link lost ...) and publish the new status."""
        d = self.daemon
        log.info("%s %s", name, " ".join(f"{k}={v}" for k, v in fields.items()))
        self.record("event", name=name, t_s=d.clock.now_s(), **fields)
        if d.threats is not None:
            d.threats.publish_status(d.status())

    def decision(self, decision, event: dict) -> None:
        if self.daemon.threats is not None:
            self.daemon.threats.tell_decision(decision, event)

    def alert(self, alert) -> None:
        """A traffic alert: recorded, then ``COLLISION`` and its STATUSTEXT through the vehicle."""
        d = self.daemon
        self.record("alert", **alert.as_record())
        if alert.statustext is not None:
            log.warning("traffic alert: %s", alert.statustext[0])
            if d.threats is not None:
                d.threats.tell(*alert.statustext)
        d.send_message("COLLISION", alert.collision)

    def path(self, reference, alternatives, leg_index: int) -> None:
        if self.daemon.threats is not None:
            self.daemon.threats.publish_path(reference, alternatives, leg_index)
