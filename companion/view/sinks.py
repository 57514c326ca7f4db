"""Where the flight record goes: a JSON Lines file, an MCAP file, a live Foxglove server.

``open_record_sinks`` picks by the record's suffix (``.mcap``: MCAP, else JSON Lines) and adds
the live server when asked; ``RecordSinks`` gives them the one ``write`` / ``close`` interface.

Writing a line costs the event loop up to a few milliseconds (the scene's entities, JSON, the
MCAP chunk): ``RecordSinks.pace`` makes the lines wait for the setpoint stream's next send and
be written right after it, so that writing never delays a send (the jitter benchmark's
``process_fifo_daemon_foxglove``).
"""

from __future__ import annotations

import logging
from collections.abc import Callable
from pathlib import Path

from companion.errors import ConfigError
from companion.record.flight_record import FlightRecorder

__all__ = ["RecordSinks", "open_record_sinks", "parse_foxglove_address"]

log = logging.getLogger(__name__)
DEFAULT_FOXGLOVE_HOST = "127.0.0.1"


class RecordSinks:
    """Every record line to every sink; one sink failing is logged and the others go on."""

    def __init__(self, sinks: list) -> None:
        self.sinks = sinks
        self._after_tick: Callable[[Callable[[], None]], None] | None = None
        self._pending: list[tuple[str, dict]] = []

    def pace(self, call_after_next_tick: Callable[[Callable[[], None]], None] | None) -> None:
        """From now on, write each line right after the stream's next send
        (``call_after_next_tick``: ``SetpointStreamer.call_after_next_tick``; call ``write`` on
        the event loop); None: at once."""
        self._after_tick = call_after_next_tick
        if call_after_next_tick is None:
            self.flush()

    def write(self, line_type: str, /, **fields) -> None:
        if self._after_tick is None:
            self._write(line_type, fields)
            return
        if not self._pending:
            self._after_tick(self.flush)
        self._pending.append((line_type, fields))

    def flush(self) -> None:
        """Write the lines waiting for the stream's next send now."""
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
            except Exception:                        # pragma: no cover - best effort at exit
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


def open_record_sinks(record_path: str | Path | None, foxglove: tuple[str, int] | None = None,
                      horizon_s: float = 10.0, uncertainty_m_s: float = 0.3) -> RecordSinks:
    """The sinks for ``--record`` (MCAP when it ends in ``.mcap``) and ``--foxglove``."""
    sinks: list = []
    mcap = record_path is not None and str(record_path).endswith(".mcap")
    if record_path is not None and not mcap:
        sinks.append(FlightRecorder(record_path))
    if mcap or foxglove is not None:
        from companion.view.publisher import FlightView            # foxglove-sdk only when used

        if mcap:
            Path(record_path).parent.mkdir(parents=True, exist_ok=True)
        sinks.append(FlightView(record_path if mcap else None, foxglove, horizon_s, uncertainty_m_s))
    return RecordSinks(sinks)
