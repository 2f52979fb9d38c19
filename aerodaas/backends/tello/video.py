"""The Tello's video: :class:`H264Reassembler` rebuilds the H.264 access units from the UDP datagrams (DJI's
packetisation: 1460-byte datagrams, a shorter one ends the frame) and decodes them with PyAV."""
from __future__ import annotations

import time

import numpy as np

from aerodaas.backends.tello.protocol import DATAGRAM_SIZE

__all__ = ["H264Reassembler"]


class H264Reassembler:
    """Decodes the Tello's H.264 UDP stream to BGR frames with PyAV (FFmpeg's ``h264`` decoder).

    :meth:`feed` takes one datagram; datagrams are concatenated until one shorter than :data:`DATAGRAM_SIZE`
    ends the frame (the Tello's packetisation), and the access unit is decoded as one packet, so a frame is
    available as soon as its last datagram arrives (no parser look-ahead). Returns the decoded frames,
    each ``(H, W, 3) uint8 BGR``. Undecodable data (e.g. P-frames before the first key frame, a lost datagram)
    is counted in :attr:`errors` and dropped. :attr:`decode_s` accumulates decode + colour-conversion time."""

    MAX_FRAME_BYTES = 4 << 20

    def __init__(self) -> None:
        import av  # lazy: only a Tello with video needs PyAV

        self._av = av
        self._codec = av.CodecContext.create("h264", "r")
        self._buf = bytearray()
        self.errors = 0
        self.frames = 0
        self.decode_s = 0.0

    def feed(self, datagram: bytes) -> list[np.ndarray]:
        self._buf += datagram
        if len(datagram) >= DATAGRAM_SIZE:
            if len(self._buf) > self.MAX_FRAME_BYTES:  # never saw a short datagram: not a Tello stream
                self._buf.clear()
                self.errors += 1
            return []
        data, self._buf = bytes(self._buf), bytearray()
        t0 = time.perf_counter()
        out = []
        try:
            for frame in self._codec.decode(self._av.Packet(data)):
                out.append(frame.to_ndarray(format="bgr24"))
        except self._av.FFmpegError:
            self.errors += 1
        self.decode_s += time.perf_counter() - t0
        self.frames += len(out)
        return out
