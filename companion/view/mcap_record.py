"""A flight's MCAP file read back as a ``FlightRecord`` (what ``companion report`` draws).

Only the companion's JSON channels are read (``companion.view.channels``); the scene channels
are for Foxglove. ``load_flight`` opens either format by its suffix: ``.mcap``, or the JSON
Lines record of ``companion.record.flight_record``.
"""

from __future__ import annotations

import json
import logging
import struct
from pathlib import Path

from companion.errors import CompanionError
from companion.extras import require
from companion.record.flight_record import SAMPLE_KEYS, FlightRecord, load_record, samples_from_columns
from companion.view import channels as ch

__all__ = ["load_mcap_record", "load_flight"]

log = logging.getLogger(__name__)

_LINE_TYPES = {topic: line_type for line_type, (topic, _) in ch.RECORD_TOPICS.items()}
_LISTS = {
    "plan": "plans",
    "decision": "decisions",
    "alternatives": "alternatives",
    "threat": "threats",
    "event": "events",
    "alert": "alerts",
}


def load_flight(path: str | Path) -> FlightRecord:
    """Read a flight record, MCAP (``.mcap``) or JSON Lines (anything else)."""
    return load_mcap_record(path) if str(path).endswith(".mcap") else load_record(path)


def load_mcap_record(path: str | Path) -> FlightRecord:
    """Read the companion's channels of an MCAP flight file, in the order they were written.

    A file cut short (the companion was killed: no summary section, a partial chunk) gives what
    was complete, with a warning.

    Raises
    ------
    CompanionError
        When the file is missing or is not MCAP (naming the file and what is wrong).
    companion.extras.MissingExtra
        Without the mcap package (the ``view`` extra).
    """
    McapError = require("view", "mcap.exceptions").McapError
    NonSeekingReader = require("view", "mcap.reader").NonSeekingReader
    path = Path(path)
    record = FlightRecord()
    columns: dict[str, list] = {k: [] for k in SAMPLE_KEYS}
    read = 0
    try:
        with open(path, "rb") as stream:
            for _, channel, message in NonSeekingReader(stream).iter_messages(log_time_order=False):
                read += 1
                if channel.message_encoding != "json":
                    continue
                data = json.loads(message.data)
                if channel.topic in ch.SAMPLE_TOPICS:
                    _sample_column(channel.topic, data, columns)
                elif channel.topic in _LINE_TYPES:
                    _add_line(record, _LINE_TYPES[channel.topic], data)
    except FileNotFoundError:
        raise CompanionError(f"{path}: no such flight record") from None
    except (McapError, ValueError, EOFError, struct.error) as exc:
        if not read:
            raise CompanionError(f"{path}: not a readable MCAP flight ({exc or type(exc).__name__})") from None
        log.warning("%s: cut short after %d messages (%s); the rest is lost", path, read, exc or type(exc).__name__)
    record.samples = samples_from_columns(_aligned(columns))
    return record


def _aligned(columns: dict[str, list]) -> dict[str, list]:
    """Columns cut to the shortest (a file cut short may end inside one sample's messages)."""
    n = min(len(v) for v in columns.values())
    return {k: v[:n] for k, v in columns.items()}


def _sample_column(topic: str, data: dict, columns: dict[str, list]) -> None:
    for key in ch.SAMPLE_TOPICS[topic]:
        if key in columns and (key != "t_s" or topic == "/vehicle/state"):
            columns[key].append(data.get(key))


def _add_line(record: FlightRecord, line_type: str, data: dict) -> None:
    if line_type in _LISTS:
        getattr(record, _LISTS[line_type]).append(data)
    else:
        setattr(record, line_type, data)
