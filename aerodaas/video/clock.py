"""When a stream frame was captured, on this host's monotonic clock.

A live stream carries presentation timestamps (PTS) on the sender's clock, not ours. :class:`CaptureClock` maps
them with a measured offset: ``offset = min over frames of (arrival - pts)``, i.e. the frame that travelled fastest
is taken as the transit floor, so ``capture = pts + offset`` is never later than the arrival and follows the
sender's own spacing of frames (jitter in the network and the decoder does not move it). The absolute transit time
(glass to the first byte on our side) is not observable from PTS alone: capture times are relative to the fastest
frame seen, which is how ground stations without RTCP sender reports align video with telemetry.

When the sender restarts (PTS jump back, or a gap far beyond the frames' spacing) the mapping starts anew
(:meth:`CaptureClock.reset` is also called by the reader on every reopen).
"""
from __future__ import annotations

from dataclasses import dataclass


@dataclass
class CaptureClock:
    """PTS (s, sender clock) -> capture time (s, our ``time.monotonic``). ``jump_s``: a change of ``arrival - pts``
    larger than this re-anchors the mapping (the sender restarted or its clock jumped)."""

    jump_s: float = 2.0
    offset: float | None = None
    last_pts: float | None = None
    resets: int = 0

    def reset(self) -> None:
        """Forget the mapping (a new connection: its PTS start anywhere)."""
        self.offset, self.last_pts = None, None

    def capture(self, pts_s: float | None, arrival: float) -> float:
        """The capture time (our monotonic s) of a frame with presentation time ``pts_s`` (s; None: unknown, then
        the arrival is all we know) that arrived at ``arrival`` (our monotonic s)."""
        if pts_s is None:
            return arrival
        d = arrival - pts_s
        if self.offset is None or (self.last_pts is not None and pts_s < self.last_pts) \
                or abs(d - self.offset) > self.jump_s:
            if self.offset is not None:
                self.resets += 1
            self.offset = d
        elif d < self.offset:
            self.offset = d
        self.last_pts = pts_s
        return min(pts_s + self.offset, arrival)
