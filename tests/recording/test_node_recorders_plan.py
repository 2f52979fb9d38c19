"""``recording.per_node`` in the run's plan: a recorder actor per edge compute, placed by its
labels, writing ``RUN.node-<compute>.mcap``, and that compute's actors recording to it. The plan only: nothing
starts (the run on a two-node cluster is ``tests/cluster/test_node_recorders_cluster.py``)."""
from __future__ import annotations

import pytest

from tests.cluster.cluster_runtime_app import _cfg


def _plan(per_node: bool, tmp_path, live: str | None = None):
    from aerodaas import Environment
    from aerodaas.config import SimulationConfig, parse_environment_config
    from aerodaas.runtime.dataflow import build_plan, collect_graph
    from aerodaas.runtime.preflight import robot_schedulers as _robot_schedulers

    env = Environment(parse_environment_config({**_cfg(3, ["a", "b"], 1.0), "recording": {"per_node": per_node}}))
    robots = env.get_env_robots()
    return build_plan(env, robots, {r.id: collect_graph(r) for r in robots}, _robot_schedulers(env, robots),
                      SimulationConfig(), record=str(tmp_path / "run.mcap"), live=live, run_id="p")


def test_per_node_adds_a_recorder_per_edge_compute_and_points_its_actors_at_it(tmp_path):
    from aerodaas.runtime.dataflow import Placement

    plan = _plan(True, tmp_path)
    recs = {h: a for h, a in plan.actors.items() if a.role == "recorder"}
    assert sorted(recs) == ["recorder", "recorder/edge-a", "recorder/edge-b"]
    for site in "ab":
        a = recs[f"recorder/edge-{site}"]
        assert a.name == f"aerodaas/p/recorder/edge-{site}"
        assert a.selector(Placement()) == {"tier": "edge", "aerodaas/site": site}
        assert a.spec.record.path == str(tmp_path / f"run.node-edge-{site}.mcap")
        assert a.spec.record.live is None and a.spec.record.meta["node"] == f"edge-{site}"
        assert a.spec.record_remote is None  # no live view: nothing forwarded to the driver's recorder
    assert recs["recorder"].spec.record.path == str(tmp_path / "run.mcap")
    drones = {h: a for h, a in plan.actors.items() if a.role == "drone"}
    assert {h: a.spec.record_remote for h, a in drones.items()} == {
        "drone/d00": "recorder/edge-a", "drone/d01": "recorder/edge-b", "drone/d02": "recorder/edge-a"}
    assert all(a.spec.epoch_ns == recs["recorder"].spec.epoch_ns for a in recs.values())


def test_with_a_live_view_the_node_recorders_forward_to_the_drivers(tmp_path):
    plan = _plan(True, tmp_path, live="127.0.0.1:0")
    assert plan.actors["recorder/edge-a"].spec.record_remote == "recorder"
    assert plan.actors["recorder"].spec.record.live == "127.0.0.1:0"


def test_without_per_node_every_actor_records_to_the_drivers_recorder(tmp_path):
    plan = _plan(False, tmp_path)
    assert [h for h, a in plan.actors.items() if a.role == "recorder"] == ["recorder"]
    assert {a.spec.record_remote for a in plan.actors.values() if a.role == "drone"} == {"recorder"}


@pytest.mark.parametrize("value", ["yes", 1])
def test_per_node_must_be_a_boolean(value):
    from aerodaas.config import ConfigError, parse_environment_config

    with pytest.raises((ConfigError, ValueError), match="recording.per_node"):
        parse_environment_config({**_cfg(1, ["a"], 1.0), "recording": {"per_node": value}})
