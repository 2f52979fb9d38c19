"""Every package of the source tree is in ``pyproject.toml``'s ``[tool.setuptools] packages`` (and nothing else is):
the list is explicit, so a folder missing from it is left out of a wheel (``pip install .``, a non-editable
install) while an editable install still finds it. ``aerodaas.commands`` (every ``aerodaas`` sub-command) was
missing until 2026-11-27: a wheel's ``aerodaas`` could not start. No build, no Ray."""
from __future__ import annotations

import tomllib
from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]


def source_packages(root: Path, package_dir: dict[str, str]) -> set[str]:
    """The dotted names of every folder with an ``__init__.py`` under ``root/aerodaas`` and under each
    ``package_dir`` mapping (package name → folder relative to ``root``)."""
    found = {".".join(p.parent.relative_to(root).parts) for p in (root / "aerodaas").rglob("__init__.py")}
    for package, folder in package_dir.items():
        base = root / folder
        found |= {".".join((package, *p.parent.relative_to(base).parts)) for p in base.rglob("__init__.py")}
    return found


def test_the_reader_finds_a_package_missing_from_the_list(tmp_path):
    (tmp_path / "aerodaas" / "commands").mkdir(parents=True)
    (tmp_path / "aerodaas" / "__init__.py").write_text("")
    (tmp_path / "aerodaas" / "commands" / "__init__.py").write_text("")
    (tmp_path / "actors" / "sub").mkdir(parents=True)
    (tmp_path / "actors" / "__init__.py").write_text("")
    (tmp_path / "actors" / "sub" / "__init__.py").write_text("")
    assert source_packages(tmp_path, {"aerodaas.actors": "actors"}) == {
        "aerodaas", "aerodaas.commands", "aerodaas.actors", "aerodaas.actors.sub"}


def test_every_source_package_is_listed_for_the_wheel():
    cfg = tomllib.loads((ROOT / "pyproject.toml").read_text(encoding="utf-8"))["tool"]["setuptools"]
    listed = set(cfg["packages"])
    found = source_packages(ROOT, cfg.get("package-dir", {}))
    assert not found - listed, f"packages missing from pyproject.toml [tool.setuptools] packages: {sorted(found - listed)}"
    assert not listed - found, f"listed in pyproject.toml but not in the tree: {sorted(listed - found)}"
