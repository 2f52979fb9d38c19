"""No tracker issue numbers in code, docs or test names: a sentence says what a thing is and why, and history goes
to ``CHANGELOG.md``. Every tracked text file is read (``git ls-files``) but for the measured data under
``docs/bench/`` and ``docs/results/`` (JSON reports, whose file names and fields keep the names of the runs that made
them) and the changelog itself; a line naming an issue by number (in words, or as ``#N`` after the word) or a test
function named after one fails. A citation of another project's tracker is written as its repository path
(``owner/repo issues/96``), which names the source without reading as one of ours."""
from __future__ import annotations

import re
import subprocess
from pathlib import Path

from tests.conftest import skip_or_fail

ROOT = Path(__file__).resolve().parents[2]
WORD = "iss" + "ue"  # spelled in two so that this file's own patterns are no hit
#: an issue named by number: "<word> 46", "<word>s 38 and 40", "<word> #46", "<Word> 49 item 6"
NUMBERED = re.compile(rf"(?<![\w/#-]){WORD}s? #?\d+", re.IGNORECASE)
#: a test function named after an issue: "def test_<word>46_...", "def test_the_<word>_40_cases"
TEST_NAME = re.compile(rf"def test\w*{WORD}", re.IGNORECASE)
#: measured data kept as it was written, and the history itself
EXCLUDED = (re.compile(r"docs/bench/.*\.json$"), re.compile(r"docs/results/"), re.compile(r"CHANGELOG\.md$"))
BINARY = {".png", ".jpg", ".jpeg", ".gif", ".onnx", ".gz", ".mcap", ".tlog", ".ulg", ".bin", ".pdf", ".ico", ".zip"}


def hits_in(text: str) -> list[tuple[int, str]]:
    """(line number, line) of each line that names an issue by number or a test named after one."""
    return [(i, line.strip()) for i, line in enumerate(text.splitlines(), 1)
            if NUMBERED.search(line) or TEST_NAME.search(line)]


def _tracked() -> list[str]:
    try:
        out = subprocess.run(["git", "ls-files", "-z"], cwd=ROOT, capture_output=True, check=True, timeout=60).stdout
    except (OSError, subprocess.CalledProcessError) as e:
        skip_or_fail(f"needs git and a git checkout of the repository ({e})")
    return [p for p in out.decode().split("\0") if p]


def test_no_line_names_a_tracker_number():
    bad = []
    for rel in _tracked():
        path = ROOT / rel
        if any(rx.search(rel) for rx in EXCLUDED) or path.suffix.lower() in BINARY or not path.is_file():
            continue
        data = path.read_bytes()
        if b"\0" in data[:4096]:
            continue
        bad += [f"{rel}:{n}: {line[:160]}" for n, line in hits_in(data.decode("utf-8", errors="replace"))]
    assert not bad, (f"{len(bad)} line(s) name a tracker issue: say what the thing is and why instead, or delete "
                     "pure history (it belongs in CHANGELOG.md):\n" + "\n".join(bad))


def test_the_patterns_catch_each_form_and_spare_the_rest():
    w, W = WORD, WORD.capitalize()
    caught = [f"the oblique number ({w} 46)", f'"""{W} 49 item 6: the hop', f"see {w}s 38 and 40",
              f"fixed in {w} #96", f"def test_{w}46_oblique():", f"def test_the_{w}s_waypoint(hz):"]
    spared = ["damiafuentes/DJITelloPy issues/96 on GitHub", "the tracker's own ids #1 and #11",
              f"docs/results/sweep_{w}41_onoff.json", "PR #533", f"what the {w} is", f"{w}d 5 commands"]
    assert [bool(hits_in(s)) for s in caught] == [True] * len(caught)
    assert [bool(hits_in(s)) for s in spared] == [False] * len(spared)
