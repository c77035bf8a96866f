"""Registries: things chosen by name (robot families, strategies, localizers, ...), and plugins.

One mechanism for every kind (STYLE.md: plugins chosen by name from a registry that rejects
duplicates, not from if-chains). A :class:`Registry` maps names to entries; registering a name
twice is an error, and asking for an unknown name suggests the closest registered one. An entry
may be the object itself or a ``"module:attribute"`` path, imported on first use, so that
registering costs no import (a laser agent never imports the vision stack).

Plugins add entries from outside the package: a module that, when imported, calls ``register``
on the registries it extends. swarmloc imports, in every process that chooses by name (``swarmloc
run`` and every piece it starts, ``swarmloc experiment`` and its workers):

- the modules named by installed packages under the entry-point group ``swarmloc.plugins``
  (``[project.entry-points."swarmloc.plugins"] my_rule = "my_package.my_rule"``);
- the modules and files listed in ``SWARMLOC_PLUGINS`` (``os.pathsep``-separated; a path ending in
  ``.py`` is imported as a file), which ``--plugin`` on the command line sets so that child
  processes inherit it.

``docs/extending.md`` walks through a complete plugin (``examples/``).
"""

from __future__ import annotations

import importlib
import importlib.util
import os
import sys
from collections.abc import Callable, Iterator
from importlib.metadata import entry_points
from pathlib import Path
from typing import Any, Generic, TypeVar

from swarmloc.config import did_you_mean

T = TypeVar("T")

#: The environment variable listing plugin modules or files (``os.pathsep``-separated).
PLUGINS_ENV = "SWARMLOC_PLUGINS"
#: The entry-point group of installed plugins.
PLUGINS_GROUP = "swarmloc.plugins"


def resolve(target: Any) -> Any:
    """A ``"module:attribute.path"`` string imported (on each call; Python caches modules), or
    the object itself."""
    if not isinstance(target, str):
        return target
    module, _, path = target.partition(":")
    obj: Any = importlib.import_module(module)
    for part in filter(None, path.split(".")):
        obj = getattr(obj, part)
    return obj


_MISSING = object()


def _caller_frame():
    frame = sys._getframe(1)
    here = __file__
    while frame is not None and frame.f_code.co_filename == here:
        frame = frame.f_back
    return frame


def _caller() -> str:
    """``file:line`` of the code that called into this module (a registration's origin)."""
    frame = _caller_frame()
    return f"{frame.f_code.co_filename}:{frame.f_lineno}" if frame is not None else "?"


#: Every registry made, so that :func:`foreign_entries` can look through them all.
_REGISTRIES: list[Registry] = []


def foreign_entries() -> list[tuple[str, str, str]]:
    """``(kind, name, origin)`` of every entry registered from outside the swarmloc package (a
    plugin, a notebook, a test): code the test suite has not checked, which the experiment engine
    checks for determinism before it starts a grid."""
    return [(r.kind, name, r.origin(name)) for r in _REGISTRIES for name in r.names() if not r.is_builtin(name)]


def plugin_hint() -> str:
    """What an unknown name may mean: a plugin that was not loaded, and which ones were."""
    loaded = ", ".join(sorted(_loaded)) or "none"
    return (f"not registered: if it comes from a plugin, did you forget --plugin FILE_OR_MODULE "
            f"(or {PLUGINS_ENV})? plugins loaded: {loaded}")


class Registry(Generic[T]):
    """Entries of one kind, by name. ``kind`` names them in errors ("strategy", "algorithm");
    ``check(name, entry)``, if given, is run at registration and raises ValueError for an entry
    the engines could not run (a strategy with a gain no kernel has), so that a mistake shows
    where it is made, not in the middle of a run."""

    def __init__(self, kind: str, check: Callable[[str, T], None] | None = None) -> None:
        self.kind = kind
        self._check = check
        self._entries: dict[str, T] = {}
        self._origins: dict[str, str] = {}
        self._builtin: dict[str, bool] = {}
        self._aliases: dict[str, str] = {}
        _REGISTRIES.append(self)

    def register(self, name_or_entry: Any, entry: Any = _MISSING) -> T:
        """Add an entry: ``register(entry)`` takes the name from ``entry.name``,
        ``register(name, entry)`` gives it. ValueError if the name is taken (naming the file
        and line of both registrations) or the registry's check refuses the entry. Returns the
        entry."""
        if entry is _MISSING:
            entry = name_or_entry
            name = getattr(entry, "name", None)
            if not isinstance(name, str):
                raise ValueError(f"{self.kind}: register(entry) needs an entry with a 'name'; "
                                 f"else register(name, entry), got {entry!r}")
        else:
            name = name_or_entry
        if not isinstance(name, str) or not name:
            raise ValueError(f"{self.kind} name: expected a non-empty string, got {name!r}")
        frame = _caller_frame()
        origin = f"{frame.f_code.co_filename}:{frame.f_lineno}" if frame is not None else "?"
        module = frame.f_globals.get("__name__", "") if frame is not None else ""
        if name in self._entries:
            raise ValueError(f"{self.kind} {name!r} is already registered (at {self._origins[name]}); "
                             f"registered again at {origin}")
        if self._check is not None:
            try:
                self._check(name, entry)
            except ValueError as exc:
                raise ValueError(f"{self.kind} {name!r} (registered at {origin}): {exc}") from None
        self._entries[name] = entry
        self._origins[name] = origin
        self._builtin[name] = module == "swarmloc" or module.startswith("swarmloc.")
        return entry

    def origin(self, name: str) -> str:
        """``file:line`` where ``name`` was registered."""
        return self._origins[name]

    def alias(self, alias: str, name: str) -> None:
        """Let ``alias`` name the entry ``name`` too (a former name kept working: the e-puck
        family was "epuck" to experiments and "foraging" to scenarios). ``names()`` lists only
        the entries' own names."""
        if alias in self._entries or alias in self._aliases:
            raise ValueError(f"{self.kind} {alias!r} is already registered")
        self.get(name)
        self._aliases[alias] = name

    def canonical(self, name: str) -> str:
        """The entry's own name for ``name`` (itself, or what it is an alias of); ValueError if
        unknown, as :meth:`get`."""
        name = self._aliases.get(name, name)
        self.get(name)
        return name

    def is_builtin(self, name: str) -> bool:
        """Whether ``name`` was registered by the swarmloc package itself (not a plugin)."""
        return self._builtin[name]

    def unregister(self, name: str) -> None:
        """Remove ``name`` (tests that register a temporary entry)."""
        self._entries.pop(name, None)
        self._origins.pop(name, None)
        self._builtin.pop(name, None)

    def get(self, name: str) -> T:
        """The entry of ``name``; ValueError naming the closest registered names if unknown."""
        try:
            return self._entries[self._aliases.get(name, name)]
        except (KeyError, TypeError):
            hint = did_you_mean(str(name), list(self._entries), 0.4)
            raise ValueError(f"unknown {self.kind} {name!r}{hint} "
                             f"(known: {', '.join(self._entries)}); {plugin_hint()}") from None

    def load(self, name: str) -> Any:
        """The entry of ``name`` with a ``"module:attribute"`` path imported."""
        return resolve(self.get(name))

    def names(self) -> tuple[str, ...]:
        return tuple(self._entries)

    def items(self) -> Iterator[tuple[str, T]]:
        return iter(tuple(self._entries.items()))

    def __getitem__(self, name: str) -> T:
        return self.get(name)

    def __contains__(self, name: object) -> bool:
        return name in self._entries or name in self._aliases

    def __iter__(self) -> Iterator[str]:
        return iter(tuple(self._entries))

    def __len__(self) -> int:
        return len(self._entries)


_loaded: set[str] = set()


def _import_plugin(spec: str) -> None:
    if spec in _loaded:
        return
    if spec.endswith(".py"):
        path = Path(spec).resolve()
        if not path.is_file():
            raise ValueError(f"plugin {spec!r}: no such file")
        name = f"swarmloc_plugin_{path.stem}"
        module_spec = importlib.util.spec_from_file_location(name, path)
        module = importlib.util.module_from_spec(module_spec)
        sys.modules[name] = module
        module_spec.loader.exec_module(module)
    else:
        importlib.import_module(spec)
    _loaded.add(spec)


def load_plugins() -> list[str]:
    """Import every plugin (entry points, then ``SWARMLOC_PLUGINS``), once per process; returns
    what was imported. A plugin that fails to import raises, naming it."""
    specs = [ep.value for ep in entry_points(group=PLUGINS_GROUP)]
    specs += [s for s in os.environ.get(PLUGINS_ENV, "").split(os.pathsep) if s]
    for spec in specs:
        try:
            _import_plugin(spec)
        except ValueError:
            raise
        except Exception as exc:  # a plugin's own error: say which plugin
            raise ValueError(f"plugin {spec!r} failed to import: {type(exc).__name__}: {exc}") from exc
    return specs


def add_plugins(specs: list[str]) -> None:
    """Add ``specs`` (``--plugin`` values) to ``SWARMLOC_PLUGINS`` for this process and its
    children, files as absolute paths (children may start elsewhere), and import them."""
    current = [s for s in os.environ.get(PLUGINS_ENV, "").split(os.pathsep) if s]
    for spec in specs:
        spec = str(Path(spec).resolve()) if spec.endswith(".py") else spec
        if spec not in current:
            current.append(spec)
    os.environ[PLUGINS_ENV] = os.pathsep.join(current)
    load_plugins()
