"""The repository's layout keeps installing: every package folder is listed in pyproject.toml."""

from __future__ import annotations

import tomllib
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
#: Folders of host files that an operator copies from the checkout (``docs/deploy.md``): systemd
#: units and Zenoh router/client templates. Nothing in the package reads them, so none ships.
REPOSITORY_ONLY = {"swarmloc.deploy.systemd", "swarmloc.deploy.zenoh"}


def _setuptools() -> dict:
    return tomllib.loads((ROOT / "pyproject.toml").read_text())["tool"]["setuptools"]


def _package_folders() -> dict[str, Path]:
    """Every folder the distribution must ship, by dotted name: under each mapped folder of
    ``package-dir``, one with an ``__init__.py`` (code) or with any other file (data only, such
    as the scenario TOMLs), caches left out."""
    found = {}
    for name, folder in _setuptools()["package-dir"].items():
        for sub in sorted([ROOT / folder, *(ROOT / folder).rglob("*")]):
            if (sub.is_dir() and "__pycache__" not in sub.parts
                    and any(f.is_file() for f in sub.iterdir())):
                relative = sub.relative_to(ROOT / folder)
                found[".".join([name, *relative.parts])] = sub
    return found


def test_every_package_folder_is_listed():
    # A subpackage or data folder missing from ``packages`` still works in an editable install,
    # but a plain ``pip install .`` leaves it out (a new scenario family's folder, say).
    assert sorted(_setuptools()["packages"]) == sorted(set(_package_folders()) - REPOSITORY_ONLY)


def test_every_package_data_glob_ships_files():
    # A glob that matches nothing would leave a folder's data out of the wheel without a word.
    folders = _package_folders()
    empty = [f"{package}: {pattern}"
             for package, patterns in _setuptools()["package-data"].items()
             for pattern in patterns
             if not [p for p in folders[package].glob(pattern) if p.is_file()]]
    assert empty == []


def test_no_module_passes_1000_lines():
    long = {str(path.relative_to(ROOT)): n
            for folder in _package_folders().values() for path in folder.glob("*.py")
            if (n := len(path.read_text(encoding="utf-8").splitlines())) > 1000}
    assert long == {}
