"""Reports are checked when read: pydantic validates the JSON against the report dataclasses.

The dataclasses in `schema` and `sweep` are the typed model (their annotations, with `Count`
and `Fraction` for the constrained numbers, and `STRICT`: no coercion, no unknown field), so
a report whose `successes` is ``"x"`` or an episode whose `success` is ``"maybe"`` is refused
rather than counted. What types cannot say (counts that add up) each report checks after.
Every problem is one `ConfigError` line naming the field.
"""

from __future__ import annotations

import json
from typing import Annotated, Any, TypeVar

from pydantic import ConfigDict, Field, TypeAdapter, ValidationError

from openral_mjx.core.errors import ConfigError

T = TypeVar("T")

# No coercion ("1" is not 1, "true" is not True; an int is still a float) and no unknown key.
STRICT = ConfigDict(strict=True, extra="forbid")
Count = Annotated[int, Field(ge=0)]
Fraction = Annotated[float, Field(ge=0.0, le=1.0)]


def _where(loc: tuple[Any, ...]) -> str:
    """A pydantic location as the report's own path: `episodes[3].success`."""
    out = ""
    for part in loc:
        out += f"[{part}]" if isinstance(part, int) else f".{part}" if out else str(part)
    return out or "(the whole report)"


def _shown(value: Any) -> str:
    text = repr(value)
    return text if len(text) <= 40 else text[:37] + "..."


def describe(error: ValidationError) -> str:
    """The first problem pydantic found, in one line naming the field (and how many more)."""
    first = error.errors(include_url=False)[0]
    where, kind = _where(first["loc"]), first["type"]
    if kind == "missing":
        text = f"field {where} is missing"
    elif kind in ("extra_forbidden", "unexpected_keyword_argument"):
        text = f"unknown field {where}"
    else:
        text = f"field {where}: {first['msg'][0].lower()}{first['msg'][1:]}"
        text += f", got {_shown(first['input'])}"
    more = error.error_count() - 1
    return text + (f" (and {more} more problem{'s' * (more > 1)})" if more else "")


def validate_json(adapter: TypeAdapter[T], text: str | bytes) -> T:
    """`text` validated into `adapter`'s type; any problem is a `ConfigError` (`describe`)."""
    try:
        return adapter.validate_json(text)
    except ValidationError as e:
        raise ConfigError(describe(e)) from None


def validate_data(adapter: TypeAdapter[T], data: Any) -> T:
    """`data` (JSON-like Python values) validated as if read from its JSON text."""
    try:
        text = json.dumps(data, allow_nan=False)
    except (TypeError, ValueError) as e:
        raise ConfigError(f"not JSON data: {e}") from None
    return validate_json(adapter, text)


def check(condition: bool, message: str) -> None:
    """A consistency check of a validated report: `ConfigError(message)` unless it holds."""
    if not condition:
        raise ConfigError(message)
