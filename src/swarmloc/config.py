"""Configuration as frozen dataclasses, loaded from plain dicts (TOML) with strict checking.

- An unknown key is an error that suggests the closest valid key (difflib), with its dotted path.
- Values are type-checked against the dataclass annotations (int is accepted for float; bool is
  never an int); nested dataclasses and fixed-length tuples are supported.
- Range checks live in each dataclass's ``__post_init__`` (raise ``ValueError``); they are reported
  with the dotted path of the section.
- ``apply_overrides`` applies ``section.key=value`` strings from the command line, the value parsed
  as a TOML value.
"""

from __future__ import annotations

import dataclasses
import difflib
import math
import tomllib
import types
import typing
from pathlib import Path
from typing import Any


class ConfigError(ValueError):
    """A configuration value, key or file is wrong; the message names it."""


def _type_name(tp) -> str:
    return getattr(tp, "__name__", str(tp))


def _convert(value: Any, tp, path: str):
    origin = typing.get_origin(tp)
    if dataclasses.is_dataclass(tp):
        if not isinstance(value, dict):
            raise ConfigError(f"{path}: expected a table, got {type(value).__name__}")
        return from_dict(tp, value, path)
    if origin in (typing.Union, types.UnionType):
        args = typing.get_args(tp)
        if value is None and type(None) in args:
            return None
        errors = []
        for arg in args:
            if arg is type(None):
                continue
            try:
                return _convert(value, arg, path)
            except ConfigError as exc:
                errors.append(str(exc))
        raise ConfigError(errors[0] if errors else f"{path}: invalid value {value!r}")
    if origin is tuple:
        args = typing.get_args(tp)
        if not isinstance(value, (list, tuple)):
            raise ConfigError(f"{path}: expected a list, got {type(value).__name__}")
        if len(args) == 2 and args[1] is Ellipsis:
            return tuple(_convert(v, args[0], f"{path}[{i}]") for i, v in enumerate(value))
        if len(value) != len(args):
            raise ConfigError(f"{path}: expected {len(args)} values, got {len(value)}")
        return tuple(_convert(v, a, f"{path}[{i}]") for i, (v, a) in enumerate(zip(value, args)))
    if tp is float:
        if isinstance(value, bool) or not isinstance(value, (int, float)):
            raise ConfigError(f"{path}: expected a number, got {value!r}")
        value = float(value)
        if not math.isfinite(value):
            raise ConfigError(f"{path}: expected a finite number, got {value!r}")
        return value
    if tp is int:
        if isinstance(value, bool) or not isinstance(value, int):
            raise ConfigError(f"{path}: expected an integer, got {value!r}")
        return value
    if tp is bool:
        if not isinstance(value, bool):
            raise ConfigError(f"{path}: expected true or false, got {value!r}")
        return value
    if tp is str:
        if not isinstance(value, str):
            raise ConfigError(f"{path}: expected a string, got {value!r}")
        return value
    if tp is Any:
        return value
    raise ConfigError(f"{path}: unsupported type {_type_name(tp)}")


def did_you_mean(name: str, known, cutoff: float = 0.5) -> str:
    """``"; did you mean 'x'?"`` with the closest of ``known`` (difflib), or ``""``."""
    close = difflib.get_close_matches(name, list(known), n=1, cutoff=cutoff)
    return f"; did you mean '{close[0]}'?" if close else ""


def from_dict(cls, data: dict, path: str = ""):
    """Build dataclass ``cls`` from ``data``; missing keys take the dataclass defaults."""
    hints = typing.get_type_hints(cls)
    fields = {f.name: f for f in dataclasses.fields(cls) if f.init}
    kwargs = {}
    for key, value in data.items():
        where = f"{path}.{key}" if path else key
        if key not in fields:
            hint = did_you_mean(key, fields)
            valid = ", ".join(sorted(fields))
            raise ConfigError(f"unknown key '{where}'{hint} (valid keys: {valid})")
        kwargs[key] = _convert(value, hints[key], where)
    try:
        return cls(**kwargs)
    except ConfigError:
        raise
    except (ValueError, TypeError) as exc:
        raise ConfigError(f"{path or cls.__name__}: {exc}") from None


def to_dict(obj) -> dict:
    """Plain nested dict (tuples as lists) of a dataclass: TOML- and msgpack-friendly."""

    def plain(value):
        if dataclasses.is_dataclass(value):
            return {f.name: plain(getattr(value, f.name)) for f in dataclasses.fields(value)}
        if isinstance(value, (list, tuple)):
            return [plain(v) for v in value]
        return value

    return plain(obj)


def load_toml(path: str | Path) -> dict:
    """Read a TOML file; a missing or malformed file is a ConfigError naming it."""
    path = Path(path)
    try:
        with path.open("rb") as handle:
            return tomllib.load(handle)
    except FileNotFoundError:
        raise ConfigError(f"{path}: no such file") from None
    except tomllib.TOMLDecodeError as exc:
        raise ConfigError(f"{path}: not valid TOML: {exc}") from None
    except OSError as exc:
        raise ConfigError(f"{path}: cannot read: {exc}") from None


def parse_value(text: str):
    """A command-line value as TOML would read it (``3``, ``0.5``, ``true``, ``[1, 2]``), else a
    plain string."""
    try:
        return tomllib.loads(f"v = {text}")["v"]
    except tomllib.TOMLDecodeError:
        return text


def parse_assignment(item: str, flag: str = "--set") -> tuple[str, Any]:
    """``"key=value"`` -> ``(key, value)``, the value read by :func:`parse_value` (TOML, else a
    plain string): the one reading of every ``KEY=VALUE`` of the command line and the API
    (``--set``, ``--param``, keyword settings). ConfigError naming ``flag`` if it has no key."""
    key, sep, text = str(item).partition("=")
    key = key.strip()
    if not sep or not key:
        raise ConfigError(f"{flag} {item!r}: expected KEY=VALUE, e.g. agent.strategy=NC")
    return key, parse_value(text.strip())


def apply_overrides(data: dict, overrides: list[str]) -> dict:
    """Return a copy of ``data`` with ``dotted.key=value`` overrides applied."""
    import copy

    out = copy.deepcopy(data)
    for item in overrides:
        key, value = parse_assignment(item, "override")
        parts = key.split(".")
        node = out
        for part in parts[:-1]:
            child = node.setdefault(part, {})
            if not isinstance(child, dict):
                raise ConfigError(f"override '{item}': '{part}' is not a table")
            node = child
        node[parts[-1]] = value
    return out
