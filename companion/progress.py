"""A flight shown as it goes, on a terminal: a live status line and a line per decision.

``FlightProgress`` takes the companion's zenoh ``status`` and ``events`` messages (DESIGN 6) as
they arrive (any thread) and shows them with ``rich``: the status line (mode, leg, path, mission
time, tracking error) refreshes in place on a terminal; a new leg, a mode change and every
threat decision are printed as lines, so a log file or a pipe gets them too.
"""

from __future__ import annotations

import threading

from rich.console import Console
from rich.markup import escape
from rich.status import Status

__all__ = ["FlightProgress", "status_text", "event_text"]


def status_text(status: dict) -> str:
    """One line of a ``status`` message: ``GUIDED · leg 2/5 · alt2-14 · t 65.6 s · error 0.12 m``."""
    parts = [str(status.get("mode") or "?")]
    if status.get("legs") and int(status.get("leg") or 0) >= 0:
        parts.append(f"leg {min(int(status.get('leg') or 0) + 1, status['legs'])}/{status['legs']}")
    if status.get("path_id"):
        parts.append(str(status["path_id"]))
    if status.get("t_s") is not None:
        parts.append(f"t {float(status['t_s']):.1f} s")
    if status.get("tracking_error_m") is not None:
        parts.append(f"error {float(status['tracking_error_m']):.2f} m")
    if status.get("link") is False:
        parts.append("LINK LOST")
    return " · ".join(parts)


def event_text(event: dict) -> str | None:
    """One line of an ``events`` message (a threat decision or a rejected payload); None for
    the 'no change' decisions."""
    kind = event.get("event")
    if kind in (None, "none"):
        return None
    latency = event.get("latency_ms")
    took = f" ({float(latency):.0f} ms)" if latency is not None else ""
    source = f" [{event['source']}]" if event.get("source") else ""
    return f"{kind}{took}{source}: {event.get('reason', '')}"


class FlightProgress:
    """Shows one flight's progress on ``console`` (stderr by default); a context manager."""

    def __init__(self, console: Console | None = None, title: str = "flight") -> None:
        self.console = console or Console(stderr=True)
        self.title = title
        self._lock = threading.Lock()
        self._last: dict = {}
        self._status: Status | None = None

    def __enter__(self) -> FlightProgress:
        self._status = self.console.status(f"{self.title}: waiting for the companion")
        self._status.start()
        return self

    def __exit__(self, *exc: object) -> None:
        if self._status is not None:
            self._status.stop()

    def on_status(self, status: dict) -> None:
        """A ``status`` message: refresh the line; print a new leg or mode."""
        with self._lock:
            for key, label in (("mode", "mode"), ("leg", "leg")):
                if status.get(key) is not None and status.get(key) != self._last.get(key):
                    if key == "leg" and status.get("legs") and int(status["leg"]) >= 0:
                        self._print(f"{self.title}: leg {int(status['leg']) + 1}/{status['legs']}")
                    elif key == "mode":
                        self._print(f"{self.title}: {label} {status[key]}")
            self._last = dict(status)
            if self._status is not None:
                self._status.update(escape(f"{self.title}: {status_text(status)}"))

    def on_event(self, event: dict) -> None:
        """An ``events`` message: print it (decisions and rejected payloads)."""
        line = event_text(event)
        if line is not None:
            with self._lock:
                self._print(f"{self.title}: {line}")

    def _print(self, text: str) -> None:
        self.console.print(text, markup=False, highlight=False)  # "[radar1]" is not a style
