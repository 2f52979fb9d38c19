"""Protocol emulators for testing the real-vehicle backends on loopback, written from the protocols' public
specifications (MAVLink common message set and the autopilots' documented behaviour; the Tello SDK 2.0),
not from our backends' assumptions."""

import socket


def free_udp_port(host: str = "127.0.0.1") -> int:
    """A UDP port on ``host`` that was free a moment ago (bind to port 0, read it back, release it)."""
    return _free_port(host, "udp")


def free_tcp_port(host: str = "127.0.0.1") -> int:
    """A TCP port on ``host`` that was free a moment ago (bind to port 0, read it back, release it)."""
    return _free_port(host, "tcp")


def _free_port(host: str, kind: str) -> int:
    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM if kind == "udp" else socket.SOCK_STREAM) as s:
        s.bind((host, 0))
        return s.getsockname()[1]
