"""``package:NAME`` in an environment file: the images shipped in ``aerodaas/sim/ground`` are found with no data
folder, from an environment file anywhere; a name that is not one of them is refused naming the field."""
from __future__ import annotations

import json
import tomllib
from fnmatch import fnmatch

import cv2
import pytest

from aerodaas.config import ConfigError, load_environment_config
from aerodaas.config.base import PACKAGE_IMAGERY_DIR
from tests.conftest import REPO


def _env(tmp_path, ground: str) -> str:
    cfg = json.loads((REPO / "apps" / "vehicle_tracking.json").read_text())
    cfg["world"]["ground"]["image"] = ground
    path = tmp_path / "elsewhere" / "env.json"
    path.parent.mkdir()
    path.write_text(json.dumps(cfg))
    return str(path)


def test_the_vehicle_tracking_imagery_resolves_without_a_data_folder(tmp_path, monkeypatch):
    monkeypatch.delenv("AERODAAS_DATA_DIR", raising=False)
    monkeypatch.chdir(tmp_path)
    cfg = load_environment_config(_env(tmp_path, "package:brighton_beach_DJI_0025_8cm.jpg"))
    ground, car = cfg.world.ground, cfg.world.targets[0]
    assert ground.image == str(PACKAGE_IMAGERY_DIR / "brighton_beach_DJI_0025_8cm.jpg")
    img = cv2.imread(ground.image)
    # the photo at the sampling the environment states: 4000x2250 px at 0.02 m/px quartered, the same 80 m x 45 m
    assert img.shape[:2] == (562, 1000) and ground.metres_per_pixel == 0.08
    x0, y0, x1, y1 = car.crop
    assert cv2.imread(car.image).shape[:2] == (y1 - y0, x1 - x0)


@pytest.mark.parametrize("name", ["package:nope.jpg", "package:../base.py", "package:", "package:ground/x.png"])
def test_a_name_that_is_not_a_packaged_image_is_refused_naming_the_field(tmp_path, name):
    with pytest.raises(ConfigError, match=r"world\.ground\.image: .*is not a packaged image.*"
                                          r"package:brighton_beach_DJI_0025_8cm\.jpg"):
        load_environment_config(_env(tmp_path, name))


def test_every_packaged_file_is_package_data_and_each_image_stays_under_100_kib():
    # the project's rule for committed images outside the shipped model, tests/data and docs
    patterns = tomllib.loads((REPO / "pyproject.toml").read_text())["tool"]["setuptools"]["package-data"]["aerodaas.sim"]
    files = sorted(p for p in PACKAGE_IMAGERY_DIR.iterdir())
    assert {"LICENSE", "README.md"} <= {p.name for p in files}
    for p in files:
        assert any(fnmatch(f"ground/{p.name}", pat) for pat in patterns), p
        assert p.stat().st_size <= 100 * 1024, p
