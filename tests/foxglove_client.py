"""A minimal Foxglove WebSocket client for tests (protocol ``foxglove.sdk.v1``).

It reads the server's channel advertisements, subscribes to the topics asked for and collects
each message: JSON channels decoded, others as bytes.
"""

from __future__ import annotations

import asyncio
import json
import struct
from dataclasses import dataclass, field

import websockets

SUBPROTOCOL = "foxglove.sdk.v1"
MESSAGE_DATA = 0x01


@dataclass
class Received:
    channels: dict[int, dict] = field(default_factory=dict)      # id -> advertised channel
    messages: dict[str, list] = field(default_factory=dict)      # topic -> payloads

    def topics(self) -> set[str]:
        return {c["topic"] for c in self.channels.values()}


async def collect(port: int, topics: set[str], seconds: float, host: str = "127.0.0.1") -> Received:
    """Subscribe to ``topics`` (as soon as they are advertised) and collect for ``seconds``."""
    got = Received()
    subscribed: dict[int, str] = {}                              # subscription id -> topic
    async with websockets.connect(f"ws://{host}:{port}", subprotocols=[SUBPROTOCOL],
                                  max_size=None) as ws:
        loop = asyncio.get_running_loop()
        end = loop.time() + seconds
        while (left := end - loop.time()) > 0:
            try:
                frame = await asyncio.wait_for(ws.recv(), left)
            except asyncio.TimeoutError:
                break
            if isinstance(frame, bytes):
                _data(frame, subscribed, got)
                continue
            message = json.loads(frame)
            if message.get("op") == "advertise":
                wanted = []
                for channel in message["channels"]:
                    got.channels[channel["id"]] = channel
                    if channel["topic"] in topics and channel["id"] not in subscribed:
                        subscribed[channel["id"]] = channel["topic"]
                        wanted.append({"id": channel["id"], "channelId": channel["id"]})
                if wanted:
                    await ws.send(json.dumps({"op": "subscribe", "subscriptions": wanted}))
    return got


def _data(frame: bytes, subscribed: dict[int, str], got: Received) -> None:
    if frame[0] != MESSAGE_DATA:
        return
    subscription, _log_time_ns = struct.unpack_from("<IQ", frame, 1)
    topic = subscribed.get(subscription)
    if topic is None:
        return
    channel = next(c for c in got.channels.values() if c["topic"] == topic)
    payload = frame[13:]
    got.messages.setdefault(topic, []).append(json.loads(payload) if channel["encoding"] == "json" else payload)
