"""The finetuning pipeline on the CPU (C backend), tiny: behaviour cloning, PPO with held-out
evaluation and checkpoints, an interrupted run resumed to the same result as an uninterrupted
one, the checkpoints evaluated by the eval CLI, and user mistakes as one-line errors."""

import json
import shutil
import sys

import jax
import numpy as np
import pytest

from openral_mjx import eval as eval_cli
from openral_mjx import finetune
from openral_mjx.policies.mlp import load_mlp

SCENE = ["--backend", "c", "--threads", "2", "--no-compile-cache"]
BC = ["--n-demos", "8", "--n-envs", "8", "--epochs", "10", "--batch-size", "64"]
BC += ["--hidden", "32", "32", "--eval-episodes", "8"]
PPO = ["--n-envs", "8", "--unroll-length", "8", "--minibatches", "2", "--epochs", "2"]
PPO += ["--max-steps", "40", "--critic-warmup", "1", "--eval-every", "2"]
PPO += ["--eval-episodes", "8", "--eval-n-envs", "8", "--checkpoint-every", "2"]
STEPS_PER_UPDATE = 64
TIMING = ("wall_s", "steps_per_s", "eval_s")


def _run(monkeypatch, capsys, module, *argv):
    monkeypatch.setattr(sys, "argv", [module.__name__, *argv])
    with pytest.raises(SystemExit) as exc:
        module.main()
    out, err = capsys.readouterr()
    return exc.value.code, out, err


@pytest.fixture(scope="module")
def bc_dir(tmp_path_factory):
    out = tmp_path_factory.mktemp("bc") / "bc"
    mp = pytest.MonkeyPatch()
    mp.setattr(sys, "argv", ["finetune", "bc", *SCENE, *BC, "--out", str(out)])
    try:
        with pytest.raises(SystemExit) as exc:
            finetune.main()
    finally:
        mp.undo()
    assert exc.value.code == 0
    return out


def _ppo(monkeypatch, capsys, out, updates, *extra):
    steps = str(updates * STEPS_PER_UPDATE)
    return _run(
        monkeypatch,
        capsys,
        finetune,
        "ppo",
        *SCENE,
        *PPO,
        "--out",
        str(out),
        "--num-timesteps",
        steps,
        *extra,
    )


def _rows(run):
    rows = [json.loads(line) for line in (run / "metrics.jsonl").read_text().splitlines()]
    return [{k: v for k, v in r.items() if k not in TIMING} for r in rows]


def test_bc_writes_an_evaluable_checkpoint(bc_dir):
    config, _ = load_mlp(bc_dir)
    assert config.metadata["trained"]["method"] == "bc" and config.hidden == (32, 32)
    summary = json.loads((bc_dir / "bc.json").read_text())
    assert summary["demo_successful"] > 0 and len(summary["losses"]) == 10
    assert summary["validation"]["n_episodes"] == 8 and summary["validation"]["first_seed"] == 10**9
    # The clone imitates: its loss falls.
    assert summary["losses"][-1] < summary["losses"][0]


@pytest.mark.heavy
def test_ppo_resume_matches_uninterrupted_run(monkeypatch, capsys, tmp_path, bc_dir):
    """Run A trains 4 updates in one go. Run B trains 3, loses its last checkpoint (as if killed
    after logging update 3 but before saving it), and resumes to 4. On the CPU, XLA and MuJoCo C
    are deterministic, so B must equal A bit for bit: params and every logged number (timings
    aside). On a GPU, reductions may differ in the last bit between runs, which PPO amplifies."""
    a, b = tmp_path / "a", tmp_path / "b"
    code, out, err = _ppo(monkeypatch, capsys, a, 4, "--init", str(bc_dir))
    assert code == 0, err
    assert "validation success" in out and "steps/s" in out and "test: python -m" in out
    assert "train success" in err and "eval @ update 2" in err
    assert _ppo(monkeypatch, capsys, b, 3, "--init", str(bc_dir))[0] == 0
    assert sorted(p.name for p in (b / "state").iterdir()) == ["update_0000002", "update_0000003"]
    shutil.rmtree(b / "state" / "update_0000003")
    code, _, err = _run(
        monkeypatch, capsys, finetune, "ppo", *SCENE, "--out", str(b), "--resume",
        "--num-timesteps", str(4 * STEPS_PER_UPDATE),
    )  # fmt: skip
    assert code == 0, err
    assert "starting at update 2" in err

    rows_a, rows_b = _rows(a), _rows(b)
    assert [(r["kind"], r["update"]) for r in rows_a] == [
        ("eval", 0), ("train", 1), ("train", 2), ("eval", 2), ("train", 3), ("train", 4),
        ("eval", 4),
    ]  # fmt: skip
    assert rows_b == rows_a
    for which in ("final", "best"):
        ca, pa = load_mlp(a / which)
        cb, pb = load_mlp(b / which)
        assert ca.metadata["trained"]["update"] == cb.metadata["trained"]["update"]
        jax.tree.map(np.testing.assert_array_equal, pa, pb)
    # The actor moved (the run trained), from the clone it started at.
    _, init = load_mlp(bc_dir)
    _, final = load_mlp(a / "final")
    assert not np.array_equal(init["actor"]["params"]["_Dense_0"]["kernel"],
                              final["actor"]["params"]["_Dense_0"]["kernel"])  # fmt: skip
    png = a / "learning_curve.png"
    assert png.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    png.unlink()
    assert _run(monkeypatch, capsys, finetune, "curve", "--out", str(a))[0] == 0
    assert png.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    settings = json.loads((a / "run.json").read_text())
    assert settings["init"] == str(bc_dir) and settings["ppo"]["n_envs"] == 8

    # The checkpoints evaluate through the eval CLI.
    report = tmp_path / "r.json"
    code, out, _ = _run(
        monkeypatch, capsys, eval_cli, "--policy", f"mlp:{a / 'best'}", "--n-envs", "4",
        "--max-steps", "40", "--threads", "2", "--out", str(report),
    )  # fmt: skip
    assert code == 0 and "tabletop_push/mlp:" in out
    assert json.loads(report.read_text())["n_episodes"] == 4

    # A second new run into the same directory is refused.
    code, _, err = _ppo(monkeypatch, capsys, a, 4, "--init", str(bc_dir))
    assert code == 2 and "already holds a run" in err


def _one_line_error(code, err, needle):
    lines = err.strip().splitlines()
    assert code == 2 and len(lines) == 1 and lines[0].startswith("error: "), err
    assert needle in lines[0], err


def test_missing_or_corrupt_checkpoints_are_clear_errors(monkeypatch, capsys, tmp_path, bc_dir):
    out = tmp_path / "run"
    code, _, err = _ppo(monkeypatch, capsys, out, 2, "--init", str(tmp_path / "nope"))
    _one_line_error(code, err, "mlp checkpoint")
    assert not out.exists()

    code, _, err = _run(monkeypatch, capsys, finetune, "ppo", "--out", str(out), "--resume")
    _one_line_error(code, err, "no run in")

    corrupt = tmp_path / "corrupt"
    shutil.copytree(bc_dir, corrupt)
    data = max(
        (p for p in (corrupt / "params").rglob("*") if p.is_file()), key=lambda p: p.stat().st_size
    )
    data.write_bytes(data.read_bytes()[:-16])
    code, _, err = _run(
        monkeypatch, capsys, eval_cli, "--policy", f"mlp:{corrupt}", "--n-envs", "2",
        "--out", str(tmp_path / "r.json"),
    )  # fmt: skip
    _one_line_error(code, err, "is corrupt")
    assert not (tmp_path / "r.json").exists()
