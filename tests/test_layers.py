"""The package's layers: every import points down docs/architecture.md's list, never up.

Read from the source (every `import`, function-level ones included), so a new module that
reaches up a layer fails here rather than growing a cycle later.
"""

from __future__ import annotations

import ast
from pathlib import Path

import openral_mjx

ROOT = Path(openral_mjx.__file__).parent
# Top to bottom, as docs/architecture.md lists them. Units on one line are peers
# that never import each other.
LAYERS = [
    {"eval.py", "compare.py", "bench.py", "finetune.py"},
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
    {"core", "__init__.py"},
]


def _unit(module: str) -> str:
    """The top-level subpackage or module of `openral_mjx.a.b` (`a`, or `a.py`)."""
    parts = module.split(".")
    if len(parts) == 1:
        return "__init__.py"
    return parts[1] if (ROOT / parts[1]).is_dir() else f"{parts[1]}.py"


def _imports(path: Path) -> set[str]:
    found = set()
    for node in ast.walk(ast.parse(path.read_text())):
        if (
            isinstance(node, ast.ImportFrom)
            and node.module
            and node.module.split(".")[0] == ("openral_mjx")
        ):
            if node.module == "openral_mjx":
                found |= {f"openral_mjx.{a.name}" for a in node.names}
            else:
                found.add(node.module)
        elif isinstance(node, ast.Import):
            found |= {a.name for a in node.names if a.name.split(".")[0] == "openral_mjx"}
    return found


def test_every_unit_has_a_layer():
    units = {p.name for p in ROOT.iterdir() if p.suffix == ".py" or (p / "__init__.py").exists()}
    assert units == set().union(*LAYERS), (
        "add the new module or package to LAYERS and docs/architecture.md"
    )


def test_imports_point_down():
    rank = {unit: i for i, layer in enumerate(LAYERS) for unit in layer}
    upward = []
    for path in sorted(ROOT.rglob("*.py")):
        module = ".".join(path.relative_to(ROOT.parent).with_suffix("").parts)
        here = _unit(module)
        for target in _imports(path):
            there = _unit(target)
            if there != here and rank[there] <= rank[here]:
                upward.append(f"{module} imports {target} ({here} -> {there})")
    assert upward == []
