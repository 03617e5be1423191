#!/usr/bin/env bash
# LIBERO task exports for the GPU machine, which has no LIBERO worker environment: exports each
# TASK here (LIBERO's task construction in the lerobot-libero worker, ~25 s a task) with the
# files its physics model reads, DRAWS of its mass-seed draws if DRAWS is set (~2.5 s a draw
# on 2 cores), and packs them as .lm/models.tar.xz (git-ignored; 3.3 MB for one task of each
# suite). Run from the project root with the project's .venv:
#   DRAWS=200 bash benchmarks/libero_models_tar.sh libero_spatial/0 libero_10/0
# On the GPU machine `source benchmarks/gpu_setup.sh` in a call that carries .lm unpacks it into
#   OPENRAL_MJX_LIBERO_MODELS (default /tmp/libero_models), which it exports.
set -euo pipefail
[ $# -gt 0 ] || { echo "usage: [DRAWS=N] bash $0 TASK..." >&2; exit 2; }
grep -qx "/.lm/" .git/info/exclude 2>/dev/null || echo "/.lm/" >> .git/info/exclude
# the tasks' folders and only the files/ their physics models read: files/ grows with every task
# exported on this machine, and the visuals' textures are no physics
mapfile -t paths < <(.venv/bin/python - "${DRAWS:-0}" "$@" <<'EOF'
import sys
from pathlib import Path

from openral_mjx.benchmarks.libero.assets import load_sampled, load_task, models_root, physics_spec

draws, root = int(sys.argv[1]), models_root()
print(root.parent)  # first line: where the paths below start
kept = set()
for task in sys.argv[2:]:
    spec = physics_spec(load_task(task))  # the export, and the files/ its model reads
    kept |= {a.file for a in [*spec.meshes, *spec.textures] if a.file}
    if draws:
        load_sampled(task, draws)
    kept.add(str(root / task))
for path in sorted(kept):
    print(Path(path).relative_to(root.parent))
EOF
)
[ ${#paths[@]} -gt 1 ] || exit 1
mkdir -p .lm && tar cJf .lm/models.tar.xz -C "${paths[0]}" "${paths[@]:1}"
du -sh .lm/models.tar.xz
