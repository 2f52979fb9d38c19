"""The ground pyramid is stored once per machine and mapped read-only by every rendering process
(aerodaas.sim.ground_cache): same pixels as the in-heap pyramid, one file per level, keyed by the configuration."""
import os
import subprocess
import sys

import numpy as np
import pytest

from aerodaas.model.types import CameraIntrinsics, FramePose
from aerodaas.config import GroundConfig
from aerodaas.sim import ground_cache
from aerodaas.sim.world import World, ground_pyramid

from tests.inputs.cli_inprocess import run_cli

GROUND = GroundConfig(seed=3, metres_per_pixel=0.05, size_m=40)


@pytest.fixture
def cache(tmp_path, monkeypatch):
    monkeypatch.setenv("AERODAAS_GROUND_CACHE_DIR", str(tmp_path / "ground"))
    monkeypatch.delenv("AERODAAS_GROUND_CACHE", raising=False)
    return tmp_path / "ground"


def _mapped_files(levels):
    return [os.path.realpath(a.filename) for a, _, _ in levels]


def test_worlds_map_one_read_only_copy_with_the_heap_pyramids_pixels(cache, monkeypatch):
    a, b = World(GROUND, []), World(GROUND, [])
    assert all(isinstance(lv[0], np.memmap) and not lv[0].flags.writeable for lv in a.levels)
    assert _mapped_files(a.levels) == _mapped_files(b.levels)
    assert all(f.startswith(os.path.realpath(cache)) for f in _mapped_files(a.levels))
    ref = ground_pyramid(GROUND)
    assert len(ref) == len(a.levels)
    for (ta, ma, ha), (tr, mr, hr) in zip(a.levels, ref):
        assert np.array_equal(ta, tr) and ma == mr and ha == hr
    monkeypatch.setenv("AERODAAS_GROUND_CACHE", "0")
    heap = World(GROUND, [])
    assert not any(isinstance(lv[0], np.memmap) for lv in heap.levels)
    k = CameraIntrinsics.from_hfov(160, 120, 78)
    pose = FramePose(position=(1, 2, 6), yaw=30)
    assert np.array_equal(a.render(pose, k, 0.0)[0], heap.render(pose, k, 0.0)[0])


def test_another_process_maps_the_pyramid_without_building_it(cache):
    code = ("from aerodaas.config import GroundConfig; from aerodaas.sim.world import World; "
            "World(GroundConfig(seed=3, metres_per_pixel=0.05, size_m=40), [])")
    subprocess.run([sys.executable, "-c", code], check=True, env=dict(os.environ), timeout=120)
    key = ground_cache.ground_key(GROUND.model_dump_json(), None)
    built = []
    levels = ground_cache.shared_levels(key, lambda: built.append(1) or ground_pyramid(GROUND))
    assert built == [] and isinstance(levels[0][0], np.memmap)


def test_key_follows_the_configuration_and_the_image_file(cache, tmp_path):
    k1 = ground_cache.ground_key(GROUND.model_dump_json(), None)
    assert k1 != ground_cache.ground_key(GroundConfig(seed=4, metres_per_pixel=0.05, size_m=40).model_dump_json(),
                                         None)
    img = tmp_path / "g.png"
    img.write_bytes(b"x")
    k2 = ground_cache.ground_key("{}", str(img))
    img.write_bytes(b"xy")
    assert k2 != ground_cache.ground_key("{}", str(img))


def test_an_unwritable_cache_falls_back_to_the_heap(tmp_path, monkeypatch):
    blocker = tmp_path / "file"
    blocker.write_text("not a directory")
    monkeypatch.setenv("AERODAAS_GROUND_CACHE_DIR", str(blocker / "ground"))
    w = World(GROUND, [])
    assert not isinstance(w.levels[0][0], np.memmap)
    assert np.array_equal(w.levels[0][0], ground_pyramid(GROUND)[0][0])


def _store(seed: int) -> str:
    g = GroundConfig(seed=seed, metres_per_pixel=0.05, size_m=40)
    key = ground_cache.ground_key(g.model_dump_json(), None)
    ground_cache.shared_levels(key, lambda: ground_pyramid(g))
    return key


def test_the_cache_keeps_the_recently_used_pyramids_within_its_bound(cache, monkeypatch):
    """Storing a pyramid removes the least recently used others beyond AERODAAS_GROUND_CACHE_MB; loading one
    marks it used; a crashed builder's old temporary directory goes too."""
    k1 = _store(1)
    one = sum(f.stat().st_size for f in (cache / k1).iterdir())
    k2 = _store(2)
    os.utime(cache / k1 / "meta.json", (2.0, 2.0))  # both last used long ago, k2 first
    os.utime(cache / k2 / "meta.json", (1.0, 1.0))
    _store(2)  # a load: k2 is now the most recently used, k1 the least
    stale = cache / ".deadbeef-x"
    stale.mkdir()
    os.utime(stale, (1.0, 1.0))
    monkeypatch.setenv("AERODAAS_GROUND_CACHE_MB", str(2.5 * one / 1e6))  # room for two
    k3 = _store(3)
    assert not stale.exists()
    assert sorted(p.name for p in cache.iterdir() if p.is_dir()) == sorted([k2, k3])
    monkeypatch.setenv("AERODAAS_GROUND_CACHE_MB", "0")  # no room: the pyramid being stored stays, alone
    k4 = _store(4)
    assert [p.name for p in cache.iterdir() if p.is_dir()] == [k4]


def test_a_bad_cache_bound_is_refused_before_ray_and_down_removes_the_cache(cache, monkeypatch, tmp_path):
    _store(1)
    env = dict(os.environ, AERODAAS_GROUND_CACHE_MB="lots")
    app = tmp_path / "app.py"
    app.write_text("raise SystemExit('the app must not run')\n")
    r = run_cli("run", str(app), env=env)  # in-process: Ray refused
    assert r.returncode == 2 and "AERODAAS_GROUND_CACHE_MB" in r.stderr and "'lots'" in r.stderr, r.stderr
    env = dict(os.environ, AERODAAS_STATE_DIR=str(tmp_path / "state"))  # no `aerodaas up` cluster there
    r = subprocess.run([sys.executable, "-m", "aerodaas.cli", "down"], env=env, capture_output=True, text=True,
                       timeout=120)
    assert r.returncode == 0 and "removed the shared ground cache" in r.stdout, (r.stdout, r.stderr)
    assert not cache.exists()


def test_processes_that_start_together_build_the_ground_once(cache, tmp_path):
    """Three processes ask for the same ground at once: one builds it (under the cache's lock), the others wait
    and map its copy."""
    log = tmp_path / "builds.txt"
    script = tmp_path / "ask.py"
    script.write_text(
        "import os, sys, time\n"
        "from aerodaas.config import GroundConfig\n"
        "from aerodaas.sim import ground_cache\n"
        "from aerodaas.sim.world import ground_pyramid\n"
        "g = GroundConfig(seed=9, metres_per_pixel=0.05, size_m=40)\n"
        "def build():\n"
        "    with open(sys.argv[1], 'a') as f:\n"
        "        f.write(f'{os.getpid()}\\n')\n"
        "    time.sleep(1.0)  # the others ask meanwhile\n"
        "    return ground_pyramid(g)\n"
        "lv = ground_cache.shared_levels(ground_cache.ground_key(g.model_dump_json(), None), build)\n"
        "print(type(lv[0][0]).__name__)\n")
    procs = [subprocess.Popen([sys.executable, str(script), str(log)], env=dict(os.environ), stdout=subprocess.PIPE,
                              text=True) for _ in range(3)]
    outs = [p.communicate(timeout=120)[0].strip() for p in procs]
    assert [p.returncode for p in procs] == [0, 0, 0]
    assert outs == ["memmap"] * 3
    assert len(log.read_text().split()) == 1


@pytest.mark.parametrize("pitch", [90.0, 35.0], ids=["nadir", "oblique-with-sky"])
def test_a_frame_rendered_into_a_given_buffer_is_that_buffer_with_the_same_pixels(cache, pitch):
    """What the camera does when a same-node channel lends it a slot (``World.render(out=...)``): the frame is the
    buffer itself, pixel for pixel the frame rendered on its own (the ground, and the sky of an oblique view)."""
    w = World(GROUND, [])
    k = CameraIntrinsics.from_hfov(160, 120, 78)
    pose = FramePose(position=(1, 2, 6), yaw=30, camera_pitch=pitch)
    alone, truth = w.render(pose, k, 0.0)
    buf = np.full((120, 160, 3), 7, np.uint8)
    into, truth_into = w.render(pose, k, 0.0, out=buf)
    assert into is buf and np.array_equal(buf, alone) and truth_into == truth
    assert len(np.unique(alone.reshape(-1, 3), axis=0)) > 10  # a real picture, not the buffer's old fill
