"""A minimal Foxglove WebSocket protocol client for tests (written from the spec, not from our server code).

Spec: https://github.com/foxglove/foxglove-sdk/blob/main/docs/spec/websocket/README.md (subprotocol
``foxglove.websocket.v1``): the server sends a JSON ``serverInfo`` then ``advertise`` with its channels
(``id``, ``topic``, ``encoding``, ``schemaName``, ``schema``, ``schemaEncoding``); the client sends
``{"op": "subscribe", "subscriptions": [{"id", "channelId"}]}``; each message then arrives as a binary frame
``0x01 | subscription id (uint32 LE) | log time (uint64 LE, ns) | payload``. Uses aiohttp's WebSocket client
(aiohttp comes with ray[default]).

foxglove-sdk (0.30.3 and its main branch, rust/foxglove/src/websocket/connected_client.rs ``advertise_channels``)
sends the ``advertise`` of a channel created while a client is connected *before* it enters the channel in that
client's map, so a client that subscribes at once can be answered ``status`` "Unknown channel ID: N" and the
subscription is dropped. This client then subscribes again (once per such status); the test records the status in
``timeline`` so the race stays visible.
"""
from __future__ import annotations

import asyncio
import base64
import json
import re
import struct
import time
from typing import Any

#: offered in preference order: the SDK's server (foxglove-sdk >= 0.2x) speaks `foxglove.sdk.v1` (the protocol of
#: `foxglove.websocket.v1` under the SDK's name; its spec now lives in the foxglove-sdk repository), older servers
#: `foxglove.websocket.v1`
SUBPROTOCOLS = ("foxglove.sdk.v1", "foxglove.websocket.v1")
_UNKNOWN_CHANNEL = re.compile(r"Unknown channel ID: (\d+)")


async def _collect(url: str, want: dict[str, int], timeout_s: float, connect_timeout_s: float, ssl: Any = True,
                   headers: dict | None = None) -> dict[str, Any]:
    import aiohttp

    out: dict[str, Any] = {"server_info": None, "channels": {}, "messages": {t: [] for t in want}, "protocol": None,
                           "closed_by_server": False, "timeline": []}
    t0 = time.monotonic()
    deadline = time.monotonic() + timeout_s
    async with aiohttp.ClientSession() as session:
        t_conn = time.monotonic() + connect_timeout_s
        while True:  # the server may not listen yet
            try:
                ws = await session.ws_connect(url, protocols=SUBPROTOCOLS, max_msg_size=0, compress=0, ssl=ssl,
                                              headers=headers)
                break
            except aiohttp.ClientConnectorError:
                if time.monotonic() > t_conn:
                    raise
                await asyncio.sleep(0.2)
        async with ws:
            out["protocol"] = ws.protocol
            subs: dict[int, str] = {}
            next_sub = 1
            while time.monotonic() < deadline:
                if all(len(out["messages"][t]) >= n for t, n in want.items()):
                    break
                try:
                    msg = await ws.receive(timeout=max(0.05, deadline - time.monotonic()))
                except asyncio.TimeoutError:
                    break
                if msg.type == aiohttp.WSMsgType.TEXT:
                    body = json.loads(msg.data)
                    if body.get("op") == "serverInfo":
                        out["server_info"] = body
                    elif body.get("op") == "advertise":
                        new = []
                        now = round(time.monotonic() - t0, 3)  # one time per message: its channels come together
                        for ch in body["channels"]:
                            out["channels"][ch["topic"]] = ch
                            out["timeline"].append((now, "advertise", ch["topic"]))
                            if ch["topic"] in want and ch["topic"] not in subs.values():
                                subs[next_sub] = ch["topic"]
                                new.append({"id": next_sub, "channelId": ch["id"]})
                                next_sub += 1
                        if new:
                            await ws.send_str(json.dumps({"op": "subscribe", "subscriptions": new}))
                    else:  # status, unadvertise, time, ...: kept for diagnosis
                        out["timeline"].append((round(time.monotonic() - t0, 3), body.get("op"), body))
                        bad = _UNKNOWN_CHANNEL.match(str(body.get("message", ""))) if body.get("op") == "status" else None
                        retry = [{"id": i, "channelId": int(bad.group(1))} for i, t in subs.items()
                                 if bad and out["channels"].get(t, {}).get("id") == int(bad.group(1))]
                        if retry:  # foxglove-sdk race (see module docstring): subscribe again
                            await asyncio.sleep(0.05)
                            await ws.send_str(json.dumps({"op": "subscribe", "subscriptions": retry}))
                elif msg.type == aiohttp.WSMsgType.BINARY:
                    data = msg.data
                    if data[0] == 0x01:
                        sub_id, log_time = struct.unpack_from("<IQ", data, 1)
                        topic = subs.get(sub_id)
                        if topic is not None:
                            out["messages"][topic].append((log_time, bytes(data[13:])))
                elif msg.type in (aiohttp.WSMsgType.CLOSE, aiohttp.WSMsgType.CLOSED, aiohttp.WSMsgType.CLOSING,
                                  aiohttp.WSMsgType.ERROR):
                    out["closed_by_server"] = True
                    out["timeline"].append((round(time.monotonic() - t0, 3), "closed", str(msg.type)))
                    break
    return out


def collect(url: str, want: dict[str, int], timeout_s: float = 60.0, connect_timeout_s: float = 30.0,
            ssl: Any = True, headers: dict | None = None) -> dict:
    """Connect to ``url``, subscribe to every topic of ``want`` as soon as it is advertised, and gather messages
    until each topic has ``want[topic]`` of them, the server closes, or ``timeout_s`` passes. Returns
    ``{"server_info", "channels": {topic: advertised channel}, "messages": {topic: [(log_time_ns, bytes)]},
    "protocol", "closed_by_server", "timeline": [(seconds since connect, "advertise" | "closed", topic)]}``.
    ``ssl``: aiohttp's (an ``ssl.SSLContext`` trusting a test certificate for ``wss://``); ``headers``: extra request
    headers (``Authorization``)."""
    return asyncio.run(_collect(url, want, timeout_s, connect_timeout_s, ssl, headers))


def schema_bytes(channel: dict) -> bytes:
    """The advertised schema as bytes (binary schemas such as protobuf FileDescriptorSets are base64 in JSON)."""
    if channel.get("schemaEncoding") in ("protobuf", "flatbuffer", "ros2msg_binary"):
        return base64.b64decode(channel["schema"])
    return channel["schema"].encode()
