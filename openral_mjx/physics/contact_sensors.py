"""`QuantitySpec.contacts` as MuJoCo ``contact`` sensors, which every backend computes.

A pair of geom sets touches where any geom of the first is in MuJoCo's contact list with any
of the second (robosuite's `check_contact`). Each backend adds ``contact`` sensors that count
such contacts ("found" data, no reduction) to its own copy of the model and reads whether any
counted one. MuJoCo C matches a set that is exactly one body subtree's colliding geoms with a
single subtree sensor; MJX's JAX implementation matches geoms only, so there every geom pair
is a sensor of its own.
"""

from __future__ import annotations

from typing import Any

import mujoco
import numpy as np

Pairs = tuple[tuple[tuple[str, ...], tuple[str, ...]], ...]


def in_subtree(model: mujoco.MjModel, body: int, root: int) -> bool:
    """Whether `body` lies in the subtree rooted at `root`."""
    while body > 0:
        if body == root:
            return True
        body = int(model.body_parentid[body])
    return root == 0


def contact_side(
    model: mujoco.MjModel, geoms: tuple[str, ...], subtrees: bool = True
) -> list[tuple[Any, str]]:
    """How ``contact`` sensors name one side of a pair: one body subtree where `subtrees`
    allows it and the set is exactly that subtree's colliding geoms, else each geom by name."""
    ids = {model.geom(g).id for g in geoms}
    if subtrees:
        collide = (model.geom_contype != 0) | (model.geom_conaffinity != 0)
        for body in sorted({int(model.geom_bodyid[g]) for g in ids}):
            subtree = {
                g
                for g in range(model.ngeom)
                if collide[g] and in_subtree(model, int(model.geom_bodyid[g]), body)
            }
            if subtree == ids:
                return [(mujoco.mjtObj.mjOBJ_XBODY, model.body(body).name)]
    return [(mujoco.mjtObj.mjOBJ_GEOM, model.geom(g).name) for g in sorted(ids)]


def add_contact_sensors(
    spec: mujoco.MjSpec, model: mujoco.MjModel, pairs: Pairs, subtrees: bool = True
) -> list[tuple[int, int]]:
    """Append to `spec` the sensors of each pair (`model`: the spec compiled, for names);
    returns each pair's range of sensor indices (first, end)."""
    ranges = []
    for first, second in pairs:
        start = len(spec.sensors)
        for a in contact_side(model, first, subtrees):
            for b in contact_side(model, second, subtrees):
                spec.add_sensor(
                    type=mujoco.mjtSensor.mjSENS_CONTACT,
                    objtype=a[0],
                    objname=a[1],
                    reftype=b[0],
                    refname=b[1],
                    intprm=[1, 0, 1],  # data "found" (a count), no reduction, one slot
                    dim=1,
                )
        ranges.append((start, len(spec.sensors)))
    return ranges


def sensordata_addresses(model: mujoco.MjModel, ranges: list[tuple[int, int]]) -> list[np.ndarray]:
    """Each pair's ``sensordata`` addresses in `model` (compiled with the sensors)."""
    return [np.asarray(model.sensor_adr[a:b], np.int32) for a, b in ranges]
