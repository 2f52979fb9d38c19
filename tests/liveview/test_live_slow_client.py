"""A live-view client that stops reading is dropped once the bounded buffers towards it are full, and the server
stops without waiting for it (such a client held the end of a run for ~120 s). The client is a raw
socket that completes the WebSocket handshake and then never reads."""
from __future__ import annotations

import base64
import os
import socket
import threading
import time

from aerodaas.liveview.server import LiveServer


def _wait(pred, limit_s: float = 120.0) -> bool:
    t0 = time.monotonic()
    while not pred():
        if time.monotonic() - t0 > limit_s:
            return False
        time.sleep(0.05)
    return True


def test_a_client_that_stops_reading_is_dropped_and_the_server_stops(tmp_path):
    live = LiveServer("127.0.0.1:0", client_send_timeout_s=1.0)
    s = socket.socket()
    s.setsockopt(socket.SOL_SOCKET, socket.SO_RCVBUF, 4096)
    s.connect(("127.0.0.1", live.port))
    key = base64.b64encode(os.urandom(16)).decode()
    s.sendall((f"GET / HTTP/1.1\r\nHost: 127.0.0.1:{live.port}\r\nUpgrade: websocket\r\nConnection: Upgrade\r\n"
               f"Sec-WebSocket-Key: {key}\r\nSec-WebSocket-Version: 13\r\n"
               f"Sec-WebSocket-Protocol: foxglove.sdk.v1\r\n\r\n").encode())
    schema = b'{"type": "object", "description": "' + b"x" * 8000 + b'"}'
    k = 0
    while not live.dropped_clients and k < 4000:  # every new channel is advertised to the client, which never reads
        live.advertise(f"/t/{k}", "t.T", "jsonschema", schema, "json")
        k += 1
    assert _wait(lambda: bool(live.dropped_clients)), f"not dropped after {k} channels"
    stopped = threading.Event()
    threading.Thread(target=lambda: (live.stop(), stopped.set()), daemon=True).start()
    assert stopped.wait(120), "the server's stop waited for the client that does not read"
    assert live.dropped_clients[0][0].startswith("127.0.0.1:")
    s.close()
