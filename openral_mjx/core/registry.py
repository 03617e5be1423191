"""Name -> factory registries (`SCENES`, `POLICIES`, `ROBOTS` live in their own packages)."""

from __future__ import annotations

import importlib
from collections.abc import Callable, Iterator
from typing import Generic, TypeVar

from openral_mjx.core.errors import unknown

T = TypeVar("T")


class Registry(Generic[T]):
    """A tiny ordered map from ID strings to factories, with typed lookup errors."""

    def __init__(self, kind: str) -> None:
        self.kind = kind
        self._items: dict[str, T] = {}
        self._lazy: dict[str, str] = {}  # name -> "module:attribute", imported on first `get`

    def register(self, name: str) -> Callable[[T], T]:
        """Decorator registering `obj` under `name`; a duplicate name is a programming error."""

        def deco(obj: T) -> T:
            self._check_new(name)
            self._items[name] = obj
            return obj

        return deco

    def register_lazy(self, name: str, ref: str) -> None:
        """Register `name` as `ref`, ``"module:attribute"``, imported on its first `get`: how
        a registry lists what imports the registry's own package back (a benchmark folder's
        scenes and expert, `openral_mjx.benchmarks`), so either side may be imported first."""
        self._check_new(name)
        if ref.count(":") != 1:
            raise ValueError(f"{self.kind} {name!r}: {ref!r} is not 'module:attribute'")
        self._lazy[name] = ref

    def _check_new(self, name: str) -> None:
        if name in self._items or name in self._lazy:
            raise KeyError(f"{self.kind} {name!r} registered twice")

    def get(self, name: str) -> T:
        """Return the factory for `name`, or raise `ConfigError` listing the known names."""
        if name in self._lazy:
            module, attribute = self._lazy[name].split(":")
            self._items[name] = getattr(importlib.import_module(module), attribute)
            del self._lazy[name]
        try:
            return self._items[name]
        except KeyError:
            raise unknown(self.kind, name, self.names()) from None

    def names(self) -> list[str]:
        return sorted([*self._items, *self._lazy])

    def __contains__(self, name: object) -> bool:
        return name in self._items or name in self._lazy

    def __iter__(self) -> Iterator[str]:
        return iter(self.names())
