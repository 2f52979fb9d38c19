"""Outputs never clobber inputs (issue 40.3): --record refuses an existing file that is not an AeroDaaS recording
unless --overwrite, and the application and its environment file always; an earlier recording is replaced as before."""
from __future__ import annotations

import subprocess
import sys

import pytest

from aerodaas.recording.writer import check_record_path, is_aerodaas_recording

from .conftest import REPO


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


def test_the_app_and_environment_file_are_never_a_recording_target(tmp_path):
    env = tmp_path / "env.json"
    env.write_text("{}")
    with pytest.raises(ValueError, match="is an input of this run"):
        check_record_path(env, overwrite=True, protect=(str(env),))
    app = REPO / "apps" / "farm_survey.py"
    before = app.read_bytes()
    p = subprocess.run([sys.executable, "-m", "aerodaas.cli", "run", str(app), "--record", str(app), "--overwrite",
                        "--quiet"], capture_output=True, text=True, timeout=120)
    assert p.returncode == 2 and "a recording never overwrites the application" in p.stderr, p.stderr
    assert app.read_bytes() == before
