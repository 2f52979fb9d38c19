"""A detector's onnxruntime execution providers. The setting is checked where the app writes it
(names against ``onnxruntime.get_all_providers()``), a provider the node's onnxruntime lacks falls back to the CPU
with a message that is logged, recorded and summarised (or fails the analytics when required: a run on this machine
is refused before Ray starts), a GPU provider makes the analytics' actor ask Ray for ``num_gpus``, and a cluster
without such a node stops the run with a message instead of waiting. The ``cluster`` test places the analytics on
the node of a local cluster that declares a logical GPU and reads where it went from Ray's state API."""
from __future__ import annotations

import json
import logging
import os
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from aerodaas.analytics.detector import ObjectDetector
from aerodaas.perception.providers import (CPU_PROVIDER, ProviderUnavailableError, Providers, open_session,
                                           providers_setting)

from tests.inputs.cli_inprocess import run_cli
from tests.conftest import needs_data
from tests.inputs.test_app_value import _ray_processes_under, fresh_ray_tmp

ROOT = Path(__file__).resolve().parents[2]
CUDA = "CUDAExecutionProvider"


def _cpu_build() -> None:
    import onnxruntime as ort

    if CUDA in ort.get_available_providers():
        pytest.skip("this onnxruntime offers the CUDA provider: the fallback cannot be shown here")


def test_provider_settings_fail_where_the_app_writes_them():
    with pytest.raises(ValueError, match=r"analytics 'det': providers.names: 'cuda' \(item 0\) is not an onnxruntime "
                                         r"execution provider \(did you mean 'CUDAExecutionProvider'\?\)"):
        ObjectDetector(name="det", providers="cuda")
    with pytest.raises(ValueError, match=r"'TensorRTExecutionProvider' .*did you mean 'TensorrtExecutionProvider'\?"):
        ObjectDetector(providers=["TensorRTExecutionProvider", CPU_PROVIDER])
    with pytest.raises(ValueError, match=r"providers.names: names \['CUDAExecutionProvider'\] more than once"):
        providers_setting([CUDA, CUDA])
    with pytest.raises(ValueError, match=r"providers.names: names no provider"):
        providers_setting([])
    with pytest.raises(ValueError, match=r"providers must be a provider name, a list of them .* got 5"):
        ObjectDetector(providers=5)
    with pytest.raises(ValueError, match=r"providers.required: Input should be a valid boolean, got 'yes'"):
        Providers(names=[CUDA], required="yes")
    with pytest.raises(ValueError, match=r"providers.num_gpus: must be a number of Ray GPUs >= 0 .* got -1"):
        Providers(names=[CUDA], num_gpus=-1)
    with pytest.raises(ValueError, match=r"providers.num_gpus: .* got True"):
        Providers(names=[CUDA], num_gpus=True)
    with pytest.raises(ValueError, match=r"options names provider\(s\) \['OpenVINOExecutionProvider'\] that are not"):
        Providers(names=[CUDA], options={"OpenVINOExecutionProvider": {"device_type": "GPU"}})
    # what is asked of Ray: 1 GPU with a GPU provider, what the user sets, none for the CPU or OpenVINO
    assert ObjectDetector(providers=[CUDA, CPU_PROVIDER]).num_gpus == 1.0
    assert ObjectDetector(providers=Providers(names=["TensorrtExecutionProvider"], num_gpus=0.25)).num_gpus == 0.25
    assert ObjectDetector(providers=["OpenVINOExecutionProvider"]).num_gpus == 0.0
    assert ObjectDetector().num_gpus == 0.0 and ObjectDetector().providers is None


def _tiny_model(tmp_path: Path) -> str:
    import onnx  # the test extra (pyproject), installed by the README and CI
    from onnx import TensorProto, helper

    x = helper.make_tensor_value_info("x", TensorProto.FLOAT, [1, 3])
    y = helper.make_tensor_value_info("y", TensorProto.FLOAT, [1, 3])
    g = helper.make_graph([helper.make_node("Relu", ["x"], ["y"])], "tiny", [x], [y])
    m = helper.make_model(g, opset_imports=[helper.make_opsetid("", 13)])
    m.ir_version = 8
    path = tmp_path / "tiny.onnx"
    onnx.save(m, str(path))
    return str(path)


def test_a_provider_this_onnxruntime_lacks_falls_back_to_the_cpu_with_a_message(tmp_path, caplog):
    import onnxruntime as ort

    _cpu_build()
    path = _tiny_model(tmp_path)
    with caplog.at_level(logging.WARNING, logger="aerodaas.perception.providers"):
        sess, used = open_session(path, ort.SessionOptions(), Providers(names=[CUDA, CPU_PROVIDER]), "model tiny")
    assert used.used == (CPU_PROVIDER,) and tuple(sess.get_providers()) == (CPU_PROVIDER,)
    assert used.requested == (CUDA, CPU_PROVIDER)
    assert "['CUDAExecutionProvider'] not in this build" in used.fallback and "onnxruntime-gpu" in used.fallback
    assert [r.getMessage() for r in caplog.records] == [used.fallback]
    out = sess.run(None, {"x": np.array([[-1.0, 0.5, 2.0]], dtype=np.float32)})[0]
    assert out.tolist() == [[0.0, 0.5, 2.0]]  # and it runs
    # the CPU is always there, last, even when not named
    _, only = open_session(path, ort.SessionOptions(), Providers(names=[CUDA]), "model tiny")
    assert only.used == (CPU_PROVIDER,) and only.fallback
    # the default (no providers): the CPU, nothing to say
    _, default = open_session(path, ort.SessionOptions(), None)
    assert default.used == (CPU_PROVIDER,) and default.fallback is None and default.requested is None
    with pytest.raises(ProviderUnavailableError, match=r"model tiny on node .*required provider\(s\) "
                                                       r"\['CUDAExecutionProvider'\] not in this build.*onnxruntime-gpu"):
        open_session(path, ort.SessionOptions(), Providers(names=[CUDA, CPU_PROVIDER], required=True), "model tiny")


@needs_data
def test_the_detector_records_the_providers_it_runs_on(data_env):
    from aerodaas.runtime.report import _analytics_lines

    _cpu_build()
    det = ObjectDetector("yolox_nano", name="det", providers=[CUDA, CPU_PROVIDER])
    det.check()
    det.setup()
    frame = np.zeros((120, 160, 3), np.uint8)
    det.process(frame, None)
    det.process(frame, None)
    (ev,) = det.take_emissions().events  # one per drone: its first frame
    assert ev[1].kind == "onnx_providers"
    assert ev[1].fields["providers"] == [CPU_PROVIDER] and ev[1].fields["providers_requested"] == [CUDA, CPU_PROVIDER]
    assert "not in this build" in ev[1].fields["provider_fallback"]
    st = det.stats()
    assert st["providers"] == [CPU_PROVIDER] and st["provider_fallback"] == ev[1].fields["provider_fallback"]
    (line,) = _analytics_lines("d1", {"analytics": [{"name": "det", "processed": 2, "process_ms_median": 5.0, **st}]},
                               {})
    assert "on CPUExecutionProvider at" in line and "CPU fallback" in line
    required = ObjectDetector("yolox_nano", name="det", providers=Providers(names=[CUDA], required=True))
    required.check()
    with pytest.raises(ProviderUnavailableError, match=r"analytics 'det': model yolox_nano.onnx on node"):
        required.setup()
    plain = ObjectDetector("yolox_nano")
    plain.check()
    plain.setup()
    plain.process(frame, None)
    assert not plain.take_emissions().events and "providers" not in plain.stats()  # nothing new without the setting


APP = """from aerodaas import *
from aerodaas.perception.providers import Providers
env = Environment({env!r})
drone = env.get_robot_by_id("d1")
detector = ObjectDetector("yolox_nano", providers={providers})
detector.deploy(env.get_compute_resource_by_id("edge"){deploy})
detector.analyse(drone.get_sensor_by_id("cam").get_data_stream())
drone.navigate(AeroNavigation(NavigationType.DISTANCE_DRIVEN, [Waypoint(id="a", x=1, y=0, z=2)]))
drone.start_mission()
"""


def _app(tmp_path: Path, providers: str, deploy: str = "", name: str = "app.py", **extra) -> Path:
    env = tmp_path / f"{name}.json"
    env.write_text(json.dumps({"robots": [{"id": "d1", "sensors": [{"id": "cam", "type": "camera"}]}],
                               "compute": [{"id": "edge", "tier": "edge", "labels": {"aerodaas/site": "a"}}],
                               **extra}))
    app = tmp_path / name
    app.write_text(APP.format(env=str(env), providers=providers, deploy=deploy))
    return app


@needs_data
def test_the_analytics_actor_asks_ray_for_a_gpu_with_a_gpu_provider(tmp_path, data_env):
    from aerodaas.config import ConfigError
    from aerodaas.runtime.app_loader import load_app
    from aerodaas.runtime.dataflow import Placement

    cases = {"gpu.py": ("['CUDAExecutionProvider', 'CPUExecutionProvider']", 1.0),
             "share.py": ("Providers(names=['TensorrtExecutionProvider'], num_gpus=0.5)", 0.5),
             "cpu.py": ("['CPUExecutionProvider']", 0.0)}
    for name, (providers, gpus) in cases.items():
        plan = load_app(_app(tmp_path, providers, name=name)).plan(run_id="p")
        actors = {a.role: a for a in plan.actors.values()}
        opts = actors["analytics"].ray_options(Placement(has_cloud=False), 1)
        assert opts["label_selector"] == {"tier": "edge", "aerodaas/site": "a"} and opts["max_restarts"] == 1
        assert opts.get("num_gpus") == (gpus or None), (name, opts)
        assert "num_gpus" not in actors["drone"].ray_options(Placement(), 1)  # only the analytics' own actor
        assert ([d.get("num_gpus") for d in plan.describe()["actors"] if d["role"] == "analytics"] == [gpus or None])
    # a colocated copy runs in the drone's actor, which asks for no GPU: refused when the app is loaded
    with pytest.raises(ConfigError, match=r"analytics 'detector': asks Ray for num_gpus=1 .* colocate=True"):
        load_app(_app(tmp_path, "['CUDAExecutionProvider']", ", colocate=True", name="colocated.py"))
    # so does one the analytics scheduler places per frame (its dispatcher and cloud copies ask for none)
    qos = {"deadline_ms": 400, "edge_ms": 20, "cloud_ms": 60, "benefit": 100, "edge_cost": 1, "cloud_cost": 5}
    with pytest.raises(ConfigError, match=r"analytics_scheduler.models.detector: 'detector' asks Ray for num_gpus=1"):
        load_app(_app(tmp_path, "['CUDAExecutionProvider']", name="scheduled.py",
                      analytics_scheduler={"name": "DEMS", "models": {"detector": qos}}))


def test_gpu_placement_errors_name_the_actor_and_the_nodes():
    from aerodaas.clusters.placement import gpu_placement_errors, selector_matches
    from aerodaas.runtime.dataflow import ActorPlan, Placement, RunPlan

    assert selector_matches({"tier": "in(edge,cloud)"}, {"tier": "cloud"})
    assert not selector_matches({"tier": "!in(edge,cloud)"}, {"tier": "cloud"})
    assert selector_matches({"tier": "edge", "site": "!b"}, {"tier": "edge", "site": "a"})
    assert not selector_matches({"tier": "edge", "site": "a"}, {"tier": "edge"})
    det = ActorPlan("analytics/edge/det#1", "analytics", "aerodaas/r/analytics/edge/det#1", "edge", "edge",
                    {"site": "a"}, num_gpus=1.0)
    plan = RunPlan("r", {}, [], {"a": det, "d": ActorPlan("drone/d1", "drone", "aerodaas/r/drone/d1", "edge",
                                                           "edge", {})}, {}, {})
    nodes = [{"Alive": True, "Labels": {"tier": "edge", "site": "a"}, "Resources": {"CPU": 2.0}},
             {"Alive": True, "Labels": {"tier": "edge", "site": "b"}, "Resources": {"GPU": 1.0}},
             {"Alive": False, "Labels": {"tier": "edge", "site": "a"}, "Resources": {"GPU": 4.0}}]
    (err,) = gpu_placement_errors(plan, Placement(), nodes)
    assert "aerodaas/r/analytics/edge/det#1 asks for num_gpus=1 on a node [tier=edge, site=a]" in err
    assert "1 node(s) match its labels, with [0.0] GPUs" in err
    nodes[0]["Resources"]["GPU"] = 0.5
    assert len(gpu_placement_errors(plan, Placement(), nodes)) == 1  # half a GPU is not one
    nodes[0]["Resources"]["GPU"] = 1.0
    assert gpu_placement_errors(plan, Placement(), nodes) == []
    # run on this machine only: the compute's labels are not asked for, the node's GPUs still are
    assert gpu_placement_errors(plan, Placement(local=True), nodes[1:]) == []


def _cli(tmp_path: Path, app: Path, in_process: bool = False):
    """``aerodaas run APP --quiet`` (a new empty RAY_TMPDIR) in a subprocess, or with ``in_process`` (bad input) in
    this process (:func:`tests.inputs.cli_inprocess.run_cli`, which fails the test if Ray is started): (result,
    RAY_TMPDIR)."""
    ray_tmp = fresh_ray_tmp(tmp_path)
    if in_process:
        env = {**os.environ, "RAY_TMPDIR": str(ray_tmp)}
        return run_cli("run", str(app), "--quiet", cwd=tmp_path, env=env), ray_tmp
    p = subprocess.run([sys.executable, "-m", "aerodaas.cli", "run", str(app), "--quiet"], capture_output=True,
                       text=True, cwd=tmp_path, env={**os.environ, "RAY_TMPDIR": str(ray_tmp)}, timeout=300)
    return p, ray_tmp


@needs_data
def test_run_refuses_a_required_provider_this_machine_lacks_before_ray(tmp_path, data_env):
    _cpu_build()
    p, ray_tmp = _cli(tmp_path, _app(tmp_path, "Providers(names=['CUDAExecutionProvider'], required=True)"),
                      in_process=True)
    assert p.returncode == 2, p.stdout[-1500:] + p.stderr[-1500:]
    assert "analytics 'detector': providers.required=True but this machine's onnxruntime" in p.stderr
    assert "does not offer ['CUDAExecutionProvider']" in p.stderr and "Traceback" not in p.stderr
    assert list(ray_tmp.iterdir()) == [] and _ray_processes_under(ray_tmp) == []  # no Ray started


@needs_data
def test_run_stops_with_a_message_when_no_node_has_the_gpu(tmp_path, data_env):
    """This machine's local Ray has no GPU: the actor would stay pending for ever; the run stops (exit 2) naming it."""
    import shutil

    if shutil.which("nvidia-smi") or os.path.exists("/dev/nvidia0") or os.path.exists("/dev/kfd"):
        pytest.skip("this machine has a GPU that a local Ray would offer")
    p, _ = _cli(tmp_path, _app(tmp_path, "['CUDAExecutionProvider', 'CPUExecutionProvider']"))
    assert p.returncode == 2, p.stdout[-1500:] + p.stderr[-1500:]
    assert "analytics/edge/detector#1 asks for num_gpus=1 on a node [tier=edge]" in p.stderr, p.stderr[-1500:]
    assert "no live node has that many GPUs" in p.stderr and "Traceback" not in p.stderr


@pytest.mark.cluster
@needs_data
def test_gpu_provider_lands_on_the_gpu_node_and_falls_back_to_the_cpu_there(tmp_path, data_env):
    """Then, on the same cluster, the provider required: the run does not start (exit 1), naming the provider."""
    from mcap.reader import make_reader

    _cpu_build()
    p = subprocess.run([sys.executable, "tests/perception/cluster_gpu_app.py", str(tmp_path)], cwd=ROOT, capture_output=True,
                       text=True, timeout=600, env=dict(os.environ))
    line = next((ln for ln in p.stdout.splitlines() if ln.startswith("RESULT ")), None)
    assert line is not None, (p.returncode, p.stdout[-3000:], p.stderr[-3000:])
    r = json.loads(line[len("RESULT "):])
    assert r["returncode"] == 0, (r["stdout"], r["stderr"])
    assert r["head"] != r["gpu_node"]
    actors = {a["name"]: a for a in r["actors"]}  # from Ray's state API, read while the mission flew
    det = actors["aerodaas/gpu/analytics/edge/detector#1"]
    assert det["node_id"] == r["gpu_node"] and det["required_resources"].get("GPU") == 1.0, actors
    assert all("GPU" not in a["required_resources"] for n, a in actors.items() if "/analytics/" not in n)
    with open(r["recording"], "rb") as f:
        events = [json.loads(m.data) for _, _, m in make_reader(f).iter_messages(topics=["/d1/events"])]
    (ev,) = [e for e in events if e.get("event") == "onnx_providers"]
    assert ev["analytics"] == "detector" and ev["providers"] == [CPU_PROVIDER]
    assert ev["providers_requested"] == [CUDA, CPU_PROVIDER] and "onnxruntime-gpu" in ev["provider_fallback"]
    assert "mission outcome: success" in r["stdout"] and "CPU fallback" in r["stdout"]
    # required: the analytics cannot start on that node, so the run does not start, and says why
    q = r["required"]
    assert q["returncode"] == 1, (q["stdout"], q["stderr"])
    assert "mission outcome: failed" in q["stdout"]  # the summary names the cause too
    assert "error: ProviderUnavailableError: analytics 'detector'" in q["stdout"], q["stdout"]
    assert "analytics 'detector': model yolox_nano.onnx on node" in q["stderr"], q["stderr"]
    assert "required provider(s) ['CUDAExecutionProvider'] not in this build" in q["stderr"]
