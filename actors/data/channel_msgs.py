"""The messages of the same-node channel (:mod:`aerodaas.actors.data.channel`) as objects: :class:`ChannelSend`
(sender -> receiver), :class:`ChannelDone` and :class:`SlotFree` (receiver -> sender); a frame's ``data`` in a
delivery is a :class:`SlotFrame`. How they travel on the socket: :mod:`aerodaas.actors.data.channel_wire`."""
from __future__ import annotations

from dataclasses import dataclass

from aerodaas.protocol.messages import Delivery

__all__ = ["SlotFrame", "ChannelSend", "ChannelDone", "SlotFree"]


@dataclass(frozen=True)
class SlotFrame:
    """A frame's pixels in the sender's shared-memory slot ``name``: ``shape`` (H, W, 3) and ``dtype`` (uint8)."""

    name: str
    shape: tuple[int, ...]
    dtype: str


@dataclass(frozen=True)
class ChannelSend:
    """Sender -> receiver: delivery number ``seq`` (the sender's count) carrying ``delivery``."""

    seq: int
    delivery: Delivery


@dataclass(frozen=True)
class ChannelDone:
    """Receiver -> sender: delivery ``seq`` was handed to its component; ``replies``: outputs bound for the
    sender's components (computed in that hand-over); ``error``: why it failed, or None; ``freed``: slots whose
    frames are no longer referenced (see :class:`SlotFree`)."""

    seq: int
    replies: list
    error: str | None = None
    freed: tuple[str, ...] = ()


@dataclass(frozen=True)
class SlotFree:
    """Receiver -> sender: the frames in slots ``names`` are no longer referenced; the slots may be written again
    (sent on its own when a frame outlives its delivery, e.g. one an analytics kept or one queued for later)."""

    names: tuple[str, ...]
