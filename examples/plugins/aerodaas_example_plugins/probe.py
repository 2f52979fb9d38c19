"""Analytics ``frame_probe``: the mean intensity of each camera frame ((H, W, 3) uint8 BGR -> 0-255), a cheap
per-frame task for the analytics scheduler to place (edge, cloud or drop)."""
from __future__ import annotations

from aerodaas.analytics.core import Analytics


class FrameProbe(Analytics):
    """See the module docstring. Produces ``{"robot", "mean"}`` per frame."""

    plugin_kind = "analytics"
    name = "frame_probe"
    stateful = False
    consumes = ("frame",)
    produces = ("value",)

    def process(self, frame, meta):
        return {"robot": getattr(meta, "robot_id", ""), "mean": float(frame.mean())}
