"""The frame-source extension point: where a camera's frames come from is one class, a subclass of
:class:`FrameSource`, selected by the camera's ``properties.source`` (``environment.json``).

A frame source is asked for frames by the camera component in the drone's actor (``actors/sensors/camera.py``); it never
publishes, records or tags a frame itself — the camera does that for every source alike (pose, intrinsics, the
``foxglove.CompressedImage`` channel ``/<robot>/camera/<sensor>``, the detector's input). Two forms:

* a *pulled* source (:class:`FrameSource`): at every due tick of the vehicle clock the camera calls
  :meth:`FrameSource.frame_at` with the run time and the camera's pose; the source returns a
  :class:`CapturedFrame` — an ``(H, W, 3)`` ``uint8`` BGR image (OpenCV's channel order, row 0 at the top) and its
  capture time in seconds on the run's vehicle clock (0 = the mission's start, the clock ``FrameMeta.capture_time``
  and the recording's log times use) — or None when it has no new frame (counted in ``dropped_at_camera``). The
  built-ins: rendered (``sim``), the vehicle's own video (``backend``), a recorded MCAP channel (``mcap``);
* a *live* source (:class:`LiveFrameSource`): frames arrive on their own on the host's clock (a video stream), the
  run then needs speedup 1; the source hands the camera a :class:`FrameReader` and the camera maps each frame's
  host capture time onto the run clock. The built-ins: a stream or file (``rtsp://``, ``udp://``, ..., ``stream``),
  the stream the vehicle announces over MAVLink (``mavlink``).

A source is registered like every plug-in (:mod:`aerodaas.plugins.registry`, kind ``frame_source``, entry-point
group ``aerodaas.frame_sources``) under its ``name``; a ``source`` that names no registered frame source is read as
a video stream URL or file (:data:`STREAM_SOURCE`). Its own properties (beside the camera's ``width``, ``height``,
``hfov_deg``, ``fps``, ``pitch_deg``) are declared by its ``Config`` (a pydantic model), validated with the
environment before Ray starts; errors name ``properties.<field>``. ``docs/extending-vehicles.md``
walks through an example (``examples/plugins/aerodaas_example_plugins/image_folder.py``).
"""
from __future__ import annotations

from abc import ABC, abstractmethod
from dataclasses import dataclass, field
from typing import Any, Callable, ClassVar, Mapping, Protocol, Sequence

import numpy as np
from pydantic import BaseModel

from aerodaas.model.types import CameraIntrinsics, FramePose
from aerodaas.plugins import registry

__all__ = ["CapturedFrame", "FrameSourceContext", "FrameSource", "LiveFrameSource", "FrameReader", "STREAM_SOURCE",
           "frame_source_class", "frame_source_names"]

#: the registered name of the source that reads a video stream or file; a camera ``source`` naming no registered
#: frame source (a URL, a path, ``/dev/videoN``) is read by it
STREAM_SOURCE = "stream"


@dataclass(frozen=True)
class CapturedFrame:
    """One frame from a pulled source: ``image`` an ``(H, W, 3)`` ``uint8`` BGR array (H, W: the camera's
    ``height``, ``width`` in pixels; the camera makes it read-only and shares it with every reader: the source must
    not change it afterwards), ``capture_t`` its capture time in seconds on the run's vehicle clock (0 = mission
    start), ``truth`` the simulated ground truth in view (dicts recorded on ``/world/targets``; empty for a real
    source)."""

    image: np.ndarray
    capture_t: float
    truth: Sequence[Mapping[str, Any]] = field(default=())


@dataclass(frozen=True)
class FrameSourceContext:
    """What a source is built with, in the drone's actor: the robot and sensor ids, the camera's validated
    ``properties`` (a JSON-ready dict, files already resolved to absolute paths), its ``intrinsics`` (pixels), the
    robot's vehicle ``backend`` (a :class:`aerodaas.backends.base.VehicleBackend`; None for an environment camera)
    and the simulated ``world`` (an :class:`aerodaas.sim.world.World`, only for a source with ``needs_world``)."""

    robot_id: str
    sensor_id: str
    properties: Mapping[str, Any]
    intrinsics: CameraIntrinsics
    backend: Any = None
    world: Any = None


class FrameReader(Protocol):
    """What a live source reads frames with (:class:`aerodaas.video.StreamReader` is one): ``waiting()`` whether a
    frame not taken yet is there; ``take()`` that frame (an object with ``image`` (H, W, 3) uint8 BGR,
    ``capture_mono`` and ``arrival_mono`` (``time.monotonic()`` seconds) and ``seq``) or None; ``drain_events()``
    the stream's events since the last call (``kind``, ``fields``: ``video_lost``, ``video_restored``); ``stats()``
    its counters; ``close()``."""

    def waiting(self) -> bool: ...

    def take(self) -> Any: ...

    def drain_events(self) -> list: ...

    def stats(self) -> dict: ...

    def close(self) -> None: ...


class FrameSource(ABC):
    """Base class of a frame source (see the module docstring). One instance per camera, built in the drone's actor
    with a :class:`FrameSourceContext`. A pulled source defines :meth:`frame_at`."""

    plugin_kind: ClassVar[str] = "frame_source"
    #: the ``properties.source`` word that selects it
    name: ClassVar[str] = ""
    #: a pydantic model of the source's own properties (its fields join the camera's), None: it has none
    Config: ClassVar[type[BaseModel] | None] = None
    #: built-in camera properties this source uses beyond the common ones (mcap, topic, transport, codec, ...);
    #: any other set is refused, naming it
    camera_properties: ClassVar[tuple[str, ...]] = ()
    #: whether the source renders the simulated world (the actor then builds it, once for all its cameras)
    needs_world: ClassVar[bool] = False
    #: whether an environment camera (``env_sensors[]``, no vehicle) may use it
    environment_ok: ClassVar[bool] = False
    #: whether its :meth:`frame_at` can make the image in a buffer the camera lends (``frame_at(t, pose, out=...)``,
    #: ``out`` a writable ``(H, W, 3)`` uint8 array it must fill and return as the image): the camera lends one of a
    #: same-node channel's shared-memory slots when the frame's consumer is in another actor on this machine, and
    #: the frame then crosses without a copy. False: ``frame_at(t, pose)`` only, and the frame is copied into a slot.
    #: The source must not keep ``out`` or write it after returning (readers share it). Pulled sources only: a
    #: :class:`LiveFrameSource`'s frames come from its reader
    renders_into: ClassVar[bool] = False
    #: whether its frames arrive on the host's wall clock (the run then needs speedup 1 and no lock-step)
    wall_clock: ClassVar[bool] = False

    def __init__(self, ctx: FrameSourceContext) -> None:
        self.ctx = ctx

    # -- before Ray starts (the environment loader)
    @classmethod
    def check_properties(cls, properties: Mapping[str, Any], where: str) -> None:
        """Checks of the camera's validated properties that are this source's (``where``: ``properties``). Raises
        ValueError naming ``properties.<field>`` and the value. Nothing here."""

    @classmethod
    def check_for_robot(cls, properties: Mapping[str, Any], robot: Any, where: str) -> None:
        """Checks that need the robot (an :class:`aerodaas.config.RobotConfig`: its backend, say); ``where`` is the
        sensor's path (``sensors.<j>``). Raises ValueError naming it and the property. Nothing here."""

    @classmethod
    def resolve_files(cls, properties: dict[str, Any], resolve: Callable[[str, str], Any], where: str,
                      robot_id: str | None, sensor_id: str) -> None:
        """Resolve the files the properties name, in place (``resolve(path, field)`` returns the absolute path or
        raises ConfigError naming ``field``). Nothing here."""

    # -- in the drone's actor
    def on_vehicle_connected(self) -> None:
        """After the robot's backend connected (before take-off): a source that asks the vehicle where its frames
        are opens now. Raises what opening raises (the run then fails before take-off). Nothing here."""

    @abstractmethod
    def frame_at(self, t: float, pose: FramePose) -> CapturedFrame | None:
        """The frame due at run time ``t`` (s, vehicle clock), the camera at ``pose`` (ENU m, degrees); None when
        there is no new one. Called on the actor's pool, one call at a time per camera. An exception fails the
        capture (reported by the actor's data plane). A source with :attr:`renders_into` is called as
        ``frame_at(t, pose, out=buf)`` when the camera lends a buffer (see there) and returns ``buf`` filled as the
        image."""

    def close(self) -> None:
        """Release what the source holds (files, devices). Nothing here."""


class LiveFrameSource(FrameSource):
    """A source whose frames arrive on their own (see the module docstring): :meth:`start` opens it (or it opens
    in :meth:`on_vehicle_connected`, once the vehicle announced where), :attr:`reader` reads it."""

    wall_clock = True

    def __init__(self, ctx: FrameSourceContext) -> None:
        super().__init__(ctx)
        self.reader: FrameReader | None = None
        #: the stream the vehicle announced (an :class:`aerodaas.video.discovery.DiscoveredStream`), when the
        #: source asked for one: the camera records it as a ``video_discovered`` event and in its stats
        self.discovered: Any = None
        self._on_frame: Callable[[], None] | None = None

    def start(self, on_frame: Callable[[], None]) -> None:
        """Open the source; ``on_frame`` is called from the reader's thread when a frame arrived. Raises
        VideoSourceError (naming the URL) when no first frame comes in time. Remembers ``on_frame`` here."""
        self._on_frame = on_frame

    def frame_at(self, t: float, pose: FramePose) -> CapturedFrame | None:
        """A live source's frames are taken from :attr:`reader` by the camera: never a frame here."""
        return None


def frame_source_names() -> list[str]:
    """The names of the registered frame sources (built in, installed, registered)."""
    return registry.names("frame_source")


def frame_source_class(source: str) -> type[FrameSource]:
    """The class of the frame source a camera's ``properties.source`` selects: the registered frame source of that
    name (or import path ``module:Class``), else the stream source (:data:`STREAM_SOURCE`: ``source`` is a URL or
    a file). Raises :class:`aerodaas.plugins.registry.InvalidPlugin` (a ValueError) for a registered class that is
    not a FrameSource."""
    try:
        return registry.get("frame_source", source)
    except registry.InvalidPlugin:
        raise
    except registry.UnknownPlugin:
        return registry.get("frame_source", STREAM_SOURCE)
