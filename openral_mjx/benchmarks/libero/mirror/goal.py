"""LIBERO's success predicates in JAX, from the goal atoms the export reads off LIBERO.

A task succeeds when every atom of its BDDL goal holds (LIBERO's `_check_success`), each
evaluated as LIBERO's object states do (`libero.libero.envs.object_states`), on the poses
and contacts of the data the last physics step leaves (what `check_success` reads after
robosuite's `step`):

- ``on_object`` (``On(a, b)``, b an object): b's body no higher than a's, the two objects
  touching, and their body origins within 3 cm horizontally;
- ``on_site`` (``On(a, region)`` where the region has an ``under`` test): a's origin in the
  region's frame above its top face by 0 to 10 cm (5 mm below it allowed) and inside its
  footprint, and a touching the region's object, if it has one;
- ``in_site`` (``In(a, region)``): a's origin inside the region's box, its half sizes
  rotated into the world (``|R size|``), its bottom lowered by 1 cm;
- ``joints`` (``Open``/``Close``/``TurnOn``/``TurnOff``): one-sided thresholds on the
  joints' positions, any joint for open and on, every joint for close and off;
- ``true``: a region with no ``under`` test, which LIBERO counts as on.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Sequence
from typing import Any

import jax
import jax.numpy as jnp
import mujoco
import numpy as np

from openral_mjx.core import fixed_order as fo
from openral_mjx.core.rotations import quat_to_mat
from openral_mjx.physics import Quantities


@dataclasses.dataclass(frozen=True)
class Goal:
    """What a task's goal reads (bodies, contact pairs) and how to evaluate it."""

    atoms: tuple[dict[str, Any], ...]
    bodies: tuple[str, ...]
    contacts: tuple[tuple[tuple[str, ...], tuple[str, ...]], ...]
    qpos_adr: dict[str, int]

    @classmethod
    def build(cls, atoms: Sequence[dict[str, Any]], model: mujoco.MjModel) -> Goal:
        bodies: list[str] = []
        contacts: list[tuple[tuple[str, ...], tuple[str, ...]]] = []
        for atom in atoms:
            for key in ("obj", "target", "site_body"):
                if key in atom and atom[key] not in bodies:
                    bodies.append(atom[key])
            if atom.get("contact"):
                pair = (tuple(atom["contact"][0]), tuple(atom["contact"][1]))
                if pair not in contacts:
                    contacts.append(pair)
        joints = [j for atom in atoms for j in atom.get("joints", ())]
        adr = {j: int(model.joint(j).qposadr[0]) for j in joints}
        return cls(tuple(atoms), tuple(bodies), tuple(contacts), adr)

    def __call__(self, q: Quantities, body_offset: int = 0) -> jax.Array:
        """Whether every atom holds; the goal's bodies are `q`'s bodies from `body_offset`
        on, in `bodies` order, and its contact pairs are `q.contacts`, in `contacts` order."""
        held = [self._atom(a, q, body_offset) for a in self.atoms]
        return jnp.all(jnp.stack(held)) if held else jnp.zeros((), bool)

    def _pos(self, q: Quantities, offset: int, body: str) -> jax.Array:
        return q.body_pos[offset + self.bodies.index(body)]

    def _touching(self, q: Quantities, atom: dict[str, Any]) -> jax.Array:
        pair = (tuple(atom["contact"][0]), tuple(atom["contact"][1]))
        return q.contacts[self.contacts.index(pair)]

    def _site(self, q: Quantities, offset: int, atom: dict[str, Any]) -> tuple:
        i = offset + self.bodies.index(atom["site_body"])
        rot = quat_to_mat(q.body_quat[i])
        pos = q.body_pos[i] + fo.mv(rot, jnp.asarray(atom["site_pos"], jnp.float32))
        mat = fo.mm(rot, quat_to_mat(jnp.asarray(atom["site_quat"], jnp.float32)))
        return pos, mat, jnp.asarray(atom["size"], jnp.float32)

    def _atom(self, atom: dict[str, Any], q: Quantities, offset: int) -> jax.Array:
        kind = atom["kind"]
        if kind == "true":
            return jnp.ones((), bool)
        if kind == "on_object":
            a, b = self._pos(q, offset, atom["obj"]), self._pos(q, offset, atom["target"])
            near = fo.norm(b[:2] - a[:2]) < 0.03
            return (b[2] <= a[2]) & self._touching(q, atom) & near
        if kind == "on_site":
            pos, mat, size = self._site(q, offset, atom)
            delta = fo.mv(mat, self._pos(q, offset, atom["obj"]) - pos)
            above = (size[2] - 0.005 < delta[2]) & (delta[2] < size[2] + 0.10)
            inside = jnp.all(jnp.abs(delta[:2]) < size[:2])
            touching = self._touching(q, atom) if atom["contact"] else jnp.ones((), bool)
            return above & inside & touching
        if kind == "in_site":
            pos, mat, size = self._site(q, offset, atom)
            half = jnp.abs(fo.mv(mat, size))
            low = (pos - half).at[2].add(-0.01)
            obj = self._pos(q, offset, atom["obj"])
            return jnp.all(obj > low) & jnp.all(obj < pos + half)
        if kind == "joints":
            values = jnp.stack([q.qpos[self.qpos_adr[j]] for j in atom["joints"]])
            t = jnp.asarray(atom["threshold"], jnp.float32)
            above = np.asarray(atom["above"], bool)
            inclusive = np.asarray(atom["inclusive"], bool)
            hold = jnp.where(
                above,
                jnp.where(inclusive, values >= t, values > t),
                jnp.where(inclusive, values <= t, values < t),
            )
            return jnp.all(hold) if atom["all"] else jnp.any(hold)
        raise ValueError(f"unknown LIBERO goal atom {kind!r}")
