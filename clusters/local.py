"""A local multi-node Ray cluster on one machine: edge nodes and cloud nodes (``ray.cluster_utils.Cluster``).

For tests and the scheduler benchmark: the head node is labelled ``tier=edge``, every other node ``tier=cloud``,
so actors placed with ``label_selector={"tier": "edge"}`` / ``{"tier": "cloud"}`` land on different raylets, and a
cloud node can be removed mid-run (its processes are killed, as when a machine is lost). Ray's token
authentication stays on: ``RAY_AUTH_MODE=token`` is set for this process (and inherited by the node processes)
unless the environment already sets a mode, and a token is generated at ``~/.ray/auth_token`` if none exists
(what ``ray.init()`` does for a new local cluster since Ray 2.59).

Every node is loopback-only, as ``aerodaas run``'s local Ray (:func:`aerodaas.clusters.loopback.loopback_only`): node
address 127.0.0.1, so the GCS, raylets, object managers, agents and workers listen on 127.0.0.1 only, never on the
machine's network address (``tests/cluster/test_local_cluster_loopback.py`` lists every listening socket).

``ray.cluster_utils.Cluster.add_node(**node_args)`` passes its keyword arguments to ``ray._private.parameter.RayParams``,
which accepts ``labels: dict[str, str]`` (checked on Ray 2.60). With ``tls`` every gRPC channel of the cluster runs
Ray's mutual TLS (:mod:`aerodaas.clusters.ray_tls`; ``tests/cluster/test_ray_tls_cluster.py``).

Usage::

    from aerodaas.clusters.local import LocalCluster
    with LocalCluster(cloud_nodes=2) as lc:       # connects this driver to it
        ...                                        # ray.* calls
        lc.remove_cloud_node(0)                    # lose a cloud node
"""
from __future__ import annotations

import logging
import os
from typing import TYPE_CHECKING, Any

from aerodaas.clusters import reaper
from aerodaas.clusters.log_monitor import lean_log_monitor
from aerodaas.clusters.loopback import loopback_only
from aerodaas.clusters.node_priority import agents_ahead
from aerodaas.clusters.ray_tls import use_tls
from aerodaas.clusters.worker_memory import lean_worker_imports, limit_malloc_arenas

if TYPE_CHECKING:
    from aerodaas.clusters.ray_tls import RayTLS

__all__ = ["LocalCluster", "enable_token_auth"]

log = logging.getLogger(__name__)


def enable_token_auth() -> None:
    """Turn Ray token authentication on for this process and the node processes it starts (``RAY_AUTH_MODE=token``
    unless the environment says otherwise) and make sure a token exists (generated at ``~/.ray/auth_token`` if
    missing), as ``ray.init()`` does for a new local cluster. Raises RuntimeError if Ray's auth setup fails."""
    try:
        from ray._private.authentication.authentication_token_setup import (
            enable_token_auth_by_default, ensure_token_if_auth_enabled,
        )  # lazy: heavy ray
    except ImportError:  # an older or newer Ray without these helpers: set the mode, let Ray find the token
        os.environ.setdefault("RAY_AUTH_MODE", "token")
        return
    enable_token_auth_by_default()
    ensure_token_if_auth_enabled(None, create_token_if_missing=True)


class LocalCluster:
    """``edge_nodes`` ``tier=edge`` nodes (the first is the head; ``edge_labels[i]``: extra labels of edge node i)
    and ``cloud_nodes`` ``tier=cloud`` nodes, all on this machine.

    ``edge_cpus``/``cloud_cpus``: logical CPUs each node advertises (Ray's scheduling resource, not a limit on real
    CPU use). ``object_store_mb``: object store per node (MiB). ``connect``: call ``ray.init(address=...)`` for this
    driver (which then runs on the edge node). ``worker_niceness``: the niceness Ray gives worker processes
    (Ray's default is 15, below its control plane; the scheduler benchmark uses 0 so that its timers compete on
    equal terms with other processes on a shared machine). ``head_gpus``: logical GPUs the head declares to Ray
    (None: what Ray detects); ``dashboard``: start Ray's dashboard (on Ray's default host, localhost;
    Ray's state API, ``ray.util.state``, reads it). ``tls``: run Ray's mutual TLS on every gRPC channel of the
    cluster with these files (:class:`aerodaas.clusters.ray_tls.RayTLS`): its ``RAY_USE_TLS``/``RAY_TLS_*``
    variables are set in this process's environment for the cluster's life (:func:`aerodaas.clusters.ray_tls.use_tls`;
    undone by :meth:`shutdown`), so every node, worker and driver started from here (this process's own
    ``ray.init``, a subprocess ``aerodaas run --address``) speaks TLS; None leaves the environment as it is. Ray's
    C++ side of this process reads them once, when it is first used (``ray.init``, the token set-up): start the
    cluster before any other Ray call of this process, or set the variables before it. Raises
    RuntimeError if Ray is already initialised in this process and ``connect`` is True (shut it down first).

    Attributes: ``address`` (the GCS address, ``host:port``), ``edge_node``, ``cloud_nodes`` (``ray._private.node.Node``
    handles, in the order they were added; removed ones are dropped from the list).
    """

    def __init__(self, cloud_nodes: int = 1, *, edge_cpus: int = 2, cloud_cpus: int = 2,
                 object_store_mb: int = 150, connect: bool = True, extra_edge_labels: dict[str, str] | None = None,
                 worker_niceness: int | None = None, edge_nodes: int = 1,
                 edge_labels: list[dict[str, str]] | None = None, head_gpus: float | None = None,
                 dashboard: bool = False, tls: "RayTLS | None" = None) -> None:
        import ray  # lazy: heavy ray
        from ray.cluster_utils import Cluster  # lazy: heavy ray

        if cloud_nodes < 0:
            raise ValueError(f"cloud_nodes must be >= 0, got {cloud_nodes}")
        if connect and ray.is_initialized():
            raise RuntimeError("Ray is already initialised in this process; call ray.shutdown() before starting a "
                               "LocalCluster with connect=True")

        # first: Ray's C++ configuration of this process reads the variables once, at its first use (the token
        # set-up below is one); every node process started afterwards inherits them. Undone by shutdown().
        self._restore_tls = use_tls(tls)
        enable_token_auth()

        limit_malloc_arenas()  # the workers' C heap (aerodaas.clusters.worker_memory)
        lean_worker_imports()  # no pyarrow in the workers (aerodaas.clusters.worker_memory)
        lean_log_monitor()  # fewer listings of the logs folder when idle (aerodaas.clusters.log_monitor)

        # the nodes' processes end with this process, however it ends (None: this process has its reaper already)
        self._reaper = reaper.ensure_started()
        # kept for the cluster's life: nodes added later must bind loopback too; undone by shutdown()
        self._restore_network = loopback_only()
        self._cloud_cpus = int(cloud_cpus)
        self._store = int(object_store_mb) * 1024 * 1024
        first = (edge_labels or [{}])[0] if edge_labels else {}
        head_args: dict[str, Any] = {"num_cpus": int(edge_cpus),
                                     "labels": {"tier": "edge", **(extra_edge_labels or {}), **first},
                                     "include_dashboard": bool(dashboard), "object_store_memory": self._store,
                                     # 8265 or the next free port (see clusters/persistent.py), never a failure
                                     "dashboard_port": None}
        if head_gpus is not None:  # else what Ray detects on this machine
            head_args["num_gpus"] = head_gpus
        if worker_niceness is not None:  # Ray starts workers at niceness 15 (below the control plane) by default
            head_args["_system_config"] = {"worker_niceness": int(worker_niceness)}
        try:
            with agents_ahead():  # the raylet aborts when its agents take over 15 s (aerodaas.clusters.node_priority)
                self.cluster = Cluster(initialize_head=True, shutdown_at_exit=True, head_node_args=head_args)
        except BaseException:
            self._restore_network()
            self._restore_tls()
            raise
        self.edge_node = self.cluster.head_node
        self.cloud_nodes: list[Any] = []
        self.edge_nodes: list[Any] = [self.edge_node]
        self.removed: list[dict] = []
        self._edge_cpus = int(edge_cpus)
        try:
            for i in range(1, max(1, int(edge_nodes))):
                self.add_edge_node((edge_labels or [{}] * edge_nodes)[i] if edge_labels else None)
            for _ in range(cloud_nodes):
                self.add_cloud_node()
            self.cluster.wait_for_nodes()
        except BaseException:
            self.cluster.shutdown()
            self._restore_network()
            self._restore_tls()
            raise
        self.address: str = self.cluster.address
        self.connected = False
        if connect:
            ray.init(address=self.address, include_dashboard=False, log_to_driver=True, logging_level="warning")
            self.connected = True

    def add_cloud_node(self, labels: dict[str, str] | None = None, num_gpus: float | None = None):
        """Add a ``tier=cloud`` node (extra ``labels`` allowed; ``num_gpus``: logical GPUs it declares to Ray, a
        scheduling resource whether or not the machine has them; None: what Ray detects) and return its handle."""
        with agents_ahead():  # as the head's (aerodaas.clusters.node_priority)
            node = self.cluster.add_node(num_cpus=self._cloud_cpus, labels={"tier": "cloud", **(labels or {})},
                                         object_store_memory=self._store,
                                         **({"num_gpus": num_gpus} if num_gpus is not None else {}))
        self.cloud_nodes.append(node)
        return node

    def add_edge_node(self, labels: dict[str, str] | None = None, num_gpus: float | None = None):
        """Add another ``tier=edge`` node (extra ``labels`` allowed, e.g. ``{"aerodaas/site": "field-2"}``;
        ``num_gpus``: logical GPUs it declares to Ray; None: what Ray detects) and return its handle. The driver
        stays on the head node (the first edge node)."""
        with agents_ahead():  # as the head's (aerodaas.clusters.node_priority)
            node = self.cluster.add_node(num_cpus=self._edge_cpus, labels={"tier": "edge", **(labels or {})},
                                         object_store_memory=self._store,
                                         **({"num_gpus": num_gpus} if num_gpus is not None else {}))
        self.edge_nodes.append(node)
        return node

    def remove_edge_node(self, index: int = 1, graceful: bool = False) -> str:
        """Kill edge node ``index`` of :attr:`edge_nodes` (not 0: the head, where the driver runs), as if the
        machine were lost. Returns its node id. Raises IndexError."""
        if not 1 <= index < len(self.edge_nodes):
            raise IndexError(f"edge node index {index} out of range (1..{len(self.edge_nodes) - 1}; 0 is the head)")
        return self._remove(self.edge_nodes.pop(index), graceful, "edge")

    def node_id(self, node) -> str:
        """The Ray node id (hex) of a node handle."""
        return node.node_id

    def remove_cloud_node(self, index: int = 0, graceful: bool = False) -> str:
        """Kill cloud node ``index`` (of :attr:`cloud_nodes`), as if the machine were lost (``graceful=False``:
        SIGKILL). Returns its node id. Raises IndexError naming the nodes left."""
        if not 0 <= index < len(self.cloud_nodes):
            raise IndexError(f"cloud node index {index} out of range; {len(self.cloud_nodes)} cloud node(s) left")
        return self._remove(self.cloud_nodes.pop(index), graceful, "cloud")

    def _remove(self, node, graceful: bool, kind: str) -> str:
        """Stop ``node`` (SIGKILL unless ``graceful``), remember it in :attr:`removed`; returns its node id."""
        nid = node.node_id
        self.cluster.remove_node(node, allow_graceful=graceful)
        self.removed.append({"node_id": nid, "graceful": graceful})
        log.info("removed %s node %s", kind, nid)
        return nid

    def shutdown(self) -> None:
        """Disconnect this driver (if it connected) and stop every node."""
        import ray  # lazy: heavy ray

        if self.connected and ray.is_initialized():
            ray.shutdown()
        self.connected = False
        self.cluster.shutdown()
        self._restore_network()
        self._restore_tls()

    def __enter__(self) -> "LocalCluster":
        return self

    def __exit__(self, *exc) -> None:
        self.shutdown()
