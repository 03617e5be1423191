"""The eval CLI: the main job, listings, and every user mistake -> one line, exit 2, no file."""

import json
import subprocess
import sys

import pytest
from cli_runs import run_cli

from openral_mjx import eval as eval_cli
from openral_mjx.policies import POLICIES
from openral_mjx.report import load_report
from openral_mjx.runner import processes
from openral_mjx.scenes import SCENES
from openral_mjx.stats import clopper_pearson_interval

EVERY_SCENE = ", ".join(sorted(SCENES.names()))  # what an unknown scene's error lists
EVERY_POLICY = ", ".join(sorted(POLICIES.names()))  # and an unknown policy's


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


def test_sequential_run_stops_at_the_target(monkeypatch, capsys, tmp_path):
    """Zero policy, 0 successes: the Clopper-Pearson half-width is 0.30 after 4 episodes and
    0.18 after 8, so a 0.2 target stops after the second chunk."""
    out_path = tmp_path / "seq.json"
    argv = ["--n-envs", "4", "--max-steps", "3", "--policy", "zero", "--threads", "1"]
    code, out, _ = run_cli(
        monkeypatch,
        capsys,
        *argv,
        "--target-halfwidth",
        "0.2",
        "--max-episodes",
        "12",
        "--out",
        str(out_path),
        "--no-breakdown",
    )
    assert code == 0
    assert "(sequential-exact 95%), 0/8 episodes" in out
    assert "sequential: stopped after 2 chunk(s) of 4, 8 of at most 12 episodes" in out
    assert "success by episode factor" not in out
    rep = load_report(out_path)
    assert rep.ci_method == "sequential-exact" and rep.n_episodes == len(rep.episodes) == 8
    assert rep.sequential.stopped == "target" and rep.sequential.looks == 2
    assert rep.ci_high == pytest.approx(clopper_pearson_interval(0, 8)[1])  # lowest outcome
    assert "--target-halfwidth 0.2 --max-episodes 12" in rep.command
    # The cap ends a run whose target is out of reach; the report says so.
    code, out, _ = run_cli(
        monkeypatch,
        capsys,
        *argv,
        "--target-halfwidth",
        "0.05",
        "--max-episodes",
        "8",
        "--out",
        str(out_path),
    )
    rep = load_report(out_path)
    assert code == 0 and rep.n_episodes == 8 and rep.sequential.stopped == "max_episodes"
    assert "reached --max-episodes before the target 0.05" in out
    assert "success by episode factor (equal-count bins, 95% Wilson):" in out


def test_eval_compare_with(monkeypatch, capsys, tmp_path):
    argv = ["--n-envs", "4", "--max-steps", "3", "--threads", "1", "--no-breakdown"]
    a, b = tmp_path / "a.json", tmp_path / "b.json"
    assert run_cli(monkeypatch, capsys, *argv, "--policy", "zero", "--out", str(a))[0] == 0
    code, out, _ = run_cli(
        monkeypatch, capsys, *argv, "--policy", "random", "--out", str(b), "--compare-with", str(a)
    )
    assert code == 0
    assert f"A: {a}  tabletop_push/zero on c: 0/4" in out
    assert f"B: {b}  tabletop_push/random on c: 0/4" in out
    assert "paired on 4 common seeds: both succeed 0, only A 0, only B 0, neither 4" in out
    assert out.strip().endswith(f"report: {b}")


def test_compare_with_another_initial_state_protocol_is_refused_before_running(
    monkeypatch, capsys, tmp_path
):
    """A LIBERO report of the standard protocol against a mirror run of the sampled one: their
    seeds start from different initial states, refused before anything is built."""
    argv = ["--n-envs", "2", "--max-steps", "2", "--threads", "1", "--no-breakdown"]
    a = tmp_path / "libero.json"
    assert run_cli(monkeypatch, capsys, *argv, "--policy", "zero", "--out", str(a))[0] == 0
    report = json.loads(a.read_text())
    a.write_text(json.dumps({**report, "scene": "libero", "task": "libero_object/0"}))
    mirror = ["--scene", "libero_mjx", "--task", "libero_object/0", "--policy", "zero"]
    out = tmp_path / "mirror.json"
    code, _, err = run_cli(
        monkeypatch,
        capsys,
        *mirror,
        "--opt",
        "protocol=sampled",
        "--compare-with",
        str(a),
        "--out",
        str(out),
    )
    assert code == 2, err
    assert "not comparable: option protocol 'standard'" in err and "vs 'sampled'" in err
    assert not out.exists()


def test_compare_with_another_scene_or_schema(monkeypatch, capsys, tmp_path):
    bad = tmp_path / "old.json"
    bad.write_text(json.dumps({"schema_version": "openral_mjx.eval_report/1"}))
    code, _, err = run_cli(monkeypatch, capsys, "--compare-with", str(bad), "--max-steps", "2")
    assert code == 2 and "schema 'openral_mjx.eval_report/1' is not supported" in err


def test_list(monkeypatch, capsys):
    code, out, _ = run_cli(monkeypatch, capsys, "--list")
    assert code == 0 and "so101_box, tabletop_push" in out and "scripted" in out and "so101" in out
    # each scene's backends, robot, tasks and suites, as registered
    assert "  libero: backends host; robot panda\n    --task  SUITE/INDEX" in out
    assert "    --suite libero_spatial, libero_object, libero_goal, libero_10, libero_90" in out
    assert "  metaworld_mjx: backends mjx, warp, c; robot sawyer\n" in out
    assert "  tabletop_push: backends mjx, warp, c; robot --robot or --robot-mjcf" in out


def test_task_and_suite_help_come_from_the_registry(monkeypatch, capsys):
    """--task/--suite help names every scene's tasks and suites, from its `SceneEntry`."""
    from openral_mjx.scenes import SCENES

    code, out, _ = run_cli(monkeypatch, capsys, "--help")
    flat = " ".join(out.replace("│", " ").split())
    assert code == 0 and "--list shows each scene's" in flat
    for name in SCENES.names():
        entry = SCENES.get(name)
        for text in (entry.tasks, ", ".join(entry.suite_names)):
            assert " ".join((text or "").split()) in flat, (name, text)


@pytest.mark.parametrize(
    "argv,needle",
    [
        (
            ["--scene", "nope"],
            f"unknown scene 'nope'; valid: {EVERY_SCENE}",
        ),
        (["--scene", "so101_box", "--robot", "ur5"], "scene 'so101_box' requires robot 'so101'"),
        (
            ["--scene", "so101_box", "--robot-mjcf", "arm.xml"],
            "scene 'so101_box' requires robot 'so101', not 'mjcf:arm.xml'",
        ),
        (["--scene", "so101_box", "--opt", "tube_diameter=0.03"], "must be < hole_diameter"),
        (
            ["--policy", "nope"],
            f"unknown policy 'nope'; valid: {EVERY_POLICY}",
        ),
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
        (["--devices", "0"], "devices must be >= 1, got 0"),
        (["--processes", "0"], "--processes must be >= 1, got 0"),
        (["--processes", "2"], "give --backend mjx or warp, not 'auto'"),
        (
            ["--processes", "2", "--backend", "warp", "--video", "1", "--devices", "1"],
            "--processes 2 does not combine with --video, --devices",
        ),
        (["--target-halfwidth", "0"], "target_halfwidth must lie in (0, 0.5), got 0.0"),
        (["--target-halfwidth", "0.5"], "target_halfwidth must lie in (0, 0.5), got 0.5"),
        (["--target-halfwidth", "nan"], "--target-halfwidth must be a finite number, got nan"),
        (["--max-episodes", "100"], "max_episodes caps a sequential run: give target_halfwidth"),
        (
            ["--n-episodes", "10", "--target-halfwidth", "0.1"],
            "n_episodes and target_halfwidth exclude each other",
        ),
        (
            ["--target-halfwidth", "0.1", "--max-episodes", "0"],
            "max_episodes must be a positive integer, got 0",
        ),
        (["--factor-bins", "0"], "factor_bins must be a positive integer, got 0"),
        (["--compare-with", "missing.json"], "report 'missing.json' does not exist"),
        (["--video", "-1"], "--video and --video-failures must be >= 0, got -1, 0"),
        (["--frames", "1"], "frames: scene 'tabletop_push' observes no sensors"),
        (
            ["--frames", "-1", "--opt", "obs_depth_cameras=[front]"],
            "frames must be >= 0, got -1",
        ),
        (
            ["--opt", "obs_depth_cameras=[top]"],
            "unknown camera 'top'; valid: overhead, front",
        ),
        (
            ["--video", "1", "--video-camera", "top"],
            "unknown camera 'top'; valid: overhead, front",
        ),
        (["--scene", "libero", "--backend", "c"], "scene 'libero' runs on backend host, not 'c'"),
        (["--backend", "host"], "scene 'tabletop_push' runs on a MuJoCo backend, not 'host'"),
        (["--scene", "libero", "--video", "1"], "scene 'libero' runs in host workers: drop"),
        (["--scene", "robosuite", "--frames", "1"], "scene 'robosuite' runs in host workers"),
        (["--suite", "libero_10"], "scene 'tabletop_push' has no task suites"),
        (["--scene", "libero", "--suite", "nope"], "unknown LIBERO suite 'nope'; valid:"),
        (
            ["--scene", "libero", "--suite", "libero_10", "--task", "libero_10/1"],
            "--suite runs every task of the suite: drop --task",
        ),
        (["--scene", "libero", "--suite", "libero_10", "--plots"], "drop --video/--plots"),
        (["--task-processes", "2"], "--task-processes runs the tasks of a --suite at once"),
        (
            ["--scene", "metaworld", "--suite", "mt10", "--task-processes", "0"],
            "--task-processes must be >= 1, got 0",
        ),
        (["--cluster", "auto"], "--cluster runs the tasks of a --suite, the points of a --sweep"),
        (
            ["--backend", "mjx", "--distributed", "auto", "--processes", "2"],
            "--distributed auto joins the processes a cluster's launcher started: drop --processes",
        ),
        (
            ["--backend", "c", "--distributed", "auto"],
            "--distributed auto shards envs over GPUs: give --backend mjx or warp, not 'c'",
        ),
        (
            [
                "--scene",
                "metaworld",
                "--suite",
                "mt10",
                "--cluster",
                "auto",
                "--task-processes",
                "2",
            ],
            "drop --task-processes/--processes",
        ),
        (
            ["--scene", "metaworld", "--suite", "mt10", "--cluster", "head:port"],
            "--cluster 'head:port' is not a Ray address; valid: local, auto, HOST:PORT",
        ),
        (["--scene", "libero", "--task", "libero_10/10"], "index 0..9"),
        (["--scene", "robosuite", "--task", "Stack"], "unknown robosuite task 'Stack'"),
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


def test_distributed_outside_a_launchers_job(monkeypatch, capsys, tmp_path):
    """`--distributed auto` in a process no launcher started: one line naming what was looked
    for, exit 2, before JAX would wait for peers that never come."""
    for names in processes.LAUNCHER_VARIABLES.values():
        for name in names:
            monkeypatch.delenv(name, raising=False)
    out = tmp_path / "rep.json"
    argv = ["--backend", "mjx", "--distributed", "auto", "--out", str(out)]
    code, _out, err = run_cli(monkeypatch, capsys, *argv)
    assert code == 2 and len(err.strip().splitlines()) == 1, err
    assert err.startswith("error: --distributed auto joins a job that a cluster's launcher")
    assert "SLURM_PROCID" in err and "OMPI_MCA_orte_hnp_uri" in err and not out.exists()


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
    assert proc.stderr.strip() == f"error: unknown scene 'nope'; valid: {EVERY_SCENE}"
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


def test_videos_and_plots_next_to_the_report(monkeypatch, capsys, tmp_path, gl):
    """30 steps are too few for the expert: every episode fails, so --video 1 and
    --video-failures 5 film the 4 seeds once each (and say there were only 4 failures), one
    frame per step from the reset state on."""
    import av

    out_path = tmp_path / "rep.json"
    argv = ["--n-envs", "4", "--max-steps", "30", "--threads", "1", "--no-breakdown"]
    flags = ["--video", "1", "--video-failures", "5", "--video-camera", "overhead", "--plots"]
    code, out, err = run_cli(monkeypatch, capsys, *argv, *flags, "--out", str(out_path))
    assert code == 0, err
    videos = tmp_path / "rep_videos"
    assert sorted(p.name for p in videos.iterdir()) == [f"seed{i}_failure.mp4" for i in range(4)]
    assert "note: 4 failed episode(s) to film, not 5" in out
    for p in videos.iterdir():
        assert f"video: {p} (failure at step 30)" in out
        with av.open(str(p)) as f:
            assert sum(1 for _ in f.decode(video=0)) == 31
    for name in ("success_by_factor", "episode_length", "reward"):
        assert f"plot: {tmp_path / f'rep_{name}.png'}" in out
        assert (tmp_path / f"rep_{name}.png").stat().st_size > 10_000
    assert load_report(out_path).n_episodes == 4


def test_no_gl_still_writes_the_report(monkeypatch, capsys, tmp_path):
    from openral_mjx.physics.gl import GLUnavailable

    def no_gl():
        raise GLUnavailable("no OpenGL backend can render here (egl: no display)")

    monkeypatch.setattr(eval_cli, "gl_backend", no_gl)
    out_path = tmp_path / "rep.json"
    argv = ["--n-envs", "4", "--max-steps", "3", "--threads", "1", "--policy", "zero"]
    argv += ["--video", "2"]
    code, out, err = run_cli(monkeypatch, capsys, *argv, "--out", str(out_path))
    assert code == 2 and f"report: {out_path}" in out
    assert err.strip() == (
        "error: cannot render videos: no OpenGL backend can render here (egl: no display)"
    )
    assert load_report(out_path).n_episodes == 4 and not (tmp_path / "rep_videos").exists()


def test_missing_viz_extra_names_the_install(monkeypatch, capsys, tmp_path):
    import openral_mjx.viz as viz

    monkeypatch.setitem(viz._MODULES, "no_such_module_av", "PyAV")
    out_path = tmp_path / "rep.json"
    code, _, err = run_cli(monkeypatch, capsys, "--plots", "--out", str(out_path))
    assert code == 2 and not out_path.exists()
    assert err.strip() == (
        "error: videos and plots need PyAV; install them with pip install 'openral_mjx[viz]'"
    )


def test_sensor_frames_next_to_the_report(monkeypatch, capsys, tmp_path):
    """--frames K: a depth camera in tabletop_push's observation, the first episode's depth
    images saved beside the report and referenced from it, the reproducing command kept."""
    from openral_mjx.evaluation.frames import load_frames

    out_path = tmp_path / "rep.json"
    argv = ["--n-envs", "2", "--max-steps", "3", "--policy", "zero", "--threads", "1"]
    opts = ["--opt", "obs_depth_cameras=[front]", "obs_depth_size=[8,6]"]
    code, out, err = run_cli(
        monkeypatch, capsys, *argv, *opts, "--frames", "1", "--out", str(out_path)
    )
    assert code == 0, err
    assert f"frames: {tmp_path / 'rep.frames.npz'}" in out
    report = load_report(out_path)
    assert "--frames 1" in report.command
    assert report.episodes[0].frames[0]["array"] == "seed0/depth_front"
    assert report.episodes[1].frames is None
    depth = load_frames(out_path, report)[0]["depth_front"]
    assert depth.shape == (4, 6, 8) and 0 < depth.min() < 3.0
