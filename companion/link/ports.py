"""What the parts of the vehicle link call on one another (``companion.link.vehicle``), as
Protocols: each part is given, at construction, objects with these methods, so it can be built
and tested alone (with a double) and no part imports another.
"""

from __future__ import annotations

from collections.abc import AsyncIterator
from typing import Protocol


class MessageSource(Protocol):
    """Received MAVLink messages by type (``companion.link.message_tap.MessageTap``)."""

    def messages(self, name: str) -> AsyncIterator[dict]:
        """Field dicts of the messages named ``name``, as they arrive."""
        ...


class MessageSender(Protocol):
    """Sends one MAVLink message now (``companion.link.direct_messages.DirectMessages``)."""

    def send_message(self, name: str, fields: dict) -> None: ...


class CommandSender(Protocol):
    """COMMAND_LONG with its COMMAND_ACK (``companion.link.vehicle_commands.VehicleCommands``)."""

    async def command_result(
        self, command: int, params=(), *, what: str | None = None, timeout_s: float = 10.0
    ) -> int | None: ...

    async def request_home(self) -> None: ...


class StatusTextLog(Protocol):
    """The vehicle's recent STATUSTEXTs (``companion.link.watchers.TelemetryWatchers``)."""

    def statustexts_since(self, t_monotonic_s: float) -> list[str]: ...


class StreamNotes(Protocol):
    """What the telemetry stream keeper is told and asked (``companion.link.streams.StreamKeeper``)."""

    def note(self, name: str, boot_s: float | None = None) -> None: ...

    def unavailable(self, name: str) -> bool: ...


class VehicleTarget(Protocol):
    """Who the link talks to (``companion.link.session.LinkSession``)."""

    target_system: int
    target_component: int


class Ticking(Protocol):
    """Something that runs periodically on the loop (``companion.link.periodic.PeriodicDriver``)."""

    running: bool
