"""The repository's layout keeps installing: every package folder is listed in pyproject.toml."""

from __future__ import annotations

import tomllib
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]


def _setuptools() -> dict:
    return tomllib.loads((ROOT / "pyproject.toml").read_text())["tool"]["setuptools"]


def _package_folders() -> dict[str, Path]:
    """Every package of the distribution (a folder with ``__init__.py`` under a mapped folder)."""
    found = {}
    for name, folder in _setuptools()["package-dir"].items():
        for init in sorted((ROOT / folder).rglob("__init__.py")):
            relative = init.parent.relative_to(ROOT / folder)
            found[".".join([name, *relative.parts])] = init.parent
    return found


def _folder(package: str) -> Path:
    """The folder a dotted package name maps to through ``package-dir``."""
    mapped = max((name for name in _setuptools()["package-dir"]
                  if package == name or package.startswith(name + ".")), key=len)
    rest = package[len(mapped):].lstrip(".")
    return ROOT / _setuptools()["package-dir"][mapped] / Path(*rest.split(".") if rest else ())


def test_every_package_folder_is_listed():
    # A subpackage missing from ``packages`` still imports in an editable install, but a plain
    # ``pip install .`` leaves it out. The data-only folders (no ``__init__.py``) are listed too,
    # each with its own ``package-data`` globs, so setuptools ships them by name.
    data = set(_setuptools()["package-data"]) - set(_package_folders())
    assert sorted(_setuptools()["packages"]) == sorted({*_package_folders(), *data})


def test_every_package_data_glob_ships_files():
    # A glob that matches nothing would leave a folder's data out of the wheel without a word.
    empty = [f"{package}: {pattern}"
             for package, patterns in _setuptools()["package-data"].items()
             for pattern in patterns
             if not [p for p in _folder(package).glob(pattern) if p.is_file()]]
    assert empty == []


def test_no_module_passes_1000_lines():
    long = {str(path.relative_to(ROOT)): n
            for folder in _package_folders().values() for path in folder.glob("*.py")
            if (n := len(path.read_text(encoding="utf-8").splitlines())) > 1000}
    assert long == {}
