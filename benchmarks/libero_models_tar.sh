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
.venv/bin/python - "${DRAWS:-0}" "$@" <<'EOF'
import sys

from openral_mjx.benchmarks.libero.assets import load_sampled, load_task, physics_spec

draws = int(sys.argv[1])
for task in sys.argv[2:]:
    physics_spec(load_task(task))  # the export, and the files/ its model reads
    if draws:
        load_sampled(task, draws)
EOF
root=$(.venv/bin/python -c "from openral_mjx.benchmarks.libero.assets import models_root; print(models_root())")
dirs=(files)
for t in "$@"; do dirs+=("$t"); done
mkdir -p .lm && tar cJf .lm/models.tar.xz -C "$(dirname "$root")" \
  "${dirs[@]/#/$(basename "$root")/}"
du -sh .lm/models.tar.xz
