"""The run's dataflow graph, typed, and its placement on Ray actors — built once from the application.

A :class:`RunPlan` holds:

* **nodes** (:class:`Node`): every component — each robot's drone, cameras, odometry and stat-stream sensors and
  trajectory scheduler, and every *instance* of an analytics (one per replica, or one copy per drone for a
  colocated analytics, or one per edge compute for an analytics placed per frame by the analytics scheduler);
* **edges** (:class:`Edge`): producer -> consumer, entering the consumer at a :class:`Port` (an analytics input, or
  a trajectory scheduler's priority port, optionally ``replace``), with the stream's buffer and the robots whose
  items travel on it (an edge to a replica or to a drone's own copy carries only that drone's items);
* **actors** (:class:`ActorPlan`): which Ray actor each node lives in, its Ray name, its tier and compute
  resource, and the ``label_selector`` that places it. Roles: ``drone`` (one per drone, or per
  ``drones_per_actor`` drones: vehicle backend, flight logic, sensors, waypoint queue and colocated analytics),
  ``analytics`` (one per deployed analytics replica), ``dispatcher`` (one per edge compute resource whose drones
  feed analytics placed by the analytics scheduler: the scheduler and its edge executor) and ``recorder`` (one per
  run).

``aerodaas plan APP.py`` prints it without flying (like Ray Serve's build step); :mod:`aerodaas.runtime.driver` starts
the actors it lists.
"""
from __future__ import annotations

import copy
import os
from dataclasses import dataclass, field
from typing import Any

from aerodaas.analytics.contract import output_schemas, stream_types
from aerodaas.backends import backend_class
from aerodaas.config.robot import sensor_class
from aerodaas.perception.track_records import declared_track_channels
from aerodaas.plugins import registry
from aerodaas.plugins.sensor import Delivery
from aerodaas.protocol.ids import ComponentId, ComponentKind
from aerodaas.protocol.messages import Port
from aerodaas.protocol.specs import ActorSpec, AnalyticsSpec, CameraSpec, RecordSpec, RobotSpec, Role
from aerodaas.runtime.node_recorders import add_node_recorders
from aerodaas.runtime.plan_robots import robot_uses

__all__ = ["Port", "Node", "Edge", "ActorPlan", "RunPlan", "Placement", "build_plan", "collect_graph"]


@dataclass(frozen=True)
class Node:
    """One component: ``id`` (unique in the run; a :class:`~aerodaas.protocol.ids.ComponentId` that knows its
    ``kind`` and robot), ``kind``, the robot it belongs to (None for a shared analytics) and the actor id of the
    actor it lives in."""

    id: ComponentId
    kind: ComponentKind
    robot: str | None
    actor: str
    analytics: str | None = None  # the analytics' name, for analytics nodes
    #: a plug-in sensor's type and the schema its readings are recorded with (``sensor`` nodes)
    plugin: str | None = None


@dataclass(frozen=True)
class Edge:
    """``src`` -> ``dst`` at ``port``; ``buffer`` items may wait at the consumer; ``robots``: only items of these
    robots travel on it (None: all); ``types``: the message types it carries, in the stream-type names ``consumes``
    is checked with (:func:`aerodaas.analytics.contract.stream_types`: ``frame``, ``odometry``, ``stat``, a sensor's
    type, an output model's schema name ...; ``aerodaas.AnalyticsOutput`` for a free-form analytics output)."""

    src: str
    dst: str
    port: Port
    buffer: int
    robots: tuple[str, ...] | None = None
    types: tuple[str, ...] = ()

    def route(self) -> tuple:
        """The form the actors route with: ``(dst, port, buffer, robots)``."""
        return (self.dst, self.port, self.buffer, self.robots)


@dataclass
class ActorPlan:
    """One Ray actor of the run. ``host_id`` is unique in the run (``drone/d1``, ``analytics/edge/detector#1``,
    ``dispatcher/edge``, ``recorder``); ``name`` is its Ray actor name (``aerodaas/<run>/<host_id>``); ``spec``:
    what the actor is built from (:class:`~aerodaas.protocol.specs.ActorSpec`)."""

    actor_id: str
    role: Role
    name: str
    tier: str
    compute: str | None
    labels: dict[str, str]
    components: list[str] = field(default_factory=list)
    spec: ActorSpec | None = None
    #: Ray's logical GPUs the actor asks for (an analytics actor whose analytics asks, e.g. a detector on a GPU
    #: provider: :attr:`aerodaas.analytics.base.Analytics.num_gpus`); 0: none
    num_gpus: float = 0.0

    def __post_init__(self) -> None:
        if self.spec is None:
            self.spec = ActorSpec(self.role)

    def selector(self, placement: "Placement") -> dict[str, str]:
        """The ``label_selector`` for this actor on the cluster described by ``placement``."""
        return placement.selector(self.tier, self.labels)

    def ray_options(self, placement: "Placement", max_restarts: int) -> dict[str, Any]:
        """The options this actor is created with: its Ray ``name``, ``label_selector`` (:meth:`selector`),
        ``max_restarts`` and, when it asks for GPUs, ``num_gpus``."""
        opts: dict[str, Any] = {"name": self.name, "label_selector": self.selector(placement),
                                "max_restarts": max_restarts}
        if self.num_gpus > 0:
            opts["num_gpus"] = self.num_gpus
        return opts


@dataclass(frozen=True)
class Placement:
    """What the cluster offers: ``has_cloud`` (a live node labelled ``tier=cloud``) and ``local`` (the single
    node Ray started here, labelled only ``tier=edge``). Local mode keeps everything on this machine: cloud compute
    may use the edge node and compute labels are not required."""

    has_cloud: bool = False
    local: bool = False

    def selector(self, tier: str, labels: dict[str, str]) -> dict[str, str]:
        """``{"tier": tier, **labels}``; cloud actors fall back to ``in(edge,cloud)`` without cloud nodes; local
        mode drops ``labels`` (this node has none)."""
        sel = {"tier": tier if tier == "edge" or self.has_cloud else "in(edge,cloud)"}
        if not self.local:
            sel.update(labels)
        return sel


@dataclass
class RunPlan:
    """The typed dataflow graph of a run and where each node goes (see the module docstring)."""

    run_id: str
    nodes: dict[str, Node]
    edges: list[Edge]
    actors: dict[str, ActorPlan]
    robots: dict[str, dict]
    analytics_instances: dict[int, list[str]]
    #: the run's secret for same-node channels (``same_node_transport: channel``; None: Ray calls only)
    channel_key: bytes | None = field(default=None, repr=False)
    #: robot id -> its backend, trajectory scheduler and sensors (:mod:`aerodaas.runtime.plan_robots`)
    robot_uses: dict[str, Any] = field(default_factory=dict)

    def routes(self) -> dict[str, list[tuple]]:
        """Producer id -> its edges in wire form (see :meth:`Edge.route`)."""
        out: dict[str, list[tuple]] = {}
        for e in self.edges:
            out.setdefault(e.src, []).append(e.route())
        return out

    def location(self) -> dict[str, str]:
        """Component id -> actor id of its actor."""
        return {n.id: n.actor for n in self.nodes.values()}

    def peer_names(self) -> dict[str, str]:
        """DataPlane id -> Ray actor name."""
        return {h: a.name for h, a in self.actors.items()}

    def describe(self, placement: Placement | None = None) -> dict:
        """A JSON-ready description: actors (role, name, tier, compute, label_selector, components), robots (backend,
        trajectory scheduler and sensors, :meth:`aerodaas.runtime.plan_robots.RobotUse.describe`), nodes, edges
        (with the message ``types`` each carries)."""
        placement = placement or Placement(has_cloud=True)
        return {"run": self.run_id,
                "actors": [{"host": a.actor_id, "role": a.role, "name": a.name, "tier": a.tier, "compute": a.compute,
                            "label_selector": a.selector(placement), "components": list(a.components),
                            **({"num_gpus": a.num_gpus} if a.num_gpus else {}),
                            **({"mavlink_links": a.spec.mavlink_links} if a.spec.mavlink_links else {})}
                           for a in self.actors.values()],
                "robots": [u.describe() for u in self.robot_uses.values()],
                "nodes": [{"id": n.id, "kind": n.kind, "robot": n.robot, "actor": n.actor,
                           **({"analytics": n.analytics} if n.analytics else {}),
                           **({"plugin": n.plugin} if n.plugin else {})} for n in self.nodes.values()],
                "edges": [{"from": e.src, "to": e.dst, "port": e.port.wire(), "buffer": e.buffer,
                           "robots": list(e.robots) if e.robots is not None else None, "types": list(e.types)}
                          for e in self.edges]}

    def text(self, placement: Placement | None = None) -> str:
        """The plan for humans: one block per actor, one per robot (backend, trajectory scheduler, sensors), then
        every edge with the message types it carries (those that cross actors marked)."""
        placement = placement or Placement(has_cloud=True)
        lines = [f"run {self.run_id}: {len(self.actors)} actors, {len(self.nodes)} components, {len(self.edges)} edges"]
        for a in self.actors.values():
            sel = ",".join(f"{k}={v}" for k, v in a.selector(placement).items())
            lines.append(f"  {a.role:<10} {a.name}  [{sel}]" + (f"  compute {a.compute}" if a.compute else "")
                         + (f"  num_gpus {a.num_gpus:g}" if a.num_gpus else ""))
            for key, ids in a.spec.mavlink_links.items():
                lines.append(f"      mavlink link {key} shared by {', '.join(ids)} (one socket, routed by system id)")
            for c in a.components:
                plug = f"  ({self.nodes[c].plugin})" if self.nodes[c].plugin else ""
                lines.append(f"      {self.nodes[c].kind:<11} {c}{plug}")
        for u in self.robot_uses.values():
            lines.extend(u.text())
        if self.edges:
            lines.append("  edges (* between actors):")
        for e in self.edges:
            only = f" (items of {', '.join(e.robots)})" if e.robots else ""
            cross = "*" if self.nodes[e.src].actor != self.nodes[e.dst].actor else " "
            lines.append(f"    {cross} {e.src} -> {e.dst} [{e.port.wire()}] {' | '.join(e.types)}{only}")
        return "\n".join(lines)


def _link_of(robot) -> str | None:
    return backend_class(robot.cfg.backend).link_key(robot.cfg)


def _drone_chunks(group: list, k: int) -> list[list]:
    """``group`` (robots of one edge compute, in order) cut into drone actors of at most ``k`` robots, except that
    robots whose ``mavlink.connection`` names one endpoint always share one actor (one process holds the socket;
    :mod:`aerodaas.backends.mavlink.shared_link`): such a set is never split, and is an actor of its own when it
    has more than ``k`` robots."""
    units: list[list] = []
    by_link: dict[str, list] = {}
    for r in group:
        key = _link_of(r)
        if key is None:
            units.append([r])
        elif key in by_link:
            by_link[key].append(r)
        else:
            by_link[key] = [r]
            units.append(by_link[key])
    chunks: list[list] = []
    for u in units:
        if chunks and len(chunks[-1]) + len(u) <= k and len(chunks[-1]) < k:
            chunks[-1].extend(u)
        else:
            chunks.append(list(u))
    return chunks


def _shared_links(chunk: list) -> dict[str, list[str]]:
    """Endpoint -> robot ids, for each MAVLink link that more than one robot of ``chunk`` names."""
    out: dict[str, list[str]] = {}
    for r in chunk:
        key = _link_of(r)
        if key is not None:
            out.setdefault(key, []).append(r.id)
    return {key: ids for key, ids in out.items() if len(ids) > 1}


def sensor_plugin_spec(sensor, cid: str) -> dict:
    """What a drone actor needs to run plug-in sensor ``sensor`` (an :class:`aerodaas.app.api.Sensor` whose type is
    not built in): its component id, sensor id, type, the plug-in class itself (it travels to the actor), its
    validated properties, its recording schema (``{name: JSON Schema}``; empty when the plug-in names a
    schema the recorder knows) and its failure limit (``max_failure_fraction``, :mod:`aerodaas.recording.health`)."""
    entry = registry.resolve("sensor", sensor.type)
    cls = entry.load()
    js = cls.json_schema()
    return {"cid": cid, "sensor": sensor.id, "type": sensor.type, "cls": cls, "origin": entry.origin,
            "properties": dict(sensor.cfg.properties), "schema_name": cls.schema_name(),
            "schema": {cls.schema_name(): js} if js else {}, "max_failure_fraction": sensor.cfg.max_failure_fraction}


def robot_plugins(cfg) -> list[tuple[str, str, type, str]]:
    """The plug-in classes ``cfg`` (a RobotConfig) names — a plug-in backend, plug-in sensor types and the plug-in
    frame sources its cameras' ``properties.source`` name — as ``(kind, name, class, origin)``: they travel with
    the drone actor's spec and are registered there before the robot's configuration is validated again
    (:func:`aerodaas.plugins.registry.adopt`; a node without the plug-in's distribution has no entry point of it)."""
    wanted = [("backend", cfg.backend)] + [("sensor", s.type) for s in cfg.sensors]
    sources = set(registry.names("frame_source"))
    for s in cfg.sensors:
        src = s.properties.get("source", "sim")
        if sensor_class(s.type).delivery.frames and (src in sources or registry.is_import_path(src)):
            wanted.append(("frame_source", src))
    out = []
    for kind, name in dict.fromkeys(wanted):
        e = registry.resolve(kind, name)
        if not e.builtin:  # a built-in is known in every process that imports aerodaas
            out.append((kind, name, e.load(), e.origin))
    return out


def collect_graph(robot) -> list:
    """The analytics reachable from ``robot``'s sensors, in topological order."""
    order, seen = [], set()

    def visit(stream):
        for sub in stream.subscribers:
            if id(sub) not in seen:
                seen.add(id(sub))
                order.append(sub)
                visit(sub.output)
                for named in (getattr(sub, "named_streams", None) or {}).values():  # its named outputs' subscribers
                    visit(named)

    for s in robot.sensors.values():
        visit(s.get_data_stream())
    return order


def _edge_compute(env, robot) -> tuple[str, dict[str, str]]:
    """The edge compute resource ``robot`` flies from (``robots[].compute``, default the first edge compute) and
    its labels; ``("edge", {})`` for an environment without edge compute."""
    edges = [c for c in env.cfg.compute if c.tier == "edge"]
    cid = robot.cfg.compute or (edges[0].id if edges else None)
    for c in edges:
        if c.id == cid:
            return c.id, dict(c.labels)
    return "edge", {}


@dataclass
class _PlanState:
    """What :func:`build_plan` accumulates: the nodes and the actors (by actor id) of the run."""

    run_id: str
    env: Any
    sim_d: dict
    recorded: bool
    nodes: dict[str, Node] = field(default_factory=dict)
    actors: dict[str, ActorPlan] = field(default_factory=dict)

    def actor(self, actor_id: str, role: Role, tier: str, compute: str | None, labels: dict) -> ActorPlan:
        """The actor ``actor_id``, created on first use."""
        if actor_id not in self.actors:
            spec = ActorSpec(role, sim=self.sim_d,
                             record_remote="recorder" if self.recorded and role != "recorder" else None,
                             restart_hold_s=float(self.env.cfg.actor_restart_timeout_s),
                             opencv_threads=self.env.cfg.actor_opencv_threads)
            self.actors[actor_id] = ActorPlan(actor_id, role, f"aerodaas/{self.run_id}/{actor_id}", tier, compute,
                                              dict(labels), [], spec)
        return self.actors[actor_id]

    def add(self, node: Node) -> None:
        """Add ``node`` to its actor."""
        self.nodes[node.id] = node
        self.actors[node.actor].components.append(node.id)


def _place_drones(st: _PlanState, robots: list, k: int) -> dict[str, str]:
    """Drone actors: one per drone (or per group of ``k`` drones flying from the same edge compute). Returns robot
    id -> its drone actor's id."""
    env = st.env
    drone_host: dict[str, str] = {}
    by_compute: dict[str, list] = {}
    for r in robots:
        by_compute.setdefault(_edge_compute(env, r)[0], []).append(r)
    for comp, group in by_compute.items():
        for chunk in _drone_chunks(group, k):
            hid = f"drone/{chunk[0].id}" if len(chunk) == 1 else f"drones/{chunk[0].id}+{len(chunk) - 1}"
            _, labels = _edge_compute(env, chunk[0])
            a = st.actor(hid, "drone", "edge", comp, labels)
            a.spec.world = env.cfg.world.model_dump(mode="json")
            a.spec.mavlink_links = _shared_links(chunk)
            for r in chunk:
                drone_host[r.id] = hid
    return drone_host


def _place_analytics(st: _PlanState, robots: list, graphs: dict, scheduled: dict,
                     drone_host: dict[str, str]) -> tuple[dict, dict]:
    """Analytics instances: a copy per edge compute's dispatcher (placed per frame by the analytics scheduler), a
    copy inside each drone's actor (colocated), else one actor per replica, each serving a share of the drones.
    Returns (id(a) -> [(component id, actor id, robots served)], id(a) -> analytics)."""
    actors = st.actors
    inst: dict[int, list[tuple[str, str, tuple[str, ...]]]] = {}  # id(a) -> [(cid, actor id, robots served)]
    users: dict[int, list[str]] = {}
    every: dict[int, Any] = {}
    for r in robots:
        for a in graphs[r.id]:
            users.setdefault(id(a), []).append(r.id)
            every[id(a)] = a
    for n, (aid, a) in enumerate(every.items(), start=1):
        base = f"{a.name}#{n}"
        served = users[aid]
        buffer = sum(s.buffer for s in a.inputs) or 1  # a shared analytics keeps each input's share
        inst[aid] = []

        def place(name: str, hid: str, robots_: tuple, role: Role, tier: str, compute: str | None, labels: dict,
                  scheduled_: bool = False, obj: Any = None) -> None:
            pa = st.actor(hid, role, tier, compute, labels)
            if role == "analytics":  # its own actor: the GPUs it asks for (colocated/scheduled: refused before)
                pa.num_gpus = max(pa.num_gpus, float(getattr(a, "num_gpus", 0.0) or 0.0))
            cid = ComponentId(name, "analytics", robots_[0] if len(robots_) == 1 and role == "drone" else None)
            pa.spec.analytics.append(AnalyticsSpec(cid, a.name, a if obj is None else obj,
                                                   max(buffer, 8) if scheduled_ else buffer, scheduled_))
            st.add(Node(cid, "analytics", cid.robot, hid, a.name))
            inst[aid].append((cid, hid, robots_))

        if aid in scheduled:  # per frame by the analytics scheduler: a copy in each edge compute's dispatcher
            per: dict[str, list[str]] = {}
            for rid in served:
                per.setdefault(actors[drone_host[rid]].compute or "edge", []).append(rid)
            for comp, rids in per.items():
                labels = actors[drone_host[rids[0]]].labels
                cid = base if len(per) == 1 else f"{base}@{comp}"
                place(cid, f"dispatcher/{comp}", tuple(rids), "dispatcher", "edge", comp, labels, True)
        elif getattr(a, "colocate", False):  # a copy inside each drone's actor: per-drone state by construction
            for j, rid in enumerate(served):
                place(f"{base}@{rid}", drone_host[rid], (rid,), "drone", "edge", None, {},
                      obj=a if j == 0 else copy.deepcopy(a))
        else:
            n_rep = max(1, int(getattr(a, "replicas", 1)))
            comp = a.compute
            labels = dict(getattr(getattr(comp, "cfg", None), "labels", {}) or {})
            cname = getattr(comp, "id", a.compute.tier)
            for i in range(n_rep):
                rids = tuple(rid for j, rid in enumerate(served) if j % n_rep == i)
                if not rids:
                    continue
                suffix = f"/r{i}" if n_rep > 1 else ""
                place(base + suffix, f"analytics/{cname}/{base}{suffix}", rids, "analytics", comp.tier, cname,
                      labels)
    return inst, every


def _consumers_of(robots: list, scheds: dict, scheduled: dict, inst: dict):
    """The function ``consumers(stream, robot)``: the edges (``src`` left empty) from ``stream`` (of ``robot``'s
    items when known) to every consumer instance: analytics instances and trajectory schedulers' priority ports."""

    def consumers(stream, robot: str | None) -> list[Edge]:
        out = []
        for sub in stream.subscribers:
            # frames for the analytics scheduler: its dispatcher decides what to drop, not the edge's in-flight limit
            buffer = max(stream.buffer, 8) if id(sub) in scheduled else stream.buffer
            for cid, _, served in inst.get(id(sub), []):
                if robot is not None and robot not in served:
                    continue
                out.append(Edge("", cid, Port("in"), buffer, served if robot is None else None))
        for rr in robots:
            if robot is not None and rr.id != robot:
                continue
            for st, prio, replace in scheds[rr.id].stream_inputs:
                if st is stream:
                    out.append(Edge("", ComponentId.scheduler(rr.id), Port("priority", prio, replace), 4,
                                    (rr.id,) if robot is None else None))
        return out

    return consumers


def _drone_components(st: _PlanState, robots: list, scheds: dict, drone_host: dict[str, str], consumers,
                      edges: list[Edge], schemas: dict[str, dict]) -> dict[str, dict]:
    """Each robot's own components in its drone actor (drone, trajectory scheduler, sensors that feed something or
    are recorded, plug-in sensors), their edges, and its :class:`~aerodaas.protocol.specs.RobotSpec`. Returns robot id
    -> its component ids."""
    recorded, actors, add = st.recorded, st.actors, st.add
    robot_ids: dict[str, dict] = {}
    for r in robots:
        hid = drone_host[r.id]
        sched = scheds[r.id]
        preplanned = sum(sum(1 for i in m.items if type(i).__name__ == "Waypoint")
                         for m in sched.missions() if m.distance_driven)
        ids = {"drone": ComponentId.drone(r.id), "scheduler": ComponentId.scheduler(r.id), "cameras": {}, "actor": hid}
        add(Node(ids["drone"], "drone", r.id, hid))
        add(Node(ids["scheduler"], "scheduler", r.id, hid))
        cams = []
        plugin_sensors: list[dict] = []
        # the components whose data the drone publishes itself (RobotSpec odom_cids, stat_cids)
        published: dict[Delivery, list[str]] = {Delivery.VEHICLE_STATE: [], Delivery.MISSION_STATUS: []}
        for s in r.sensors.values():
            # the sensor's class names the component that delivers its data (built-ins and plug-ins alike): a
            # frame sensor's frame source is chosen in the actor from its properties (aerodaas.plugins.frames)
            scls = sensor_class(s.type)
            cid = ComponentId.sensor(r.id, s.id, scls.component_kind)
            subs = consumers(s.get_data_stream(), r.id)
            # a camera is made when something takes its frames: a subscriber, or the recorder (record_fps 0: never)
            recorded_here = recorded and s.cfg.properties.get("record_fps") != 0
            if not scls.delivery.has_component(bool(subs or s.get_data_stream().subscribers), recorded_here):
                continue
            if scls.delivery.frames:
                cams.append(CameraSpec(cid, s.id, dict(s.cfg.properties), scls.frame_source(s.cfg.properties)))
                ids["cameras"][s.id] = cid
            elif scls.delivery.sampled:  # its readings: sampled and recorded by its own component
                plugin_sensors.append(sensor_plugin_spec(s, cid))
                schemas.update(plugin_sensors[-1].pop("schema"))
            else:  # the drone publishes it to its component's subscribers
                published[scls.delivery].append(cid)
            ps = plugin_sensors[-1] if plugin_sensors and plugin_sensors[-1]["cid"] == cid else None
            add(Node(cid, scls.component_kind, r.id, hid,
                     plugin=f"{ps['type']} -> {ps['schema_name']}" if ps else None))
            types = tuple(dict.fromkeys(stream_types(s.get_data_stream())))  # "odometry" is delivery and type
            edges.extend(Edge(cid, e.dst, e.port, e.buffer, e.robots, types) for e in subs)
        actors[hid].spec.robots.append(RobotSpec(r.cfg.model_dump(mode="json"), ids["drone"], ids["scheduler"], sched,
                                                 preplanned, cams, published[Delivery.VEHICLE_STATE],
                                                 published[Delivery.MISSION_STATUS], plugin_sensors,
                                                 robot_plugins(r.cfg), list(getattr(r, "gimbal_commands", ()))))
        robot_ids[r.id] = ids
    return robot_ids


def _analytics_edges(st: _PlanState, every: dict, inst: dict, consumers) -> list[Edge]:
    """The edges out of every analytics instance (to analytics downstream and to trajectory schedulers), each
    carrying only the robots the instance serves; a named output that feeds anything is a producer node of its own
    (``<instance>:<output>``, in the instance's actor)."""
    edges: list[Edge] = []
    seen_out: set[str] = set()
    for aid, a in every.items():
        for cid, hid, served in inst[aid]:
            if cid in seen_out:
                continue
            seen_out.add(cid)
            only = served[0] if len(served) == 1 else None
            outs = [(cid, a.output)]
            for out_name, named in (getattr(a, "named_streams", None) or {}).items():
                src = ComponentId(f"{cid}:{out_name}", "analytics", cid.robot)
                st.add(Node(src, "analytics", cid.robot, hid, a.name, plugin=f"named output {out_name}"))
                outs.append((src, named))
            for src, stream in outs:
                types = tuple(dict.fromkeys(stream_types(stream))) or ("aerodaas.AnalyticsOutput",)  # free-form
                for e in consumers(stream, only):
                    robots_ = e.robots if e.robots is not None else None
                    if only is None and robots_ is not None:
                        robots_ = tuple(x for x in robots_ if x in served) or None
                        if robots_ is None:
                            continue  # no robot of this instance goes there
                    edges.append(Edge(src, e.dst, e.port, e.buffer, robots_, types))
    return edges


def build_plan(env, robots: list, graphs: dict, scheds: dict, sim: Any, *, record: str | None = None,
               live: str | None = None, live_access: Any = None, scheduled: dict[int, Any] | None = None,
               epoch_ns: int = 0,
               run_id: str | None = None, max_restarts: int | None = None) -> RunPlan:
    """Place the application's components on actors (see the module docstring) and compute every edge.

    ``graphs``: robot id -> its analytics (:func:`collect_graph`); ``scheds``: robot id -> its trajectory
    scheduler; ``scheduled``: id(analytics) -> analytics placed per frame by the analytics scheduler. Pure: starts
    nothing. Specs hold the objects the actors need (analytics, schedulers), pickled when the actors start."""
    scheduled = scheduled or {}
    run_id = run_id or os.urandom(3).hex()
    k = max(1, int(getattr(env.cfg, "drones_per_actor", 1)))
    recorded = bool(record or live)
    st = _PlanState(run_id, env, sim.model_dump(), recorded)
    rec = st.actor("recorder", "recorder", "edge", None, {})
    if recorded:  # the recorder also feeds the live view; without --record it writes no file
        rec.spec.record = RecordSpec(os.path.abspath(record) if record else None, live, {
            "environment": env.cfg.name, "robots": ",".join(r.id for r in robots), "speedup": str(sim.speedup),
            "lockstep": str(sim.lockstep), "run": run_id, "aerodaas": "0.1.0"})
        rec.spec.record.live_access = live_access
    drone_host = _place_drones(st, robots, k)
    inst, every = _place_analytics(st, robots, graphs, scheduled, drone_host)
    if recorded:  # the drones' homes (lat/lon of recorded tracks) and the track channels known from the plan

        rec.spec.record.homes = {r.id: getattr(r, "cfg", r).home.model_dump() for r in robots}
        rec.spec.record.declare = declared_track_channels([r.id for r in robots], graphs)
    consumers = _consumers_of(robots, scheds, scheduled, inst)
    edges: list[Edge] = []
    schemas: dict[str, dict] = {}  # plug-in sensors' schema name -> JSON Schema, for the recorder
    robot_ids = _drone_components(st, robots, scheds, drone_host, consumers, edges, schemas)
    edges.extend(_analytics_edges(st, every, inst, consumers))
    for r in robots:
        robot_ids[r.id]["analytics"] = [cid for a in graphs[r.id] for cid, _, served in inst[id(a)]
                                        if r.id in served]

    for a in every.values():  # analytics' declared output models (Output, named_outputs)
        schemas.update(output_schemas(a))
    if recorded and schemas:
        rec.spec.record.schemas = schemas
    if recorded and getattr(getattr(env.cfg, "recording", None), "per_node", False):
        add_node_recorders(st.actors, rec, run_id)  # one recorder per edge compute (recording.per_node)
    for a in st.actors.values():
        a.spec.epoch_ns = epoch_ns
    key = os.urandom(32) if getattr(env.cfg, "same_node_transport", "channel") == "channel" else None

    return RunPlan(run_id, st.nodes, edges, st.actors, robot_ids,
                   {aid: [c for c, _, _ in v] for aid, v in inst.items()}, channel_key=key,
                   robot_uses=robot_uses(robots, scheds, set(st.nodes)))
