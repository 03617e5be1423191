"""`python -m openral_mjx.finetune`: behaviour cloning (`bc`) and PPO finetuning (`ppo`).

    python -m openral_mjx.finetune bc --scene tabletop_push --out runs/bc
    python -m openral_mjx.finetune ppo --scene tabletop_push --init runs/bc --out runs/ppo
    python -m openral_mjx.eval --policy mlp:runs/ppo/best --seed 2000000000 --n-episodes 4096

Both write `mlp` policy checkpoints that `--policy mlp:DIR` evaluates. Progress goes to
stderr; the summary to stdout.
"""

from __future__ import annotations

import dataclasses
import json
import shlex
import sys
from collections.abc import Sequence
from pathlib import Path
from typing import Any

import tyro

from openral_mjx.cli.common import command_line, guarded, parse
from openral_mjx.core.errors import ConfigError, unknown
from openral_mjx.core.files import check_writable_dir
from openral_mjx.core.options import load_yaml, parse_overrides
from openral_mjx.physics import BACKEND_NAMES, resolve_backend_name
from openral_mjx.runner import MAX_ENVS, MAX_EPISODES, check_counts, check_seeds
from openral_mjx.runner.compile_cache import enable_compilation_cache
from openral_mjx.scenes import SCENES, check_task, scene_options
from openral_mjx.training import runs
from openral_mjx.training.bc import BCConfig
from openral_mjx.training.curves import can_plot, plot_learning_curve
from openral_mjx.training.evaluation import TEST_SEEDS
from openral_mjx.training.ppo import PPOConfig
from openral_mjx.training.run_dir import RunDir


@dataclasses.dataclass
class SceneArgs:
    scene: str = "tabletop_push"
    """Scene ID."""
    task: str | None = None
    """Task of a multi-task scene (metaworld_mjx: reach-v3, ...); the scene option `task`."""
    backend: str = "auto"
    """Physics backend: auto (warp with warp-lang on a CUDA GPU, mjx on another accelerator,
    else c), mjx, warp or c. Training runs on the backend's first device."""
    config: Path | None = None
    """YAML file of scene options (see configs/)."""
    opt: tuple[str, ...] = ()
    """Scene option overrides, KEY=VALUE (after --config)."""
    threads: int | None = None
    """Threads of the C backend (default: all cores)."""
    compile_cache: bool = True
    """Use JAX's persistent compilation cache (~/.cache/openral_mjx/jax)."""


@dataclasses.dataclass
class BcArgs(SceneArgs):
    """Behaviour cloning of the scene's scripted expert into an `mlp` policy checkpoint."""

    out: Path = Path("runs/bc")
    """Checkpoint directory to write (an `mlp` policy, plus bc.json)."""
    n_demos: int = 1024
    """Expert episodes to roll out (seeds 0 .. n_demos-1); the successful ones are kept."""
    n_envs: int = 1024
    """Envs rolled out in parallel for the demonstrations and the evaluation."""
    max_steps: int | None = None
    """Control steps per episode (default: the scene's)."""
    hidden: tuple[int, ...] = (256, 256, 256)
    """Hidden layer sizes of the policy MLP."""
    activation: str = "silu"
    """silu, tanh or relu."""
    epochs: int = 30
    batch_size: int = 4096
    lr: float = 1e-3
    """Adam learning rate (cosine-decayed to 0)."""
    min_std: float = 0.1
    """Floor of the Gaussian's std, in units of each joint's typical expert action."""
    seed: int = 0
    """Network initialisation and minibatch order."""
    eval_episodes: int = 1024
    """Held-out validation episodes to evaluate the clone on (0: skip)."""


@dataclasses.dataclass
class CurveArgs:
    """(Re)draw a PPO run's learning curve from its metrics log."""

    out: Path = Path("runs/ppo")
    """Run directory."""


@dataclasses.dataclass
class PpoArgs(SceneArgs):
    """PPO from an `mlp` checkpoint (or from scratch), with held-out evaluation and checkpoints.

    With --resume, the run's settings come from OUT/run.json; only --num-timesteps (to extend
    the run) and --threads are taken from the command line.
    """

    out: Path = Path("runs/ppo")
    """Run directory (run.json, metrics.jsonl, learning_curve.png, state/, best/, final/)."""
    init: Path | None = None
    """`mlp` checkpoint to start from (e.g. the bc output); none: a fresh network."""
    resume: bool = False
    """Continue the run in --out from its newest checkpoint."""
    num_timesteps: int | None = None
    """Environment steps to train for, rounded up to whole updates (default 20M)."""
    n_envs: int = PPOConfig.n_envs
    unroll_length: int = PPOConfig.unroll_length
    """Control steps per env per update."""
    minibatches: int = PPOConfig.n_minibatches
    epochs: int = PPOConfig.n_epochs
    """Passes over each update's batch."""
    actor_lr: float = PPOConfig.actor_lr
    """Initial actor learning rate (then adapted to --target-kl)."""
    critic_lr: float = PPOConfig.critic_lr
    target_kl: float = PPOConfig.target_kl
    """KL divergence per update the actor learning rate adapts to (0: fixed rate)."""
    gamma: float = PPOConfig.gamma
    gae_lambda: float = PPOConfig.gae_lambda
    clip: float = PPOConfig.clip_eps
    entropy: float = PPOConfig.entropy_coef
    critic_warmup: int = PPOConfig.critic_warmup
    """Updates that train only the critic before the actor moves."""
    reward_scale: float = PPOConfig.reward_scale
    """Factor on the scene's reward in training."""
    success_bonus: float = PPOConfig.success_bonus
    """Training reward added on the step an episode succeeds (the scene's reward is unchanged)."""
    max_steps: int | None = None
    """Episode time limit in control steps (default: the scene's)."""
    update_normalizer: bool | None = None
    """Keep updating the observation statistics (default: only when training from scratch)."""
    seed: int = 0
    eval_every: int = 25
    """Evaluate on held-out validation seeds every this many updates (and at the end)."""
    eval_episodes: int = 1024
    eval_n_envs: int = 1024
    checkpoint_every: int = 50
    """Checkpoint the full training state every this many updates (and at the end)."""
    log_every: int = 1
    """Print a progress line every this many updates."""
    hidden: tuple[int, ...] = (256, 256, 256)
    """From scratch only: hidden layer sizes."""
    activation: str = "silu"
    """From scratch only: silu, tanh or relu."""
    action_scale: float = 0.05
    """From scratch only: how far one unit of the network's output moves each action, as a
    fraction of its range (0.05 suits position servos; metaworld_mjx's hand-velocity actions
    learn faster with 0.5)."""


DEFAULT_TIMESTEPS = 20_000_000


def _log(line: str) -> None:
    """A progress line on stderr (one line each, never wrapped: logs stay greppable)."""
    print(line, file=sys.stderr, flush=True)


def _scene_options(args: SceneArgs) -> dict[str, Any]:
    options: dict[str, Any] = {}
    if args.config is not None:
        options.update(load_yaml(args.config))
    options.update(parse_overrides(args.opt))
    if check_task(args.scene, args.task):  # a single-task scene's own task is no option
        options["task"] = args.task
    return options


def _validate(args: BcArgs | PpoArgs) -> dict[str, Any]:
    """Check a bc or ppo run before anything is built (the scene's name, backend and options,
    the sizes that drive memory, the seed, the output directory) and return its scene options;
    each `ConfigError` names the flag and the value."""
    SCENES.get(args.scene)
    if args.backend not in BACKEND_NAMES:
        raise unknown("backend", args.backend, BACKEND_NAMES)
    options = _scene_options(args)
    scene_options(args.scene, options)
    sizes = [("n_envs", args.n_envs, MAX_ENVS), ("eval_episodes", args.eval_episodes, MAX_EPISODES)]
    if isinstance(args, BcArgs):
        sizes.append(("n_demos", args.n_demos, MAX_EPISODES))
    else:
        sizes.append(("eval_n_envs", args.eval_n_envs, MAX_ENVS))
    for name, value, most in sizes:
        if value > most:
            raise ConfigError(f"{name} must be at most {most:,} (a bound on memory), got {value}")
    if args.max_steps is not None:
        check_counts(1, 1, args.max_steps)
    check_seeds(args.seed)
    check_writable_dir(args.out)
    return options


def _fmt_steps(n: float) -> str:
    return f"{n / 1e6:.2f}M" if n >= 1e6 else f"{n / 1e3:.0f}k"


# ---- bc ------------------------------------------------------------------------------------


def run_bc(args: BcArgs) -> int:
    options = _validate(args)
    config = BCConfig(
        hidden=args.hidden,
        activation=args.activation,
        epochs=args.epochs,
        batch_size=args.batch_size,
        learning_rate=args.lr,
        min_std=args.min_std,
        seed=args.seed,
    )
    backend = resolve_backend_name(args.backend)
    if args.compile_cache:
        enable_compilation_cache()
    summary = runs.run_bc(
        args.scene,
        options,
        backend,
        args.out,
        config,
        threads=args.threads,
        n_demos=args.n_demos,
        n_envs=args.n_envs,
        max_steps=args.max_steps,
        eval_episodes=args.eval_episodes,
        command=command_line("openral_mjx.finetune", ["bc", *_bc_argv(args, backend)]),
        log=_log,
    )
    line = ""
    if "validation" in summary:
        r = summary["validation"]
        line = (
            f", validation success {100 * r['success_rate']:.1f}% "
            f"[{100 * r['ci_low']:.1f}, {100 * r['ci_high']:.1f}] "
            f"({r['n_episodes']} held-out seeds)"
        )
    n, loss = summary["transitions"], summary["losses"][-1]
    print(f"bc on {summary['scene']}/{backend}: {n:,} transitions, loss {loss:.4f}{line}")
    print(f"policy: {args.out} (evaluate with --policy mlp:{args.out})")
    return 0


def _bc_argv(args: BcArgs, backend: str) -> list[str]:
    argv = ["--scene", args.scene, "--backend", backend, "--out", str(args.out)]
    for flag in ("n_demos", "n_envs", "epochs", "batch_size", "lr", "min_std", "seed"):
        argv += [f"--{flag.replace('_', '-')}", str(getattr(args, flag))]
    argv += ["--hidden", *map(str, args.hidden), "--activation", args.activation]
    if args.max_steps is not None:
        argv += ["--max-steps", str(args.max_steps)]
    if args.task is not None:
        argv += ["--task", args.task]
    if args.config is not None:
        argv += ["--config", str(args.config)]
    if args.opt:
        argv += ["--opt", *args.opt]
    return argv


# ---- ppo -----------------------------------------------------------------------------------


def _ppo_fields(args: PpoArgs) -> dict[str, Any]:
    """`PPOConfig` fields from the flags (`max_steps` None: the scene's)."""
    return {
        "n_envs": args.n_envs,
        "unroll_length": args.unroll_length,
        "n_minibatches": args.minibatches,
        "n_epochs": args.epochs,
        "actor_lr": args.actor_lr,
        "critic_lr": args.critic_lr,
        "target_kl": args.target_kl,
        "gamma": args.gamma,
        "gae_lambda": args.gae_lambda,
        "clip_eps": args.clip,
        "entropy_coef": args.entropy,
        "critic_warmup": args.critic_warmup,
        "reward_scale": args.reward_scale,
        "success_bonus": args.success_bonus,
        "max_steps": args.max_steps,
        "update_normalizer": args.update_normalizer,
        "seed": args.seed,
    }


def _plot(run_dir: RunDir, settings: dict[str, Any]) -> None:
    """Draw the run's learning curve from its metrics log (training statistics start once every
    env has run a full episode)."""
    title = (
        f"PPO on {settings['scene']} ({settings['backend']}), from {settings['init'] or 'scratch'}"
    )
    warmup = settings["ppo"]["max_steps"] * settings["ppo"]["n_envs"]
    plot_learning_curve(run_dir.read_metrics(), run_dir.curve_path, title, warmup)


class _Progress:
    """Prints the run's progress lines to stderr and redraws the learning curve after evals."""

    def __init__(self, run_dir: RunDir, settings: dict[str, Any], num_updates: int) -> None:
        self.dir, self.settings, self.n = run_dir, settings, num_updates
        self.log_every = int(settings["log_every"])

    def __call__(self, row: dict[str, Any]) -> None:
        kind, u = row["kind"], row["update"]
        if kind == "compiled":
            _log(f"compiled the update in {row['compile_s']:.1f} s; starting at update {u}")
        elif kind == "train" and (u % self.log_every == 0 or u == self.n):
            rate = row["train_success_rate"]
            success = "-" if rate is None else f"{100 * rate:.1f}%"
            _log(
                f"update {u}/{self.n}  steps {_fmt_steps(row['env_steps'])}  "
                f"train success {success} ({row['episodes']} episodes)  "
                f"return {row['episode_return']:.2f}  reward {row['reward']:.4f}  "
                f"{row['steps_per_s']:,.0f} steps/s  kl {row['approx_kl']:.4f}  "
                f"lr {row['actor_lr']:.1e}"
            )
        elif kind == "eval":
            _log(
                f"eval @ update {u} ({_fmt_steps(row['env_steps'])} steps): success "
                f"{100 * row['success_rate']:.1f}% [{100 * row['ci_low']:.1f}, "
                f"{100 * row['ci_high']:.1f}] on {row['n_episodes']} validation seeds"
                + ("  (best)" if row["best"] else "")
            )
            self.plot()

    def plot(self) -> None:
        if can_plot():
            _plot(self.dir, self.settings)


def run_ppo(args: PpoArgs) -> int:
    options = _validate(args)
    run_dir = RunDir(args.out)
    if args.resume:
        settings = run_dir.load_settings()
        if args.num_timesteps is not None:
            settings["num_timesteps"] = args.num_timesteps
    else:
        settings = {
            "scene": args.scene,
            "scene_options": options,
            "backend": resolve_backend_name(args.backend),
            "init": None if args.init is None else str(args.init),
            "num_timesteps": args.num_timesteps or DEFAULT_TIMESTEPS,
            "schedule": {
                "eval_every": args.eval_every,
                "checkpoint_every": args.checkpoint_every,
                "eval_episodes": args.eval_episodes,
                "eval_n_envs": args.eval_n_envs,
            },
            "log_every": args.log_every,
        }
    if args.compile_cache:
        enable_compilation_cache()
    start = None
    if not args.resume:
        start = runs.NewPolicy(
            args.init, args.hidden, args.activation, args.seed, args.action_scale
        )
    run = runs.prepare_ppo(
        run_dir,
        settings,
        ppo=None if args.resume else _ppo_fields(args),
        start=start,
        threads=args.threads,
        command=command_line("openral_mjx.finetune", ["ppo", *sys.argv[2:]]),
    )
    scene, num_updates, ppo_config = run.scene, run.num_updates, run.session.ppo.config
    progress = _Progress(run_dir, settings, num_updates)
    if not can_plot():
        _log(
            "matplotlib is not installed: no learning curve (pip install 'openral_mjx[train]', "
            f"then python -m openral_mjx.finetune curve --out {run_dir.path})"
        )
    _log(
        f"ppo on {scene.name}/{settings['backend']}: {num_updates} updates x "
        f"{ppo_config.steps_per_update:,} steps ({ppo_config.n_envs} envs x "
        f"{ppo_config.unroll_length}), from {settings['init'] or 'scratch'}"
    )
    summary = run.run(on_row=progress)
    progress.plot()
    init = summary["init"]
    start = "" if init is None else f"{100 * init['success_rate']:.1f}% -> "
    rate = summary["steps_per_s"]
    speed = "" if rate is None else f" ({rate:,.0f} steps/s)"
    print(
        f"ppo on {scene.name}/{settings['backend']}: validation success {start}"
        f"{100 * summary['final_success_rate']:.1f}% (best "
        f"{100 * summary['best_success_rate']:.1f}% at update {summary['best_update']}), "
        f"{_fmt_steps(summary['env_steps'])} steps, {summary['wall_s']:.0f} s training{speed}, "
        f"{summary['elapsed_s']:.0f} s in all"
    )
    vs = summary["final_vs_init"]
    if vs is not None and init is not None:
        print(
            f"final vs start on the same {vs['n_episodes']} validation seeds (paired): "
            f"{100 * vs['difference']:+.1f} points [{100 * vs['ci_low']:+.1f}, "
            f"{100 * vs['ci_high']:+.1f}], McNemar p = {vs['p_value']:.3g}; mean return "
            f"{init['mean_return']:.1f} -> {summary['final_mean_return']:.1f}"
        )
    print(f"policies: {run_dir.best} (best), {run_dir.final} (last), {run_dir.init} (start)")
    curve = f"; curve: {run_dir.curve_path}" if can_plot() else ""
    print(f"metrics: {run_dir.metrics_path}{curve}; summary: {run_dir.summary_path}")
    print(
        f"test: python -m openral_mjx.eval --scene {scene.name}{_eval_flags(scene, settings)} "
        f"--policy mlp:{run_dir.best} --seed {TEST_SEEDS} --n-episodes 4096 (and the same "
        f"with mlp:{run_dir.init}; pair the two reports with python -m openral_mjx.compare)"
    )
    return 0


def _yaml(value: Any) -> str:
    return value if isinstance(value, str) else json.dumps(value)


def _eval_flags(scene: Any, settings: dict[str, Any]) -> str:
    """The eval CLI's flags for the scene options and episode length the run trained on."""
    flags = []
    options = dict(settings["scene_options"])
    if "task" in options:
        flags += ["--task", str(options.pop("task"))]
    if options:
        flags += ["--opt", *(f"{k}={_yaml(v)}" for k, v in options.items())]
    if settings["ppo"]["max_steps"] != scene.max_steps:
        flags += ["--max-steps", str(settings["ppo"]["max_steps"])]
    return "".join(f" {shlex.quote(f)}" for f in flags)


def run_curve(args: CurveArgs) -> int:
    if not can_plot():
        raise ConfigError("drawing the curve needs matplotlib: pip install 'openral_mjx[train]'")
    check_writable_dir(args.out)
    run_dir = RunDir(args.out)
    _plot(run_dir, run_dir.load_settings())
    print(f"curve: {run_dir.curve_path}")
    return 0


def main(argv: Sequence[str] | None = None) -> None:
    """The command: `argv` (default: the process's arguments) -> exit code."""
    prog = "python -m openral_mjx.finetune"
    commands = {"bc": BcArgs, "ppo": PpoArgs, "curve": CurveArgs}
    args = parse(lambda: tyro.extras.subcommand_cli_from_dict(commands, prog=prog, args=argv), prog)
    run = {BcArgs: run_bc, PpoArgs: run_ppo, CurveArgs: run_curve}[type(args)]
    raise SystemExit(guarded(lambda: run(args)))


if __name__ == "__main__":
    main()
