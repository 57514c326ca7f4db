"""Messages in: the types someone reads, straight from the signing gate (``messages``).

The gate parses every frame it admits anyway (``companion.link.gate``): the types someone reads
are handed to the event loop in batches as field dicts (``tapped_fields``), without MAVSDK's
JSON round trip. While the daemon's schedule runs, the batches are taken by its ``telemetry``
task (``take_batches``, right after each setpoint) instead of waking the loop (``batch_reads``).
A *listener* (``listen``: the live view) gets its messages on the gate's thread as each is read,
neither waiting for the hand-over nor touching the loop; while one listens, the batches of the
vehicle's datagrams are read every ``LIVE_READ_PERIOD_S`` instead of ``TAP_HANDOVER_PERIOD_S``.
"""

from __future__ import annotations

import asyncio
import collections
from collections.abc import AsyncIterator, Callable

from companion.link.ports import Ticking
from companion.link.session import LinkSession
from companion.link.transport import TAP_HANDOVER_PERIOD_S

#: While a listener listens (``MessageTap.listen``), the vehicle's datagrams are read in
#: batches this often (s) during the schedule (``batch_reads``): a listener then hears a
#: message at most this long after it arrived (the live view's lag), for 40 wake-ups of the
#: gate's thread a second instead of 10; the hand-overs to the loop stay at 10 a second.
LIVE_READ_PERIOD_S = 0.025


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
        self._taker: Ticking | None = None  # the running schedule that takes them
        self._listeners: dict[str, list[Callable[[dict], None]]] = {}  # shared with each gate's filter

    def attach(self, gate, loop: asyncio.AbstractEventLoop) -> None:
        """A new connection's gate (``companion.link.transport.GateThread``): its hand-overs
        come to this tap and its filter calls the listeners (``listen``)."""
        gate.on_tap = self.gate_callback(loop)
        gate.inbound.listeners = self._listeners

    def listen(self, name: str, listener: Callable[[dict], None]) -> Callable[[], None]:
        """Call ``listener(fields)`` with every message named ``name`` the link admits, on the
        gate's thread, as soon as it is read (the fields ``messages`` yields); for every
        connection from now on. Returns the function that stops it. A listener must be quick
        and must not touch the event loop: it runs beside the setpoint stream."""
        self._listeners[name] = [*self._listeners.get(name, ()), listener]  # copied: the gate may be iterating
        self._read_period_changed()

        def stop() -> None:
            left = [f for f in self._listeners.get(name, ()) if f is not listener]
            if left:
                self._listeners[name] = left
            else:
                self._listeners.pop(name, None)
            self._read_period_changed()

        return stop

    def _read_period(self) -> float:
        """How often the gate reads the vehicle's datagrams while a schedule runs."""
        return LIVE_READ_PERIOD_S if self._listeners else TAP_HANDOVER_PERIOD_S

    def _read_period_changed(self) -> None:
        gate = self._session.gate
        if gate is not None and self._taker is not None:
            gate.batch_reads(self._read_period())

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

    def batch_reads(self, taker: Ticking | None = None) -> None:
        """While ``taker`` runs (the daemon's ``PeriodicDriver``; None: from now on, no longer),
        the gate reads the vehicle's datagrams in batches every ``TAP_HANDOVER_PERIOD_S``
        (``GateThread.batch_reads``) and the messages it read wait for ``take_batches`` (the
        schedule's ``telemetry`` task) instead of waking the loop: the companion's about 40
        telemetry datagrams a second then cost the gate 10 wake-ups and the loop none."""
        gate = self._session.gate
        if gate is None:
            return
        self._taker = taker
        gate.batch_reads(self._read_period() if taker is not None else 0.0)
        self.take_batches()

    def take_batches(self) -> None:
        """On the loop: the messages the gate read, to their readers (``messages``)."""
        batches = self._batches
        while batches:
            for name, fields in batches.popleft():
                for queue in self._readers.get(name, ()):
                    queue.put_nowait(fields)

    def gate_callback(self, loop: asyncio.AbstractEventLoop) -> Callable[[list], None]:
        """The gate's ``on_tap`` (called on the gate's thread): keep each batch for the loop,
        and wake the loop for it unless the running schedule takes it (``batch_reads``)."""

        def on_tap(batch: list) -> None:
            self._batches.append(batch)
            taker = self._taker
            if taker is None or not taker.running:  # a schedule that stopped takes none
                try:
                    loop.call_soon_threadsafe(self.take_batches)
                except RuntimeError:  # the loop is closed: the link is closing
                    pass

        return on_tap
