"""No silent skips: a test that cannot run because something CI provides is missing (shared data, firmware, a test
rig, node/npm, a test dependency) must fail in CI, not pass as skipped. The one way to say so is
``tests/conftest.py``'s ``skip_or_fail`` (or what calls it: ``needs_data``, ``needs_path``, ``needs_sitl``,
``needs_workload``): it skips on a developer's machine and fails when ``CI`` is set.

Scans the source of every Python file under ``tests/`` (its syntax tree, so code quoted in strings does not count)
for the calls and marks that skip unconditionally: ``pytest.skip(...)``, ``pytest.mark.skip`` / ``skipif``,
``pytest.importorskip(...)``, a bare ``skip(...)`` / ``importorskip(...)`` (imported from pytest), unittest's
``skipTest`` / ``skipIf`` / ``skipUnless``. Each is an error unless it is inside ``skip_or_fail`` in
``tests/conftest.py`` or listed in :data:`ALLOWED` with the reason it can never hide a failure in CI.
"""
from __future__ import annotations

import ast
from pathlib import Path

from tests.architecture import sources

ROOT = Path(__file__).resolve().parents[2]
TESTS = ROOT / "tests"

#: the names whose call (or, for marks, whose use) skips a test
SKIP_NAMES = {"skip", "skipif", "importorskip", "skipTest", "skipIf", "skipUnless"}

#: (file relative to the repository, a piece of the skip's source line) -> why it can never hide a failure in CI.
#: Each entry must match a skip that exists (a stale entry fails too).
ALLOWED = {
    ("tests/mavlink/test_mavlink_links.py", 'not sys.platform.startswith("linux")'):
        "pseudo-terminals as serial ports exist on Linux only; CI runs on Linux, where this never skips",
    ("tests/inputs/test_sim_cli.py", 'sys.platform.startswith("win")'):
        "POSIX signals: skips on Windows only, which CI never is",
    ("tests/cluster/test_cluster_yaml.py", 'shutil.which("bash") is None'):
        "CI runs the suite from a bash script (.ci/run), so bash is always there",
    ("tests/liveview/test_liveview_npm_client.py", 'not hasattr(os, "SCHED_IDLE")'):
        "Linux scheduling policies: present on every Linux Python, and CI runs on Linux",
    ("tests/perception/test_perception_providers.py", "this onnxruntime offers the CUDA provider"):
        "the CPU fallback can only be shown by a CPU build of onnxruntime; on a GPU build the behaviour under test "
        "does not exist (CI installs the CPU build: pyproject onnxruntime)",
    ("tests/perception/test_perception_providers.py", "this machine has a GPU that a local Ray would offer"):
        "the refusal is for a machine without a GPU; on one with a GPU there is nothing to refuse (CI has none)",
    ("tests/bench/test_bench_peers.py", "peers_dora.unavailable_reason() is not None"):
        "dora-rs is an optional peer of `aerodaas bench peers` (extra `bench`), deliberately not installed by CI: "
        "its column is measured on demand",
    ("tests/bench/test_bench_dora_shapes.py", "unavailable_reason() is not None"):
        "dora-rs is an optional peer (extra `bench`), deliberately not installed by CI (see test_bench_peers.py)",
}


def _skip_name(node: ast.AST) -> str | None:
    """The skip name (:data:`SKIP_NAMES`) ``node`` refers to: ``skip``, ``pytest.skip``, ``pytest.mark.skipif``,
    ``self.skipTest``, ``unittest.skipIf``..., else None."""
    if isinstance(node, ast.Name) and node.id in SKIP_NAMES:
        return node.id
    if isinstance(node, ast.Attribute) and node.attr in SKIP_NAMES:
        return node.attr
    return None


def _skips(path: Path) -> list[tuple[int, str, str | None]]:
    """(line, source line, enclosing function name) of every use of a skip name in ``path``: a call, or a mark
    used without a call (``@pytest.mark.skip``)."""
    tree = sources.tree(path)
    lines = sources.source(path).splitlines()
    found: list[tuple[int, str, str | None]] = []

    def visit(node: ast.AST, func: str | None) -> None:
        if isinstance(node, (ast.FunctionDef, ast.AsyncFunctionDef)):
            func = node.name
        name = None
        if isinstance(node, ast.Call):
            name = _skip_name(node.func)
        elif isinstance(node, ast.Attribute) and node.attr in ("skip", "skipif") \
                and isinstance(node.value, ast.Attribute) and node.value.attr == "mark":
            name = node.attr  # pytest.mark.skip as a bare decorator (a call's func is visited below too)
        if name is not None:
            found.append((node.lineno, lines[node.lineno - 1].strip(), func))
        for child in ast.iter_child_nodes(node):
            if isinstance(node, ast.Call) and child is node.func and name is not None:
                continue  # the callee of a call already counted
            visit(child, func)

    visit(tree, None)
    return found


def _all_skips() -> list[tuple[str, int, str, str | None]]:
    out = []
    for path in sorted(TESTS.rglob("*.py")):
        rel = path.relative_to(ROOT).as_posix()
        if "__pycache__" in path.parts:
            continue
        out += [(rel, line, text, func) for line, text, func in _skips(path)]
    return out


def _allowed(rel: str, text: str, func: str | None) -> tuple[str, str] | None:
    if rel == "tests/conftest.py" and func == "skip_or_fail":
        return (rel, "skip_or_fail")
    return next((key for key in ALLOWED if key[0] == rel and key[1] in text), None)


def test_no_test_skips_where_ci_should_fail():
    skips = _all_skips()
    silent = [f"{rel}:{line}: {text}" for rel, line, text, func in skips if _allowed(rel, text, func) is None]
    assert not silent, ("skips that would pass silently in CI; use tests/conftest.py skip_or_fail (needs_path, "
                        "needs_data, needs_sitl) or, for a platform CI never is, add it to ALLOWED with the reason:\n"
                        + "\n".join(silent))


def test_every_allowed_skip_still_exists():
    used = {_allowed(rel, text, func) for rel, _, text, func in _all_skips()}
    assert ("tests/conftest.py", "skip_or_fail") in used, "skip_or_fail no longer skips: this scan looks for nothing"
    stale = [key for key in ALLOWED if key not in used]
    assert not stale, f"ALLOWED entries that match no skip any more (remove them): {stale}"


def test_the_scan_finds_every_form(tmp_path):
    """The scan's own control: each form of skip in a sample file is found, code in a string is not."""
    sample = tmp_path / "sample.py"
    sample.write_text('import pytest\nfrom pytest import skip, importorskip\n'
                      'onnx = pytest.importorskip("onnx")\n'
                      '@pytest.mark.skip\ndef test_a(): pass\n'
                      '@pytest.mark.skipif(True, reason="r")\ndef test_b(): pass\n'
                      'def test_c():\n    pytest.skip("x")\n'
                      'def test_d():\n    skip("y")\n    importorskip("z")\n'
                      'class T:\n    def test_e(self):\n        self.skipTest("w")\n'
                      'CODE = "pytest.skip(1)"\n')
    assert [line for line, _, _ in _skips(sample)] == [3, 4, 6, 9, 11, 12, 15]
