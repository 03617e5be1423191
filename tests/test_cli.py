"""The eval CLI: the main job, listings, and every user mistake -> one line, exit 2, no file."""

import json
import subprocess
import sys

import pytest

from openral_mjx import eval as eval_cli


def run_cli(monkeypatch, capsys, *argv):
    monkeypatch.setattr(sys, "argv", ["openral_mjx.eval", *argv])
    with pytest.raises(SystemExit) as exc:
        eval_cli.main()
    out, err = capsys.readouterr()
    return exc.value.code, out, err


def test_small_eval_writes_report(monkeypatch, capsys, tmp_path):
    out_path = tmp_path / "rep.json"
    code, out, _ = run_cli(
        monkeypatch,
        capsys,
        "--n-envs",
        "4",
        "--max-steps",
        "3",
        "--policy",
        "zero",
        "--out",
        str(out_path),
        "--threads",
        "1",
    )
    assert code == 0
    assert "success 0.0% [0.0, 49.0]" in out and f"report: {out_path}" in out
    rep = json.loads(out_path.read_text())
    assert rep["n_episodes"] == 4 and rep["backend"] == "c"
    assert "--policy zero" in rep["command"] and "--backend c" in rep["command"]


def test_list(monkeypatch, capsys):
    code, out, _ = run_cli(monkeypatch, capsys, "--list")
    assert code == 0 and "tabletop_push" in out and "scripted" in out and "so101" in out


@pytest.mark.parametrize(
    "argv,needle",
    [
        (["--scene", "nope"], "unknown scene 'nope'; valid: tabletop_push"),
        (["--policy", "nope"], "unknown policy 'nope'; valid: random, scripted, zero"),
        (["--robot", "ur5"], "unknown robot 'ur5'; valid: so101"),
        (["--backend", "gpu"], "unknown backend 'gpu'; valid: auto, mjx, warp, c"),
        (["--opt", "goal_radiuss=0.1"], "unknown option for TabletopPushOptions 'goal_radiuss'"),
        (["--opt", "goal_radius"], "not of the form key=value"),
        (["--n-envs", "0"], "n_envs must be a positive integer, got 0"),
        (["--n-episodes", "-3"], "n_episodes must be a positive integer, got -3"),
        (["--max-steps", "0"], "max_steps must be a positive integer, got 0"),
        (["--config", "missing.yaml"], "config file 'missing.yaml' does not exist"),
        (["--robot-mjcf", "missing.xml"], "robot MJCF 'missing.xml' does not exist"),
        (["--threads", "0"], "threads must be >= 1, got 0"),
        (["--contacts-per-env", "0"], "contacts_per_env must be >= 1, got 0"),
    ],
)
def test_bad_input(monkeypatch, capsys, tmp_path, argv, needle):
    out_path = tmp_path / "rep.json"
    code, _out, err = run_cli(
        monkeypatch,
        capsys,
        *argv,
        "--out",
        str(out_path),
        "--max-steps" if "--max-steps" not in argv else "--seed",
        "2",
    )
    assert code == 2
    lines = err.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith("error: ") and needle in lines[0], err
    assert "Traceback" not in err
    assert not out_path.exists() and list(tmp_path.iterdir()) == []


def test_config_with_unknown_key(monkeypatch, capsys, tmp_path):
    cfg = tmp_path / "c.yaml"
    cfg.write_text("cube_size: 0.03\nbogus: 1\n")
    code, _, err = run_cli(monkeypatch, capsys, "--config", str(cfg), "--max-steps", "2")
    assert code == 2 and "'bogus'" in err and "cube_size" in err


def test_process_exit_code_and_no_traceback(tmp_path):
    """The real entry point, as a user runs it."""
    proc = subprocess.run(
        [sys.executable, "-m", "openral_mjx.eval", "--scene", "nope", "--out", str(tmp_path / "r")],
        capture_output=True,
        text=True,
        timeout=120,
    )
    assert proc.returncode == 2
    assert proc.stderr.strip() == "error: unknown scene 'nope'; valid: tabletop_push"
    assert not (tmp_path / "r").exists()


def test_warp_without_warp_lang(monkeypatch, capsys, tmp_path):
    import openral_mjx.physics.warp_backend as warp_backend

    monkeypatch.setattr(warp_backend, "warp_installed", lambda: False)
    out_path = tmp_path / "r.json"
    code, _, err = run_cli(monkeypatch, capsys, "--backend", "warp", "--out", str(out_path))
    assert code == 2 and not out_path.exists()
    assert err.strip() == (
        "error: backend 'warp' needs warp-lang; install it with pip install 'openral_mjx[warp]'"
        " (warp-lang)"
    )
