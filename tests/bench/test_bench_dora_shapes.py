"""The dora-rs peers of ``aerodaas bench overhead``: the per-component dataflow and the one grouped like the
AeroDaaS ``actors`` layout (camera+follow+scheduler+drone in one process, the detector in another)."""
import pytest
import yaml

from aerodaas.bench.peers_dora import SHAPES, DoraPipeline, dataflow_yaml, unavailable_reason
from aerodaas.bench.pipeline import overheads


def _graph(shape):
    doc = yaml.safe_load(dataflow_yaml("/tmp/x", shape))
    return {n["id"]: ({k: v["source"] for k, v in (n.get("inputs") or {}).items()}, n.get("outputs", []))
            for n in doc["nodes"]}


def test_grouped_dataflow_has_two_processes_and_two_crossings_per_frame():
    g = _graph("grouped")
    assert set(g) == {"group", "detector"}
    assert g["detector"] == ({"frame": "group/frame"}, ["dets"])
    assert g["group"] == ({"dets": "detector/dets"}, ["frame"])


def test_per_component_dataflow_is_a_chain_of_five():
    g = _graph("per_component")
    assert list(g) == ["camera", "detector", "follow", "scheduler", "drone"]
    sources = [src for ins, _ in g.values() for src in ins.values()]
    assert sources == ["camera/frame", "detector/dets", "follow/nav", "scheduler/item"]


def test_unknown_shape_is_refused_naming_it():
    with pytest.raises(KeyError):
        dataflow_yaml("/tmp/x", "diamond")
    assert set(SHAPES) == {"per_component", "grouped"}


@pytest.mark.skipif(unavailable_reason() is not None, reason=str(unavailable_reason()))
def test_grouped_dora_pipeline_applies_commands_with_one_hop_each_way():
    d = DoraPipeline(320, 240, "stub", 2.0, shape="grouped")
    try:
        assert d.name == "dora_rs_grouped"
        d.window(0.5)
        rows = d.window(2.0)
    finally:
        d.close()
    o = overheads(rows, "stub", 2.0)
    assert o["commands_applied"] > 0
    assert set(o["hops_ms"]) == {"camera_detector", "detector_group"}  # exactly two crossings per frame
    assert o["inference_ms"]["median"] >= 2.0 * 0.9
