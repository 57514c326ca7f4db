"""Messages in: the types someone reads, straight from the signing gate (``messages``).

The gate parses every frame it admits anyway (``companion.link.gate``): the types someone reads
are handed to the event loop in batches as field dicts (``tapped_fields``), without MAVSDK's
JSON round trip. While the setpoint stream runs, the batches are taken at its ticks instead of
waking the loop (``batch_reads``).
"""

from __future__ import annotations

import asyncio
import collections
from typing import AsyncIterator, Callable

from companion.link.ports import TickStream
from companion.link.session import LinkSession
from companion.link.transport import TAP_HANDOVER_PERIOD_S


class MessageTap:
    """The readers of the messages the gate taps (``VehicleLink.inbound``).

    Parameters
    ----------
    session : LinkSession
        The connection: its gate is told which types to tap.
    """

    def __init__(self, session: LinkSession) -> None:
        self._session = session
        self._readers: dict[str, set[asyncio.Queue]] = {}  # message type -> the queues of messages()
        self._batches: collections.deque = collections.deque()  # what the gate read, for the loop
        self._streamer: TickStream | None = None      # the setpoint stream that takes them

    async def messages(self, name: str) -> AsyncIterator[dict]:
        """Raw MAVLink messages named ``name`` (e.g. ``"SERVO_OUTPUT_RAW"``) as field dicts.

        Each dict has the message fields plus ``"_sysid"``, ``"_compid"`` and ``"_t_s"``
        (monotonic arrival time). They come straight from the gate (``companion.link.gate``:
        the frames it admits, parsed once on its thread, ``tapped_fields``), not through MAVSDK;
        every reader of a type gets the same dict: read it, do not change it.
        """
        self._session.require_connected()
        queue: asyncio.Queue[dict] = asyncio.Queue()
        readers = self._readers.setdefault(name, set())
        readers.add(queue)
        self._session.gate.inbound.tapped.add(name)
        try:
            while True:
                yield await queue.get()
        finally:
            readers.discard(queue)
            if not readers and self._session.gate is not None:
                self._session.gate.inbound.tapped.discard(name)

    def batch_reads(self, streamer: TickStream | None = None) -> None:
        """While the setpoint ``streamer`` runs (None: from now on, no longer), the gate reads
        the vehicle's datagrams in batches every ``TAP_HANDOVER_PERIOD_S``
        (``GateThread.batch_reads``) and the messages it read are taken at the stream's next
        tick (``SetpointStreamer.tick_hooks``) instead of waking the loop: the companion's about
        40 telemetry datagrams a second then cost the gate 10 wake-ups and the loop none."""
        gate = self._session.gate
        if gate is None:
            return
        if self._streamer is not None:
            self._streamer.tick_hooks.remove(self._take_batches)
        self._streamer = streamer
        if streamer is not None:
            streamer.tick_hooks.append(self._take_batches)
        gate.batch_reads(TAP_HANDOVER_PERIOD_S if streamer is not None else 0.0)
        self._take_batches()

    def _take_batches(self) -> None:
        """On the loop: the messages the gate read, to their readers (``messages``)."""
        batches = self._batches
        while batches:
            for name, fields in batches.popleft():
                for queue in self._readers.get(name, ()):
                    queue.put_nowait(fields)

    def gate_callback(self, loop: asyncio.AbstractEventLoop) -> Callable[[list], None]:
        """The gate's ``on_tap`` (called on the gate's thread): keep each batch for the loop,
        and wake the loop for it unless the setpoint stream's next tick takes it
        (``batch_reads``)."""
        def on_tap(batch: list) -> None:
            self._batches.append(batch)
            streamer = self._streamer
            if streamer is None or not streamer.running:     # a stream that stopped takes none
                try:
                    loop.call_soon_threadsafe(self._take_batches)
                except RuntimeError:           # the loop is closed: the link is closing
                    pass
        return on_tap
