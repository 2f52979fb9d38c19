"""Outputs never clobber inputs: --record refuses an existing file that is not an AeroDaaS recording
unless --overwrite, and the application and its environment file always; an earlier recording is replaced as before.
The runs use a temporary copy of apps/farm_survey.py and its environment file, never the checkout's own."""
from __future__ import annotations

import shutil

import pytest

from aerodaas.recording.writer import McapRecorder
from aerodaas.recording.record_path import check_record_path, is_aerodaas_recording
from aerodaas.recording.reader import read_messages

from tests.inputs.cli_inprocess import run_cli
from tests.conftest import REPO


def _farm_copy(tmp_path):
    """apps/farm_survey.py and farm_survey.json copied into ``tmp_path``: (app, environment file)."""
    for name in ("farm_survey.py", "farm_survey.json"):
        shutil.copy(REPO / "apps" / name, tmp_path / name)
    return tmp_path / "farm_survey.py", tmp_path / "farm_survey.json"


def _earlier_recording(path) -> None:
    """A recording of ours (the project's writer), holding only an ``/earlier`` message."""
    with McapRecorder(path) as rec:
        rec.write_json("/earlier", 1, {"run": "earlier"}, schema_name="aerodaas.Earlier")


def test_only_our_recordings_are_replaced_without_overwrite(tmp_path):

    notes = tmp_path / "notes.mcap"
    notes.write_text("field notes")
    with pytest.raises(ValueError, match="not an AeroDaaS recording; pass --overwrite"):
        check_record_path(notes)
    assert check_record_path(notes, overwrite=True) == notes
    foreign = tmp_path / "other.mcap"  # an MCAP file another tool wrote: not ours either
    from mcap.writer import Writer

    with open(foreign, "wb") as f:
        w = Writer(f)
        w.start(profile="", library="someone-else")
        w.finish()
    assert not is_aerodaas_recording(foreign)
    with pytest.raises(ValueError, match="not an AeroDaaS recording"):
        check_record_path(foreign)
    assert notes.read_text() == "field notes"  # checking never touches the file
    ours = tmp_path / "earlier.mcap"  # the positive path: a recording of ours is accepted without --overwrite
    _earlier_recording(ours)
    before = ours.read_bytes()
    assert is_aerodaas_recording(ours) and check_record_path(ours) == ours
    assert ours.read_bytes() == before  # ... and left as it is until the run starts


def test_the_app_and_environment_file_are_never_a_recording_target(tmp_path):
    env = tmp_path / "env.json"
    env.write_text("{}")
    with pytest.raises(ValueError, match="is an input of this run"):
        check_record_path(env, overwrite=True, protect=(str(env),))
    app, env_file = _farm_copy(tmp_path)
    for target in (app, env_file):
        before = target.read_bytes()
        # in-process (Ray refused): the record path is checked before anything starts
        p = run_cli("run", str(app), "--record", str(target), "--overwrite", "--quiet", cwd=app.parent)
        assert p.returncode == 2 and "a recording never overwrites the application" in p.stderr, p.stderr
        assert target.read_bytes() == before


@pytest.mark.e2e
@pytest.mark.parametrize("earlier", ["ours", "foreign"])
def test_a_run_replaces_an_earlier_recording_and_with_overwrite_a_foreign_file(tmp_path, earlier, ray_session):
    """The positive path, on a copy of the farm survey: an earlier recording of ours is replaced without
    --overwrite, a file that is not ours with it; the file then holds this run (its mission result, its odometry),
    nothing of what was there."""
    app, _ = _farm_copy(tmp_path)
    rec = tmp_path / "run.mcap"
    if earlier == "ours":
        _earlier_recording(rec)
    else:
        rec.write_text("field notes")
    # in-process on the worker's shared Ray session (no Ray start of its own; the session checked clean after)
    p = run_cli("run", str(app), "--record", str(rec), "--speedup", "20",
                *(["--overwrite"] if earlier == "foreign" else []), "--quiet", cwd=app.parent, shared_ray=True)
    assert p.returncode == 0, p.stdout[-2000:] + p.stderr[-2000:]
    assert is_aerodaas_recording(rec)
    topics = [m[0] for m in read_messages(str(rec))]
    assert "/earlier" not in topics and "/quadrotor_base/odometry" in topics, sorted(set(topics))
    results = [m[3] for m in read_messages(str(rec)) if m[0] == "/mission/result"]
    assert results and results[-1]["outcome"] == "success", results
