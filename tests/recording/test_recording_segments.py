"""A recording in segments (the recorder actor was restarted mid-run: ``RUN.mcap``, ``RUN.1.mcap`` ...) is joined by
``aerodaas recover`` into one file that mcap's own reader accepts; samples re-sent with a stamp already recorded
(a drone actor restarted from its checkpoint) are recorded once. Fast: no Ray."""
from __future__ import annotations

from pathlib import Path

from mcap.reader import make_reader

from aerodaas.actors.recording.recorder import RecorderService
from aerodaas.recording.segments import list_segments, remove_stale_segments, segment_path
from aerodaas.recording.writer import McapRecorder

from tests.inputs.cli_inprocess import run_cli


def _odom(t: float) -> dict:
    return {"t": t, "position": [t, 0.0, 3.0], "geodetic": {"lat": 47.0, "lon": 8.0, "alt": 500.0},
            "attitude": {"roll": 0.0, "pitch": 0.0, "yaw": 0.0}}


def _read(path: Path, topic: str) -> list[tuple[int, int]]:
    with open(path, "rb") as f:
        return [(m.log_time, m.sequence) for _, _, m in make_reader(f).iter_messages(topics=[topic],
                                                                                     log_time_order=False)]


def test_resent_samples_are_recorded_once(tmp_path):
    svc = RecorderService(str(tmp_path / "dup.mcap"))
    for t in [1, 2, 3, 4, 5]:  # the first actor's samples
        svc.odometry("d1", t * 1_000_000_000, _odom(t))
    for t in [3, 4, 5, 6, 7]:  # restarted from a checkpoint at t = 3: 3, 4, 5 again, then new ones
        svc.odometry("d1", t * 1_000_000_000, _odom(t))
    svc.odometry("d2", 4_000_000_000, _odom(4))  # another robot's stream is its own
    svc.close()
    stamps = [t for t, _ in _read(tmp_path / "dup.mcap", "/d1/odometry")]
    assert stamps == [t * 1_000_000_000 for t in range(1, 8)]
    assert [t for t, _ in _read(tmp_path / "dup.mcap", "/d2/odometry")] == [4_000_000_000]
    assert svc.report()["duplicates"] == 3


def _segment(path: Path, t0: int, n: int, finish: bool = True) -> None:
    r = McapRecorder(path)
    for i in range(n):
        r.write_json("/d1/odometry", t0 + i, {"i": i}, schema_name="aerodaas.Odometry")
        r.write_json("/d1/events", t0 + i, {"event": "e"}, schema_name="aerodaas.MissionEvent")
    if finish:
        r.close()
    else:  # the process died: data written, no summary
        r.flush()
        r._file.close()


def test_segment_names():
    assert segment_path("/x/run.mcap", 0) == Path("/x/run.mcap")
    assert segment_path("/x/run.mcap", 2) == Path("/x/run.2.mcap")
    assert segment_path("/x/run", 1) == Path("/x/run.1")


def test_recover_joins_segments(tmp_path):
    base = tmp_path / "run.mcap"
    _segment(base, 1_000, 300, finish=False)  # the dead recorder's file: unfinished
    _segment(segment_path(base, 1), 10_000, 200)  # the restarted recorder's
    _segment(segment_path(base, 2), 20_000, 100)
    assert len(list_segments(base)) == 3
    p = run_cli("recover", str(base))  # in-process: a reader and writer, no Ray
    assert p.returncode == 0, p.stderr
    assert "3 segments" in p.stdout
    with open(base, "rb") as f:
        r = make_reader(f)
        summary = r.get_summary()
        msgs = list(r.iter_messages())
        meta = {m.name: m.metadata for m in r.iter_metadata()}
    assert summary is not None and summary.statistics.message_count == len(msgs) == 2 * (300 + 200 + 100)
    assert len(summary.channels) == 2  # one channel per topic across the segments
    odom = [m.log_time for _, ch, m in msgs if ch.topic == "/d1/odometry"]
    assert sorted(odom) == [1_000 + i for i in range(300)] + [10_000 + i for i in range(200)] + \
        [20_000 + i for i in range(100)]
    assert meta["aerodaas.segments"]["joined"] == "run.mcap,run.1.mcap,run.2.mcap"
    assert list_segments(base) == [base]  # joined: the segment files are gone
    p2 = run_cli("recover", str(base))
    assert p2.returncode == 0 and "already finished" in p2.stdout  # idempotent


def test_a_new_run_removes_stale_segments(tmp_path):
    base = tmp_path / "run.mcap"
    _segment(base, 0, 5)
    _segment(segment_path(base, 1), 100, 5)
    assert remove_stale_segments(base) == [segment_path(base, 1)]
    assert list_segments(base) == [base]


def test_the_runs_own_outcome_wins_over_its_missions(tmp_path):
    """A recorder that replaced a dead one records ``/run/result`` ``recording_lost`` (actors/recording/actor.py):
    summaries of that recording (unfinished or finished) say so, even where every drone's ``/mission/result`` says
    success and comes later in log time."""
    from aerodaas.recording.writer import McapRecorder
    from aerodaas.recording.reader import summarize_mcap

    path = tmp_path / "run.mcap"
    with McapRecorder(path) as rec:
        rec.write_json("/run/result", 10, {"outcome": "recording_lost", "losses": []}, schema_name="aerodaas.RunResult")
        rec.write_json("/mission/result", 20, {"robot": "r", "outcome": "success"}, schema_name="aerodaas.MissionResult")
    assert summarize_mcap(path)["mission"]["outcome"] == "recording_lost"
    plain = tmp_path / "plain.mcap"
    with McapRecorder(plain) as rec:
        rec.write_json("/mission/result", 20, {"robot": "r", "outcome": "success"}, schema_name="aerodaas.MissionResult")
    assert summarize_mcap(plain)["mission"]["outcome"] == "success"
