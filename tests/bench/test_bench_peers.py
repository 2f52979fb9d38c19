"""The peers of ``aerodaas bench overhead`` and ``aerodaas bench raypath``: each does the pipeline's work and reports
the structure the rework will be judged by. No timing is asserted (the numbers live in docs/results/).

The dora-rs peer needs the optional ``bench`` extra (dora-rs + dora-rs-cli), which CI does not install: its test
skips cleanly there. The naive Ray peer is exercised by ``tests/bench/test_bench_cli.py`` (it runs in every overhead
run); ``bench raypath``'s report by ``tests/bench/test_bench_json_stdout.py``."""
from __future__ import annotations

import os

import pytest

from aerodaas.bench import peers_dora
from aerodaas.bench.pipeline import overheads


def test_dora_dataflow_wires_one_node_per_component_in_pipeline_order(tmp_path):
    text = peers_dora.dataflow_yaml(str(tmp_path))
    ids = [line.split("id: ")[1] for line in text.splitlines() if line.strip().startswith("- id: ")]
    assert ids == ["camera", "detector", "follow", "scheduler", "drone"]
    sources = [line.split("source: ")[1] for line in text.splitlines() if "source: " in line]
    assert sources == ["camera/frame", "detector/dets", "follow/nav", "scheduler/item"]
    assert text.count("-m aerodaas.bench.peers_dora") == 5 and str(tmp_path) in text


def test_overheads_use_the_nominal_stub_time_for_the_honest_tail():
    # one frame: due at 0, render starts 1 ms late, ready at 5 ms, command applied at 17 ms; the stub slept 11 ms
    # for a nominal 10, post-processing 0.5 ms
    row = {"tick": 0.0, "start": 0.001, "ready": 0.005, "applied": 0.017, "inference_ms": 11.0, "post_ms": 0.5,
           "hop_camera_detector": 0.002}
    o = overheads([row], "stub", 10.0)
    assert o["framework_overhead_ms"]["median"] == pytest.approx(12.0 - 11.0 - 0.5)
    assert o["honest_overhead_ms"]["median"] == pytest.approx(12.0 + 1.0 - 10.0)   # dispatch in, overshoot in
    assert o["hops_ms"]["camera_detector"]["median"] == pytest.approx(2.0)
    assert overheads([row], "yolox", 10.0)["honest_overhead_ms"] is None        # no nominal time for a real model


@pytest.mark.e2e
@pytest.mark.skipif(peers_dora.unavailable_reason() is not None,
                    reason="dora-rs is an optional benchmark peer (pip install '.[bench]')")
def test_dora_peer_flies_the_pipeline_and_cleans_up():
    p = peers_dora.DoraPipeline(320, 240, "stub", 2.0)
    workdir, proc = p.dir, p.proc
    try:
        rows = p.window(1.5)
    finally:
        p.close()
    assert rows, "no command reached the drone node"
    o = overheads(rows, "stub", 2.0)
    assert o["inference_ms"]["median"] >= 2.0 * 0.9 and o["e2e_ms"]["median"] >= o["inference_ms"]["median"]
    assert set(o["hops_ms"]) == {"camera_detector", "detector_follow", "follow_scheduler", "scheduler_drone"}
    assert proc.poll() is not None and not os.path.exists(workdir)      # dora stopped, its directory removed


def test_a_peer_that_dies_mid_run_is_reported_failed_and_the_run_goes_on(monkeypatch):
    """dora's daemon stopped a node it found stuck (load 11): the whole ``bench overhead`` run raised. Now that peer
    is reported unavailable with the reason and its windows discarded; the others are measured."""
    from aerodaas.bench import overhead

    class Fake:
        def __init__(self, name: str, die_in: int | None = None) -> None:
            self.name, self.die_in, self.windows, self.closed = name, die_in, 0, False

        def window(self, seconds: float) -> list[dict]:
            self.windows += 1
            if self.die_in is not None and self.windows >= self.die_in:
                raise RuntimeError("dora run exited (0): stuck node `detector`")
            return [{"t": float(self.windows)}]

        def close(self) -> None:
            self.closed = True

        def report(self, rows, kind, stub_ms):
            return {"windows": len(rows)}

    made: dict[str, Fake] = {}

    def peer(name, *_a):
        # dora_rs: warm-up, round 1, dies in round 2; dora_rs_grouped dies in its warm-up
        made[name] = Fake(name, die_in={"dora_rs": 3, "dora_rs_grouped": 1}.get(name))
        return made[name], None

    monkeypatch.setattr(overhead, "_peer", peer)
    monkeypatch.setattr(overhead, "FrameworkWindows", lambda *a: Fake("framework"))
    monkeypatch.setattr(overhead, "overheads", lambda rows, kind, stub_ms: {"windows": len(rows)})
    rep = overhead.interleaved(320, 240, "stub", 3.0, 1.0, 2.0, None, [], ("colocated",))
    assert rep["dora_rs"]["available"] is False and "round 2" in rep["dora_rs"]["reason"]
    assert "stuck node" in rep["dora_rs"]["reason"]
    assert rep["dora_rs_grouped"]["available"] is False and "warm-up" in rep["dora_rs_grouped"]["reason"]
    assert rep["naive_ray"] == {"available": True, "windows": 3} and rep["framework:colocated"] == {"windows": 3}
    assert all(p.closed for p in made.values())
