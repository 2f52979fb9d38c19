"""``start_mission(timeout=...)`` from the application is bounded as ``aerodaas run --timeout`` is.
A value that is not a number of seconds in (0, 1e7] (a negative one, NaN, a string, a bool, 0, 1e8) is refused
while the app loads, exit 2 naming ``start_mission(timeout=...)`` and the value, before Ray (it used to reach the
actors: ``-1`` and NaN ended the mission after 1 s as ``timeout``, a string was a TypeError traceback after Ray
started); a valid one ends the mission as ``timeout``, exit 1, with a finished recording, within the fault
catalogue's bound of the timeout."""
from __future__ import annotations

import pytest

from aerodaas import cli
from aerodaas.reliability.faults import run_fault

from tests.inputs.test_bad_input import no_ray  # noqa: F401 - the fixture: fails the test if Ray is started or reached

APP = """from aerodaas import *
env = Environment({env!r})
drone = env.get_robot_by_id("d1")
drone.navigate(AeroNavigation(NavigationType.DISTANCE_DRIVEN, [Waypoint(id="a", x=1, y=0, z=2)]))
{call}
"""


@pytest.mark.parametrize("call", ["drone.start_mission(timeout={v})", "env.start_mission([drone], timeout={v})",
                                  "env.start_mission(timeout={v})"])
@pytest.mark.parametrize("value,said", [("-1", "got -1"), ("float('nan')", "got nan"), ("0", "got 0"),
                                        ("1e8", "got 100000000.0"), ('"60"', "got str '60'"),
                                        ("True", "got bool True"), ("float('inf')", "got inf")])
def test_a_bad_timeout_of_the_app_exits_2_before_ray(tmp_path, no_ray, capsys, call, value, said):  # noqa: F811
    env = tmp_path / "env.json"
    env.write_text('{"robots": [{"id": "d1"}]}')
    app = tmp_path / "app.py"
    app.write_text(APP.format(env=str(env), call=call.format(v=value)))
    assert cli.main(["run", str(app), "--quiet"]) == 2
    err = capsys.readouterr().err
    assert f"start_mission(timeout=...) must be a number of wall-clock seconds within (0, 1e+07], {said}" in err, err
    assert "Traceback" not in err and no_ray == []


def test_a_good_timeout_of_the_app_passes_the_check(tmp_path, no_ray, capsys, monkeypatch):  # noqa: F811
    """The positive path of the check: ``timeout=30`` (and ``--timeout 5``, which wins) get past it to the run
    itself, which starts Ray (here: the stand-in records the attempt and the run stops there)."""
    env = tmp_path / "env.json"
    env.write_text('{"robots": [{"id": "d1"}]}')
    app = tmp_path / "app.py"
    app.write_text(APP.format(env=str(env), call="drone.start_mission(timeout=30)"))
    from aerodaas.runtime import driver

    seen = []

    def stop_at_the_run(run):
        seen.append(run.timeout)
        raise KeyboardInterrupt

    monkeypatch.setattr(driver, "_run_mission", stop_at_the_run)
    for extra, want in (([], 30), (["--timeout", "5"], 5.0)):
        cli.main(["run", str(app), "--quiet", *extra])
        assert seen[-1] == want, seen
    assert "must be a number" not in capsys.readouterr().err


@pytest.mark.e2e
@pytest.mark.faults
def test_the_apps_timeout_ends_the_mission_as_timeout_exit_1():
    """A copy of the farm survey calling ``start_mission(timeout=8)`` at speedup 0.01 (its mission would take
    hours): exit 1, ``mission outcome: timeout``, the recording readable by mcap's reader, within the catalogue's
    bound of the timeout (counted from when the recording file appears, so Ray's start is not counted)."""
    name = "start_mission(timeout=8) in the app at the slowest speedup (0.01)"
    r = run_fault(name)
    assert r["clean"] and r["exit"] == 1, f"{name}: expected {r['expected']}; observed {r['observed']}\n" \
                                          f"{r.get('output', '')}"
