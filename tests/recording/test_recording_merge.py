"""``aerodaas merge``: the files of one run recorded by one recorder per node, merged into one.

Two node recordings are made by the recorder's own writer (:class:`~aerodaas.actors.recording.recorder.RecorderService`, with
its ``/run/accounting``), each holding one drone's frames and odometry numbered as a remote producer numbers them;
the merged file is read back with the ``mcap`` library's own reader and with ``aerodaas info``."""
from __future__ import annotations

import json

import pytest

from aerodaas.cli import main

JPEG = b"\xff\xd8" + bytes(range(256)) * 4 + b"\xff\xd9"


def _node_recording(path, robot: str, t0_s: float, n: int, produced: int | None = None) -> None:
    """A node recorder's file: ``n`` odometry samples and ``n`` frames of ``robot`` every 0.1 s from ``t0_s``,
    numbered 0..n-1 by the drone actor, whose ledger says it numbered ``produced`` (default ``n``) of each."""
    from aerodaas.actors.recording.recorder import RecorderService
    from aerodaas.bench.recorder import odometry_sample
    from aerodaas.protocol.messages import ProducerLedger

    rec = RecorderService(str(path), {"run": "r1", "node": robot}, max_pending_frames=10_000)
    rec.camera(robot, "cam", {"width": 64, "height": 48, "fx": 50, "fy": 50, "cx": 32, "cy": 24}, 90.0)
    for i in range(n):
        t_ns = int((t0_s + 0.1 * i) * 1e9)
        rec.odometry(robot, t_ns, odometry_sample(0, 0.1 * i), seq=i)
        assert rec.image(f"/{robot}/camera/cam", t_ns, JPEG, f"{robot}/cam", seq=i)
    k = n if produced is None else produced
    rec.close(ledgers=[ProducerLedger(f"drone/{robot}", {f"/{robot}/odometry": k, f"/{robot}/camera/cam": k})])


def _read(path):
    from mcap.reader import make_reader

    with open(path, "rb") as f:
        r = make_reader(f)
        summary = r.get_summary()
        msgs = [(c.topic, m.log_time, m.sequence) for _, c, m in r.iter_messages(log_time_order=False)]
        meta = {m.name: dict(m.metadata) for m in r.iter_metadata()}
    return summary, msgs, meta


def test_two_node_recordings_merge_into_one_run_with_the_accounting_summed(tmp_path, capsys):
    a, b, out = tmp_path / "run.mcap", tmp_path / "run.node-edge-b.mcap", tmp_path / "all.mcap"
    _node_recording(a, "d0", 100.0, 20)
    _node_recording(b, "d1", 100.05, 30)  # interleaved in time with d0
    assert main(["merge", str(a), str(b), "--out", str(out)]) == 0
    assert "2 recordings merged" in capsys.readouterr().out

    summary, msgs, meta = _read(out)
    topics = [c.topic for c in summary.channels.values()]
    assert len(topics) == len(set(topics)), topics  # /tf of both nodes is one channel
    assert {"/d0/odometry", "/d1/odometry", "/d0/camera/cam", "/d1/camera/cam", "/tf"} <= set(topics)
    times = [t for _, t, _ in msgs]  # file order (no re-sorting by the reader): log-time order across the files
    assert times == sorted(times)
    per = {}
    for topic, _, seq in msgs:
        per.setdefault(topic, []).append(seq)
    assert per["/d0/odometry"] == list(range(20)) and per["/d1/odometry"] == list(range(30))  # sequences kept
    _, msgs_a, _ = _read(a)
    _, msgs_b, _ = _read(b)
    # every message of both files, their accountings and recorder drops each replaced by one summed
    summed = ("/run/accounting", "/run/recorder_drops")
    assert sorted(m for m in msgs if m[0] not in summed) == sorted(m for m in msgs_a + msgs_b if m[0] not in summed)
    assert [m[0] for m in msgs if m[0] in summed] == list(reversed(summed))
    assert per["/run/accounting"] == [0] and msgs[-1][0] == "/run/accounting"
    assert meta["aerodaas.merged"]["files"] == "run.mcap,run.node-edge-b.mcap"
    assert {meta.get("aerodaas", {}).get("node")} <= {"d0", "d1"}

    assert main(["info", str(out), "--json"]) == 0
    info = json.loads(capsys.readouterr().out)
    acc = info["accounting"]
    assert acc["lost_total"] == 0
    assert acc["channels"]["/d0/odometry"]["produced"] == 20 and acc["channels"]["/d1/odometry"]["produced"] == 30
    assert acc["channels"]["/d1/camera/cam"]["recorded"] == 30


def test_a_loss_on_one_node_stays_a_loss_in_the_merged_run(tmp_path):
    from aerodaas.recording.accounting import account_recording

    a, b, out = tmp_path / "run.mcap", tmp_path / "run.node-b.mcap", tmp_path / "all.mcap"
    _node_recording(a, "d0", 1.0, 10)
    _node_recording(b, "d1", 1.0, 10, produced=13)  # three of d1's numbered messages never reached its recorder
    assert main(["merge", str(a), str(b), "--out", str(out)]) == 0
    acc = account_recording([out])
    assert acc["lost"] == {"/d1/odometry": 3, "/d1/camera/cam": 3} and acc["lost_total"] == 6


def test_bad_inputs_are_refused_naming_the_file(tmp_path, capsys):
    a, b = tmp_path / "run.mcap", tmp_path / "run.node-b.mcap"
    _node_recording(a, "d0", 1.0, 3)
    assert main(["merge", str(a), "--out", str(a)]) == 2
    assert "is one of the inputs" in capsys.readouterr().err
    assert main(["merge", str(a), str(tmp_path / "missing.mcap"), "--out", str(tmp_path / "o.mcap")]) == 2
    assert "missing.mcap" in capsys.readouterr().err
    b.write_bytes(a.read_bytes()[: a.stat().st_size // 2])  # a node recorder that died: unfinished
    assert main(["merge", str(a), str(b), "--out", str(tmp_path / "o.mcap")]) == 2
    err = capsys.readouterr().err
    assert "unfinished" in err and "aerodaas recover" in err and str(b) in err
    assert not (tmp_path / "o.mcap").exists()


@pytest.mark.parametrize("base,compute,name", [("/x/run.mcap", "edge-b", "run.node-edge-b.mcap"),
                                              ("/x/run", "a", "run.node-a.mcap")])
def test_node_recording_path(base, compute, name):
    from aerodaas.recording.merge import node_recording_path

    p = node_recording_path(base, compute)
    assert p.name == name and str(p.parent) == "/x"
