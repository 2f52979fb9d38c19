"""The environment's configuration (``environment.json`` as a whole): compute resources (places: tier and Ray node
labels), the simulated world (ground, moving targets), the simulation clock, the HITL API, the analytics scheduler
and its QoS, the runtime's actor settings; parsing and loading with errors that name the field and the value."""
from __future__ import annotations

import ipaddress
import json
import math
import os
import re
from pathlib import Path
from typing import Annotated, Any, Literal, NamedTuple
import typing
import warnings

from pydantic import BaseModel, Field, PrivateAttr, Strict, ValidationError, field_validator, model_validator

from aerodaas.model.jsonfile import JsonFileError, read_json
from aerodaas.navigation.geofence import Geofence, GeofenceConfig

from aerodaas.config.base import ConfigError, DATA_DIR_ENV, PACKAGE_PREFIX, _Cfg, did_you_mean, packaged_file
from aerodaas.model.bounds import (MAX_DURATION_S, MAX_GROUND_PX, MAX_IMAGE_SIDE_PX, MAX_RATE_HZ, MAX_LIST_ITEMS,
                                   MAX_SEED, MAX_SPEEDUP, MIN_PHYSICS_HZ, MIN_SPEEDUP)
from aerodaas.model.ids import Identifier, check_unique
from aerodaas.config.backends import MavlinkDefaults, apply_mavlink_defaults
from aerodaas.config.robot import RobotConfig, SensorConfig, sensor_class
from aerodaas.plugins import registry


_LABEL_KEY = re.compile(r"^([a-z0-9]([-a-z0-9.]*[a-z0-9])?/)?[A-Za-z0-9]([-A-Za-z0-9_.]{0,61}[A-Za-z0-9])?$")
_LABEL_VALUE = re.compile(r"^([A-Za-z0-9]([-A-Za-z0-9_.]{0,61}[A-Za-z0-9])?)?$")


class ComputeConfig(_Cfg):
    """A compute resource, and the place its actors run: ``tier`` ``edge`` or ``cloud``; ``labels`` are Ray node
    labels beyond ``tier`` that a node must carry to run this resource's actors (e.g.
    ``{"aerodaas/site": "field-2"}``; ``ray start --labels``), matched with Ray's ``label_selector``;
    ``properties`` e.g. cpus, memory_gb, accelerators (informative). Label keys and values follow Ray's (Kubernetes')
    label syntax: ``[prefix/]name`` of at most 63 characters, alphanumerics, ``-``, ``_``, ``.``."""

    id: Identifier
    tier: Literal["edge", "cloud"]
    labels: dict[str, str] = Field(default_factory=dict)
    properties: dict[str, Any] = Field(default_factory=dict)

    @model_validator(mode="after")
    def _labels(self) -> "ComputeConfig":
        for k, v in self.labels.items():
            if k == "tier":
                raise ValueError(f"labels.tier: the tier is the compute resource's 'tier' field ({self.tier!r}); "
                                 f"do not repeat it as a label")
            if not _LABEL_KEY.match(k):
                raise ValueError(f"labels: {k!r} is not a Ray node label key ([prefix/]name, alphanumerics, '-', '_', "
                                 f"'.', at most 63 characters)")
            if not isinstance(v, str) or not _LABEL_VALUE.match(v):
                raise ValueError(f"labels.{k}: {v!r} is not a Ray node label value (alphanumerics, '-', '_', '.', "
                                 f"at most 63 characters)")
        return self


class GroundConfig(_Cfg):
    """The textured ground plane. With ``image`` (any PNG/JPEG) and ``metres_per_pixel``, the image is laid on
    the ground with its top edge north; ``home_px`` is the pixel (x, y) under the home position (default:
    image centre), on the image (checked against the image's size when the file is read). Without ``image``, a
    procedural ground is generated from ``seed``, centred on home (no ``home_px``)."""

    image: str | None = None
    metres_per_pixel: float = Field(default=0.05, gt=0, le=100_000)
    home_px: Annotated[tuple[float, float], Strict(False)] | None = None
    seed: int = Field(default=0, ge=0, le=MAX_SEED)
    size_m: float = Field(default=120.0, gt=0, le=100_000, description="procedural ground side length, metres")

    @model_validator(mode="after")
    def _bounded_texture(self) -> "GroundConfig":
        if self.home_px is not None and self.image is None:
            raise ValueError(f"home_px: {list(self.home_px)} places an image on the ground, but there is no image (the "
                             f"procedural ground is centred on home)")
        if self.image is None and self.size_m / self.metres_per_pixel > MAX_GROUND_PX:
            raise ValueError(f"size_m / metres_per_pixel = {self.size_m:g} / {self.metres_per_pixel:g} = "
                             f"{self.size_m / self.metres_per_pixel:.4g} px per side, above {MAX_GROUND_PX} (the ground "
                             f"texture would not fit in memory): use a larger metres_per_pixel")
        return self


class TargetPathPoint(_Cfg):
    """Target position (ENU metres from the home of the first robot) at sim time ``t`` seconds."""

    t: float = Field(ge=0, le=MAX_DURATION_S * 365)
    x: float = Field(ge=-100_000, le=100_000)
    y: float = Field(ge=-100_000, le=100_000)

    @field_validator("t", "x", "y")
    @classmethod
    def _finite(cls, v: float, info) -> float:
        if not math.isfinite(v):
            raise ValueError(f"{info.field_name} must be finite, got {v!r}")
        return v


class TargetConfig(_Cfg):
    """A moving ground target drawn from a crop of a real image. ``crop`` is (x0, y0, x1, y1) in pixels of
    ``image``; the crop's long axis is drawn ``length_m`` long, facing along its path (the crop's front is
    its right edge, i.e. the crop image points east). The target exists between the first and last ``path``
    times; it is linearly interpolated in between."""

    id: Identifier
    class_name: str = "car"
    image: str
    crop: Annotated[tuple[int, int, int, int], Strict(False)]
    length_m: float = Field(default=4.3, gt=0, le=100_000)
    path: list[TargetPathPoint] = Field(min_length=2, max_length=100_000)

    @model_validator(mode="after")
    def _check(self) -> "TargetConfig":
        x0, y0, x1, y1 = self.crop
        if x1 <= x0 or y1 <= y0 or min(self.crop) < 0:
            raise ValueError(f"crop must be (x0, y0, x1, y1) with x1 > x0 >= 0 and y1 > y0 >= 0, got {self.crop}")
        ts = [p.t for p in self.path]
        if any(b <= a for a, b in zip(ts, ts[1:])):
            raise ValueError(f"path times must be strictly increasing, got {ts}")
        return self


class WorldConfig(_Cfg):
    ground: GroundConfig = Field(default_factory=GroundConfig)
    targets: list[TargetConfig] = Field(default_factory=list, max_length=MAX_LIST_ITEMS)


class SimulationConfig(_Cfg):
    """Simulation clock: ``speedup`` x real time; ``lockstep`` makes sim time wait for analytics to consume each
    frame; ``physics_hz`` is the integration rate. Bounds: ``speedup`` in [MIN_SPEEDUP, MAX_SPEEDUP] = [0.01, 1000];
    ``physics_hz`` in [MIN_PHYSICS_HZ, MAX_RATE_HZ] = [10, 1000] Hz (a coarser step than the 0.1 s control period is
    not covered by the safety gate's envelope model).

    ``recorder_hold_s``: how long in all (wall s, default 120) the simulated clock may wait for a recorder that
    falls behind instead of dropping frames; the summary and ``clock_held`` events say how long it waited; past it
    frames are shed and the run ends ``recording_lost``. Real vehicles and video streams never wait (0 there,
    :func:`aerodaas.runtime.preflight.simulation_for`)."""

    speedup: float = Field(default=1.0, ge=MIN_SPEEDUP, le=MAX_SPEEDUP)
    lockstep: bool = False
    physics_hz: float = Field(default=50.0, ge=MIN_PHYSICS_HZ, le=MAX_RATE_HZ)
    recorder_hold_s: float = Field(default=120.0, ge=0.0, le=3600.0)


class HitlConfig(_Cfg):
    """Human-in-the-loop HTTP API (see :mod:`aerodaas.tools.hitl`). Loopback-only by default; ``token`` is the
    bearer token (generated at start when not given; either way handed over in the owner-only state file, never
    printed). ``port`` 0 picks a free port. Off loopback: HTTPS with ``tls_cert`` / ``tls_key`` (PEM files, relative
    to this file or ``$AERODAAS_DATA_DIR``), or plain HTTP only with ``insecure: true``
    (:mod:`aerodaas.clusters.tls`)."""

    enabled: bool = False
    host: str = "127.0.0.1"
    port: int = Field(default=8470, ge=0, le=65535)
    token: str | None = Field(default=None, min_length=16, max_length=256)
    docs: bool = Field(default=False, description="serve /docs and /openapi.json (behind the bearer token)")
    tls_cert: str | None = Field(default=None, min_length=1, description="PEM certificate (chain): serve HTTPS")
    tls_key: str | None = Field(default=None, min_length=1, description="PEM private key of tls_cert (mode 0600)")
    insecure: bool = Field(default=False, description="serve plain HTTP off loopback (the summary says so)")

    @field_validator("token")
    @classmethod
    def _token_chars(cls, v: str | None) -> str | None:
        """A bearer token is RFC 6750 section 2.1's ``b64token``: letters, digits and ``-._~+/``, then ``=``
        padding; no blank (16 spaces are not a secret)."""
        if v is not None and not re.fullmatch(r"[A-Za-z0-9\-._~+/]{16,}=*", v):  # as aerodaas.tools.hitl.TOKEN_RE
            raise ValueError("a bearer token is 16 to 256 characters of A-Z a-z 0-9 - . _ ~ + / (then '=' padding; "
                             "RFC 6750 section 2.1), no blanks")
        return v

    @field_validator("host")
    @classmethod
    def _host_syntax(cls, v: str) -> str:
        """A host name (RFC 1123 labels) or an IPv4/IPv6 address; dotted numbers must be a valid IPv4 address
        (``999.999.1.1`` is not). Whether it is an address of this machine is checked before Ray starts."""
        h = v.strip()
        if h.startswith("[") and h.endswith("]"):
            h = h[1:-1]
        try:
            ipaddress.ip_address(h)
            return h
        except ValueError:
            pass
        if re.fullmatch(r"[0-9.]+", h) or not re.fullmatch(
                r"(?=.{1,253}$)[A-Za-z0-9]([A-Za-z0-9-]{0,61}[A-Za-z0-9])?(\.[A-Za-z0-9]([A-Za-z0-9-]{0,61}[A-Za-z0-9])?)*", h):
            raise ValueError(f"{v!r} is neither an IP address nor a host name")
        return h


class AnalyticsQosConfig(_Cfg):
    """Quality of service of one scheduled analytics, in the terms of the Ocularone workload (Raj et al., FGCS 2025):
    a result within ``deadline_ms`` of the frame's capture earns ``benefit``; running it costs ``edge_cost`` on the
    edge or ``cloud_cost`` on the cloud, charged whether or not it met the deadline. ``edge_ms`` / ``cloud_ms`` are
    the expected execution times (ms; the cloud's includes the network round trip) the scheduler plans with."""

    deadline_ms: float = Field(gt=0, le=1e7, description="relative deadline from capture, ms")
    edge_ms: float = Field(gt=0, le=1e7, description="expected execution time on the edge, ms")
    cloud_ms: float = Field(gt=0, le=1e7, description="expected round trip on the cloud, ms")
    benefit: float = Field(ge=0, le=1e9)
    edge_cost: float = Field(default=0.0, ge=0, le=1e9)
    cloud_cost: float = Field(default=0.0, ge=0, le=1e9)


class AnalyticsSchedulerConfig(_Cfg):
    """The analytics scheduler (the paper's ``setAnalyticsScheduler``): per frame, it places each *scheduled*
    analytics on the edge, on the cloud, or drops it with a reason.

    ``name``: a registered scheduler (``EDGE_FIFO`` ... ``DEMS``, ``DEMS-A``, ``GEMS``, ``GAINPLAN``, or a plug-in
    registered with :func:`aerodaas.schedulers.analytics_base.register_analytics_scheduler`); ``default`` runs
    every analytics where it is deployed. ``models``: analytics name -> its QoS, inline, or the name of a model
    of ``workload`` under ``load`` (e.g. ``"HV"`` of ``workloads/ocularone_lambda.json``). Analytics not named
    here run where they are deployed. ``cloud_executors``: cloud executor actors (tier=cloud nodes, else this
    node). ``network``: emulated extra cloud latency (:class:`aerodaas.schedulers.dispatch.emulation.NetworkModel` specs, e.g.
    ``"const:40"`` or ``"normal:60,15"``; ``"none"`` for a real network)."""

    name: str = "default"
    models: dict[str, AnalyticsQosConfig | str] = Field(default_factory=dict)
    workload: str | None = Field(default=None, description="workload JSON (Ocularone format) for named models")
    load: str | None = Field(default=None, description="load of the workload: LIGHT, MEDIUM, HEAVY")
    cloud_executors: int = Field(default=1, ge=1, le=64)
    network: list[str] = Field(default_factory=lambda: ["none"])
    jpeg_quality: int = Field(default=90, ge=10, le=100, description="JPEG quality of frames sent to the cloud")

    @field_validator("name")
    @classmethod
    def _known_scheduler(cls, v: str) -> str:
        if v != "default":
            try:  # a registered name, an installed entry point or "module.path:ClassName"; imported here
                registry.get("analytics_scheduler", v)
            except registry.UnknownPlugin as e:
                raise ValueError(f"{e} (or 'default')") from None
        return v

    @field_validator("network", mode="before")
    @classmethod
    def _one_or_many(cls, v: Any) -> Any:
        return [v] if isinstance(v, str) else v

    @model_validator(mode="after")
    def _check(self) -> "AnalyticsSchedulerConfig":
        if self.name == "default":
            return self
        if not self.models:
            raise ValueError(f"models: the {self.name} scheduler needs the QoS of at least one analytics "
                             f"(analytics name -> {{deadline_ms, edge_ms, cloud_ms, benefit, edge_cost, cloud_cost}})")
        named = sorted(k for k, v in self.models.items() if isinstance(v, str))
        if named and (self.workload is None or self.load is None):
            raise ValueError(f"models: {named} name workload models, which needs 'workload' and 'load'")
        from aerodaas.schedulers.dispatch.emulation import NetworkModel  # lazy: start-up (a scheduler only)

        NetworkModel.parse(self.network)  # ValueError naming the bad spec
        return self

    def resolved_workload(self, base: "EnvironmentConfig | None" = None):
        """The QoS of every scheduled analytics as a :class:`aerodaas.schedulers.analytics_base.Workload` keyed by
        analytics name (named models read from ``workload``, resolved like every file of the environment).
        Raises ConfigError naming the field for a missing file, load or model."""
        from aerodaas.schedulers.analytics_base import ModelProfile, Workload  # lazy: start-up (a scheduler only)

        data = None
        if any(isinstance(v, str) for v in self.models.values()):
            path = base.resolve_path(self.workload, "analytics_scheduler.workload") if base is not None \
                else Path(self.workload)
            try:
                data = read_json(path)
            except (OSError, ValueError) as e:
                raise ConfigError(f"analytics_scheduler.workload: cannot read {str(path)!r}: {e}") from None
        models = {}
        for name, v in self.models.items():
            if isinstance(v, str):
                try:
                    p = Workload.from_dict(data, self.load)[v]
                except (ValueError, KeyError) as e:
                    raise ConfigError(f"analytics_scheduler.models.{name}: {str(e).strip(chr(34))}") from None
                models[name] = ModelProfile(name, p.edge_ms, p.cloud_ms, p.benefit, p.edge_cost, p.cloud_cost,
                                            p.deadline_ms)
            else:
                models[name] = ModelProfile(name, v.edge_ms, v.cloud_ms, v.benefit, v.edge_cost, v.cloud_cost,
                                            v.deadline_ms)
        return Workload(self.load or "custom", models)


class RecordingConfig(_Cfg):
    """How a run is recorded (``recording`` in ``environment.json``). ``per_node``: one recorder actor per edge
    compute of the run besides the driver's (each on its compute's nodes, by its labels), writing
    ``RUN.node-<compute>.mcap`` next to ``RUN.mcap`` with its own accounting; the drones and analytics of that
    compute record to it, everything else (cloud analytics, the mission results) to the driver's file.
    ``aerodaas merge`` joins the files into one (``docs/results/recorder.md``: when one recorder is the limit)."""

    per_node: bool = Field(default=False, description="one recorder per edge compute, each writing "
                           "RUN.node-<compute>.mcap (joined by `aerodaas merge`); false: every actor records into the "
                           "driver's file")


class ReferencedFile(NamedTuple):
    """A file the environment names: ``field`` (its place in ``environment.json``, e.g. ``world.ground.image``,
    ``robots.0.replay.log``) and ``path`` (absolute, as :meth:`EnvironmentConfig.resolve_path` found it)."""

    field: str
    path: str


class EnvironmentConfig(_Cfg):
    """Root of ``environment.json``. ``aerodaas schema`` prints its JSON Schema.

    ``trajectory_scheduler`` is resolved through :mod:`aerodaas.plugins.registry` when the file is validated
    (before Ray starts); an unknown name is a ``ValueError`` naming the field, the value, the available
    schedulers and the closest match."""

    name: str = "environment"
    robots: list[RobotConfig] = Field(min_length=1, max_length=MAX_LIST_ITEMS)
    env_sensors: list[SensorConfig] = Field(default_factory=list, max_length=MAX_LIST_ITEMS)
    compute: list[ComputeConfig] = Field(default_factory=lambda: [ComputeConfig(id="edge", tier="edge")],
                                         max_length=MAX_LIST_ITEMS)
    world: WorldConfig = Field(default_factory=WorldConfig)
    simulation: SimulationConfig = Field(default_factory=SimulationConfig)
    hitl: HitlConfig = Field(default_factory=HitlConfig)
    analytics_scheduler: AnalyticsSchedulerConfig = Field(default_factory=AnalyticsSchedulerConfig)
    trajectory_scheduler: str | None = Field(
        default=None, description="the trajectory scheduler used when the app sets none: a registered name "
        "(TrajectoryScheduler, NearestNeighborScheduler, TwoOptScheduler, a plug-in) or 'module.path:ClassName'; "
        "constructed as Class(env). Unset: TrajectoryScheduler")
    recording: RecordingConfig = Field(default_factory=RecordingConfig)
    mavlink: MavlinkDefaults = Field(default_factory=MavlinkDefaults, description="defaults for every robot on a "
                                     "MAVLink backend (a robot's own mavlink section overrides them)")
    drones_per_actor: int = Field(default=1, ge=1, le=256, description="drones sharing one drone actor (one process); "
                                  "1: an actor per drone; more for large fleets (less memory and CPU per drone)")
    actor_max_restarts: int = Field(default=1, ge=0, le=100, description="Ray max_restarts of every drone, analytics, "
                                    "dispatcher and per-node recorder actor (the run's recorder: 3, new segments)")
    actor_opencv_threads: int | None = Field(
        default=1, ge=1, le=256, description="OpenCV's worker threads (cv2.setNumThreads) in each drone and analytics "
        "actor of a run: 1 renders each frame on the thread that asks for it, no pool thread per actor competing for "
        "a node's cores shared by many actors; null keeps OpenCV's default, one per core (a shorter render for a node "
        "that carries one drone)")
    actor_restart_timeout_s: float = Field(default=60.0, gt=0, le=3600, description="how long the driver waits for "
                                           "a dead drone actor to come back before its drones end as 'lost', s")
    same_node_transport: Literal["channel", "ray"] = Field(
        default="channel", description="how messages (frames above all) travel between two actors of a run on the "
        "same machine: 'channel' (the frame copied once into a shared-memory slot the receiver reads in place, the "
        "message and its reply on a persistent authenticated Unix socket: no Ray call per frame) or 'ray' (ray.put "
        "of the frame and an actor call per message). Actors on different machines always use Ray (an ObjectRef on "
        "one tier, JPEG across tiers), in lock-step runs too (lock-step only makes the clock wait for each frame's "
        "cascade)")
    base_dir: str | None = Field(default=None, description="set by the loader: folder of the environment file")
    _source_file: str | None = PrivateAttr(default=None)
    #: absolute path -> the field that named it, for every file :meth:`resolve_path` found (see :attr:`files_read`)
    _files_read: dict[str, str] = PrivateAttr(default_factory=dict)

    @property
    def files_read(self) -> tuple[ReferencedFile, ...]:
        """Every file this configuration names that was resolved (:meth:`resolve_path`: the ground and target
        images, a replay's log, a recorded camera's MCAP or video file, a geofence ``.plan``, the analytics
        workload, a MAVLink signing key, the HITL API's TLS files, and any file a plug-in resolves through it), in
        the order they were first resolved: inputs of the run, which ``--record`` never overwrites."""
        return tuple(ReferencedFile(field, path) for path, field in self._files_read.items())

    @property
    def source_file(self) -> str | None:
        """The absolute path of the file this configuration was read from (:func:`load_environment_config`), None
        when it was built from a dict: an input of the run, which ``--record`` never overwrites."""
        return self._source_file

    def read_from(self, path: str | os.PathLike) -> "EnvironmentConfig":
        """Note that this configuration was read from the file ``path`` (made absolute): :attr:`source_file`.
        Returns self."""
        self._source_file = str(Path(path).resolve())
        return self

    @field_validator("trajectory_scheduler")
    @classmethod
    def _known_trajectory_scheduler(cls, v: str | None) -> str | None:
        if v is not None:
            try:  # a registered name, an installed entry point or "module.path:ClassName"; imported here
                registry.get("trajectory_scheduler", v)
            except registry.UnknownPlugin as e:
                raise ValueError(str(e)) from None
        return v

    @model_validator(mode="after")
    def _unique(self) -> "EnvironmentConfig":
        for name, items in (("robots", self.robots), ("compute", self.compute), ("env_sensors", self.env_sensors),
                            ("world.targets", self.world.targets)):
            check_unique([i.id for i in items], name)
        edges = [c.id for c in self.compute if c.tier == "edge"]
        for j, r in enumerate(self.robots):
            if r.compute is not None and r.compute not in edges:
                raise ValueError(f"robots.{j}.compute: {r.compute!r} is not an edge compute resource of this "
                                 f"environment (edge: {edges})")

        by_backend: dict[type, list] = {}
        for j, r in enumerate(self.robots):
            by_backend.setdefault(registry.get("backend", r.backend), []).append((j, r))
        for backend_cls, on_it in by_backend.items():  # each backend's own checks across its robots
            backend_cls.check_fleet(on_it)

        for j, s in enumerate(self.env_sensors):
            try:
                cls = sensor_class(s.type)
            except registry.UnknownPlugin:
                cls = None
            if not getattr(cls, "environment_sensor", False):
                kinds = sorted(e.name for e in registry.entries("sensor")
                               if e.builtin and getattr(e.load(), "environment_sensor", False))
                raise ValueError(f"env_sensors.{j}.type: sensor {s.id!r} has type {s.type!r}; an environment sensor is "
                                 f"one of {kinds} (a sensor plug-in samples a robot's state: "
                                 f"list it under robots[].sensors)")
            cls.check_for_environment(s.properties, f"env_sensors.{j}")
        return self

    @model_validator(mode="after")
    def _mavlink_defaults(self) -> "EnvironmentConfig":
        apply_mavlink_defaults(self.robots, self.mavlink)  # require_signing, checked before Ray (config/backends.py)
        return self

    def resolve_path(self, rel: str, field: str) -> Path:
        """Resolve a file named in the config: ``package:NAME``, one of the images shipped in the package
        (:func:`~aerodaas.config.base.packaged_file`); else absolute, relative to the env file, under
        $AERODAAS_DATA_DIR, or relative to the current folder, the first that exists. Raises ConfigError naming
        ``field`` and the search locations when it is not found."""
        if rel.startswith(PACKAGE_PREFIX):
            found = packaged_file(rel, field)
            self._files_read.setdefault(str(found), field)
            return found
        p = Path(os.path.expanduser(rel))
        cands = [p] if p.is_absolute() else []
        if not p.is_absolute():
            if self.base_dir:
                cands.append(Path(self.base_dir) / p)
            if os.environ.get(DATA_DIR_ENV):
                cands.append(Path(os.environ[DATA_DIR_ENV]) / p)
            cands.append(Path.cwd() / p)
        for c in cands:
            if c.is_file():
                found = c.resolve()
                self._files_read.setdefault(str(found), field)
                return found
        raise ConfigError(f"{field}: file {rel!r} not found (looked in: {', '.join(str(c) for c in cands)}); "
                          f"set {DATA_DIR_ENV} to the folder that holds it, or give an absolute path")


def _format_errors(err: ValidationError, source: str) -> str:
    lines = [f"invalid environment configuration in {source}:"]
    for e in err.errors():
        loc = ".".join(str(x) for x in e["loc"]) or "(root)"
        if e["type"] == "extra_forbidden" and e["loc"]:
            known = _fields_at(EnvironmentConfig, e["loc"][:-1])
            e["msg"] = f"unknown key{did_you_mean(e['loc'][-1], known)}" + (f"; known: {sorted(known)}" if known else "")
        val = e.get("input")
        sval = json.dumps(val, default=str) if not isinstance(val, dict) else "{...}"
        if len(sval) > 80:
            sval = sval[:77] + "..."
        lines.append(f"  {loc}: {e['msg']} (got {sval})")
    return "\n".join(lines)


def _fields_at(model: type, loc: tuple) -> list[str]:
    """The field names of the pydantic model reached from ``model`` along an error location (list indices and dict
    keys skipped); [] when the path does not end at a model."""
    def models_in(tp) -> list[type]:
        if isinstance(tp, type) and issubclass(tp, BaseModel):
            return [tp]
        return [m for a in typing.get_args(tp) for m in models_in(a)]

    cur: list[type] = [model]
    for part in loc:
        if isinstance(part, int) or not cur:
            continue
        nxt = []
        for m in cur:
            f = m.model_fields.get(str(part))
            if f is not None:
                nxt += models_in(f.annotation)
        if not nxt and any(str(part) not in m.model_fields for m in cur):
            continue  # a dict key (e.g. analytics_scheduler.models.<name>)
        cur = nxt
    return sorted({k for m in cur for k in m.model_fields if k != "base_dir"})


def parse_environment_config(data: dict[str, Any], source: str = "<dict>", base_dir: str | None = None) -> EnvironmentConfig:
    """Validate a parsed ``environment.json`` dict. Raises ConfigError naming each bad field and value."""
    if not isinstance(data, dict):
        raise ConfigError(f"invalid environment configuration in {source}: the top level must be a JSON object")
    try:
        cfg = EnvironmentConfig.model_validate(data)
    except ValidationError as e:
        raise ConfigError(_format_errors(e, source)) from None
    cfg.base_dir = base_dir
    # resolve referenced files now, so a missing image fails before any actor starts
    ground = cfg.world.ground
    if ground.image:
        ground.image = str(cfg.resolve_path(ground.image, "world.ground.image"))
        w, h = _image_size(ground.image, "world.ground.image")
        if ground.home_px is not None and not (0 <= ground.home_px[0] <= w and 0 <= ground.home_px[1] <= h):
            raise ConfigError(f"world.ground.home_px: {list(ground.home_px)} is not a pixel of the image "
                              f"{ground.image!r} ({w} x {h} px): x must be within [0, {w}] and y within [0, {h}]")
    for i, t in enumerate(cfg.world.targets):
        t.image = str(cfg.resolve_path(t.image, f"world.targets.{i}.image"))
        w, h = _image_size(t.image, f"world.targets.{i}.image")
        if t.crop[2] > w or t.crop[3] > h:
            raise ConfigError(f"world.targets.{i}.crop: {list(t.crop)} reaches outside its image {t.image!r} "
                              f"({w} x {h} px); x1 must be <= {w} and y1 <= {h}")
    sensors = [(f"robots.{i}.sensors.{j}", r.id, s) for i, r in enumerate(cfg.robots) for j, s in enumerate(r.sensors)]
    sensors += [(f"env_sensors.{j}", None, s) for j, s in enumerate(cfg.env_sensors)]

    for where, robot_id, s in sensors:
        try:
            sensor_class(s.type).resolve_files(s.properties, cfg.resolve_path, where, robot_id, s.id)
        except ConfigError:
            raise
        except ValueError as e:  # a file the sensor reads that is not what it needs (a replay's recording)
            raise ConfigError(str(e)) from None
    for i, r in enumerate(cfg.robots):
        registry.get("backend", r.backend).resolve_files(r, cfg.resolve_path, f"robots.{i}")
        if r.safety.geofence_plan:
            field = f"robots.{i}.safety.geofence_plan"
            path = cfg.resolve_path(r.safety.geofence_plan, field)
            from aerodaas.missionfile import MissionFileError, load_mission  # lazy: start-up (a geofence plan only)

            try:
                fence = load_mission(path).geofence
            except (MissionFileError, OSError) as e:
                raise ConfigError(f"{field}: {e}") from None
            r.safety.geofence = GeofenceConfig(polygons=[*r.safety.geofence.polygons, *fence.polygons],
                                               circles=[*r.safety.geofence.circles, *fence.circles])
            r.safety.geofence_plan = str(path)
    for i, r in enumerate(cfg.robots):
        try:
            why = Geofence(r.safety.geofence, r.home).check_point(0.0, 0.0)
        except ValueError as e:
            raise ConfigError(f"robots.{i}.safety.geofence: {e}") from None
        if why is not None:
            raise ConfigError(f"robots.{i}.safety.geofence: the home position ({r.home.lat}, {r.home.lon}) is {why}; "
                              f"the drone takes off there, so the fence must allow it")
        registry.get("backend", r.backend).check_config(r, f"robots.{i}")
    sched = cfg.analytics_scheduler
    if sched.name != "default":
        if sched.workload is not None and any(isinstance(v, str) for v in sched.models.values()):
            sched.workload = str(cfg.resolve_path(sched.workload, "analytics_scheduler.workload"))
        sched.resolved_workload(cfg)  # a missing load or model fails here, before any actor starts
    return cfg


#: largest image (pixels in all) a ground or target image may have: 300 MB as 8-bit RGB, under Pillow's own
#: decompression-bomb bound (2 x Image.MAX_IMAGE_PIXELS = 179 MP)
MAX_IMAGE_PIXELS = 100_000_000


def _image_size(path: str, field: str) -> tuple[int, int]:
    """(width, height) in pixels of an image file. The size is read from the file's header first (Pillow decodes
    nothing to open a file) and refused above :data:`MAX_IMAGE_SIDE_PX` per side or :data:`MAX_IMAGE_PIXELS` in all:
    a PNG "decompression bomb" (a few KB declaring 100,000 x 100,000 px) made ``cv2.imread`` raise ``cv2.error``
    (OpenCV's own bound, CV_IO_MAX_IMAGE_PIXELS) or allocate gigabytes. Only then is it decoded with OpenCV, which
    must read it. Raises ConfigError naming ``field``, the file and the size."""
    import cv2  # lazy: heavy cv2
    from PIL import Image, UnidentifiedImageError  # lazy: heavy PIL
    from PIL.JpegImagePlugin import JpegImageFile  # lazy: heavy PIL

    try:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", Image.DecompressionBombWarning)  # our own bound follows
            with Image.open(path) as im:
                w, h = (int(v) for v in im.size)
                jpeg = isinstance(im, JpegImageFile)  # MPO too (a subclass): what DJI cameras write as .JPG
    except Image.DecompressionBombError as e:
        raise ConfigError(f"{field}: {str(path)!r}: {e} (from its header; at most {MAX_IMAGE_SIDE_PX} px per side "
                          f"and {MAX_IMAGE_PIXELS} px in all; nothing was decoded)") from None
    except (UnidentifiedImageError, OSError, SyntaxError, ValueError) as e:
        raise ConfigError(f"{field}: {str(path)!r} is not an image file (PNG, JPEG, ...): {e}") from None
    if max(w, h) > MAX_IMAGE_SIDE_PX or w * h > MAX_IMAGE_PIXELS:
        raise ConfigError(f"{field}: {str(path)!r} is {w} x {h} px (from its header), above {MAX_IMAGE_SIDE_PX} px "
                          f"per side or {MAX_IMAGE_PIXELS} px in all; nothing was decoded")
    # a JPEG is decoded at 1/8 scale (libjpeg's DCT scaling reads the whole stream, as a full decode does, and fails
    # where it fails): 0.04 s instead of 0.07-0.13 s of CPU per 12 MP drone photo, on the driver before Ray starts;
    # the size is the header's (checked above). Other formats: OpenCV's reduced modes decode in full, then resize
    img = cv2.imread(str(path), cv2.IMREAD_REDUCED_COLOR_8 if jpeg else cv2.IMREAD_UNCHANGED)
    if img is None:
        raise ConfigError(f"{field}: {str(path)!r} is not an image OpenCV can read (PNG, JPEG, ...)")
    return (w, h) if jpeg else (int(img.shape[1]), int(img.shape[0]))


def load_environment_config(path: str | os.PathLike) -> EnvironmentConfig:
    """Read and validate an environment file. Raises ConfigError (missing file, bad JSON, bad fields)."""
    p = Path(path)
    if not p.is_file():
        raise ConfigError(f"environment file {str(p)!r} not found")

    try:
        data = read_json(p)
    except JsonFileError as e:
        raise ConfigError(f"environment file {e}") from None
    except OSError as e:
        raise ConfigError(f"environment file {str(p)!r}: cannot read ({e.strerror or e})") from None
    cfg = parse_environment_config(data, source=str(p), base_dir=str(p.resolve().parent))
    return cfg.read_from(p)


def json_schema() -> dict[str, Any]:
    """The JSON Schema of ``environment.json``."""
    return EnvironmentConfig.model_json_schema()
