"""The factors `--randomize` and `--sweep` may vary, and the parser of their ranges.

Each factor names the `RandomizationTargets` entry it needs and the values it takes; a range is
written ``NAME=LOW:HIGH`` (``LOWx:HIGHx``: multiples of the model's own values), ``NAME=VALUE``,
or, for a sweep, ``NAME=LOW:HIGH:N``. Apart from `randomization` (which applies them to a
scene) so the CLI and sweeps check ranges without the wrapper.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Sequence

import numpy as np

from openral_mjx.core.errors import ConfigError, unknown
from openral_mjx.raycast.mount import JITTER_POS_M, JITTER_ROT_RAD
from openral_mjx.scenes.base import Scene

MAX_DELAY = 32  # the longest action delay, in control steps (`Randomized` queues this many)
# The most points of one `--sweep`: each point runs every seed again and keeps its outcomes.
MAX_SWEEP_POINTS = 1000


@dataclasses.dataclass(frozen=True)
class FactorKind:
    """A factor the CLI can randomise: what it needs from the scene and which values are valid."""

    help: str
    target: str  # the `RandomizationTargets` entry it needs
    relative: bool  # whether LOWx:HIGHx (a multiple of the model's values) is allowed
    minimum: float = 0.0
    positive: bool = False  # values must be > minimum (not >=)
    maximum: float = np.inf
    integer: bool = False
    unit: str = ""


FACTORS: dict[str, FactorKind] = {
    "friction": FactorKind(
        "sliding friction of the objects and the surfaces they rest on", "contact_geoms", True
    ),
    "mass": FactorKind(
        "mass of the manipulated objects (inertia scaled with it)",
        "object_bodies",
        True,
        positive=True,
        unit="kg",
    ),
    "kp": FactorKind("position gain of the arm's servos", "arm_actuators", True, positive=True),
    "damping": FactorKind("joint damping of the arm", "arm_dofs", True),
    "armature": FactorKind("joint armature of the arm", "arm_dofs", True),
    "delay": FactorKind(
        "action delay in control steps",
        "hold",
        False,
        maximum=MAX_DELAY,
        integer=True,
        unit="steps",
    ),
    "action_noise": FactorKind(
        "std of Gaussian action noise, as a fraction of each action's range", "hold", False
    ),
    "joint_noise": FactorKind(
        "std of Gaussian noise on observed joint positions", "joint_obs", False
    ),
    "object_noise": FactorKind(
        "std of Gaussian noise on observed object poses", "object_obs", False, unit="m"
    ),
    "depth_noise": FactorKind(
        "std of Gaussian noise on depth and laser readings", "range_obs", False, unit="m"
    ),
    "depth_dropout": FactorKind(
        "probability that a depth pixel or laser beam returns nothing",
        "range_obs",
        False,
        maximum=1.0,
    ),
    "camera_pos": FactorKind(
        "distance each observed camera moves from its pose, in a random direction",
        "cameras",
        False,
        maximum=JITTER_POS_M,
        unit="m",
    ),
    "camera_rot": FactorKind(
        "angle each observed camera turns about a random axis",
        "cameras",
        False,
        maximum=JITTER_ROT_RAD,
        unit="rad",
    ),
    "light": FactorKind(
        "diffuse intensity of the scene's lights in rendered RGB images (warp, obs_rgb_cameras)",
        "lights",
        True,
    ),
}


@dataclasses.dataclass(frozen=True)
class FactorRange:
    """One factor's range: values uniform in [low, high] (one value when equal); `relative`:
    multiples of the model's own values."""

    name: str
    low: float
    high: float
    relative: bool = False

    @property
    def fixed(self) -> bool:
        return self.low == self.high

    @property
    def label(self) -> str:
        """The name episode factors and reports use (``NAME_scale`` for a multiple)."""
        return f"{self.name}_scale" if self.relative else self.name

    def text(self) -> str:
        """The range as the CLI writes it."""
        x = "x" if self.relative else ""
        value = f"{self.low:g}{x}" if self.fixed else f"{self.low:g}{x}:{self.high:g}{x}"
        return f"{self.name}={value}"


def _number(name: str, text: str, item: str) -> tuple[float, bool]:
    relative = text.endswith("x")
    try:
        value = float(text[:-1] if relative else text)
    except ValueError:
        raise ConfigError(f"{item!r}: {text!r} is not a number (factor {name})") from None
    if not np.isfinite(value):  # inf would run, then fail writing the report (not JSON)
        raise ConfigError(f"{item!r}: {text!r} is not a finite number (factor {name})")
    return value, relative


def _check_value(kind: FactorKind, name: str, value: float, relative: bool, item: str) -> None:
    if relative:
        if not value > 0:
            raise ConfigError(f"{item!r}: a multiple must be > 0, got {value:g}x")
        return
    low_ok = value > kind.minimum if kind.positive else value >= kind.minimum
    if not (low_ok and value <= kind.maximum):
        side = ">" if kind.positive else ">="
        top = f" and <= {kind.maximum:g}" if np.isfinite(kind.maximum) else ""
        raise ConfigError(f"{item!r}: {name} must be {side} {kind.minimum:g}{top}, got {value:g}")
    if kind.integer and value != int(value):
        raise ConfigError(f"{item!r}: {name} takes whole numbers, got {value:g}")


def parse_factor(item: str, *, grid: bool = False) -> tuple[FactorRange, int]:
    """``NAME=LOW:HIGH`` (``LOWx:HIGHx`` relative) or ``NAME=VALUE`` -> (range, 1); with
    `grid`, ``NAME=LOW:HIGH:N`` -> (range, N points). `ConfigError` naming the bad part."""
    name, sep, value = item.partition("=")
    name = name.strip()
    if not sep or not value:
        form = "NAME=LOW:HIGH:N" if grid else "NAME=LOW:HIGH or NAME=VALUE"
        raise ConfigError(f"{item!r} is not {form}; factors: {', '.join(FACTORS)}")
    if name not in FACTORS:
        raise unknown("randomisation factor", name, FACTORS)
    kind = FACTORS[name]
    parts = value.split(":")
    points = 1
    if grid:
        if len(parts) != 3:
            raise ConfigError(f"--sweep {item!r} is not NAME=LOW:HIGH:N")
        try:
            points = int(parts.pop())
        except ValueError:
            raise ConfigError(f"--sweep {item!r}: N must be a whole number") from None
        if not 2 <= points <= MAX_SWEEP_POINTS:
            raise ConfigError(
                f"--sweep {item!r}: N must lie in [2, {MAX_SWEEP_POINTS}] (each point is a "
                f"run of every seed), got {points}"
            )
    elif len(parts) > 2:
        raise ConfigError(f"{item!r} is not NAME=LOW:HIGH or NAME=VALUE")
    numbers = [_number(name, p.strip(), item) for p in parts]
    if len({r for _, r in numbers}) > 1:
        raise ConfigError(f"{item!r}: write both ends as multiples (0.5x:2x) or neither")
    relative = numbers[0][1]
    if relative and not kind.relative:
        raise ConfigError(f"{item!r}: {name} takes absolute values only ({kind.help})")
    for v, _ in numbers:
        _check_value(kind, name, v, relative, item)
    low, high = numbers[0][0], numbers[-1][0]
    if low > high:
        raise ConfigError(f"{item!r}: low {low:g} is above high {high:g}")
    if grid and low == high:
        raise ConfigError(f"--sweep {item!r}: LOW and HIGH must differ")
    if grid and kind.integer and points > high - low + 1:
        raise ConfigError(f"--sweep {item!r}: {name} has only {int(high - low + 1)} values there")
    return FactorRange(name, low, high, relative), points


def parse_factors(items: Sequence[FactorRange | str]) -> tuple[FactorRange, ...]:
    """Every ``--randomize`` item (``NAME=LOW:HIGH`` or a parsed range), each factor at most
    once."""
    ranges = tuple(i if isinstance(i, FactorRange) else parse_factor(i)[0] for i in items)
    names = [r.name for r in ranges]
    twice = sorted({n for n in names if names.count(n) > 1})
    if twice:
        raise ConfigError(f"--randomize names {', '.join(twice)} more than once")
    return ranges


def grid_values(factor: FactorRange, points: int) -> list[float]:
    """A sweep's grid: `points` evenly spaced values from low to high (whole numbers for an
    integer factor)."""
    values = np.linspace(factor.low, factor.high, points)
    if FACTORS[factor.name].integer:
        values = np.round(values)
    return [float(v) for v in values]


def available_factors(scene: Scene) -> list[str]:
    """The factors `scene` can randomise."""
    targets = scene.randomization_targets()
    if targets is None:
        return []
    return [n for n, k in FACTORS.items() if getattr(targets, k.target)]
