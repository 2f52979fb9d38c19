import json

import pytest

from aerodaas.config import ConfigError, load_environment_config, parse_environment_config

from tests.inputs.cli_inprocess import run_cli

GOOD = {"robots": [{"id": "d1", "sensors": [{"id": "cam", "type": "camera"}, {"id": "odom", "type": "odometry"}]}]}


def test_good_config_gets_defaults_and_a_stat_stream():
    cfg = parse_environment_config(json.loads(json.dumps(GOOD)))
    r = cfg.robots[0]
    assert r.backend == "sim" and r.limits.max_speed > 0
    assert {s.type for s in r.sensors} == {"camera", "odometry", "stat_stream"}
    assert r.sensors[0].properties["fps"] == 15.0


@pytest.mark.parametrize("mutate,expect", [
    (lambda d: d["robots"][0].update(limits={"max_speed": -1}), "robots.0.limits.max_speed"),
    (lambda d: d["robots"][0].update(backend="gazebo"), "robots.0.backend"),
    (lambda d: d["robots"][0]["sensors"][0].update(properties={"hfov_deg": 200}), "hfov_deg"),
    (lambda d: d["robots"][0].update(home={"lat": 95, "lon": 0}), "robots.0.home.lat"),
    (lambda d: d.update(robots=[]), "robots"),
    (lambda d: d["robots"].append({"id": "d1"}), "duplicate ids"),
    (lambda d: d.update(compute=[{"id": "c", "tier": "fog"}]), "compute.0.tier"),
    (lambda d: d.update(world={"ground": {"image": "nope/missing.png"}}), "world.ground.image"),
    (lambda d: d["robots"][0].update(colour="red"), "robots.0.colour"),
])
def test_malformed_config_names_field_and_value(mutate, expect):
    d = json.loads(json.dumps(GOOD))
    mutate(d)
    with pytest.raises(ConfigError) as e:
        parse_environment_config(d)
    assert expect in str(e.value)


def test_bad_json_and_missing_file(tmp_path):
    p = tmp_path / "env.json"
    p.write_text("{\"robots\": [")
    with pytest.raises(ConfigError, match="line 1 column [0-9]+: invalid JSON"):
        load_environment_config(p)
    with pytest.raises(ConfigError, match="not found"):
        load_environment_config(tmp_path / "missing.json")


def test_schema_command_prints_json_schema():
    out = run_cli("schema")
    assert out.returncode == 0, out.stderr
    schema = json.loads(out.stdout)
    assert "robots" in schema["properties"] and "RobotConfig" in schema["$defs"]


@pytest.mark.parametrize("fmt", ["JPEG", "MPO"])
def test_a_jpeg_image_is_checked_at_reduced_scale_and_still_refused_when_unreadable(fmt, tmp_path, monkeypatch):
    """A JPEG (and an MPO, what DJI cameras write as .JPG) is read by OpenCV at 1/8 scale to prove it decodes (issue
    49 item 5: the driver's check of the ground and target images); its size is the header's. A file cut after its
    header (Pillow opens it, OpenCV cannot decode it) is refused naming the field."""
    import cv2
    import numpy as np
    from PIL import Image

    from aerodaas.config.environment import _image_size

    rgb = (np.random.default_rng(0).random((48, 64, 3)) * 255).astype(np.uint8)
    path = tmp_path / "photo.jpg"
    Image.fromarray(rgb).save(path, fmt, **({"save_all": True, "append_images": [Image.fromarray(rgb)]}
                                            if fmt == "MPO" else {}))
    with Image.open(path) as im:
        assert im.format == fmt
    flags = []
    imread = cv2.imread
    monkeypatch.setattr(cv2, "imread", lambda p, flag=cv2.IMREAD_COLOR: flags.append(flag) or imread(p, flag))
    assert _image_size(str(path), "world.ground.image") == (64, 48)
    assert flags == [cv2.IMREAD_REDUCED_COLOR_8]
    data = path.read_bytes()
    cut = tmp_path / "cut.jpg"
    cut.write_bytes(data[:data.find(b"\xff\xda")])  # everything before the scan: no image data
    with pytest.raises(ConfigError, match=r"world\.ground\.image.*not an image OpenCV can read"):
        _image_size(str(cut), "world.ground.image")
