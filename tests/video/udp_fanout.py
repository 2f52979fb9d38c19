"""A minimal MAVLink UDP router for tests, as MAVProxy ``--out`` and mavlink-router forward: every datagram from any
vehicle goes to the ground-station port; every datagram from the ground station goes to every vehicle. Vehicles
are emulators listening on ``udpin`` ports; the ground station connects with ``udpout:127.0.0.1:<gcs_port>``."""
from __future__ import annotations

import selectors
import socket
import threading


class UdpFanout:
    """Forward between one ground-station socket and one socket per vehicle (see the module docstring)."""

    def __init__(self, vehicle_ports: list[int]) -> None:
        self.gcs = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        self.gcs.bind(("127.0.0.1", 0))
        self.gcs_port = self.gcs.getsockname()[1]
        self.gcs_addr = None
        self.vehicles = []
        for p in vehicle_ports:
            s = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
            s.bind(("127.0.0.1", 0))
            self.vehicles.append((s, ("127.0.0.1", p)))
        self.forwarded = 0
        self._stop = threading.Event()
        self._t = threading.Thread(target=self._run, daemon=True)
        self._t.start()

    def _run(self) -> None:
        sel = selectors.DefaultSelector()
        sel.register(self.gcs, selectors.EVENT_READ, None)
        for s, addr in self.vehicles:
            sel.register(s, selectors.EVENT_READ, addr)
        while not self._stop.is_set():
            for key, _ in sel.select(0.05):
                try:
                    data, src = key.fileobj.recvfrom(65536)
                except OSError:
                    continue
                if key.data is None:  # from the ground station: to every vehicle
                    self.gcs_addr = src
                    for s, addr in self.vehicles:
                        s.sendto(data, addr)
                elif self.gcs_addr is not None:
                    self.gcs.sendto(data, self.gcs_addr)
                self.forwarded += 1
        sel.close()

    def close(self) -> None:
        self._stop.set()
        self._t.join(timeout=2)
        for s in [self.gcs] + [s for s, _ in self.vehicles]:
            s.close()
