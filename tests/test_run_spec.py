"""`RunSpec`: checked once on construction; a suite honours batching and refuses what it
cannot apply (one line naming the flag, exit 2, before any scene or worker environment)."""

import dataclasses
import inspect
import pickle
import sys

import pytest

from openral_mjx import eval as eval_cli
from openral_mjx.core.errors import ConfigError
from openral_mjx.evaluation import RunSpec, build_scene
from openral_mjx.evaluation import suite as suite_module


@pytest.mark.parametrize(
    "kwargs, needle",
    [
        ({"factor_bins": 0}, "factor_bins must be a positive integer, got 0"),
        ({"seed": -1}, r"seed must lie in \[0, 2147482624\] for 1,024 episodes .*got -1"),
        ({"devices": 0}, "devices must be >= 1, got 0"),
        ({"batching": "nope"}, "unknown batching 'nope'; valid: auto, chunks, refill"),
        ({"refill_every": 0}, "refill_every must be a positive integer, got 0"),
        ({"batching": "refill", "backend": "host"}, "use batching 'chunks'"),
        ({"batching": "refill", "step_rewards": True}, "per-step traces"),
        ({"n_episodes": 4, "target_halfwidth": 0.1}, "exclude each other"),
        ({"max_episodes": 9}, "max_episodes caps a sequential run"),
        ({"n_envs": 0}, "n_envs"),
    ],
)
def test_spec_refuses_bad_values(kwargs, needle):
    with pytest.raises(ConfigError, match=needle):
        RunSpec(**kwargs)


def test_spec_counts_and_a_fresh_rule_per_run():
    assert RunSpec(n_envs=8).episodes == 8 and RunSpec(n_envs=8).stopping_rule() is None
    assert RunSpec(n_envs=8, n_episodes=20).episodes == 20
    spec = RunSpec(n_envs=8, target_halfwidth=0.1, max_episodes=64, batching="refill")
    assert spec.episodes == 64
    assert spec.stopping_rule() is not spec.stopping_rule()  # a rule keeps its run's design
    assert pickle.loads(pickle.dumps(spec)) == spec  # task processes get it pickled
    with pytest.raises(dataclasses.FrozenInstanceError):
        spec.seed = 3  # type: ignore[misc]


@pytest.mark.parametrize(
    "kwargs, flag",
    [
        ({"factor_bins": 3}, "factor_bins (--factor-bins)"),
        ({"target_halfwidth": 0.1}, "target_halfwidth (--target-halfwidth)"),
        ({"step_rewards": True, "batching": "chunks"}, "step_rewards (--plots)"),
    ],
)
def test_suite_refuses_what_it_cannot_apply(kwargs, flag):
    with pytest.raises(ConfigError) as e:
        RunSpec(n_envs=2, **kwargs).for_suite()
    assert str(e.value).startswith(f"{flag} does not apply to a suite")
    spec = RunSpec(n_envs=2, batching="chunks", refill_every=3, factor_bins=5)
    assert spec.for_suite() is spec


@pytest.mark.parametrize(
    "scene, suite", [("metaworld_mjx", "mt10"), ("metaworld", "mt10"), ("libero", "libero_10")]
)
def test_suite_flag_refused_before_any_scene_or_worker_env(
    monkeypatch, capsys, tmp_path, scene, suite
):
    """`--factor-bins` on a suite used to be dropped silently (the report's command kept it);
    now it is one line on stderr, exit 2, no file, and nothing built or installed first."""

    def touched(*_a, **_k):
        raise AssertionError("built or touched before validation")

    monkeypatch.setenv("OPENRAL_MJX_ENVS", str(tmp_path / "no_envs"))
    monkeypatch.setattr("openral_mjx.host.envs.ensure_env", touched)
    monkeypatch.setattr(eval_cli, "build", touched)
    monkeypatch.setattr(eval_cli, "evaluate_suite", touched)
    out = tmp_path / "rep.json"
    argv = ["--scene", scene, "--suite", suite, "--batching", "chunks", "--factor-bins", "3"]
    monkeypatch.setattr(sys, "argv", ["openral_mjx.eval", *argv, "--out", str(out)])
    with pytest.raises(SystemExit) as exc:
        eval_cli.main()
    _, err = capsys.readouterr()
    assert exc.value.code == 2
    assert err.count("\n") == 1 and "--factor-bins" in err and "suite" in err
    assert list(tmp_path.iterdir()) == []


def test_suite_plan_carries_batching():
    """`--batching`/`--refill-every` on a suite reach the plan's spec, which each task runs."""
    args = eval_cli.EvalArgs(
        scene="metaworld_mjx", suite="mt10", backend="c", batching="chunks", refill_every=2
    )
    spec = eval_cli.validate(args).spec
    assert (spec.batching, spec.refill_every, spec.backend) == ("chunks", 2, "c")
    assert "--batching chunks" in spec.command and "--refill-every 2" in spec.command


@pytest.mark.parametrize(
    "batching, refill_every, shown",
    [("chunks", 1, "chunks"), ("auto", 1, "refill every 1"), ("refill", 2, "refill every 2")],
)
def test_suite_honours_batching(monkeypatch, batching, refill_every, shown):
    """Every task of a suite runs with the spec's batching (two stand-in tasks on a cheap
    MuJoCo scene: the suite machinery is what is under test)."""
    monkeypatch.setattr(suite_module, "scene_suite", lambda scene, suite: ["a", "b"])

    def cheap_scene(name, options, spec, randomize=()):
        return build_scene("tabletop_push", backend="c", n_envs=spec.n_envs, threads=1)

    monkeypatch.setattr(suite_module, "build_spec_scene", cheap_scene)
    spec = RunSpec(
        n_envs=2,
        n_episodes=4,
        max_steps=3,
        backend="c",
        threads=1,
        batching=batching,
        refill_every=refill_every,
    )
    report = suite_module.evaluate_suite("tabletop_push", "pair", "zero", spec)
    assert report.options["batching"] == shown
    assert [r.n_episodes for r in report.per_task] == [4, 4]


def test_every_run_flag_reaches_the_spec():
    """Each flag a run needs lands in the plan's spec (the one object every mode runs from),
    so no mode can be handed a partial list of them."""
    args = eval_cli.EvalArgs(
        backend="c",
        n_envs=8,
        n_episodes=16,
        max_steps=7,
        seed=3,
        factor_bins=2,
        batching="chunks",
        refill_every=2,
        threads=1,
        contacts_per_env=9,
        ccd_contacts_per_env=5,
        warp_graphs="staged",
        devices=1,
        plots=False,
    )
    spec = eval_cli.validate(args).spec
    for name in (
        "n_envs",
        "n_episodes",
        "max_steps",
        "seed",
        "factor_bins",
        "batching",
        "refill_every",
        "threads",
        "contacts_per_env",
        "ccd_contacts_per_env",
        "warp_graphs",
        "devices",
        "backend",
    ):
        assert getattr(spec, name) == getattr(args, name), name
    assert spec.command.startswith("python -m openral_mjx.eval")


def test_the_python_api_takes_every_spec_field():
    """`run_evaluation` (and so `evaluate`) builds its `RunSpec` from keywords of the same
    names: every field of the spec is one, and a bad one is refused as the CLI refuses it."""
    from openral_mjx.evaluation.run import evaluate, run_evaluation

    taken = set(inspect.signature(run_evaluation).parameters)
    assert {f.name for f in dataclasses.fields(RunSpec)} <= taken
    with pytest.raises(ConfigError, match="unknown warp_graphs 'cuda'"):
        evaluate("tabletop_push", "zero", warp_graphs="cuda")
    with pytest.raises(ConfigError, match="ccd_contacts_per_env must be >= 1, got 0"):
        evaluate("tabletop_push", "zero", ccd_contacts_per_env=0)
