"""The eval command as a pipeline: each step alone, and validation before anything is built."""

from __future__ import annotations

import contextlib
import sys
from pathlib import Path

import pytest

from openral_mjx import eval as eval_cli
from openral_mjx.core.errors import ConfigError
from openral_mjx.core.files import check_writable
from openral_mjx.report import load_report


def _no_build(*args, **kwargs):
    raise AssertionError("validation must reject the run before the scene is built")


@pytest.mark.parametrize(
    "out, needle",
    [
        ("file.txt/rep.json", "file.txt' is not a directory"),
        ("file.txt/sub/rep.json", "file.txt' is not a directory"),
        ("a_dir", "is a directory; give a file path"),
    ],
)
def test_unwritable_out_is_one_line_before_anything_runs(
    monkeypatch, capsys, tmp_path, out, needle
):
    """A report path that cannot be written fails at once, not after the run: exit 2, one
    line naming the path, no scene built, nothing written."""
    (tmp_path / "file.txt").write_text("x")
    (tmp_path / "a_dir").mkdir()
    before = sorted(p.name for p in tmp_path.iterdir())
    monkeypatch.setattr(eval_cli, "build_spec_scene", _no_build)
    monkeypatch.setattr(sys, "argv", ["openral_mjx.eval", "--out", str(tmp_path / out)])
    with pytest.raises(SystemExit) as exc:
        eval_cli.main()
    _, err = capsys.readouterr()
    assert exc.value.code == 2
    lines = err.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith("error: --out ") and needle in lines[0], err
    assert sorted(p.name for p in tmp_path.iterdir()) == before


def test_check_writable_probes_the_directory(tmp_path):
    """A missing directory is fine when its nearest existing ancestor takes a file; a directory
    that refuses files is not (probed by writing, since root passes every permission check)."""
    check_writable(tmp_path / "new" / "deeper" / "rep.json")
    assert list(tmp_path.iterdir()) == []  # the probe leaves nothing behind
    with pytest.raises(ConfigError, match="cannot write in '/proc'"):
        check_writable(Path("/proc/rep.json"))  # procfs takes no new files, even from root


def test_validate_builds_nothing_and_plans_every_path(monkeypatch, tmp_path):
    monkeypatch.setattr(eval_cli, "build_spec_scene", _no_build)
    args = eval_cli.EvalArgs(n_envs=4, max_steps=3, out=tmp_path / "r.json", frames=2)
    args.opt = ("cube_friction=0.5",)
    plan = eval_cli.validate(args)
    assert plan.backend == "c" and plan.options == {"cube_friction": 0.5}
    assert plan.frames_file == tmp_path / "r.frames.npz"
    assert plan.videos_dir == tmp_path / "r_videos"
    assert "--opt cube_friction=0.5" in plan.command and "--frames 2" in plan.command
    args.opt = ("cube_friction=-1",)
    with pytest.raises(ConfigError, match="cube_friction"):  # options are checked here too
        eval_cli.validate(args)


def test_each_step_alone(capsys, tmp_path):
    """validate -> build -> execute -> write -> show, called one by one."""
    args = eval_cli.EvalArgs(
        n_envs=2, max_steps=3, policy="zero", threads=1, out=tmp_path / "r.json", plots=False
    )
    plan = eval_cli.validate(args)
    with contextlib.ExitStack() as owned:
        built = eval_cli.build(plan, owned)
        assert built.scene is not None and built.scene.backend.name == "c"
        result = eval_cli.execute(plan, built, owned)
        assert not (tmp_path / "r.json").exists()  # nothing is written before `write`
        written = eval_cli.write(plan, built, result)
    assert written is not None and written.report.n_episodes == 2
    assert load_report(tmp_path / "r.json").successes == written.report.successes
    # the scene `build` made and the policy `execute` made are both timed in the report
    assert set(written.report.build_s) == {"scene", "policy"} == set(built.build_s) | {"policy"}
    capsys.readouterr()
    eval_cli.show(plan, written)
    out = capsys.readouterr().out
    assert out.splitlines()[0] == written.report.summary()
    assert f"report: {tmp_path / 'r.json'}" in out


@pytest.mark.parametrize(
    "argv, needle",
    [
        (["--batching", "nope"], "unknown batching 'nope'; valid: auto, chunks, refill"),
        (["--batching", "refill", "--scene", "robosuite"], "host scene.s envs live in its workers"),
        (["--batching", "refill", "--refill-every", "0"], "refill_every must be a positive"),
    ],
)
def test_batching_mistakes_are_refused_before_anything_is_built(monkeypatch, argv, needle):
    monkeypatch.setattr(eval_cli, "build_spec_scene", _no_build)
    with pytest.raises(ConfigError, match=needle):
        eval_cli.validate(eval_cli.EvalArgs(**_flags(argv)))


def _flags(argv: list[str]) -> dict:
    pairs = zip(argv[::2], argv[1::2], strict=True)
    kinds = {"refill_every": int}
    return {k[2:].replace("-", "_"): kinds.get(k[2:].replace("-", "_"), str)(v) for k, v in pairs}


def test_sequential_run_with_refill_matches_chunks(monkeypatch, capsys, tmp_path):
    """A sequential run stops at the same look with either batching, with the same episodes
    (c backend: bit for bit) and the same exact interval; the report says how it batched.
    Continuous batching is the default for more episodes than envs."""
    reports = {}
    for batching in ("chunks", "refill"):
        out = tmp_path / f"{batching}.json"
        argv = ["openral_mjx.eval", "--n-envs", "4", "--max-steps", "40", "--threads", "1"]
        argv += ["--target-halfwidth", "0.3", "--no-breakdown", "--out", str(out)]
        argv += ["--batching", "chunks"] if batching == "chunks" else []
        argv += ["--seed", "3"]
        monkeypatch.setattr(sys, "argv", argv)
        with pytest.raises(SystemExit) as exc:
            eval_cli.main()
        assert exc.value.code == 0, capsys.readouterr().err
        reports[batching] = load_report(out)
    a, b = reports["chunks"], reports["refill"]
    assert b.options["batching"] == "refill every 1" and a.options["batching"] == "chunks"
    assert (a.n_episodes, a.successes, a.ci_low, a.ci_high) == (
        b.n_episodes,
        b.successes,
        b.ci_low,
        b.ci_high,
    )
    assert a.sequential.looks == b.sequential.looks
    assert [e.success for e in a.episodes] == [e.success for e in b.episodes]
    assert [e.total_reward for e in a.episodes] == [e.total_reward for e in b.episodes]
    assert "--batching chunks" in a.command and "--batching" not in b.command
