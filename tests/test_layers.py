"""The package's layers: every import points down docs/architecture.md's list, never up.

Read from the source (every `import`, function-level ones included), so a new module that
reaches up a layer fails here rather than growing a cycle later.

A benchmark folder (`benchmarks/<name>/`) spans layers: each module in it is named for its role
(`ROLES`), and the role is its unit, so `benchmarks/metaworld/agreement.py` is `evaluation`
and `benchmarks/metaworld/mirror/` is `scenes`. The same rule then holds inside the folder,
and for every module outside that imports one in it.
"""

from __future__ import annotations

import ast
import re
import subprocess
import sys
from pathlib import Path

import openral_mjx

ROOT = Path(openral_mjx.__file__).parent
# Top to bottom, as docs/architecture.md lists them. Units on one line are peers
# that never import each other.
LAYERS = [
    {"eval.py", "compare.py", "plan.py", "bench.py", "finetune.py"},
    {"cli"},
    {"viz", "training", "perf"},
    {"evaluation"},
    {"runner"},
    {"stats"},
    {"report"},
    {"scenes"},
    {"policies"},
    {"host"},
    {"physics"},
    {"raycast"},
    {"robots"},
    {"__init__.py"},  # the package's version, and the CPU codegen pin it sets on import
    {"core"},
]

# A benchmark folder's modules and subpackages by role, and the unit whose layer each takes.
# The folders' `__init__` files (and `benchmarks/__init__.py`) import nothing of the package:
# the worker env is imported in the benchmark's worker environment, which has no JAX.
BENCHMARKS = "benchmarks"
ROLES = {
    "agreement": "evaluation",
    "render": "viz",
    "host_scene": "scenes",
    "mirror": "scenes",
    "instructions": "scenes",  # data: the benchmark's task instructions, read by its scenes
    "expert": "policies",
    "worker_env": "host",
    "export": "host",  # runs in the worker environment too: what a mirror reads of the original
    "assets": "host",  # the export's cache: models and files a mirror and an expert read
}


def _unit(module: str) -> str:
    """The top-level subpackage or module of `openral_mjx.a.b` (`a`, or `a.py`); for a module
    of a benchmark folder, `openral_mjx.benchmarks.<name>.<role>...`, its role's unit."""
    parts = module.split(".")
    if len(parts) == 1:
        return "__init__.py"
    if parts[1] == BENCHMARKS:
        parts = [p for p in parts if p != "__init__"]
        # the package and its folders' `__init__`, which import nothing, or a module with no
        # role (`test_benchmark_folders_hold_only_roles` names it)
        return ROLES.get(parts[3], BENCHMARKS) if len(parts) > 3 else BENCHMARKS
    return parts[1] if (ROOT / parts[1]).is_dir() else f"{parts[1]}.py"


def _is_package(module: str) -> bool:
    return (ROOT.parent.joinpath(*module.split(".")) / "__init__.py").exists()


# "module:attribute" references (registered lazily, worker factories) count as imports
REFERENCE = re.compile(r"(openral_mjx(?:\.\w+)+):\w+")


def _imports(path: Path) -> set[str]:
    found = set()
    for node in ast.walk(ast.parse(path.read_text())):
        if isinstance(node, ast.Constant) and isinstance(node.value, str):
            if match := REFERENCE.fullmatch(node.value):
                found.add(match[1])
        elif (
            isinstance(node, ast.ImportFrom)
            and node.module
            and node.module.split(".")[0] == ("openral_mjx")
        ):
            if _is_package(node.module):  # `from openral_mjx.x import y`: y may be a module
                for a in node.names:
                    sub = f"{node.module}.{a.name}"
                    is_module = ROOT.parent.joinpath(*sub.split(".")).with_suffix(".py").exists()
                    found.add(sub if is_module or _is_package(sub) else node.module)
            else:
                found.add(node.module)
        elif isinstance(node, ast.Import):
            found |= {a.name for a in node.names if a.name.split(".")[0] == "openral_mjx"}
    return found


def test_every_unit_has_a_layer():
    units = {p.name for p in ROOT.iterdir() if p.suffix == ".py" or (p / "__init__.py").exists()}
    assert units - {BENCHMARKS} == set().union(*LAYERS), (
        "add the new module or package to LAYERS and docs/architecture.md"
    )


def test_benchmark_folders_hold_only_roles():
    """Every module in `benchmarks/<name>/` is one of `ROLES` (its layer), and the folders'
    `__init__` files import nothing of the package (see `BENCHMARKS`)."""
    unknown, importing = [], []
    for path in sorted((ROOT / BENCHMARKS).rglob("*.py")):
        parts = path.relative_to(ROOT / BENCHMARKS).with_suffix("").parts
        if len(parts) >= 2 and parts[1] not in ROLES and parts[1:] != ("__init__",):
            unknown.append(str(path.relative_to(ROOT)))
        if len(parts) <= 2 and parts[-1] == "__init__" and _imports(path):
            importing.append(str(path.relative_to(ROOT)))
    assert unknown == [], f"name each module of a benchmark folder for one of {sorted(ROLES)}"
    assert importing == []


def test_imports_point_down():
    rank = {unit: i for i, layer in enumerate(LAYERS) for unit in layer}
    upward = []
    for path in sorted(ROOT.rglob("*.py")):
        module = ".".join(path.relative_to(ROOT.parent).with_suffix("").parts)
        here = _unit(module)
        for target in _imports(path):
            there = _unit(target)
            if there == BENCHMARKS:  # the import-free `__init__` of a benchmark folder
                continue
            if here == BENCHMARKS or (there != here and rank[there] <= rank[here]):
                upward.append(f"{module} imports {target} ({here} -> {there})")
    assert upward == []


def test_the_clis_start_without_mjx():
    """`eval`, `compare` and `plan` import MJX and MuJoCo-Warp only for a run on `mjx` or `warp`:
    importing them defines Warp's kernels (~7 s on 2 cores), which a run on `c`, a host scene,
    a report or `--help` never needs (and every process a suite or a cluster starts pays)."""
    code = (
        "import sys, openral_mjx.eval, openral_mjx.compare, openral_mjx.plan; "
        "print(sorted({m.split('.')[1] for m in sys.modules if m.startswith('mujoco.')}))"
    )
    proc = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    assert "mjx" not in proc.stdout, proc.stdout
    # and the lazy names still resolve
    from openral_mjx import physics

    assert physics.MjxBackend.name == "mjx" and physics.WarpBackend.name == "warp"
