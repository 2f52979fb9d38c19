"""``aerodaas up`` / ``aerodaas down``: the persistent local Ray cluster (:mod:`aerodaas.clusters.persistent`)."""
from __future__ import annotations

import argparse
import sys

from aerodaas.clusters.persistent import DEFAULT_WARM_WORKERS, down, up

def run_up(args: argparse.Namespace) -> int:
    """``aerodaas up [--cpus N] [--warm-workers K]``: start the persistent local cluster
    (:mod:`aerodaas.clusters.persistent`) with K warm workers (:mod:`aerodaas.clusters.warm_pool`). Exit 0 (also
    when it already runs), 1 when it cannot start, 2 for a bad ``--cpus`` or ``--warm-workers``."""
    if not 1 <= args.cpus <= 256:
        print(f"aerodaas up: --cpus must be in [1, 256], got {args.cpus}", file=sys.stderr)
        return 2
    if not 0 <= args.warm_workers <= 64:
        print(f"aerodaas up: --warm-workers must be in [0, 64], got {args.warm_workers}", file=sys.stderr)
        return 2
    try:
        st = up(cpus=args.cpus, warm_workers=args.warm_workers)
    except RuntimeError as e:
        print(e, file=sys.stderr)
        return 1
    what = "already running" if st["already"] else "started"
    warm = f", {st['warm_workers']} warm workers" if st.get("warm_workers") else ""
    print(f"aerodaas up: local cluster {what} at {st['address']} (pid {st['pid']}, loopback only, tier=edge{warm}"
          + (f", dashboard http://{st['dashboard']}" if st.get("dashboard") else "") + "); `aerodaas run` attaches "
          "to it, `aerodaas down` stops it", flush=True)
    return 0


def run_down(args: argparse.Namespace) -> int:
    """``aerodaas down``: stop the cluster ``aerodaas up`` started (its processes only) and remove the shared
    ground cache (:func:`aerodaas.sim.ground_cache.clear`). Exit 0, 1 if it would not stop."""
    try:
        st = down()
    except RuntimeError as e:
        print(e, file=sys.stderr)
        return 1
    print("aerodaas down: " + (f"stopped the local cluster at {st['address']} (pid {st['pid']})" if st else
                               "no local cluster of `aerodaas up` is running"), flush=True)
    from aerodaas.sim import ground_cache  # lazy: CLI start-up (NumPy)

    freed = ground_cache.clear()
    if freed:
        print(f"aerodaas down: removed the shared ground cache at {ground_cache.cache_dir()} "
              f"({freed / 1e6:.1f} MB)", flush=True)
    return 0


def add_parser(sub) -> None:
    """``aerodaas up`` and ``aerodaas down``."""
    upp = sub.add_parser("up", help="start a persistent local Ray cluster (loopback, token auth, tier=edge, "
                                     "dashboard) that `aerodaas run` attaches to")
    upp.add_argument("--cpus", type=int, default=3, help="logical CPUs of the node (sizes the prestarted workers)")
    upp.add_argument("--warm-workers", type=int, default=DEFAULT_WARM_WORKERS,
                     help="idle workers kept with the framework imported, for the next run's actors (0: none)")
    upp.set_defaults(func=run_up)
    sub.add_parser("down", help="stop the cluster `aerodaas up` started (only that one)").set_defaults(func=run_down)
