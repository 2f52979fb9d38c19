"""Placement you can see before flying: computes that Ray cannot tell apart (issue 27, item 4).

An actor of compute resource ``c`` is placed with ``label_selector={"tier": c.tier, **c.labels}``
(:meth:`aerodaas.runtime.dataflow.ActorPlan.selector`). Two computes of the same tier with the same labels (typically none)
get the same selector, so which of their nodes each actor lands on is Ray's choice (six drones over two unlabelled
edge computes landed 5 + 1). :func:`indistinct_computes` finds them in a plan; ``aerodaas plan`` and ``aerodaas run``
(on a cluster) print :func:`placement_warning`. :func:`compute_label` is the label that tells them apart, which
:class:`aerodaas.clusters.local.LocalCluster` callers and cluster files put on the node of each compute.
"""
from __future__ import annotations

from typing import Any

__all__ = ["COMPUTE_LABEL", "compute_label", "indistinct_computes", "placement_warning"]

#: the node label naming the compute resource a node serves
COMPUTE_LABEL = "aerodaas/compute"


def compute_label(compute_id: str) -> dict[str, str]:
    """``{"aerodaas/compute": compute_id}``: the label of the node that serves ``compute_id`` (Ray label values:
    letters, digits, ``-_.``, at most 63 characters). Raises ``ValueError`` naming the id when it cannot be one."""
    import re

    if not re.fullmatch(r"[A-Za-z0-9]([A-Za-z0-9_.-]{0,61}[A-Za-z0-9])?", compute_id or ""):
        raise ValueError(f"compute id {compute_id!r} cannot be a Ray label value ({COMPUTE_LABEL})")
    return {COMPUTE_LABEL: compute_id}


def indistinct_computes(plan: Any) -> list[tuple[str, dict[str, str], list[str]]]:
    """Groups of two or more computes the plan's actors use whose selectors are equal: ``[(tier, labels,
    [compute ids])]`` (sorted). ``plan``: a :class:`aerodaas.runtime.dataflow.RunPlan`."""
    by_selector: dict[tuple, set[str]] = {}
    for a in plan.actors.values():
        if a.compute is None:
            continue
        key = (a.tier, tuple(sorted(a.labels.items())))
        by_selector.setdefault(key, set()).add(a.compute)
    return sorted((tier, dict(labels), sorted(ids)) for (tier, labels), ids in by_selector.items() if len(ids) > 1)


def placement_warning(plan: Any) -> str | None:
    """A warning naming the computes :func:`indistinct_computes` finds and the label that separates them, or None."""
    groups = indistinct_computes(plan)
    if not groups:
        return None
    parts = []
    for tier, labels, ids in groups:
        sel = ", ".join(f"{k}={v}" for k, v in {"tier": tier, **labels}.items())
        parts.append(f"computes {', '.join(repr(i) for i in ids)} all place with [{sel}]")
    return ("placement between them is Ray's choice: " + "; ".join(parts) + f". Give each compute a label (e.g. "
            f"labels: {{{COMPUTE_LABEL}: <compute id>}}) and start its node with it")
