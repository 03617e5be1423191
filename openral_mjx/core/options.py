"""Typed scene options: frozen dataclasses filled from YAML files and `key=value` overrides.

Unknown keys are rejected loudly, values are coerced to the field's declared type (lists to
tuples, ints to floats), and each options class validates its own ranges in `__post_init__`.
"""

from __future__ import annotations

import dataclasses
import math
import re
import types
import typing
from collections.abc import Iterable, Mapping
from pathlib import Path
from typing import Any, TypeVar

import yaml

from openral_mjx.core.errors import ConfigError, unknown

T = TypeVar("T")


class NumberLoader(yaml.SafeLoader):
    """PyYAML's safe loader, reading every float notation Python's `float()` takes as a number.

    PyYAML follows YAML 1.1, whose floats need a dot: `5e-2` and `1e6` would stay strings (and
    then be refused as "expected a number"). YAML 1.2, like Python, reads them as floats."""


NumberLoader.add_implicit_resolver(
    "tag:yaml.org,2002:float",
    re.compile(r"^[-+]?(?:[0-9][0-9_]*\.?[0-9_]*|\.[0-9][0-9_]*)[eE][-+]?[0-9]+$"),
    list("-+.0123456789"),
)


def yaml_value(text: str) -> Any:
    """One YAML document (a file's text or an override's value) with `NumberLoader`."""
    return yaml.load(text, Loader=NumberLoader)  # a SafeLoader: builds no Python objects


def _coerce(name: str, value: Any, tp: Any) -> Any:
    origin = typing.get_origin(tp)
    args = typing.get_args(tp)
    if origin in (typing.Union, types.UnionType):
        if value is None and type(None) in args:
            return None
        inner = [a for a in args if a is not type(None)]
        try:
            return _coerce(name, value, inner[0])
        except ConfigError as e:
            if type(None) not in args:
                raise
            raise ConfigError(f"{e} or null") from None  # it may be left unset too
    if origin is tuple:
        if not isinstance(value, list | tuple):
            raise ConfigError(f"option {name}={value!r}: expected a list of {len(args)} numbers")
        if len(args) == 2 and args[1] is Ellipsis:
            return tuple(_coerce(name, v, args[0]) for v in value)
        if len(value) != len(args):
            raise ConfigError(f"option {name}={value!r}: expected {len(args)} values")
        return tuple(_coerce(name, v, a) for v, a in zip(value, args, strict=True))
    if tp is float:
        if isinstance(value, bool) or not isinstance(value, int | float):
            raise ConfigError(f"option {name}={value!r}: expected a number")
        if not math.isfinite(value):
            raise ConfigError(f"option {name}={value!r}: expected a finite number")
        return float(value)
    if tp is int:
        if isinstance(value, bool) or not isinstance(value, int):
            raise ConfigError(f"option {name}={value!r}: expected an integer")
        return value
    if tp is bool:
        if not isinstance(value, bool):
            raise ConfigError(f"option {name}={value!r}: expected true or false")
        return value
    if tp is str:
        if not isinstance(value, str):
            raise ConfigError(f"option {name}={value!r}: expected a string")
        return value
    return value


def from_mapping(cls: type[T], mapping: Mapping[str, Any], base: T | None = None) -> T:
    """Build `cls` from `mapping` (on top of `base` or the defaults), rejecting unknown keys."""
    fields = {f.name: f for f in dataclasses.fields(cls)}  # type: ignore[arg-type]
    hints = typing.get_type_hints(cls)
    values: dict[str, Any] = {}
    for key, value in mapping.items():
        if key not in fields:
            raise unknown(f"option for {cls.__name__}", key, sorted(fields))
        values[key] = _coerce(key, value, hints[key])
    start = base if base is not None else cls()
    return dataclasses.replace(start, **values)  # type: ignore[type-var]


def load_yaml(path: Path) -> dict[str, Any]:
    """Read a YAML mapping; a missing file or a non-mapping is a `ConfigError`."""
    if path.is_dir():
        raise ConfigError(f"config file {str(path)!r} is a directory, not a YAML file")
    if not path.is_file():
        raise ConfigError(f"config file {str(path)!r} does not exist")
    try:
        data = yaml_value(path.read_text()) or {}
    except yaml.YAMLError as e:
        raise ConfigError(f"config file {str(path)!r} is not valid YAML: {_one_line(e)}") from None
    if not isinstance(data, dict):
        raise ConfigError(f"config file {str(path)!r} must hold a mapping of option: value")
    return data


def _one_line(error: yaml.YAMLError) -> str:
    """A YAML error in one line: what is wrong and where (PyYAML's spans several, with the
    offending line quoted and a caret under it)."""
    problem = getattr(error, "problem", None)
    mark = getattr(error, "problem_mark", None)
    if problem is None:
        return " ".join(str(error).split())
    context = getattr(error, "context", None)
    where = f" at line {mark.line + 1}, column {mark.column + 1}" if mark is not None else ""
    return f"{f'{context}: ' if context else ''}{problem}{where}"


def parse_overrides(items: Iterable[str]) -> dict[str, Any]:
    """Parse `key=value` strings; values are YAML scalars or lists (`x=0.1`, `r=[0.1, 0.2]`)."""
    out: dict[str, Any] = {}
    for item in items:
        key, sep, raw = item.partition("=")
        if not sep or not key.strip():
            raise ConfigError(f"option override {item!r} is not of the form key=value")
        try:
            out[key.strip()] = yaml_value(raw)
        except yaml.YAMLError:
            raise ConfigError(f"option override {item!r}: value is not valid YAML") from None
    return out


def to_dict(options: Any) -> dict[str, Any]:
    """Options as a JSON-friendly dict (tuples become lists)."""
    return {
        k: list(v) if isinstance(v, tuple) else v for k, v in dataclasses.asdict(options).items()
    }


def check(condition: bool, message: str) -> None:
    """Raise `ConfigError(message)` unless `condition` holds (for `__post_init__` checks)."""
    if not condition:
        raise ConfigError(message)
