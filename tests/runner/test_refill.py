"""Continuous batching: each seed's episode as the fixed-chunk runner gives it, and statistics
only ever from a contiguous prefix of seeds."""

from __future__ import annotations

import numpy as np
import pytest

from openral_mjx.core.errors import ConfigError
from openral_mjx.policies import make_policy
from openral_mjx.runner import finished_prefix, run_seeds
from openral_mjx.runner.refill import RefillRunner, device_order, shrink_sizes

STEPS = 100
SEEDS = np.arange(40, 55)  # 15 seeds: some succeed early, some run out of time


@pytest.fixture(scope="module")
def chunked(push_c):
    policy = make_policy("scripted", push_c)
    arrays, timing = run_seeds(push_c, policy, None, seeds=SEEDS, n_envs=5, max_steps=STEPS)
    assert 0 < arrays["success"].sum() < len(SEEDS)  # both kinds of episode end
    assert (arrays["steps"] < STEPS).any() and (arrays["steps"] == STEPS).any()
    return policy, arrays, timing


@pytest.mark.parametrize("n_envs, refill_every", [(5, 1), (4, 3), (15, 1)])
def test_every_seed_gives_the_chunked_episode_bit_for_bit(push_c, chunked, n_envs, refill_every):
    """On `c` a seed's episode does not depend on its batch: refilled slots, whatever their
    earlier episodes and however often they refill, give exactly the chunked outcomes and
    factors."""
    policy, reference, chunk_timing = chunked
    arrays, timing = run_seeds(
        push_c,
        policy,
        None,
        seeds=SEEDS,
        n_envs=n_envs,
        max_steps=STEPS,
        batching="refill",
        refill_every=refill_every,
    )
    assert set(arrays) == set(reference)
    for k in reference:
        np.testing.assert_array_equal(arrays[k], reference[k], err_msg=k)
    assert timing.n_envs == n_envs and timing.batch_steps is not None
    # Finished episodes are not simulated to the time limit: fewer env-steps than in chunks
    # (where every chunk runs STEPS steps), at least the episodes' own steps.
    assert arrays["steps"].sum() <= timing.env_steps
    if n_envs < len(SEEDS):
        assert timing.env_steps < chunk_timing.env_steps


@pytest.mark.heavy
def test_a_draining_batch_shrinks_and_keeps_every_episode(push_c, chunked):
    """Once every seed has a slot, the running slots move into half-size batches (8 -> 4 -> 2
    slots): the same outcomes bit for bit, and fewer env-steps simulated than at full size."""
    policy, reference, _ = chunked
    results = {}
    for levels in (0, 2):
        runner = RefillRunner(
            push_c, policy, n_envs=8, max_steps=STEPS, shrink_levels=levels, min_slots=2
        )
        arrays, timing = runner.run(None, SEEDS)
        for k in reference:
            np.testing.assert_array_equal(arrays[k], reference[k], err_msg=k)
        results[levels] = timing
    assert sorted(runner._advance) == [2, 4, 8]  # the run reached both smaller sizes
    full, shrunk = results[0], results[2]
    assert full.env_steps == full.batch_steps * 8
    assert arrays["steps"].sum() <= shrunk.env_steps < full.env_steps


def test_resets_in_slices_give_the_chunked_episodes(push_c, chunked, monkeypatch):
    """On `c` a refill resets only the slots that take a seed, `RESET_SLICE` at a time: in
    slices of 2 (several slices in one refill, the last one padded) every seed still gets its
    chunked episode bit for bit."""
    monkeypatch.setattr("openral_mjx.runner.refill.RESET_SLICE", 2)
    policy, reference, _ = chunked
    arrays, _ = run_seeds(
        push_c,
        policy,
        None,
        seeds=SEEDS,
        n_envs=5,
        max_steps=STEPS,
        batching="refill",
        refill_every=16,
    )
    for k in reference:
        np.testing.assert_array_equal(arrays[k], reference[k], err_msg=k)


def test_shrink_sizes():
    assert shrink_sizes(4096, 3, 1024) == [2048, 1024]
    assert shrink_sizes(4096, 2, 16) == [2048, 1024]
    assert shrink_sizes(8, 5, 1) == [4, 2]
    assert shrink_sizes(1024, 3, 1024) == []


@pytest.mark.heavy
def test_refill_on_warp_cpu_is_bit_identical_to_chunks(push_warp):
    """Warp shares one contact buffer across the batch: a reset slot takes the fresh state's
    per-env leaves and leaves the shared buffer to the next step's collision pass. In Warp's
    CPU mode episodes do not depend on the batch, so outcomes match chunks bit for bit (which
    also shows the runner deterministic from run to run on warp)."""
    policy = make_policy("scripted", push_warp)
    # Six seeds, two of which succeed within 40 steps (33 and 35 on `c`): two chunks of 4 (Warp's
    # CPU mode runs ~0.2 s an env-step on 2 cores, so every step saved counts).
    seeds = np.arange(19, 25)
    kw = dict(seeds=seeds, n_envs=4, max_steps=40)
    reference, timing = run_seeds(push_warp, policy, None, **kw)
    assert 0 < reference["success"].sum() < len(seeds)
    # the runner's bookkeeping on warp (freezing via `Data.where`, steps, first success)
    assert timing.n_devices == 1 and timing.n_envs == 4 and not reference["diverged"].any()
    done = reference["success"]
    np.testing.assert_array_equal(reference["steps"][done], reference["first_success_step"][done])
    assert (reference["steps"][~done] == 40).all()
    # Resets batched every 2 steps, and the drained batch shrinking (4 -> 2 slots) with the
    # shared buffer kept as it is: one run covers both.
    runner = RefillRunner(push_warp, policy, n_envs=4, max_steps=40, refill_every=2, min_slots=1)
    arrays, _ = runner.run(None, seeds)
    assert sorted(runner._advance) == [2, 4]
    for k in reference:
        np.testing.assert_array_equal(arrays[k], reference[k], err_msg=k)


def test_until_sees_fixed_prefixes_only(push_c, chunked):
    """Stopping rules look at the first 5, 10, 15 seeds (fixed before the run), each once all of
    them have finished, never at whatever happened to finish."""
    policy, reference, _ = chunked
    seen = []

    def until(arrays):
        n = len(arrays["success"])
        seen.append(n)
        assert "success" in arrays
        for k in arrays:  # the outcomes (factors are added for the seeds finally kept)
            np.testing.assert_array_equal(arrays[k], reference[k][:n], err_msg=k)
        return n >= 10

    arrays, _ = run_seeds(
        push_c,
        policy,
        None,
        seeds=SEEDS,
        n_envs=5,
        max_steps=STEPS,
        batching="refill",
        until=until,
    )
    assert seen == [5, 10] and len(arrays["success"]) == 10
    for k in reference:
        np.testing.assert_array_equal(arrays[k], reference[k][:10], err_msg=k)


def test_refill_is_refused_where_envs_cannot_reset_alone(push_c):
    policy = make_policy("scripted", push_c)
    with pytest.raises(ConfigError, match="unknown batching 'bogus'; valid: auto, chunks, refill"):
        run_seeds(push_c, policy, None, seeds=SEEDS, n_envs=5, max_steps=3, batching="bogus")
    with pytest.raises(ConfigError, match="need batching 'chunks'"):
        run_seeds(
            push_c,
            policy,
            None,
            seeds=SEEDS,
            n_envs=5,
            max_steps=3,
            batching="refill",
            record=("rewards",),
        )


def test_finished_prefix():
    assert finished_prefix(np.array([True, True, False, True])) == 2
    assert finished_prefix(np.array([False, True])) == 0
    assert finished_prefix(np.ones(3, bool)) == 3


def test_device_order_interleaves_seeds():
    """Device d gets rows d, d + D, ...: every device works near the front of the queue."""
    order = device_order(6, 2)
    np.testing.assert_array_equal(order, [0, 2, 4, 1, 3, 5])
    np.testing.assert_array_equal(np.sort(order), np.arange(6))


def _simulate_refill(success: np.ndarray, durations: np.ndarray, n_slots: int):
    """Slots taking seeds in order, as `RefillRunner` does; yields the finished mask after
    every control step."""
    n = len(success)
    end = np.full(n, np.inf)
    slot_free_at = np.zeros(n_slots)
    for s in range(n):  # the next seed goes to the slot that frees first
        k = int(np.argmin(slot_free_at))
        end[s] = slot_free_at[k] + durations[s]
        slot_free_at[k] = end[s]
    for t in range(1, int(end.max()) + 1):
        yield end <= t


def test_prefix_rule_is_unbiased_where_whatever_finished_is_not():
    """Successes end early (5-20 steps), failures run to the limit (100): stopping when K
    episodes have finished and counting those over-estimates the rate; waiting until the first
    K seeds have all finished (the runner's rule, through `finished_prefix`) does not.
    Simulated over 4,000 runs at a true rate of 0.5."""
    rng = np.random.default_rng(0)
    p, n, n_slots, k = 0.5, 64, 16, 32
    naive, prefix = [], []
    for _ in range(4000):
        success = rng.random(n) < p
        durations = np.where(success, rng.integers(5, 21, n), 100)
        naive_rate = prefix_rate = None
        for finished in _simulate_refill(success, durations, n_slots):
            if naive_rate is None and finished.sum() >= k:
                naive_rate = success[finished].mean()
            if prefix_rate is None and finished_prefix(finished) >= k:
                prefix_rate = success[:k].mean()
                break
        naive.append(naive_rate)
        prefix.append(prefix_rate)
    se = 0.5 / np.sqrt(k * len(prefix))  # standard error of the mean of the prefix estimates
    assert np.mean(naive) > p + 0.1  # whatever finished first: mostly the quick successes
    assert abs(np.mean(prefix) - p) < 4 * se


def test_bench_batching_measures_both_runners_on_the_same_seeds(monkeypatch, capsys, tmp_path):
    """`bench --batching` on `c`: the chunked reference over the first 8 seeds, refill over
    all 12; on `c` both give every common seed the same outcome (no discordant pair), and
    refill simulates fewer idle steps."""
    import json
    import sys

    from openral_mjx import bench

    out = tmp_path / "b.json"
    argv = ["bench", "--batching", "--backend", "c", "--n", "4", "--episodes", "12"]
    argv += ["--chunk-episodes", "8", "--max-steps", "60", "--threads", "1", "--out", str(out)]
    monkeypatch.setattr(sys, "argv", argv)
    with pytest.raises(SystemExit) as exc:
        bench.main()
    assert exc.value.code == 0, capsys.readouterr().err
    (row,) = json.loads(out.read_text())["rows"]
    chunks, refill = row["chunks"], row["refill"]
    assert (chunks["n_episodes"], refill["n_episodes"]) == (8, 12)
    assert chunks["simulated_env_steps"] == 2 * 4 * 60  # two chunks of 4 envs x 60 steps
    assert row["paired"]["only_chunks"] == row["paired"]["only_refill"] == 0
    assert refill["live_share"] > chunks["live_share"]
    assert row["speedup"] == pytest.approx(refill["episodes_per_s"] / chunks["episodes_per_s"])
    assert "--chunk-episodes 8" in json.loads(out.read_text())["command"]
