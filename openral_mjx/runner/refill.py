"""Continuous batching: a slot whose episode has ended takes the next seed.

`n_slots` envs run in one `lax.while_loop` over control steps. When a slot's episode ends
(success, divergence or its step limit), its outcome goes to its seed's row at once, and every
`refill_every` control steps the ended slots reset to the next unassigned seeds (one batched
reset under `lax.cond`, skipped when no slot has ended). Slots with nothing left to do idle
until the batch drains. Seed s's episode starts from `reset_with_seed(s, reset key of s)` with
a fresh policy state and its own key stream from step 0: nothing carries over from the slot's
earlier episode, so seed s gives the episode the fixed-chunk runner gives it (bit for bit
where a backend's episodes do not depend on the batch: `c`, and warp on a CPU). A reset slot
takes the fresh state's slice of every per-env leaf; leaves the whole batch shares (warp's
contact buffer) are rebuilt by the next step and stay as they are.

Where a seed's episode does not depend on the batch layout at all (`layout_invariant`: `c`),
a refill resets only the slots that take a seed, a slice of `RESET_SLICE` at a time, not the
whole batch: on `c` a reset is a MuJoCo C forward pass per env, and a control step ends a
handful of episodes out of a thousand slots.

The loop runs in segments of at most a given number of control steps, so the host can read
between segments which seeds have finished. Statistics and stopping rules must use the
finished *prefix* of the seeds only (`finished_prefix`): successes end episodes early, so the
set of whatever has finished is biased towards success.
"""

from __future__ import annotations

import time
from collections.abc import Callable, Sequence
from typing import Any

import jax
import jax.numpy as jnp
import numpy as np
from flax import struct

from openral_mjx.core.errors import ConfigError, unknown
from openral_mjx.policies.base import Policy
from openral_mjx.runner.chunks import (
    FACTOR_PREFIX,
    EpisodeRunner,
    RunTiming,
    outcome_arrays,
    seed_chunks,
)
from openral_mjx.runner.device_layout import Program
from openral_mjx.runner.episode import (
    EpisodeArrays,
    accumulate,
    control_step,
    policy_state0,
    seed_keys,
    start_arrays,
)
from openral_mjx.scenes.base import Scene, State

BATCHING = ("auto", "chunks", "refill")
REFILL_BACKENDS = ("mjx", "warp", "c")


def check_batching(
    batching: str,
    backend: str,
    refill_every: int = 1,
    traces: bool = False,
    aligned: bool = False,
) -> None:
    """Reject a batching mode the run cannot use, before anything is built (`ConfigError`).
    `auto` is always valid (see `resolve_batching`). `aligned`: the policy needs every env of
    a batch to start its episode together (`Policy.aligned_episodes`)."""
    if batching not in BATCHING:
        raise unknown("batching", batching, BATCHING)
    if refill_every < 1:
        raise ConfigError(f"refill_every must be a positive integer, got {refill_every}")
    if batching == "refill" and backend not in REFILL_BACKENDS:
        raise ConfigError(
            f"batching 'refill' resets single envs in place, which backend {backend!r} cannot "
            "(a host scene's envs live in its workers): use batching 'chunks'"
        )
    if batching == "refill" and traces:
        raise ConfigError("per-step traces (reward curves for plots) need batching 'chunks'")
    if batching == "refill" and aligned:
        raise ConfigError(
            "this policy keeps one history for the whole batch (observation history or "
            "temporal ensembling), so every env must start its episode together: use batching "
            "'chunks'"
        )


def resolve_batching(
    batching: str,
    backend: str,
    n_seeds: int | None,
    n_envs: int,
    traces: bool = False,
    aligned: bool = False,
) -> str:
    """`chunks` or `refill` for the run: `auto` is `refill` where it pays and applies (more
    seeds than envs, or a seed count not known yet; on mjx, warp or c, without per-step
    traces, for a policy that does not need aligned episodes), else `chunks`."""
    check_batching(batching, backend, traces=traces, aligned=aligned)
    if batching != "auto":
        return batching
    more = n_seeds is None or n_seeds > n_envs
    applies = backend in REFILL_BACKENDS and not traces and not aligned and more
    return "refill" if applies else "chunks"


@struct.dataclass
class Slots:
    """The envs of the batch, each running one seed's episode (leading axis: slot)."""

    state: State
    pstate: Any
    acc: EpisodeArrays  # the running episode's accumulators (`info` empty)
    keys: jax.Array  # the episode's policy key stream
    t: jax.Array  # int32: control steps into the episode
    seed_index: jax.Array  # int32: row of the slot's seed; `n_seeds` once idle
    ended: jax.Array  # bool: the episode is over and its row written (idle slots too)


@struct.dataclass
class RefillCarry:
    """Everything the loop carries between segments. Every leaf has a leading axis that
    splits over devices: slots, seeds, or one entry per device (`next_seed`, `steps`)."""

    slots: Slots
    results: EpisodeArrays  # one row per seed (`info`: the scene's `episode_info` at its end)
    finished: jax.Array  # bool per seed: its row is final
    next_seed: jax.Array  # (1,) int32: the next unassigned seed row
    steps: jax.Array  # (1,) int32: control steps the batch has taken


def where_per_env(mask: jax.Array, a: Any, b: Any, per_env: Any = None) -> Any:
    """Per slot (leading axis): `a` where `mask`, else `b`, leaf by leaf. Where `per_env` (a
    tree of bools like `a`) says a leaf has no slot axis, it is a buffer the whole batch
    shares (warp's contact buffer): it comes from `b`, and the next step rebuilds it."""

    def pick(x: jax.Array, y: jax.Array, batched: bool = True) -> jax.Array:
        if not batched:
            return y
        return jnp.where(mask.reshape(mask.shape + (1,) * (x.ndim - 1)), x, y)

    if per_env is None:
        return jax.tree.map(pick, a, b)
    return jax.tree.map(pick, a, b, per_env)


def per_env_leaves(scene: Scene) -> Any:
    """For each leaf of a batch of the scene's states: whether it has the env axis (vmap adds
    one to every per-env leaf; a leaf the batch shares keeps the single env's rank)."""
    one = scene.state_spec
    two = jax.eval_shape(
        jax.vmap(scene.traced.reset_with_seed),
        jax.ShapeDtypeStruct((2,), jnp.int32),
        jax.ShapeDtypeStruct((2, 2), jnp.uint32),
    )
    return jax.tree.map(lambda a, b: b.ndim == a.ndim + 1, one, two)


# Envs a refill on a layout-invariant backend resets at once (see `make_refill_fns`): a few
# more than the episodes a step of a thousand slots ends, on average.
RESET_SLICE = 16


class RefillLoop:
    """The continuous-batching loop's pieces for one scene, policy and episode limit:
    `start` fills the first `n_slots` slots, `advance` runs control steps (see
    `make_refill_fns`). Each method is one traced piece of the loop: a fresh episode for
    some seed rows, writing ended episodes' rows, the refill (of the whole batch, or of the
    slots that take a seed, slice by slice on a layout-invariant backend), one step."""

    def __init__(
        self, scene: Scene, policy: Policy, max_steps: int, n_slots: int, refill_every: int
    ) -> None:
        self.scene, self.policy = scene, policy
        self.max_steps, self.n_slots, self.refill_every = max_steps, n_slots, refill_every
        self.budget_ms = 1000.0 * scene.control_dt
        self.state_per_env = per_env_leaves(scene)
        # A reset of fewer envs than the batch, at other positions, gives each seed the same
        # bits only where the backend's episodes do not depend on the layout (`c`): there a
        # refill resets the slots that take a seed in slices of `RESET_SLICE` envs, not the
        # whole batch. Elsewhere (mjx, warp) the whole batch resets, as in the chunked runner.
        self.sliced = scene.backend.layout_invariant

    def fresh(self, seeds: jax.Array, rows: jax.Array) -> Slots:
        """New episodes of the seeds at `rows` (one slot each), from their reset states."""
        chosen = seeds[rows]
        reset_keys, policy_keys = seed_keys(chosen)
        state = jax.vmap(self.scene.traced.reset_with_seed)(chosen, reset_keys)
        return Slots(
            state=state,
            pstate=policy_state0(self.policy, state.obs, rows.shape[0]),
            acc=start_arrays(state),
            keys=policy_keys,
            t=jnp.zeros(rows.shape, jnp.int32),
            seed_index=rows.astype(jnp.int32),
            ended=jnp.zeros(rows.shape, bool),
        )

    def write_out(self, carry: RefillCarry, s: Slots | None = None) -> tuple[RefillCarry, Slots]:
        """Write the rows of the episodes of slots `s` (default: the carry's) that ended since
        the last write; returns the carry and `s` with those slots marked ended."""
        s = carry.slots if s is None else s
        n = carry.finished.shape[0]
        over = ~s.ended & (s.state.done | (s.t >= self.max_steps))
        rows = jnp.where(over, s.seed_index, n)  # row n: dropped
        acc = s.acc.replace(info=jax.vmap(self.scene.episode_info)(s.state))
        results = jax.tree.map(lambda r, a: r.at[rows].set(a, mode="drop"), carry.results, acc)
        carry = carry.replace(
            results=results, finished=carry.finished.at[rows].set(True, mode="drop")
        )
        return carry, s.replace(ended=s.ended | over)

    def refill(self, carry: RefillCarry, seeds: jax.Array) -> RefillCarry:
        """Ended slots take the next seeds in order; those past the last seed go idle."""
        s, n = carry.slots, seeds.shape[0]
        want = s.ended & (s.seed_index < n)
        rows = carry.next_seed[0] + jnp.cumsum(want) - 1
        take = want & (rows < n)
        next_seed = jnp.minimum(carry.next_seed + jnp.sum(want), n)
        idle = want & ~take
        if not self.sliced:
            return self._refill_whole(carry, seeds, rows, take, idle, next_seed)
        s = s.replace(seed_index=jnp.where(idle, n, s.seed_index))
        return self._refill_slices(carry.replace(slots=s, next_seed=next_seed), seeds, rows, take)

    def _refill_whole(
        self,
        carry: RefillCarry,
        seeds: jax.Array,
        rows: jax.Array,
        take: jax.Array,
        idle: jax.Array,
        next_seed: jax.Array,
    ) -> RefillCarry:
        """The whole batch resets; the slots that take a seed keep their slices."""
        s, n = carry.slots, seeds.shape[0]
        new = self.fresh(seeds, jnp.where(take, rows, 0))
        slots = where_per_env(take, new.replace(state=None), s.replace(state=None))
        state = where_per_env(take, new.state, s.state, self.state_per_env)
        slots = slots.replace(state=state, seed_index=jnp.where(idle, n, slots.seed_index))
        carry, slots = self.write_out(carry.replace(slots=slots, next_seed=next_seed))
        return carry.replace(slots=slots)

    def _refill_slices(
        self, carry: RefillCarry, seeds: jax.Array, rows: jax.Array, take: jax.Array
    ) -> RefillCarry:
        """Only the slots that take a seed reset, `RESET_SLICE` at a time."""
        n, n_slots = seeds.shape[0], take.shape[0]
        k = min(n_slots, RESET_SLICE)
        # The slots that take a seed, in slot order, padded with n_slots (no slot) to a
        # multiple of k; slice i of them resets in iteration i.
        order = jnp.nonzero(take, size=-(-n_slots // k) * k, fill_value=n_slots)[0]

        def reset_slice(i: jax.Array, c: RefillCarry) -> RefillCarry:
            at = jax.lax.dynamic_slice(order, (i * k,), (k,))
            used = at < n_slots
            new = self.fresh(seeds, jnp.where(used, jnp.take(rows, at, mode="clip"), 0))
            # Episodes that end at their reset are written now; padding writes nothing (row n).
            new = new.replace(seed_index=jnp.where(used, new.seed_index, n))
            c, new = self.write_out(c, new)

            def put(x: jax.Array, y: jax.Array, batched: bool = True) -> jax.Array:
                return x.at[at].set(y, mode="drop") if batched else x

            slots = jax.tree.map(put, c.slots.replace(state=None), new.replace(state=None))
            state = jax.tree.map(put, c.slots.state, new.state, self.state_per_env)
            return c.replace(slots=slots.replace(state=state))

        return jax.lax.fori_loop(0, (jnp.sum(take) + k - 1) // k, reset_slice, carry)

    def start(self, params: Any, seeds: jax.Array) -> RefillCarry:
        """The carry with the first `n_slots` seeds' episodes started."""
        del params
        n = seeds.shape[0]
        slots = self.fresh(seeds, jnp.arange(self.n_slots))
        info = jax.eval_shape(jax.vmap(self.scene.episode_info), slots.state)
        results = jax.tree.map(
            lambda x: jnp.zeros((n, *x.shape[1:]), x.dtype),
            slots.acc.replace(info=info),
        )
        carry = RefillCarry(
            slots=slots,
            results=results,
            finished=jnp.zeros(n, bool),
            next_seed=jnp.full((1,), self.n_slots, jnp.int32),
            steps=jnp.zeros((1,), jnp.int32),
        )
        carry, slots = self.write_out(carry)
        return carry.replace(slots=slots)

    def step(self, params: Any, carry: RefillCarry, seeds: jax.Array) -> RefillCarry:
        """One control step of every slot, its ended episodes written, then a refill if due."""
        s = carry.slots
        new_state, new_pstate, _ = control_step(
            self.scene, self.policy, params, s.state, s.pstate, s.keys, s.t
        )
        live = ~s.ended
        acc = accumulate(s.acc, new_state, new_pstate, live, s.t, self.policy, self.budget_ms)
        slots = s.replace(state=new_state, pstate=new_pstate, acc=acc, t=s.t + 1)
        carry, slots = self.write_out(carry.replace(steps=carry.steps + 1), slots)
        carry = carry.replace(slots=slots)
        due = (carry.steps[0] % self.refill_every == 0) & jnp.any(
            slots.ended & (slots.seed_index < seeds.shape[0])
        )
        return jax.lax.cond(due, self.refill, lambda c, _: c, carry, seeds)

    def advance(
        self,
        params: Any,
        carry: RefillCarry,
        seeds: jax.Array,
        budget: jax.Array,
        shrink_at: jax.Array,
    ) -> RefillCarry:
        """Control steps until every seed has finished, `budget` more have run, or the batch
        has drained to `shrink_at` running slots with every seed assigned."""
        stop_at = carry.steps[0] + budget[0]

        def going(c: RefillCarry) -> jax.Array:
            drained = (c.next_seed[0] >= seeds.shape[0]) & (jnp.sum(~c.slots.ended) <= shrink_at[0])
            return ~jnp.all(c.finished) & (c.steps[0] < stop_at) & ~drained

        return jax.lax.while_loop(going, lambda c: self.step(params, c, seeds), carry)


def make_refill_fns(
    scene: Scene, policy: Policy, max_steps: int, n_slots: int, refill_every: int = 1
) -> tuple[Callable[[Any, jax.Array], RefillCarry], Callable[..., RefillCarry]]:
    """`start(params, seeds[n]) -> carry` and `advance(params, carry, seeds[n], budget[1],
    shrink_at[1]) -> carry` (jit both): `advance` runs control steps until every seed has
    finished, `budget` more steps have run, or every seed has a slot and at most `shrink_at`
    slots are still running (the batch has drained enough to `shrink`; -1: never). `n_slots
    <= n` envs run at once at the start; `advance` runs any slot count."""
    loop = RefillLoop(scene, policy, max_steps, n_slots, refill_every)
    return loop.start, loop.advance


def make_shrink_fn(scene: Scene, n_out: int) -> Callable[[RefillCarry], RefillCarry]:
    """`shrink(carry) -> carry` with `n_out` slots: the slots still running (at most `n_out`;
    `advance`'s `shrink_at` guarantees it) move, unchanged, into a smaller batch, so the drain
    at the end of a run does not simulate a full batch of idle slots. Leaves the batch shares
    (warp's contact buffer, sized for the largest batch) stay as they are."""
    state_per_env = per_env_leaves(scene)

    def shrink(carry: RefillCarry) -> RefillCarry:
        s = carry.slots
        keep = jnp.argsort(s.ended, stable=True)[:n_out]  # running slots first, in slot order

        def take(x: jax.Array, batched: bool = True) -> jax.Array:
            return x[keep] if batched else x

        slots = jax.tree.map(take, s.replace(state=None))
        return carry.replace(slots=slots.replace(state=jax.tree.map(take, s.state, state_per_env)))

    return shrink


def shrink_sizes(n_slots: int, levels: int, min_slots: int) -> list[int]:
    """The slot counts a drained batch of `n_slots` shrinks to, in turn: halving, at most
    `levels` times, never below `min_slots` nor two (see `envs_per_device`: a batch of one
    compiles to code that may round differently)."""
    sizes: list[int] = []
    while len(sizes) < levels and (sizes[-1] if sizes else n_slots) // 2 >= max(min_slots, 2):
        sizes.append((sizes[-1] if sizes else n_slots) // 2)
    return sizes


def finished_prefix(finished: np.ndarray) -> int:
    """How many seeds, from the first, have all finished: the only outcomes a running rate or a
    stopping rule may use."""
    finished = np.asarray(finished, bool)
    unfinished = np.flatnonzero(~finished)
    return int(unfinished[0]) if unfinished.size else len(finished)


def device_order(n_seeds: int, n_devices: int) -> np.ndarray:
    """The order in which seed rows go to devices (device d gets rows d, d + D, ...): every
    device then works on the same stretch of seeds, so the finished prefix grows evenly.
    `n_seeds` must be a multiple of `n_devices`."""
    return np.arange(n_seeds).reshape(-1, n_devices).T.reshape(-1)


class RefillRunner(EpisodeRunner):
    """`EpisodeRunner` with continuous batching: `n_envs` slots take seeds one after another
    until every seed has run (see the module docstring).

    All seeds of a `run` go to the devices at once (device d gets rows d, d + D, ...), with
    `n_envs / D` slots each; the loop returns to the host every `segment_steps` control steps
    (default: one episode length) to report progress and let `until` look at the finished
    prefix of seeds at sizes `n_envs`, `2 n_envs`, ... fixed before the run (as the chunked
    runner's looks). Refilling every `refill_every` control steps batches the resets.

    Once every seed has a slot, the batch drains: whenever at most half of a device's slots
    still run, the running ones move into a batch half the size (`shrink_levels` times at
    most, never below `min_slots` per device), so the tail of the run does not step idle
    slots. Each size compiles once, when first reached (counted in `compile_s`, not `run_s`).
    """

    def __init__(
        self,
        scene: Scene,
        policy: Policy,
        *,
        n_envs: int,
        max_steps: int,
        refill_every: int = 1,
        segment_steps: int | None = None,
        shrink_levels: int = 3,
        min_slots: int = 1024,
        memory_fraction: float = 0.85,
        devices: Sequence[jax.Device] | None = None,
    ) -> None:
        check_batching("refill", scene.backend.name, refill_every, aligned=policy.aligned_episodes)
        for name, value in (("segment_steps", segment_steps), ("min_slots", min_slots)):
            if value is not None and value < 1:
                raise ConfigError(f"{name} must be a positive integer, got {value}")
        if shrink_levels < 0:
            raise ConfigError(f"shrink_levels must be >= 0, got {shrink_levels}")
        super().__init__(
            scene,
            policy,
            n_envs=n_envs,
            max_steps=max_steps,
            memory_fraction=memory_fraction,
            devices=devices,
        )
        self.refill_every = refill_every
        self.segment_steps = segment_steps or max_steps
        self.shrink_levels, self.min_slots = shrink_levels, min_slots
        self._slots = self.per_device  # as asked; a run with fewer seeds per device uses fewer
        self._seeds_per_device = 0
        self._start: Program | None = None
        self._advance: dict[int, Program] = {}  # slots per device -> compiled `advance`
        self._shrink: dict[int, Program] = {}  # slots per device after -> compiled `shrink`

    def _lower_with(self, program: str, slots: int) -> Callable:
        policy = self.policy
        return lambda fn, local_args: self._lower(
            program,
            fn,
            local_args,
            cacheable=policy.cache_key is not None,
            policy=policy.cache_key,
            max_steps=self.max_steps,
            slots=slots,
            refill_every=self.refill_every,
        )

    def _lower_compile(self, params: Any) -> Program:
        """Compile `start` and `advance` for `per_device` slots and the current seed count;
        return `advance` (what runs for the whole run, and what memory is fitted to)."""
        start, advance = make_refill_fns(
            self.scene, self.policy, self.max_steps, self.per_device, self.refill_every
        )
        self._advance_fn = self.layout.per_device(advance)
        n_dev = len(self.layout.devices)
        seeds = self.layout.put_envs(np.zeros(self._seeds_per_device * n_dev, np.int32))
        self._start = self.layout.per_device(start).compile(
            (params, seeds), self._lower_with("refill-start", self.per_device)
        )
        carry = self._start(params, seeds)
        self._advance, self._shrink = {}, {}
        return self._compile_advance(params, carry, seeds)

    def _compile_advance(self, params: Any, carry: RefillCarry, seeds: jax.Array) -> Program:
        """`advance` for the slot count of `carry` (compiled once per count)."""
        slots = carry.slots.t.shape[0] // len(self.layout.devices)
        if slots not in self._advance:
            one = self.layout.put_envs(np.ones(len(self.layout.devices), np.int32))
            self._advance[slots] = self._advance_fn.compile(
                (params, carry, seeds, one, one), self._lower_with("refill-advance", slots)
            )
        return self._advance[slots]

    def _shrunk(self, carry: RefillCarry, n_out: int) -> RefillCarry:
        """`carry` with `n_out` slots per device (see `make_shrink_fn`)."""
        if n_out not in self._shrink:
            fn = self.layout.per_device(make_shrink_fn(self.scene, n_out))
            self._shrink[n_out] = fn.compile((carry,), self._lower_with("refill-shrink", n_out))
        return self._shrink[n_out](carry)

    def run(
        self,
        params: Any,
        seeds: np.ndarray,
        on_chunk: Callable[[int, int, int], None] | None = None,
        until: Callable[[dict[str, Any]], bool] | None = None,
    ) -> tuple[dict[str, Any], RunTiming]:
        """Roll out every seed, as `EpisodeRunner.run` (same arrays); `on_chunk(done, total,
        successes)` reports the finished prefix of seeds (`done` seeds, `successes` among them)
        after each segment, never whatever else has finished; `until` sees the outcomes of the
        first `n_envs`, `2 n_envs`, ... seeds once all of them have finished, with their
        episode factors (a run stopped there keeps what it saw)."""
        seeds = self._checked(seeds)
        layout, n = self.layout, len(seeds)
        n_dev = len(layout.devices)
        padded = seed_chunks(seeds, -(-n // n_dev) * n_dev)[0]
        per_dev = len(padded) // n_dev
        compile_s = 0.0
        # Placed before compiling: the compile reads the params' shardings (as `chunks` does).
        params = layout.put_replicated(params) if params is not None else None
        if self._compiled is None or per_dev != self._seeds_per_device:
            self._seeds_per_device = per_dev
            self.per_device = min(self._slots, per_dev)
            compile_s = self._compile(params)
        order = device_order(len(padded), n_dev)
        rows_of = np.argsort(order)  # global seed row -> position in the devices' layout
        device_seeds = layout.put_envs(padded[order])
        budget = layout.put_envs(np.full(n_dev, self.segment_steps, np.int32))
        looks = [*range(self.n_envs, n, self.n_envs), n]
        sizes = shrink_sizes(self.per_device, self.shrink_levels, self.min_slots)
        if on_chunk is not None:
            on_chunk(0, n, 0)
        assert self._start is not None
        t0 = time.perf_counter()
        carry = self._start(params, device_seeds)
        advance, slots = self._compiled, self.per_device
        segment_s: list[float] = []
        done, slot_steps, steps_before = 0, 0, np.zeros(n_dev, np.int64)
        factors: list[Any] = []  # episode factors per batch of n_envs seeds, as computed
        while True:
            t = time.perf_counter()
            shrink_at = sizes[0] if sizes else -1
            carry = advance(
                params,
                carry,
                device_seeds,
                budget,
                layout.put_envs(np.full(n_dev, shrink_at, np.int32)),
            )
            finished = np.asarray(layout.get(carry.finished))[rows_of][:n]
            segment_s.append(time.perf_counter() - t)
            steps = np.asarray(layout.get(carry.steps), np.int64)
            slot_steps += int((steps - steps_before).sum()) * slots
            steps_before = steps
            prefix = finished_prefix(finished)
            if on_chunk is not None:
                success = np.asarray(layout.get(carry.results.success))[rows_of][:prefix]
                on_chunk(prefix, n, int(success.sum()))
            stop = False
            while until is not None and looks and looks[0] <= prefix:
                done = looks.pop(0)
                if until(self._with_factors(self._outcomes(carry, rows_of, done), seeds, factors)):
                    stop = True
                    break
            if stop or prefix == n:
                done = done if stop else n
                break
            if sizes and self._drained(carry, per_dev, sizes[0]):
                t = time.perf_counter()
                carry = self._shrunk(carry, sizes[0])
                jax.block_until_ready(carry)
                slots = sizes.pop(0)
                advance = self._compile_advance(params, carry, device_seeds)
                spent = time.perf_counter() - t
                t0 += spent  # compiling is not running: it goes to compile_s
                compile_s += spent
        run_s = time.perf_counter() - t0
        arrays = self._with_factors(self._outcomes(carry, rows_of, done), seeds, factors)
        timing = RunTiming(
            compile_s=compile_s,
            run_s=run_s,
            chunk_s=tuple(segment_s),
            scan_steps=self.max_steps,
            n_envs=self.n_envs,
            n_devices=n_dev,
            bytes_per_device=self._need,
            batch_steps=round(float(steps.mean())),
            simulated_steps=slot_steps,
        )
        return arrays, timing

    def _drained(self, carry: RefillCarry, seeds_per_device: int, n_out: int) -> bool:
        """Whether every seed has a slot and at most `n_out` slots run on every device."""
        n_dev = len(self.layout.devices)
        assigned = np.asarray(self.layout.get(carry.next_seed)) >= seeds_per_device
        running = (~np.asarray(self.layout.get(carry.slots.ended))).reshape(n_dev, -1).sum(1)
        return bool(assigned.all() and (running <= n_out).all())

    def _with_factors(
        self, arrays: dict[str, Any], seeds: np.ndarray, known: list[Any]
    ) -> dict[str, Any]:
        """`arrays` of the first seeds with their episode factors (see `make_factor_fn`),
        computed per batch of `n_envs` seeds; `known` keeps the full batches' values between
        calls (the last, short batch is computed each time)."""
        if self._factor_fn is None:
            return arrays
        done, layout = len(arrays["success"]), self.layout
        chunks = seed_chunks(seeds[:done], self.n_envs)
        n_full = done // self.n_envs
        for c in chunks[len(known) : n_full]:
            known.append(layout.get(self._factor_fn(layout.put_envs(c))))
        values = known[:n_full]
        if done % self.n_envs:
            values = [*values, layout.get(self._factor_fn(layout.put_envs(chunks[n_full])))]
        for k in values[0]:
            arrays[FACTOR_PREFIX + k] = np.concatenate([np.asarray(v[k]) for v in values])[:done]
        return arrays

    def _outcomes(self, carry: RefillCarry, rows_of: np.ndarray, n: int) -> dict[str, Any]:
        """The first `n` seeds' outcomes by field name (see `outcome_arrays`)."""
        rows = self.layout.get(carry.results)
        return {k: np.asarray(v)[rows_of][:n] for k, v in outcome_arrays(rows).items()}
