"""Every file the environment names is an input ``--record`` never overwrites, with
``--overwrite`` too, and a recording of ours among them (a replayed camera's MCAP) as well: the ground image, a
target's image, a geofence ``.plan``, a replay log, a recorded camera's MCAP, a MAVLink signing key. Each case runs
``aerodaas run APP --record <that file>`` on an environment written here: exit 2 before Ray, the message names the
environment field, the file is unchanged; the positive path (a new file beside them) gets past the check."""
from __future__ import annotations

import json
import os

import numpy as np
import pytest

from aerodaas import cli

from tests.inputs.test_bad_input import no_ray  # noqa: F401 - the fixture: fails the test if Ray is started or reached

NAVIGATE = ('drone = env.get_robot_by_id("d1")\n'
            'drone.navigate(AeroNavigation(NavigationType.DISTANCE_DRIVEN, [Waypoint(id="a", x=1, y=0, z=2)]))\n')
APP = 'from aerodaas import *\nenv = Environment("env.json")\n{navigate}env.start_mission()\n'


def _png(path) -> str:
    import cv2

    assert cv2.imwrite(str(path), np.full((64, 64, 3), 90, np.uint8))
    return path.name


def _ground(tmp) -> tuple[dict, str, str]:
    return {"world": {"ground": {"image": _png(tmp / "ground.png")}}}, "ground.png", "world.ground.image"


def _target(tmp) -> tuple[dict, str, str]:
    target = {"id": "car1", "image": _png(tmp / "car.png"), "crop": [0, 0, 8, 4],
              "path": [{"t": 0, "x": 0, "y": 0}, {"t": 10, "x": 5, "y": 0}]}
    return {"world": {"targets": [target]}}, "car.png", "world.targets.0.image"


def _plan(tmp) -> tuple[dict, str, str]:
    (tmp / "fence.plan").write_text(json.dumps({
        "fileType": "Plan", "version": 1, "groundStation": "QGroundControl",
        "mission": {"version": 2, "items": [], "plannedHomePosition": [47.397742, 8.545594, 488.0]},
        "geoFence": {"version": 2, "polygons": [], "circles": []}, "rallyPoints": {"version": 2, "points": []}}))
    return {"robot": {"safety": {"geofence_plan": "fence.plan"}}}, "fence.plan", "robots.0.safety.geofence_plan"


def _replay_log(tmp) -> tuple[dict, str, str]:
    from tests.recording.test_replay import write_ulog_flight

    write_ulog_flight(tmp / "flight.ulg")
    return {"robot": {"backend": "replay", "replay": {"log": "flight.ulg"}}}, "flight.ulg", "robots.0.replay.log"


def _camera_mcap(tmp) -> tuple[dict, str, str]:
    """A recording of ours (the project's writer) holding the camera topic: without the rule it would be replaced
    even without --overwrite."""
    from aerodaas.recording.writer import McapRecorder

    with McapRecorder(tmp / "camera.mcap") as rec:
        for i in range(3):
            rec.write_image("/d1/camera/cam", 1_000_000_000 + i * 100_000_000, np.zeros((16, 16, 3), np.uint8))
    sensors = [{"id": "cam", "type": "camera", "properties": {"source": "mcap", "mcap": "camera.mcap"}}]
    return {"robot": {"sensors": sensors}}, "camera.mcap", "robots.0.sensors.0.properties.mcap"


def _signing_key(tmp) -> tuple[dict, str, str]:
    key = tmp / "link.key"
    key.write_bytes(os.urandom(32))
    key.chmod(0o600)
    mav = {"connection": "udpin:127.0.0.1:14599", "signing_key_file": "link.key"}
    return {"robot": {"backend": "mavlink", "mavlink": mav}}, "link.key", "robots.0.mavlink.signing_key_file"


KINDS = {"ground image": _ground, "target image": _target, "geofence .plan": _plan, "replay log": _replay_log,
         "recorded camera MCAP": _camera_mcap, "MAVLink signing key": _signing_key}


def _write(tmp, make) -> tuple[str, str, str]:
    """The environment (one robot d1 with what ``make`` adds) and the app, in ``tmp``: (app, the file, its field)."""
    extra, name, field = make(tmp)
    robot = {"id": "d1", **extra.pop("robot", {})}
    (tmp / "env.json").write_text(json.dumps({"robots": [robot], **extra}))
    navigable = robot.get("backend") != "replay"
    (tmp / "app.py").write_text(APP.format(navigate=NAVIGATE if navigable else ""))
    return str(tmp / "app.py"), str(tmp / name), field


@pytest.mark.parametrize("overwrite", [False, True], ids=["", "--overwrite"])
@pytest.mark.parametrize("kind", list(KINDS))
def test_a_file_the_environment_names_is_never_a_recording_target(tmp_path, monkeypatch, no_ray, capsys,  # noqa: F811
                                                                   kind, overwrite):
    monkeypatch.chdir(tmp_path)
    app, target, field = _write(tmp_path, KINDS[kind])
    before = open(target, "rb").read()
    code = cli.main(["run", app, "--record", target, "--quiet", *(["--overwrite"] if overwrite else [])])
    err = capsys.readouterr().err
    assert code == 2, err
    assert f"--record {target!r} is an input of this run ({field} of the environment: " in err, err
    assert "Traceback" not in err and no_ray == []
    assert open(target, "rb").read() == before


@pytest.mark.parametrize("kind", list(KINDS))
def test_a_new_file_beside_them_passes_the_check(tmp_path, monkeypatch, no_ray, capsys, kind):  # noqa: F811
    """The positive path: ``--record run.mcap`` in the same folder gets past every check to the run itself (here a
    stand-in that records what it was given and stops), the environment's files untouched."""
    monkeypatch.chdir(tmp_path)
    app, target, _ = _write(tmp_path, KINDS[kind])
    before = open(target, "rb").read()
    from aerodaas.runtime import driver

    seen = []

    def stop_at_the_run(run):
        seen.append(run.opts.record)
        raise KeyboardInterrupt

    monkeypatch.setattr(driver, "_run_mission", stop_at_the_run)
    cli.main(["run", app, "--record", str(tmp_path / "run.mcap"), "--quiet"])
    assert seen == [str(tmp_path / "run.mcap")], capsys.readouterr().err
    assert open(target, "rb").read() == before
