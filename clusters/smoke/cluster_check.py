"""Checks of a running cluster for clusters/smoke/ray_up_test.sh, run on the head (`ray exec`): the nodes with their
labels and IPs, and where actors ran, from Ray's state API (``ray.util.state``, served by the head's dashboard).

    python cluster_check.py wait-nodes --count 2 [--timeout S]      # JSON list of alive nodes (node_id, ip, labels)
    python cluster_check.py placement --class AnalyticsActor --tier cloud [--alive] [--timeout S]

``placement`` exits 0 when some actor of that class ran (or, with ``--alive``, is running) on a node labelled
``tier=<tier>`` and prints those actors; exit 1 otherwise, after ``--timeout`` seconds (default 0: one look).
Results are printed as one line ``CHECK-RESULT <json>`` (``ray exec`` mixes its own log lines into stdout).
"""
from __future__ import annotations

import argparse
import json
import sys
import time


def _result(obj) -> None:
    print("CHECK-RESULT " + json.dumps(obj), flush=True)


def _nodes() -> list[dict]:
    from ray.util.state import list_nodes

    return [{"node_id": n.node_id, "ip": n.node_ip, "labels": dict(n.labels or {}), "state": n.state}
            for n in list_nodes(detail=True)]


def wait_nodes(count: int, timeout: float) -> int:
    deadline = time.monotonic() + timeout
    alive: list[dict] = []
    while True:
        alive = [n for n in _nodes() if n["state"] == "ALIVE"]
        if len(alive) >= count:
            _result(alive)
            return 0
        if time.monotonic() > deadline:
            print(f"only {len(alive)} of {count} nodes alive after {timeout:.0f} s: {alive}", file=sys.stderr)
            return 1
        time.sleep(2.0)


def placement(cls: str, tier: str, alive_only: bool, timeout: float) -> int:
    from ray.util.state import list_actors

    deadline = time.monotonic() + timeout
    while True:
        tiers = {n["node_id"]: n["labels"].get("tier") for n in _nodes()}
        actors = [{"actor_id": a.actor_id, "class": a.class_name, "state": a.state, "node_id": a.node_id,
                   "tier": tiers.get(a.node_id), "name": a.name}
                  for a in list_actors(filters=[("class_name", "=", cls)], detail=True, limit=1000)]
        hits = [a for a in actors if a["tier"] == tier and (not alive_only or a["state"] == "ALIVE")]
        if hits:
            _result(hits)
            return 0
        if time.monotonic() > deadline:
            print(f"no {'alive ' if alive_only else ''}{cls} on a tier={tier} node; {cls} actors: {actors}",
                  file=sys.stderr)
            return 1
        time.sleep(1.0)


def main() -> int:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    sub = p.add_subparsers(dest="cmd", required=True)
    w = sub.add_parser("wait-nodes")
    w.add_argument("--count", type=int, required=True)
    w.add_argument("--timeout", type=float, default=0.0)
    pl = sub.add_parser("placement")
    pl.add_argument("--class", dest="cls", required=True)
    pl.add_argument("--tier", required=True)
    pl.add_argument("--alive", action="store_true")
    pl.add_argument("--timeout", type=float, default=0.0)
    args = p.parse_args()
    import ray

    ray.init(address="auto", logging_level="error", log_to_driver=False)
    if args.cmd == "wait-nodes":
        return wait_nodes(args.count, args.timeout)
    return placement(args.cls, args.tier, args.alive, args.timeout)


if __name__ == "__main__":
    sys.exit(main())
