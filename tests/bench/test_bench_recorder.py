"""``aerodaas bench recorder``: its parts that need no Ray. The Ray run itself is in
``tests/bench/test_bench_json_stdout.py`` (slow tier); timing is never asserted."""
from __future__ import annotations

import pytest

from aerodaas.cli import main


def test_bench_frames_are_distinct_jpegs_of_the_asked_size():
    import cv2
    import numpy as np

    from aerodaas.bench.recorder import bench_frames

    frames, source = bench_frames(320, 240, count=6)
    assert len(set(frames)) == 6 and source  # distinct: a zstd chunk cannot shrink a repeated frame
    img = cv2.imdecode(np.frombuffer(frames[0], np.uint8), cv2.IMREAD_COLOR)
    assert img.shape == (240, 320, 3)


def test_baseline_writes_every_message_of_the_recording_again(tmp_path):
    from aerodaas.bench.recorder import baseline_write, odometry_sample
    from aerodaas.actors.recording.recorder import RecorderService

    path = tmp_path / "r.mcap"
    rec = RecorderService(str(path))
    for i in range(25):
        rec.odometry("d0", (i + 1) * 10**8, odometry_sample(0, i * 0.1))
    counts = rec.close()
    b = baseline_write(path)
    assert b["messages"] == sum(counts.values()) > 25 * 5 and b["messages_per_s"] > 0
    assert sorted(p.name for p in tmp_path.iterdir()) == ["r.mcap"]  # its own file removed


def _row(drones, lost=0, rec_dropped=0, drain=0.1, mps=100.0):
    return {"drones": drones, "lost_by_accounting": lost, "frames_dropped_by_recorder": rec_dropped,
            "frames_dropped_by_producers": 0, "drain_s": drain, "messages_per_s": mps, "mb_per_s": mps / 100}


@pytest.mark.parametrize("rows, limit, ceiling", [
    ([_row(5), _row(10, mps=200.0)], None, 10),
    ([_row(5), _row(10, mps=200.0), _row(20, lost=3, mps=150.0)], (20, "lost messages"), 10),
    ([_row(5), _row(10, drain=4.2, mps=300.0)], (10, "drained 4.2 s > 1.0 s"), 5),
    ([_row(5, rec_dropped=1)], (5, "lost messages"), None),
])
def test_the_limit_is_the_first_size_that_lost_or_drained_too_long(rows, limit, ceiling):
    from aerodaas.bench.recorder import _limit

    out = _limit(rows)
    assert (out["limit"] and (out["limit"]["drones"], out["limit"]["why"])) == (limit or None)
    assert (out["ceiling"] and out["ceiling"]["drones"]) == ceiling


@pytest.mark.parametrize("argv, named", [(["--drones", "0"], "--drones"), (["--duration", "0"], "--duration"),
                                         (["--fps", "-1"], "--fps"), (["--width", "8"], "--width/--height"),
                                         (["--recorders", "0"], "--recorders")])
def test_bad_options_are_refused_before_ray_starts(argv, named, capsys):
    assert main(["bench", "recorder", *argv]) == 2
    captured = capsys.readouterr()
    assert named in captured.err and captured.out == ""
