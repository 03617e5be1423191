"""Bad input through every CLI, as a new user types it (issue 41): each case is refused while
the input is validated, before any scene is built or anything compiled, with exit code 2 and
exactly one line that names the bad value; nothing is written.

The CLIs run in process (`main(argv)`), with the first step after validation replaced by one
that fails the test, so a case that gets past validation shows up as an error here rather than
as a slow run. Two cases run as real processes, to see what a user sees.
"""

from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path

import pytest

from openral_mjx import bench, compare, finetune, plan
from openral_mjx import eval as eval_cli
from openral_mjx.training import runs

ROOT = Path(__file__).parents[1]
SAVED = ROOT / "benchmarks/2026-11-23-ci2core/rays/box_c_nodepth.json"
NOT_A_DIR = "/etc/hostname/x.json"  # under a file: no directory can be made there

# (CLI, argv, the text the one line must contain: the bad value). `{in}` is the folder of the
# case's input files (reports, YAML), made by `_inputs`.
EVAL = [
    (["--n-envs", "abc"], "'abc'"),
    (["--seed", "1.5"], "'1.5'"),
    (["--video"], "--video"),
    (["--nosuch-flag", "3"], "--nosuch-flag"),
    (["--plots", "yes"], "yes"),
    (["--seed", "18446744073709551616"], "18446744073709551616"),
    (["--seed", "4294967296"], "4294967296"),
    (["--seed", "-1"], "-1"),
    (["--n-envs", "1000000000000"], "1000000000000"),
    (["--n-episodes", "100000000"], "100000000"),
    (["--max-steps", "2000000"], "2000000"),
    (["--threads", "100000"], "100000"),
    (["--target-halfwidth", "nan"], "nan"),
    (["--target-halfwidth", "inf"], "inf"),
    (["--sweep", "friction=0.1:0.6:1000000000"], "1000000000"),
    (["--sweep", "friction=0.1:0.6:1"], "friction=0.1:0.6:1"),
    (["--randomize", "friction=0.3:inf"], "'inf'"),
    (["--randomize", "friction=nan"], "'nan'"),
    (["--randomize", "friction=0.3:abc"], "'abc'"),
    (["--opt", "cube_mass=abc"], "cube_mass='abc'"),
    (["--opt", "cube_mass=.inf"], "cube_mass=inf"),
    (["--opt", "cube_mass=-5e-2"], "cube_mass"),
    (["--config", "{in}/malformed.yaml"], "malformed.yaml"),
    (["--config", "{in}/object.yaml"], "python/object"),
    (["--config", "{in}"], "{in}' is a directory"),
    (["--task", "nosuch"], "'nosuch'"),
    (["--scene", "so101_box", "--task", "nosuch"], "'nosuch'"),
    (["--scene", "metaworld_mjx", "--task", "nosuch-v3"], "'nosuch-v3'"),
    (["--scene", "robosuite"], "zero, random"),
    (["--compare-with", "{in}"], "is a directory"),
    (["--compare-with", "{in}/successes_x.json"], "'x'"),
    (["--out", NOT_A_DIR], "/etc/hostname"),
    (["--batching", "sometimes"], "'sometimes'"),
    (["--factor-bins", "1000000000000"], "1000000000000"),
    (["--refill-every", "100000000000000000000"], "100000000000000000000"),
    (["--processes", "100000", "--backend", "mjx"], "100000"),
    (["--video", "100000000000000000000"], "100000000000000000000"),
    (["--frames", "100000000000000000000"], "100000000000000000000"),
    (["--scene", "metaworld", "--suite", "mt10", "--task-processes", "100000"], "100000"),
    (["--scene", "libero", "--suite", "libero_10,libero_100"], "'libero_100'"),
    (["--scene", "libero", "--suite", "libero_10,,libero_goal"], "empty suite name"),
    (["--scene", "metaworld_mjx", "--suite", "mt10,mt50"], "share tasks"),
    (["--scene", "metaworld", "--opt", "mujoco=pinned"], "mujoco='pinned'; valid: metaworld, ours"),
    (["--target-halfwidth", "0.1", "--max-episodes", "1000000000000000"], "1000000000000000"),
    (["--factor-bins", "x"], "'x'"),
    # a flag a suite cannot honour is refused, never recorded in the command and ignored
    (["--scene", "metaworld_mjx", "--suite", "mt10", "--factor-bins", "3"], "--factor-bins"),
    # --decide (issue 40): its design flags, its baseline and what it excludes
    (["--decide"], "--compare-with"),
    (["--margin", "0.05"], "--margin"),
    (
        ["--scene", "so101_box", "--compare-with", "{in}/good.json", "--decide", "--margin", "1.5"],
        "1.5",
    ),
    (
        ["--scene", "so101_box", "--compare-with", "{in}/good.json", "--decide", "--alpha", "0"],
        "got 0",
    ),
    (
        ["--scene", "so101_box", "--compare-with", "{in}/good.json", "--decide", "--spending", "x"],
        "'x'",
    ),
    (["--compare-with", "{in}/good.json", "--decide"], "'so101_box'"),
    (
        [
            "--scene",
            "so101_box",
            "--compare-with",
            "{in}/good.json",
            "--decide",
            "--n-episodes",
            "300",
        ],
        "--n-episodes 300",
    ),
    (
        ["--scene", "so101_box", "--compare-with", "{in}/good.json", "--decide", "--seed", "256"],
        "seed 256",
    ),
    (
        [
            "--scene",
            "so101_box",
            "--compare-with",
            "{in}/good.json",
            "--decide",
            "--target-halfwidth",
            "0.1",
        ],
        "--target-halfwidth",
    ),
    (
        [
            "--scene",
            "so101_box",
            "--compare-with",
            "{in}/good.json",
            "--decide",
            "--task",
            "nosuch",
        ],
        "'nosuch'",
    ),
]
COMPARE = [
    (["{in}/good.json", "{in}/good.json"], "same file"),
    (["{in}/good.json", "{in}/../in/./good.json"], "same file"),
    (["{in}/good.json", "{in}/successes_x.json"], "'x'"),
    (["{in}/good.json", "{in}/maybe.json"], "'maybe'"),
    (["{in}/good.json", "{in}/missing_field.json"], "field breakdown is missing"),
    (["{in}/good.json", "{in}/too_many.json"], "successes 999 > n_episodes"),
    (["{in}/good.json", "{in}/extra_field.json"], "unknown field bogus"),
    (["{in}/good.json", "{in}/not_json.json"], "not valid JSON"),
    (["{in}/good.json", "{in}"], "is a directory"),
    (["{in}/good.json", "{in}/nope.json"], "nope.json' does not exist"),
    (["{in}/good.json"], "compare needs two reports or more"),
    (["{in}/good.json", "{in}/good.json", "{in}/maybe.json"], "'maybe'"),
    (["{in}/good.json", "{in}/successes_x.json", "--plots", "{in}/good.json"], "is a file"),
    (["{in}/good.json", "{in}/good.json", "--confidence", "nan"], "nan"),
    (["{in}/good.json", "{in}/good.json", "--confidence", "abc"], "'abc'"),
]
PLAN = [
    (["compare", "--rate", "1.5", "--difference", "0.1"], "1.5"),
    (["compare", "--rate", "0.6", "--difference", "0.5"], "0.5"),
    (["compare", "--rate", "0.6", "--difference", "0.1", "--discordance", "0.01"], "0.01"),
    (["compare", "--rate", "0.6", "--difference", "0.1", "--power", "1"], "1.0"),
    (["compare", "--rate", "abc", "--difference", "0.1"], "'abc'"),
    (["compare", "--rate", "0.6", "--difference", "inf"], "inf"),
    (["compare", "--difference", "0.1", "--from", "{in}/good.json", "{in}/good.json"], "same file"),
    (["compare", "--difference", "0.1", "--from", "{in}/good.json", "{in}/maybe.json"], "'maybe'"),
    (["compare", "--difference", "0.1", "--from", "{in}/good.json"], "--from"),
    (["compare", "--rate", "0.6", "--difference", "0.1", "--max-seeds", "10**12"], "'10**12'"),
    (
        ["compare", "--rate", "0.6", "--difference", "0.1", "--max-seeds", "1000000000000"],
        "1000000000000",
    ),
    (["decide", "--difference", "0.3", "--discordance", "0.2"], "0.3"),
    (["decide", "--difference", "0.05", "--discordance", "0.2", "--looks-every", "0"], "got 0"),
    (["decide", "--difference", "0.05", "--discordance", "0.2", "--spending", "x"], "'x'"),
    (["decide", "--difference", "0.05", "--discordance", "0.2", "--power", "1"], "1.0"),
    (["decide", "--difference", "0.05", "--discordance", "0.2", "--margin", "2"], "2.0"),
    (["interval", "--halfwidth", "0.7"], "0.7"),
    (["interval", "--halfwidth", "0.03", "--method", "wald"], "'wald'"),
    (["nosuch"], "nosuch"),
]
BENCH = [
    (["--out", NOT_A_DIR], "/etc/hostname"),
    (["--out", "{in}"], "is a directory"),
    (["--n", "0"], "got 0"),
    (["--n", "64", "10000000000"], "10000000000"),
    (["--n", "abc"], "'abc'"),
    (["--episodes", "100000000"], "100000000"),
    (["--scene", "nope"], "'nope'"),
    (["--backend", "gpu"], "'gpu'"),
    (["--repeats", "inf"], "'inf'"),
    (["--warp-graphs", "cuda"], "'cuda'"),
    (["--ccd-contacts-per-env", "0"], "got 0"),
]
FINETUNE = [
    (["bc", "--out", "/etc/hostname/run"], "/etc/hostname"),
    (["bc", "--out", "{in}/good.json"], "is a file"),
    (["bc", "--lr", "nan"], "nan"),
    (["bc", "--lr", "abc"], "'abc'"),
    (["bc", "--n-envs", "1000000000000"], "1000000000000"),
    (["bc", "--seed", "18446744073709551616"], "18446744073709551616"),
    (["bc", "--task", "nosuch"], "'nosuch'"),
    (["bc", "--opt", "cube_mass=abc"], "'abc'"),
    (["bc", "--config", "{in}/malformed.yaml"], "malformed.yaml"),
    (["ppo", "--gamma", "inf"], "inf"),
    (["ppo", "--seed", "-1"], "-1"),
    (["ppo", "--out", "/etc/hostname/run"], "/etc/hostname"),
    (["ppo", "--eval-n-envs", "1000000000000"], "1000000000000"),
    (["nosuch"], "nosuch"),
]
CASES = [
    *((eval_cli, *c) for c in EVAL),
    *((compare, *c) for c in COMPARE),
    *((plan, *c) for c in PLAN),
    *((bench, *c) for c in BENCH),
    *((finetune, *c) for c in FINETUNE),
]


def _corrupt(good: dict, change) -> dict:
    data = json.loads(json.dumps(good))
    change(data)
    return data


def _inputs(folder: Path) -> Path:
    """The input files the cases name: a valid report, corrupt ones, broken YAML."""
    folder.mkdir()
    good = json.loads(SAVED.read_text())
    (folder / "good.json").write_text(json.dumps(good))
    for name, change in {
        "successes_x": lambda d: d.update(successes="x"),
        "maybe": lambda d: d["episodes"][0].update(success="maybe"),
        "missing_field": lambda d: d.pop("breakdown"),
        "too_many": lambda d: d.update(successes=999),
        "extra_field": lambda d: d.update(bogus=1),
    }.items():
        (folder / f"{name}.json").write_text(json.dumps(_corrupt(good, change)))
    (folder / "not_json.json").write_text('{"schema_version": ')
    (folder / "malformed.yaml").write_text("cube_size: [0.03\ncube_mass: 0.05\n")
    (folder / "object.yaml").write_text("cube_size: !!python/object:os.system {}\n")
    return folder


def _never(*args, **kwargs):
    raise AssertionError("validation let the case through: the run started")


@pytest.fixture
def cli(tmp_path, monkeypatch, capsys):
    """Run a CLI in process in an empty working directory; the step after validation fails.
    Returns (exit code, every line printed, the working directory's files)."""
    inputs = _inputs(tmp_path / "in")
    cwd = tmp_path / "cwd"
    cwd.mkdir()
    monkeypatch.chdir(cwd)
    monkeypatch.setattr(eval_cli, "build", _never)
    monkeypatch.setattr(bench, "make_scene", _never)
    monkeypatch.setattr(runs, "run_bc", _never)
    monkeypatch.setattr(runs, "prepare_ppo", _never)

    def run(module, argv):
        argv = [a.replace("{in}", str(inputs)) for a in argv]
        with pytest.raises(SystemExit) as exc:
            module.main(argv)
        out, err = capsys.readouterr()
        return exc.value.code, (out + err).splitlines(), sorted(cwd.rglob("*"))

    run.inputs = inputs
    return run


@pytest.mark.parametrize(
    "module, argv, named",
    CASES,
    ids=[f"{m.__name__.rpartition('.')[2]}:{' '.join(a)}" for m, a, _ in CASES],
)
def test_bad_input_is_one_line_exit_2_nothing_written(cli, module, argv, named):
    code, lines, written = cli(module, argv)
    assert code == 2, lines
    assert len(lines) == 1 and lines[0].startswith("error: "), lines
    assert "Traceback" not in lines[0]
    assert named.replace("{in}", str(cli.inputs)) in lines[0], lines[0]
    assert written == []


def test_every_seed_out_of_range_gets_the_same_message(cli):
    """Negative, 2**32 and 2**64 alike: one rule, one message (only the value differs)."""
    messages = set()
    for seed in ("-1", "2147483647", "4294967296", "18446744073709551616"):
        code, lines, _ = cli(eval_cli, ["--seed", seed])
        assert code == 2 and len(lines) == 1
        messages.add(lines[0].replace(seed, "S"))
    assert len(messages) == 1, messages


def test_mirror_without_policy_runs_its_benchmarks_expert(cli):
    """`--policy scripted` (the default) on metaworld_mjx, which has no scripted policy of its
    own, means MetaWorld's expert: validation passes (a note says so) and the run starts."""
    with pytest.raises(AssertionError, match="the run started"):
        cli(eval_cli, ["--scene", "metaworld_mjx", "--task", "reach-v3", "--max-steps", "2"])
    plan = eval_cli.validate(
        eval_cli.EvalArgs(scene="metaworld_mjx", task="reach-v3", out=Path("r.json"))
    )
    assert plan.args.policy == "metaworld-expert" and "--policy metaworld-expert" in plan.command


@pytest.mark.parametrize(
    "module, argv",
    [
        ("openral_mjx.eval", ["--n-envs", "abc"]),
        ("openral_mjx.compare", ["{in}/good.json", "{in}/maybe.json"]),
    ],
)
def test_as_a_process_one_line_no_traceback(tmp_path, module, argv):
    """What a user sees: tyro's error and a corrupt report, each one line on stderr, exit 2."""
    inputs = _inputs(tmp_path / "in")
    argv = [a.replace("{in}", str(inputs)) for a in argv]
    proc = subprocess.run(
        [sys.executable, "-m", module, *argv],
        capture_output=True,
        text=True,
        timeout=120,
        cwd=tmp_path,
        env={**os.environ, "JAX_PLATFORMS": "cpu", "PYTHONPATH": str(ROOT)},
    )
    assert proc.returncode == 2 and proc.stdout == ""
    assert len(proc.stderr.splitlines()) == 1 and proc.stderr.startswith("error: ")
    assert sorted(p.name for p in tmp_path.iterdir()) == ["in"]
