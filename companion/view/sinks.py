"""Where the flight record goes: a JSON Lines file, an MCAP file, a live Foxglove server.

``open_record_sinks`` picks by the record's suffix (``.mcap``: MCAP, else JSON Lines) and adds
the live server when asked; ``RecordSinks`` gives them the one ``write`` / ``close`` interface.

Writing a line costs the event loop up to a few milliseconds (the scene's entities, JSON, the
MCAP chunk): ``RecordSinks.pace`` makes the lines wait for ``flush`` (the daemon's schedule
task ``record_write``, right after a setpoint), so that writing never delays a send (the jitter
benchmark's ``process_fifo_daemon_foxglove``).
"""

from __future__ import annotations

import logging
from pathlib import Path

from companion.errors import ConfigError
from companion.extras import require
from companion.record.flight_record import FlightRecorder

__all__ = ["RecordSinks", "open_record_sinks", "parse_foxglove_address"]

log = logging.getLogger(__name__)
DEFAULT_FOXGLOVE_HOST = "127.0.0.1"


class RecordSinks:
    """Every record line to every sink; one sink failing is logged and the others go on."""

    def __init__(self, sinks: list) -> None:
        self.sinks = sinks
        self.paced = False
        self._pending: list[tuple[str, dict]] = []

    def pace(self, paced: bool) -> None:
        """From now on, keep each line until ``flush`` (True: the daemon's schedule flushes
        right after its setpoints), or write it at once (False: what waits is written now)."""
        self.paced = bool(paced)
        if not paced:
            self.flush()

    def write(self, line_type: str, /, **fields) -> None:
        if not self.paced:
            self._write(line_type, fields)
            return
        self._pending.append((line_type, fields))

    def flush(self) -> None:
        """Write the lines that wait now."""
        pending, self._pending = self._pending, []
        for line_type, fields in pending:
            self._write(line_type, fields)

    def _write(self, line_type: str, fields: dict) -> None:
        for sink in self.sinks:
            sink.write(line_type, **fields)

    def close(self) -> None:
        """Write what waits, then close every sink."""
        self.flush()
        for sink in self.sinks:
            try:
                sink.close()
            except Exception:  # pragma: no cover - best effort at exit
                log.exception("closing %s", type(sink).__name__)


def parse_foxglove_address(text: str, name: str = "--foxglove") -> tuple[str, int]:
    """``[HOST:]PORT`` -> (host, port); port 0 picks a free port.

    Raises
    ------
    ConfigError
        Naming ``name`` and the text when it is not ``[HOST:]PORT``.
    """
    host, _, port = str(text).rpartition(":")
    if not port.isdigit() or not 0 <= int(port) <= 65535:
        raise ConfigError(f"{name}: expected [HOST:]PORT (e.g. 8765 or 0.0.0.0:8765), got {text!r}")
    return host or DEFAULT_FOXGLOVE_HOST, int(port)


def open_record_sinks(
    record_path: str | Path | None,
    foxglove: tuple[str, int] | None = None,
    horizon_s: float = 10.0,
    uncertainty_m_s: float = 0.3,
    live=None,
) -> RecordSinks:
    """The sinks for ``--record`` (MCAP when it ends in ``.mcap``) and ``--foxglove``.

    Parameters
    ----------
    record_path : path, optional
    foxglove : (host, port), optional
        A live server of the flight's own (stopped with the sinks).
    horizon_s, uncertainty_m_s : float
        The threat tubes' (``FlightView``).
    live : companion.view.live.LiveServer, optional
        A live server that outlives the flight, instead of ``foxglove`` (left up by ``close``).

    Raises
    ------
    companion.extras.MissingExtra
        For an MCAP record or the live view without foxglove-sdk (the ``view`` extra).
    """
    sinks: list = []
    mcap = record_path is not None and str(record_path).endswith(".mcap")
    if record_path is not None and not mcap:
        sinks.append(FlightRecorder(record_path))
    if mcap or foxglove is not None or live is not None:
        require("view", "foxglove")  # foxglove-sdk only when used
        from companion.view.publisher import FlightView

        if mcap:
            Path(record_path).parent.mkdir(parents=True, exist_ok=True)
        sinks.append(
            FlightView(
                record_path if mcap else None,
                None if live is not None else foxglove,
                horizon_s,
                uncertainty_m_s,
                live=live,
            )
        )
    return RecordSinks(sinks)
