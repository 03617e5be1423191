"""A PPO run from start (or checkpoint) to end: updates, periodic held-out evaluation, best and
final policies, resumable checkpoints, a metrics log.

Evaluation goes through `HeldOutEvaluator` (the runner, deterministic `mlp` policy, validation
seeds), compiled once per run. The initial policy is evaluated before the first update, so
the log starts from the pretrained success rate and `best/` is never worse than the start.
A checkpoint holds the training state and the best policy so far, so a resumed run continues
exactly, `best/` included, whatever the interruption lost.

The summary compares the final policy with the initial one on the same validation seeds, paired
(exact McNemar test, Newcombe interval): nothing selects the final policy on those seeds, so the
comparison is honest, where `best/`'s validation rate is the maximum of several looks.
"""

from __future__ import annotations

import dataclasses
import json
import time
from collections.abc import Callable
from typing import Any

import jax
import numpy as np

from openral_mjx.core.errors import ConfigError
from openral_mjx.core.files import write_json_atomic
from openral_mjx.policies.mlp import CONFIG_FILE, MlpConfig, init_params, save_mlp
from openral_mjx.scenes.base import Scene
from openral_mjx.stats import paired_comparison
from openral_mjx.training.evaluation import VALIDATION_SEEDS, EvalResult, HeldOutEvaluator
from openral_mjx.training.ppo import PPO, PPOConfig
from openral_mjx.training.run_dir import RunDir


@dataclasses.dataclass(frozen=True)
class Schedule:
    """How long to train, and how often to evaluate and checkpoint (in updates)."""

    num_updates: int
    eval_every: int = 10
    checkpoint_every: int = 10
    eval_episodes: int = 1024
    eval_n_envs: int = 1024
    keep_checkpoints: int = 2

    def __post_init__(self) -> None:
        for f in dataclasses.fields(self):
            value = getattr(self, f.name)
            if value < 1:
                raise ConfigError(f"{f.name} must be a positive integer, got {value}")


Row = dict[str, Any]


def _eval_row(update: int, env_steps: int, r: EvalResult, best: bool) -> Row:
    return {
        "kind": "eval",
        "update": update,
        "env_steps": env_steps,
        "success_rate": r.success_rate,
        "ci_low": r.ci_low,
        "ci_high": r.ci_high,
        "successes": r.successes,
        "n_episodes": r.n_episodes,
        "first_seed": VALIDATION_SEEDS,
        "mean_return": r.mean_return,
        "diverged": r.diverged,
        "eval_s": r.run_s + r.compile_s,
        "best": best,
    }


def _vs_init(init: str | None, final: np.ndarray) -> Row | None:
    """The final policy against the initial one on the same validation seeds (paired); None
    where the initial outcomes are unknown (a run checkpointed by an older version)."""
    if init is None or len(init) != len(final):
        return None
    c = paired_comparison(np.array([x == "1" for x in init]), final)
    return {
        "n_episodes": c.n_a,
        "init_successes": c.successes_a,
        "final_successes": c.successes_b,
        "difference": float(c.difference),
        "ci_low": float(c.ci_low),
        "ci_high": float(c.ci_high),
        "confidence": float(c.confidence),
        "test": c.test,
        "p_value": float(c.p_value),
        "only_init": c.only_a,
        "only_final": c.only_b,
    }


class PPOSession:
    """Trains `mlp_config`'s policy on `scene` into `run_dir` (see `run`)."""

    def __init__(
        self,
        scene: Scene,
        run_dir: RunDir,
        mlp_config: MlpConfig,
        ppo_config: PPOConfig,
        schedule: Schedule,
        on_row: Callable[[Row], None] | None = None,
    ) -> None:
        self.scene, self.dir, self.mlp, self.schedule = scene, run_dir, mlp_config, schedule
        self.ppo = PPO(scene, mlp_config, ppo_config)
        self.steps_per_update = ppo_config.steps_per_update
        self.on_row = on_row or (lambda row: None)
        # Training runs on one device: the backend's first (the host CPU for `c`).
        device = scene.backend.devices()[0]
        self._put = lambda x: jax.device_put(x, device)

    def _emit(self, row: Row) -> None:
        self.dir.append_metrics(row)
        self.on_row(row)

    def _policy_metadata(self, update: int, r: EvalResult) -> dict[str, Any]:
        return {
            **self.mlp.metadata,
            "trained": {
                "method": "ppo",
                "update": update,
                "env_steps": update * self.steps_per_update,
                "validation_success_rate": r.success_rate,
                "validation_episodes": r.n_episodes,
                "run": str(self.dir.path),
            },
        }

    def _save_policy(self, where, params: Any, update: int, r: EvalResult) -> None:
        config = dataclasses.replace(self.mlp, metadata=self._policy_metadata(update, r))
        save_mlp(where, config, jax.device_get(params))

    def _start(self, init_policy: dict[str, Any] | None, resume: bool):
        """The training state, the best policy's params so far, and the progress record."""
        template_policy = jax.eval_shape(lambda: init_params(self.mlp, jax.random.PRNGKey(0)))
        if not resume:
            if init_policy is None:
                raise ValueError("a new run needs init_policy")
            ts = jax.jit(self.ppo.init)(self._put(init_policy))
            progress = {
                "best_eval": None,
                "best_update": -1,
                "wall_s": 0.0,
                "init": None,
                "init_successes": None,
            }
            return ts, None, progress
        template = {
            "train": jax.eval_shape(self.ppo.init, template_policy),
            "best": template_policy,
        }
        tree, progress = self.dir.load_state(template)
        self.dir.truncate_metrics(int(tree["train"].update))
        best = progress["best_eval"]
        saved = self.dir.best / CONFIG_FILE
        trained = (
            json.loads(saved.read_text())["metadata"].get("trained", {}) if saved.is_file() else {}
        )
        if trained.get("update") != progress["best_update"]:
            # best/ was replaced after this checkpoint by work the interruption lost: restore it.
            self._save_policy(
                self.dir.best, tree["best"], progress["best_update"], EvalResult(**best)
            )
        return self._put(tree["train"]), tree["best"], progress

    def run(self, init_policy: dict[str, Any] | None, *, resume: bool) -> Row:
        """Train to `schedule.num_updates`; `resume` continues from the newest checkpoint
        (`init_policy` is then ignored). Returns a summary row: `wall_s` counts the updates
        alone (all sessions of the run), `elapsed_s` this session's whole time (compilation,
        evaluations and checkpoints included)."""
        started = time.perf_counter()
        ts, best_params, progress = self._start(init_policy, resume)
        start, s = int(ts.update), self.schedule
        if start > s.num_updates:
            raise ConfigError(
                f"the checkpoint is at update {start}, past the requested "
                f"{s.num_updates} updates; raise --num-timesteps to continue"
            )
        evaluator = HeldOutEvaluator(
            self.scene,
            self.mlp,
            n_episodes=s.eval_episodes,
            n_envs=s.eval_n_envs,
            max_steps=self.ppo.config.max_steps,
        )
        t0 = time.perf_counter()
        update_fn = jax.jit(self.ppo.update).lower(ts).compile()
        self.on_row({"kind": "compiled", "update": start, "compile_s": time.perf_counter() - t0})
        wall = wall_start = float(progress["wall_s"])
        last_eval: EvalResult | None = None
        last_success: np.ndarray | None = None

        def evaluate(update: int) -> None:
            nonlocal last_eval, last_success, best_params
            r, last_success = evaluator.run(ts.policy)
            last_eval = r
            best = (
                progress["best_eval"] is None
                or r.success_rate > progress["best_eval"]["success_rate"]
            )
            if best:
                best_params = jax.device_get(ts.policy)
                progress.update(best_eval=dataclasses.asdict(r), best_update=update)
                self._save_policy(self.dir.best, best_params, update, r)
            if update == 0:
                progress["init"] = dataclasses.asdict(r)
                self._save_policy(self.dir.init, ts.policy, 0, r)
                # per validation seed, "0"/"1": the final summary's paired comparison
                progress["init_successes"] = "".join("01"[int(x)] for x in last_success)
            self._emit(_eval_row(update, update * self.steps_per_update, r, best))

        if start == 0:
            evaluate(0)
        for update in range(start + 1, s.num_updates + 1):
            t = time.perf_counter()
            ts, metrics = update_fn(ts)
            metrics = {k: float(v) for k, v in jax.device_get(metrics).items()}
            dt = time.perf_counter() - t
            wall += dt
            episodes = metrics.pop("episodes")
            successes = metrics.pop("successes")
            self._emit(
                {
                    "kind": "train",
                    "update": update,
                    "env_steps": update * self.steps_per_update,
                    "wall_s": wall,
                    "steps_per_s": self.steps_per_update / dt,
                    "episodes": int(episodes),
                    "train_success_rate": successes / episodes if episodes else None,
                    **metrics,
                }
            )
            if update % s.eval_every == 0 or update == s.num_updates:
                evaluate(update)
            if update % s.checkpoint_every == 0 or update == s.num_updates:
                progress["wall_s"] = wall
                tree = {"train": jax.device_get(ts), "best": best_params}
                self.dir.save_state(update, tree, progress, s.keep_checkpoints)
        if last_eval is None:  # resumed at the end: nothing left to train
            last_eval, last_success = evaluator.run(ts.policy)
        self._save_policy(self.dir.final, ts.policy, s.num_updates, last_eval)
        trained = s.num_updates - start
        summary = {
            "kind": "summary",
            "update": s.num_updates,
            "env_steps": s.num_updates * self.steps_per_update,
            "wall_s": wall,
            "elapsed_s": time.perf_counter() - started,
            "steps_per_s": (trained * self.steps_per_update / (wall - wall_start))
            if trained
            else None,
            "init": progress["init"],
            "final_success_rate": last_eval.success_rate,
            "final_mean_return": last_eval.mean_return,
            "final_vs_init": _vs_init(progress.get("init_successes"), last_success),
            "best_success_rate": progress["best_eval"]["success_rate"],
            "best_update": progress["best_update"],
        }
        write_json_atomic(self.dir.summary_path, summary)
        return summary
