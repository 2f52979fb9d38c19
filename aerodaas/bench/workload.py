"""The workload of the analytics-scheduler benchmarks: where the measured workload is, which drones fly from which
edge, the seeded arrival trace of their frames (:func:`make_trace`) and the network-variability scenarios
(:func:`scenario_specs`). Shared by the runtime benchmark (:mod:`aerodaas.bench.schedulers`) and the policy
harness's sweep (:mod:`aerodaas.bench.sweep`), below both."""
from __future__ import annotations

import math
import os
import random
from pathlib import Path

from aerodaas.bench.options import DEFAULT_DRONES_PER_EDGE, DEFAULT_FPS, SCENARIOS
from aerodaas.bench.traces import frame_times


def default_workload_path() -> Path:
    """``$AERODAAS_DATA_DIR/workloads/ocularone_lambda.json`` (default data dir: ``../shared/data`` of the repo)."""
    base = os.environ.get("AERODAAS_DATA_DIR") or str(Path(__file__).resolve().parents[2].parent / "shared" / "data")
    return Path(base) / "workloads" / "ocularone_lambda.json"


def edge_layout(drones: int, drones_per_edge: int) -> list[list[str]]:
    """Drones ``d000..`` assigned to edges in order, ``drones_per_edge`` each (the last edge may have fewer).
    Raises ValueError for non-positive counts."""
    if drones < 1:
        raise ValueError(f"drones must be >= 1, got {drones}")
    if drones_per_edge < 1:
        raise ValueError(f"drones_per_edge must be >= 1, got {drones_per_edge}")
    names = [f"d{i:03d}" for i in range(drones)]
    return [names[i:i + drones_per_edge] for i in range(0, drones, drones_per_edge)]


def make_trace(workload, drones: int, duration_s: float, seed: int, drones_per_edge: int = DEFAULT_DRONES_PER_EDGE,
               fps: float = DEFAULT_FPS, trace=None) -> list[tuple[float, str, str, str]]:
    """The arrival trace: rows ``(arrival_ms, edge_id, drone, model)`` sorted by time, for frames sent in
    ``[0, duration_s)``. Each frame yields one task per model of ``workload`` in a seeded shuffled order.
    ``trace`` (a :class:`aerodaas.bench.traces.TraceSpec`, default periodic): periodic — each drone sends a frame
    every ``1/fps`` s from a seeded phase in ``[0, 1/fps)`` (the published sweep's traces, unchanged); realistic or
    recording — the frame times of :func:`aerodaas.bench.traces.frame_times`. Raises ValueError for bad
    parameters."""
    if not duration_s > 0:
        raise ValueError(f"duration must be > 0 s, got {duration_s}")
    if not fps > 0:
        raise ValueError(f"fps must be > 0, got {fps}")
    rng = random.Random(seed)
    period_ms = 1000.0 / fps
    models = list(workload.models)
    rows = []
    periodic = trace is None or trace.kind == "periodic"
    n = 0
    for e, group in enumerate(edge_layout(drones, drones_per_edge)):
        for i, drone in enumerate(group):
            if periodic:
                t = round(rng.uniform(0.0, period_ms), 3)
                times = []
                while t < duration_s * 1000.0:
                    times.append(t)
                    t = round(t + period_ms, 3)
            else:
                times = frame_times(trace, drone, i, len(group), n, period_ms, duration_s * 1000.0, seed)
            n += 1
            for t in times:
                order = models[:]
                rng.shuffle(order)
                rows.extend((t, f"edge{e:02d}", drone, m) for m in order)
    rows.sort(key=lambda r: r[0])  # stable: keeps each frame's shuffled model order
    return rows


def scenario_specs(name: str, duration_s: float) -> list[str]:
    """The NetworkModel specs of scenario ``name`` for a run of ``duration_s`` s. Raises ValueError if unknown."""
    if name == "none":
        return []
    if name == "step":
        return [f"+200@{60 * k + 40:g}-{60 * k + 60:g}" for k in range(max(1, math.ceil(duration_s / 60)))]
    if name == "walk":
        return ["walk:25,250"]
    raise ValueError(f"network scenario {name!r}: choose from {sorted(SCENARIOS)}")
