"""Every repository path a test launches or a docstring names exists (when ``tests/`` moved into area
folders, one stream test still launched ``tests/video_rig.py`` and failed only in CI's slow tier).

Scans the tests, the production packages, ``.ci/`` and the docs (not ``docs/results``, which quote old runs) for
``tests/<path>.<ext>`` literals and ``"tests" / "<a>" / "<b>"`` path joins, and fails naming each file that points
at a path which is not in the work tree.
"""
from __future__ import annotations

import glob
import re
from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]
SCANNED = ("tests", "aerodaas", "actors", "schedulers", "clusters", "apps", "examples", "docs", ".ci")
#: ``tests/<path>`` with a file suffix, or a glob such as ``tests/firmware/test_sitl_*.py``
LITERAL = re.compile(r"\btests/[A-Za-z0-9_*./-]*\.(?:py|lua|json|sh|js|mjs|md|png|mcap|csv|txt|waypoints|plan)\b")
#: ``"tests" / "a"`` or ``"tests" / "a" / "b"`` (pathlib joins)
JOIN = re.compile(r"""["']tests["']\s*/\s*["']([^"']+)["'](?:\s*/\s*["']([^"']+)["'])?""")


def _scanned_files():
    for top in SCANNED:
        for path in (ROOT / top).rglob("*"):
            rel = path.relative_to(ROOT)
            if (path.suffix in {".py", ".md", ".sh", ".toml", ".yaml"} or top == ".ci") and path.is_file() \
                    and "__pycache__" not in rel.parts and rel.parts[:2] != ("docs", "results") \
                    and path != Path(__file__).resolve():  # this file quotes stale paths on purpose
                yield path, rel


def _missing_paths() -> list[str]:
    missing = []
    for path, rel in _scanned_files():
        text = path.read_text(errors="replace")
        for match in LITERAL.finditer(text):
            if not glob.glob(str(ROOT / match.group(0))):
                missing.append(f"{rel}: {match.group(0)}")
        for match in JOIN.finditer(text):
            target = Path("tests", *[part for part in match.groups() if part])
            if not (ROOT / target).exists():
                missing.append(f"{rel}: {target}")
    return missing


def test_every_tests_path_named_in_the_repository_exists():
    assert _missing_paths() == []


def test_the_scan_finds_a_stale_path(tmp_path, monkeypatch):
    """The scan is not vacuous: a file naming the old ``tests/video_rig.py`` is reported."""
    (tmp_path / "tests").mkdir()
    (tmp_path / "tests" / "test_x.py").write_text('RIG = REPO / "tests" / "video_rig.py"\n# tests/video_rig.py\n')
    monkeypatch.setattr(__import__(__name__, fromlist=["ROOT"]), "ROOT", tmp_path)
    assert _missing_paths() == ["tests/test_x.py: tests/video_rig.py", "tests/test_x.py: tests/video_rig.py"]
