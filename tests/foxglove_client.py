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
    channels: dict[int, dict] = field(default_factory=dict)  # id -> advertised channel
    messages: dict[str, list] = field(default_factory=dict)  # topic -> payloads

    def topics(self) -> set[str]:
        return {c["topic"] for c in self.channels.values()}


async def connect(url: str, within_s: float):
    """A WebSocket to ``url``, retrying while the server is not up yet."""
    loop = asyncio.get_running_loop()
    end = loop.time() + within_s
    while True:
        try:
            return await websockets.connect(url, subprotocols=[SUBPROTOCOL], max_size=None)
        except OSError:
            if loop.time() > end:
                raise
            await asyncio.sleep(0.2)


async def collect(
    port: int,
    topics: set[str] | None,
    seconds: float,
    host: str = "127.0.0.1",
    until=None,
    connect_within_s: float = 30.0,
) -> Received:
    """Subscribe to ``topics`` (None: every topic; as soon as they are advertised) and collect
    for ``seconds``, or until ``until()`` is true (polled every 0.2 s) or the server closes."""
    got = Received()
    subscribed: dict[int, str] = {}  # subscription id -> topic
    ws = await connect(f"ws://{host}:{port}", connect_within_s)
    async with ws:
        loop = asyncio.get_running_loop()
        end = loop.time() + seconds
        while (left := end - loop.time()) > 0 and not (until and until()):
            try:
                frame = await asyncio.wait_for(ws.recv(), min(left, 0.2))
            except TimeoutError:
                continue
            except websockets.ConnectionClosed:
                break
            if isinstance(frame, bytes):
                _data(frame, subscribed, got)
                continue
            message = json.loads(frame)
            if message.get("op") == "advertise":
                wanted = []
                for channel in message["channels"]:
                    got.channels[channel["id"]] = channel
                    if (topics is None or channel["topic"] in topics) and channel["id"] not in subscribed:
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


def main(argv=None) -> int:
    """``python foxglove_client.py PORT SECONDS``: subscribe to every topic for SECONDS and
    print ``{topic: messages received}`` as JSON (a viewer in another process, for benchmarks)."""
    import sys

    port, seconds = (sys.argv[1:] if argv is None else argv)[:2]
    got = asyncio.run(collect(int(port), None, float(seconds)))
    print(json.dumps({topic: len(messages) for topic, messages in sorted(got.messages.items())}))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
