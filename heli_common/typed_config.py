"""Typed settings trees: frozen dataclasses filled from TOML tables.

One generic, pure loader shared by ``sim_vehicle``, ``companion`` and ``heli_model`` (neither of
the first two imports the other). Every default lives in the dataclass; a TOML
table only overrides. A wrong key, type or value raises the caller's error class with the dotted
key at fault, e.g. ``planning.gart.step_m: expected a number, got 'abc'``.
"""

from __future__ import annotations

import dataclasses
import math
import tomllib
import types
import typing
from pathlib import Path
from typing import TYPE_CHECKING, Any, TypeVar

if TYPE_CHECKING:
    from _typeshed import DataclassInstance

T = TypeVar("T", bound="DataclassInstance")


class SettingsError(ValueError):
    """A settings key or value is wrong; the message starts with the dotted key."""


def _check_scalar(kind: Any, value: Any, key: str, error: type[Exception]) -> Any:
    if kind is bool:
        if not isinstance(value, bool):
            raise error(f"{key}: expected true or false, got {value!r}")
        return value
    if kind is float:
        if isinstance(value, bool) or not isinstance(value, (int, float)):
            raise error(f"{key}: expected a number, got {value!r}")
        if not math.isfinite(float(value)):
            raise error(f"{key}: expected a finite number, got {value!r}")
        return float(value)
    if kind is int:
        if isinstance(value, bool) or not isinstance(value, int):
            raise error(f"{key}: expected an integer, got {value!r}")
        return value
    if kind is str:
        if not isinstance(value, str):
            raise error(f"{key}: expected a string, got {value!r}")
        return value
    return value


def _convert(kind: Any, value: Any, key: str, error: type[Exception]) -> Any:
    origin = typing.get_origin(kind)
    if isinstance(kind, type) and dataclasses.is_dataclass(kind):  # a hint is a class, never an instance
        return from_dict(kind, value, key, error)
    if origin in (typing.Union, types.UnionType):
        members = [a for a in typing.get_args(kind) if a is not type(None)]
        if value is None:
            return None
        return _convert(members[0], value, key, error)
    if origin is typing.Literal:
        allowed = typing.get_args(kind)
        if value not in allowed:
            raise error(f"{key}: expected one of {', '.join(map(repr, allowed))}, got {value!r}")
        return value
    if origin is tuple:
        args = typing.get_args(kind)
        if not isinstance(value, (list, tuple)):
            raise error(f"{key}: expected a list, got {value!r}")
        if len(args) == 2 and args[1] is Ellipsis:
            return tuple(_convert(args[0], v, f"{key}[{i}]", error) for i, v in enumerate(value))
        if len(args) != len(value):
            raise error(f"{key}: expected {len(args)} values, got {len(value)}")
        return tuple(_convert(a, v, f"{key}[{i}]", error) for i, (a, v) in enumerate(zip(args, value)))
    return _check_scalar(kind, value, key, error)


def from_dict(cls: type[T], data: Any, prefix: str = "", error: type[Exception] = SettingsError) -> T:
    """Build the frozen dataclass ``cls`` from a (TOML) mapping, defaults for missing keys.

    Parameters
    ----------
    cls : dataclass type
        The settings class; nested dataclass fields become nested tables.
    data : mapping
        Values that override the defaults.
    prefix : str
        Dotted key of this table, used in error messages.
    error : exception class
        Raised, with the dotted key, for unknown keys and wrong types or values. A
        ``__post_init__`` that raises ``ValueError`` is re-raised as ``error`` with the prefix.
    """
    if data is None:
        data = {}
    if not isinstance(data, dict):
        raise error(f"{prefix or 'settings'}: expected a table, got {data!r}")
    hints = typing.get_type_hints(cls)
    fields = {f.name: f for f in dataclasses.fields(cls) if f.init}
    unknown = sorted(set(data) - set(fields))
    if unknown:
        where = f"{prefix}." if prefix else ""
        raise error(f"{where}{unknown[0]}: unknown setting (known: {', '.join(sorted(fields))})")
    kwargs = {}
    for name, value in data.items():
        key = f"{prefix}.{name}" if prefix else name
        kwargs[name] = _convert(hints[name], value, key, error)
    try:
        return cls(**kwargs)
    except error:
        raise
    except (ValueError, TypeError) as exc:
        raise error(f"{prefix or cls.__name__}: {exc}") from None


def require_numbers(
    error: type[Exception],
    owner: str,
    obj: Any = None,
    *,
    positive: tuple = (),
    non_negative: tuple = (),
    **values: float,
) -> None:
    """Check settings values: finite numbers, > 0 (``positive``) or >= 0 (``non_negative``).

    Values are the attributes of ``obj`` named in ``positive`` / ``non_negative``, or the keyword
    arguments (checked as > 0). The first bad one raises ``error`` naming it, e.g.
    ``link.time_scale: must be a finite number > 0, got -1``.
    """
    checks = (
        [(n, getattr(obj, n), True) for n in positive]
        + [(n, getattr(obj, n), False) for n in non_negative]
        + [(n, v, True) for n, v in values.items()]
    )
    for name, value, strict in checks:
        ok = (
            not isinstance(value, bool)
            and isinstance(value, (int, float))
            and math.isfinite(value)
            and (value > 0 if strict else value >= 0)
        )
        if not ok:
            raise error(f"{owner}.{name}: must be a finite number {'>' if strict else '>='} 0, got {value!r}")


def require_int(error: type[Exception], owner: str, name: str, value: Any, lo: int, hi: int) -> None:
    """Check that ``value`` is an integer in ``lo..hi``; raises ``error`` naming ``owner.name``."""
    if isinstance(value, bool) or not isinstance(value, int) or not lo <= value <= hi:
        raise error(f"{owner}.{name}: an integer in {lo}..{hi}, got {value!r}")


def load_toml(path: str | Path, error: type[Exception] = SettingsError) -> dict:
    """Read a TOML file; syntax errors are raised as ``error`` naming the file and line."""
    try:
        with open(path, "rb") as fh:
            return tomllib.load(fh)
    except FileNotFoundError:
        raise error(f"{path}: no such file") from None
    except tomllib.TOMLDecodeError as exc:
        raise error(f"{path}: {exc}") from None
